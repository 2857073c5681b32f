// The CLI's commands on a basis's subspace: project, solve, lift, eigen, smoothest,
// singularities.

#include "absl/strings/str_cat.h"
#include "client/cli_commands.h"
#include "client/cli_flags.h"
#include "client/cli_json.h"

namespace fieldspace::client::cli {

namespace v1 = ::fieldspace::v1;

int Project(Cli& cli, const CommandLine& a) {
  absl::StatusOr<FieldFile> field = ReadFieldFile(a.positional()[1]);
  if (!field.ok()) return cli.FailLocal(field.status());
  v1::ProjectRequest request;
  request.set_basis_id(a.positional()[0]);
  request.mutable_field()->set_encoding(field->encoding);
  request.mutable_field()->mutable_values()->Add(field->values.begin(), field->values.end());
  absl::StatusOr<v1::ProjectResponse> response = cli.client().Project(request);
  if (!response.ok()) return cli.Fail(response.status(), "Project");
  JsonWriter j;
  j.BeginObject();
  j.Key("basis_id").String(request.basis_id());
  j.Key("relative_error").Number(response->relative_error());
  j.Key("seconds").Number(response->seconds());
  j.Key("coefficients");
  WriteNumbers(j, response->coefficients());
  j.EndObject();
  cli.Emit(j);
  return 0;
}

int Solve(Cli& cli, const CommandLine& a) {
  if (a.Has("out")) Cli::CheckFieldOut(GetString(a, "out"));
  const std::string constraints_path = GetString(a, "constraints");
  absl::StatusOr<std::string> text = ReadFile(constraints_path);
  if (!text.ok()) return cli.FailLocal(text.status());
  std::vector<v1::ConstraintGroup> groups;  // the designer's tools
  absl::StatusOr<std::vector<v1::Constraint>> constraints = ParseConstraints(*text, &groups);
  if (!constraints.ok()) {
    return cli.FailLocal(absl::InvalidArgumentError(
        absl::StrCat(constraints_path, ": ", constraints.status().message())));
  }
  v1::SolveRequest request;
  request.set_basis_id(a.positional()[0]);
  SetWeights(a, "mu-s", request.mutable_weights());
  request.set_raw_weights(a.Has("raw-weights"));
  request.set_biharmonic(ParseBiharmonic(a));
  request.set_singularities(a.Has("singularities"));
  for (v1::Constraint& c : *constraints) *request.add_constraints() = std::move(c);
  for (v1::ConstraintGroup& g : groups) *request.add_constraint_groups() = std::move(g);
  absl::StatusOr<v1::SolveResponse> response = cli.client().Solve(request);
  if (!response.ok()) return cli.Fail(response.status(), "Solve");
  std::vector<double> coefficients(response->coefficients().begin(),
                                   response->coefficients().end());
  if (int rc = cli.LiftToOut(a, request.basis_id(), coefficients); rc != 0) return rc;
  JsonWriter j;
  j.BeginObject();
  j.Key("basis_id").String(request.basis_id());
  j.Key("num_constraints").Int(request.constraints_size());
  j.Key("backward_error").Number(response->backward_error());
  j.Key("iterations").Int(response->iterations());
  j.Key("timings").BeginObject();
  j.Key("solve_ms").Number(response->timings().solve_ms());
  j.Key("total_ms").Number(response->timings().total_ms());
  j.EndObject();
  EndSolution(j, a.Get("out"), response->has_singularities() ? &response->singularities() : nullptr,
              coefficients);
  cli.Emit(j);
  return 0;
}

int Lift(Cli& cli, const CommandLine& a) {
  if (a.Has("out")) Cli::CheckFieldOut(GetString(a, "out"));
  absl::StatusOr<std::vector<double>> coefficients =
      ReadNumbersFile(a.positional()[1], ParseMode(a));
  if (!coefficients.ok()) return cli.FailLocal(coefficients.status());
  const v1::FieldEncoding encoding = ParseEncoding(a);
  if (a.Has("out") == a.Has("faces")) {
    throw UsageError("lift needs exactly one of --out FIELD_FILE and --faces F1,F2,...");
  }
  if (a.Has("out")) {
    const std::string out = GetString(a, "out");
    if (int rc = cli.LiftToFile(a.positional()[0], *coefficients, encoding, out); rc != 0) {
      return rc;
    }
    JsonWriter j;
    j.BeginObject().Key("basis_id").String(a.positional()[0]).Key("out").String(out);
    j.EndObject();
    cli.Emit(j);
    return 0;
  }
  v1::LiftRequest request;
  request.set_basis_id(a.positional()[0]);
  request.mutable_coefficients()->Add(coefficients->begin(), coefficients->end());
  request.set_encoding(encoding);
  for (int32_t f : ParseFaceList(GetString(a, "faces"))) request.add_faces(f);
  absl::StatusOr<std::vector<v1::FieldChunk>> chunks = cli.client().Lift(request);
  if (!chunks.ok()) return cli.Fail(chunks.status(), "Lift");
  JsonWriter j;
  j.BeginObject().Key("basis_id").String(request.basis_id()).Key("faces").BeginArray();
  for (const v1::FieldChunk& chunk : *chunks) WriteFaceValues(j, chunk.field());
  j.EndArray().EndObject();
  cli.Emit(j);
  return 0;
}

int Eigen(Cli& cli, const CommandLine& a) {
  v1::EigenfieldsRequest request;
  request.set_basis_id(a.positional()[0]);
  const int64_t count = ParseInt(a, "count", 0);
  if (count < 1 || count > INT32_MAX) throw UsageError("--count must be a positive integer");
  request.set_count(static_cast<int32_t>(count));
  absl::StatusOr<v1::EigenfieldsResponse> response = cli.client().Eigenfields(request);
  if (!response.ok()) return cli.Fail(response.status(), "Eigenfields");
  JsonWriter j;
  j.BeginObject();
  j.Key("basis_id").String(request.basis_id());
  j.Key("seconds").Number(response->seconds());
  j.Key("eigenvalues");
  WriteNumbers(j, response->eigenvalues());
  if (a.Has("coefficients")) {
    j.Key("coefficients").BeginArray();
    const int d = response->dimension();
    for (int i = 0; d > 0 && i < response->eigenvalues_size(); ++i) {
      j.BeginArray();
      for (int c = 0; c < d; ++c) j.Number(response->coefficients(i * d + c));
      j.EndArray();
    }
    j.EndArray();
  }
  j.EndObject();
  cli.Emit(j);
  return 0;
}

int Smoothest(Cli& cli, const CommandLine& a) {
  if (a.Has("out")) Cli::CheckFieldOut(GetString(a, "out"));
  v1::EigenfieldsRequest request;
  request.set_basis_id(a.positional()[0]);
  request.set_count(1);
  absl::StatusOr<v1::EigenfieldsResponse> response = cli.client().Eigenfields(request);
  if (!response.ok()) return cli.Fail(response.status(), "Eigenfields");
  const std::vector<double> coefficients(response->coefficients().begin(),
                                         response->coefficients().end());
  if (int rc = cli.LiftToOut(a, request.basis_id(), coefficients); rc != 0) return rc;
  JsonWriter j;
  j.BeginObject();
  j.Key("basis_id").String(request.basis_id());
  // The field is M-normalized (unit L2 norm); its Dirichlet energy x^T (U^T S U) x is the lowest
  // reduced eigenvalue.
  j.Key("energy").Number(response->eigenvalues(0));
  j.Key("seconds").Number(response->seconds());
  EndSolution(j, a.Get("out"), nullptr, coefficients);
  cli.Emit(j);
  return 0;
}

int Singularities(Cli& cli, const CommandLine& a) {
  absl::StatusOr<std::vector<double>> coefficients =
      ReadNumbersFile(a.positional()[1], ParseMode(a));
  if (!coefficients.ok()) return cli.FailLocal(coefficients.status());
  v1::SingularitiesRequest request;
  request.set_basis_id(a.positional()[0]);
  request.mutable_coefficients()->Add(coefficients->begin(), coefficients->end());
  request.set_zero_tolerance(ParseDouble(a, "zero-tolerance", 0.0));
  absl::StatusOr<v1::SingularitiesResponse> response = cli.client().Singularities(request);
  if (!response.ok()) return cli.Fail(response.status(), "Singularities");
  JsonWriter j;
  j.BeginObject();
  j.Key("basis_id").String(request.basis_id());
  WriteSingularityFields(j, *response);
  j.EndObject();
  cli.Emit(j);
  return 0;
}

}  // namespace fieldspace::client::cli
