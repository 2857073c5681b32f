// The CLI's application commands: curvature, smooth, align.

#include <algorithm>
#include <limits>

#include "absl/strings/str_cat.h"
#include "client/cli_commands.h"
#include "client/cli_flags.h"
#include "client/cli_json.h"

namespace fieldspace::client::cli {
namespace {

namespace v1 = ::fieldspace::v1;

// Prints a Smooth / Align answer (and writes --out) as `smooth` and `align` do.
int EmitSmoothed(Cli& cli, const CommandLine& a, const std::string& basis_id, bool scale_free,
                 const v1::SmoothResponse& response) {
  const std::vector<double> coefficients(response.coefficients().begin(),
                                         response.coefficients().end());
  if (int rc = cli.LiftToOut(a, basis_id, coefficients); rc != 0) return rc;
  const v1::SmoothTimings& t = response.timings();
  JsonWriter j;
  j.BeginObject();
  j.Key("basis_id").String(basis_id);
  j.Key("scale_free").Bool(scale_free);
  j.Key("timings").BeginObject();
  j.Key("rhs_ms").Number(t.rhs_ms());
  j.Key("weighted_mass_ms").Number(t.weighted_mass_ms());
  j.Key("factorize_ms").Number(t.factorize_ms());
  j.Key("solve_ms").Number(t.solve_ms());
  j.Key("total_ms").Number(t.total_ms());
  j.EndObject();
  EndSolution(j, a.Get("out"), response.has_singularities() ? &response.singularities() : nullptr,
              coefficients);
  cli.Emit(j);
  return 0;
}

}  // namespace

int Curvature(Cli& cli, const CommandLine& a) {
  const std::string out = GetString(a, "out");
  Cli::CheckFieldOut(out);
  v1::CurvatureRequest request;
  request.set_mesh_id(a.positional()[0]);
  const v1::FieldEncoding encoding = ParseEncoding(a);
  request.set_encoding(encoding);
  request.set_estimator(ParseEstimator(a));
  request.set_principal(a.Has("principal"));
  absl::StatusOr<std::vector<v1::CurvatureChunk>> chunks = cli.client().Curvature(request);
  if (!chunks.ok()) return cli.Fail(chunks.status(), "Curvature");
  FieldFile field;
  field.encoding = encoding;
  field.values_per_face = encoding == v1::FIELD_ENCODING_AMBIENT ? 6 : 3;
  std::vector<double> principal;
  double k_min = std::numeric_limits<double>::infinity();
  double k_max = -std::numeric_limits<double>::infinity();
  double server_ms = 0;
  for (const v1::CurvatureChunk& chunk : *chunks) {
    if (chunk.start_face() != field.num_faces()) {
      return cli.Fail(absl::DataLossError("Curvature chunks arrived out of order"), "Curvature");
    }
    field.values.insert(field.values.end(), chunk.tensor().values().begin(),
                        chunk.tensor().values().end());
    for (int i = 0; i < chunk.k1_size(); ++i) {
      k_min = std::min<double>(k_min, chunk.k2(i));
      k_max = std::max<double>(k_max, chunk.k1(i));
      principal.insert(principal.end(), {chunk.k1(i), chunk.k2(i)});
      for (int c = 0; c < 3; ++c) principal.push_back(chunk.d1(3 * i + c));
      for (int c = 0; c < 3; ++c) principal.push_back(chunk.d2(3 * i + c));
    }
    server_ms = chunk.server_ms();
  }
  if (int rc = cli.WriteFieldOut(out, field, "tensor", request.mesh_id()); rc != 0) return rc;
  if (a.Has("principal")) {
    FieldFile p;
    p.encoding = v1::FIELD_ENCODING_DOF;
    p.values_per_face = 8;
    p.values = std::move(principal);
    if (absl::Status st = WriteFieldText(GetString(a, "principal"), p, "principal curvatures");
        !st.ok()) {
      return cli.FailLocal(st);
    }
  }
  JsonWriter j;
  j.BeginObject();
  j.Key("mesh_id").String(request.mesh_id());
  j.Key("faces").Int(field.num_faces());
  j.Key("estimator").String(GetString(a, "estimator", "jet"));
  j.Key("encoding").String(encoding == v1::FIELD_ENCODING_AMBIENT ? "ambient" : "dof");
  j.Key("out").String(out);
  if (a.Has("principal")) {
    j.Key("principal").String(GetString(a, "principal"));
    j.Key("k_min").Number(k_min);
    j.Key("k_max").Number(k_max);
  }
  j.Key("server_ms").Number(server_ms);
  j.EndObject();
  cli.Emit(j);
  return 0;
}

int Smooth(Cli& cli, const CommandLine& a) {
  if (a.Has("out")) Cli::CheckFieldOut(GetString(a, "out"));
  absl::StatusOr<FieldFile> field = ReadFieldFile(a.positional()[1]);
  if (!field.ok()) return cli.FailLocal(field.status());
  v1::SmoothRequest request;
  request.set_basis_id(a.positional()[0]);
  request.mutable_field()->set_encoding(field->encoding);
  request.mutable_field()->mutable_values()->Add(field->values.begin(), field->values.end());
  SetWeights(a, "mu-s", request.mutable_weights());
  request.set_scale_free(!a.Has("raw-weights"));
  request.set_singularities(a.Has("singularities"));
  if (absl::Status st = ReadFaceWeights(a, request.mutable_face_weights()); !st.ok()) {
    return cli.FailLocal(st);
  }
  absl::StatusOr<v1::SmoothResponse> response = cli.client().Smooth(request);
  if (!response.ok()) return cli.Fail(response.status(), "Smooth");
  return EmitSmoothed(cli, a, request.basis_id(), request.scale_free(), *response);
}

int Align(Cli& cli, const CommandLine& a) {
  if (a.Has("out")) Cli::CheckFieldOut(GetString(a, "out"));
  v1::GetBasisRequest basis_request;
  basis_request.set_basis_id(a.positional()[0]);
  absl::StatusOr<v1::BasisInfo> basis = cli.client().GetBasis(basis_request);
  if (!basis.ok()) return cli.Fail(basis.status(), "GetBasis");
  if (a.Has("n") && (basis->field().kind() != v1::FIELD_KIND_NFIELD ||
                     ParseInt(a, "n", 0) != basis->field().n())) {
    return cli.FailLocal(absl::InvalidArgumentError(
        absl::StrCat("--n ", ParseInt(a, "n", 0), " does not match the basis's field type ",
                     FieldKindName(basis->field()), " (align uses the basis's n)")));
  }
  v1::AlignRequest request;
  request.set_basis_id(a.positional()[0]);
  SetWeights(a, "smooth-mu", request.mutable_weights());
  request.set_estimator(ParseEstimator(a));
  request.set_singularities(a.Has("singularities"));
  absl::StatusOr<v1::SmoothResponse> response = cli.client().Align(request);
  if (!response.ok()) return cli.Fail(response.status(), "Align");
  return EmitSmoothed(cli, a, request.basis_id(), true, *response);
}

}  // namespace fieldspace::client::cli
