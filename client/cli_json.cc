#include "client/cli_json.h"

#include "absl/strings/str_cat.h"

namespace fieldspace::client::cli {

namespace v1 = ::fieldspace::v1;

std::string FieldKindName(const v1::FieldType& t) {
  switch (t.kind()) {
    case v1::FIELD_KIND_VECTOR:
      return "vector";
    case v1::FIELD_KIND_NFIELD:
      return absl::StrCat("nfield", t.n());
    case v1::FIELD_KIND_TENSOR:
      return "tensor";
    default:
      return "unspecified";
  }
}

const char* PhaseName(v1::BuildPhase phase) {
  switch (phase) {
    case v1::BUILD_PHASE_QUEUED:
      return "queued";
    case v1::BUILD_PHASE_OPERATOR:
      return "operator";
    case v1::BUILD_PHASE_SAMPLING:
      return "sampling";
    case v1::BUILD_PHASE_REGIONS:
      return "regions";
    case v1::BUILD_PHASE_EIGENSOLVE:
      return "eigensolve";
    case v1::BUILD_PHASE_ASSEMBLY:
      return "assembly";
    case v1::BUILD_PHASE_PRECOMPUTE:
      return "precompute";
    case v1::BUILD_PHASE_SAVING:
      return "saving";
    case v1::BUILD_PHASE_DONE:
      return "done";
    default:
      return "unspecified";
  }
}

void WriteMeshInfo(JsonWriter& j, const v1::MeshInfo& m) {
  j.BeginObject();
  j.Key("id").String(m.id());
  j.Key("name").String(m.name());
  j.Key("num_vertices").Int(m.num_vertices());
  j.Key("num_faces").Int(m.num_faces());
  j.Key("num_edges").Int(m.num_edges());
  j.Key("num_components").Int(m.num_components());
  j.Key("num_boundary_loops").Int(m.num_boundary_loops());
  j.Key("euler_characteristic").Int(m.euler_characteristic());
  j.Key("genus").Int(m.genus());
  j.Key("total_area").Number(m.total_area());
  j.Key("dropped_unreferenced_vertices").Int(m.dropped_unreferenced_vertices());
  j.Key("polygons_triangulated").Int(m.polygons_triangulated());
  j.Key("loaded").Bool(m.loaded());
  j.Key("created_unix_ms").Int(m.created_unix_ms());
  j.EndObject();
}

void WriteBasisInfo(JsonWriter& j, const v1::BasisInfo& b) {
  j.BeginObject();
  j.Key("id").String(b.id());
  j.Key("mesh_id").String(b.mesh_id());
  j.Key("field").String(FieldKindName(b.field()));
  j.Key("dimension").Int(b.dimension());
  j.Key("sigma").Number(b.sigma());
  j.Key("fields_per_region").Int(b.fields_per_region());
  j.Key("seed").Int(static_cast<int64_t>(b.seed()));
  j.Key("coarse_dimension").Int(b.coarse_dimension());
  j.Key("kernel_columns").Bool(b.kernel_columns());
  j.Key("quality").String(b.quality() == v1::BASIS_QUALITY_LOW_MODES ? "low-modes"
                          : b.quality() == v1::BASIS_QUALITY_SMOOTH  ? "smooth"
                                                                     : "paper");
  j.Key("adaptive").Bool(b.adaptive());
  j.Key("state").String(b.state() == v1::BASIS_STATE_READY ? "ready" : "building");
  j.Key("dofs").Int(b.dofs());
  if (b.state() == v1::BASIS_STATE_READY) {
    j.Key("columns").Int(b.columns());
    j.Key("num_regions").Int(b.num_regions());
    j.Key("radius").Number(b.radius());
    j.Key("nnz").Int(b.nnz());
    j.Key("build_seconds").Number(b.build_seconds());
    j.Key("loaded").Bool(b.loaded());
    j.Key("memory_bytes").Int(b.memory_bytes());
    j.Key("created_unix_ms").Int(b.created_unix_ms());
  } else {
    j.Key("phase").String(PhaseName(b.phase()));
    j.Key("fraction").Number(b.fraction());
  }
  j.EndObject();
}

void WriteSingularity(JsonWriter& j, const v1::Singularity& s) {
  j.BeginObject().Key("vertex").Int(s.vertex()).Key("index").Number(s.turns());
  j.Key("position");
  WriteNumbers(j, s.position());
  j.EndObject();
}

void WriteSingularityFields(JsonWriter& j, const v1::SingularitiesResponse& r) {
  j.Key("n").Int(r.n());
  j.Key("singularities").BeginArray();
  for (const v1::Singularity& s : r.singularities()) WriteSingularity(j, s);
  j.EndArray();
  j.Key("index_sum").Number(r.index_sum());
  j.Key("euler_characteristic").Int(r.euler_characteristic());
  j.Key("boundary_vertices").Int(r.boundary_size());
  j.Key("undefined_vertices").Int(r.undefined_vertices_size());
}

void WriteFaceValues(JsonWriter& j, const v1::FieldValues& values) {
  const int n = values.faces_size();
  const int vpf = n == 0 ? 0 : values.values_size() / n;
  for (int i = 0; i < n; ++i) {
    j.BeginObject().Key("face").Int(values.faces(i)).Key("value").BeginArray();
    for (int c = 0; c < vpf; ++c) j.Number(values.values(i * vpf + c));
    j.EndArray().EndObject();
  }
}

void EndSolution(JsonWriter& j, const std::optional<std::string>& out,
                 const v1::SingularitiesResponse* singularities,
                 const std::vector<double>& coefficients) {
  if (out.has_value()) j.Key("out").String(*out);
  if (singularities != nullptr) {
    j.Key("singularities").BeginObject();
    WriteSingularityFields(j, *singularities);
    j.EndObject();
  }
  j.Key("coefficients");
  WriteNumbers(j, coefficients);
  j.EndObject();
}

}  // namespace fieldspace::client::cli
