#include "server/record_convert.h"

#include "absl/strings/str_cat.h"
#include "core/common/status_macros.h"
#include "server/proto_convert.h"

namespace fieldspace::server {

v1::BuildPhase PhaseToProto(BuildStage stage) {
  switch (stage) {
    case BuildStage::kQueued:
      return v1::BUILD_PHASE_QUEUED;
    case BuildStage::kOperator:
      return v1::BUILD_PHASE_OPERATOR;
    case BuildStage::kSampling:
      return v1::BUILD_PHASE_SAMPLING;
    case BuildStage::kRegions:
      return v1::BUILD_PHASE_REGIONS;
    case BuildStage::kEigensolve:
      return v1::BUILD_PHASE_EIGENSOLVE;
    case BuildStage::kAssembly:
      return v1::BUILD_PHASE_ASSEMBLY;
    case BuildStage::kPrecompute:
      return v1::BUILD_PHASE_PRECOMPUTE;
    case BuildStage::kSaving:
      return v1::BUILD_PHASE_SAVING;
    case BuildStage::kDone:
      return v1::BUILD_PHASE_DONE;
  }
  return v1::BUILD_PHASE_UNSPECIFIED;
}

void MeshInfoFromRecord(const MeshRecord& r, bool loaded, v1::MeshInfo* p) {
  p->set_id(r.id);
  p->set_name(r.name);
  p->set_num_vertices(r.num_vertices);
  p->set_num_faces(r.num_faces);
  p->set_num_edges(r.num_edges);
  p->set_num_components(r.num_components);
  p->set_num_boundary_loops(r.num_boundary_loops);
  p->set_euler_characteristic(r.euler_characteristic);
  p->set_genus(r.genus);
  p->set_total_area(r.total_area);
  p->set_dropped_unreferenced_vertices(r.dropped_unreferenced_vertices);
  p->set_polygons_triangulated(r.polygons_triangulated);
  p->set_loaded(loaded);
  p->set_created_unix_ms(r.created_unix_ms);
}

void BasisInfoFromStatus(const BasisStatus& s, v1::BasisInfo* p) {
  const BasisRecord& r = s.record;
  p->set_id(r.id);
  p->set_mesh_id(r.key.mesh_id);
  FieldTypeToProto(r.key.field, p->mutable_field());
  p->set_dimension(r.key.dimension);
  p->set_sigma(r.key.sigma);
  p->set_fields_per_region(r.key.fields_per_region);
  p->set_seed(r.key.seed);
  p->set_coarse_dimension(r.key.coarse_dimension);
  p->set_kernel_columns(r.key.kernel_columns);
  p->set_quality(static_cast<v1::BasisQuality>(r.key.quality));
  p->set_adaptive(r.key.weights_hash != 0);
  p->set_dofs(r.dofs);
  if (s.ready) {
    p->set_state(v1::BASIS_STATE_READY);
    p->set_columns(r.columns);
    p->set_num_regions(r.num_regions);
    p->set_radius(r.radius);
    p->set_nnz(r.nnz);
    p->set_build_seconds(r.build_seconds);
    p->set_loaded(s.loaded);
    p->set_memory_bytes(s.memory_bytes);
    p->set_created_unix_ms(r.created_unix_ms);
    p->set_phase(v1::BUILD_PHASE_DONE);
    p->set_fraction(1.0);
  } else {
    p->set_state(v1::BASIS_STATE_BUILDING);
    p->set_phase(PhaseToProto(s.progress.stage));
    p->set_fraction(s.progress.fraction);
    p->set_overall_fraction(OverallFraction(s.progress.stage, s.progress.fraction));
  }
}

void BasisInfoFromRecord(const BasisRecord& r, v1::BasisInfo* p) {
  BasisStatus s;
  s.record = r;
  s.ready = true;
  BasisInfoFromStatus(s, p);
}

absl::StatusOr<BuildRequest> BuildRequestFromProto(const v1::BuildBasisRequest& p) {
  BuildRequest build;
  build.key.mesh_id = p.mesh_id();
  ASSIGN_OR_RETURN(build.key.field, FieldTypeFromProto(p.field()));
  build.key.dimension = p.dimension();
  build.key.sigma = p.has_sigma() ? p.sigma() : 40.0;
  build.key.fields_per_region = p.fields_per_region();
  build.key.seed = p.seed();
  build.key.coarse_dimension = p.coarse_dimension();
  build.key.kernel_columns = !p.has_kernel_columns() || p.kernel_columns();
  switch (p.quality()) {
    case v1::BASIS_QUALITY_PAPER:
      build.key.quality = BasisQuality::kPaper;
      break;
    case v1::BASIS_QUALITY_LOW_MODES:
      build.key.quality = BasisQuality::kLowModes;
      break;
    case v1::BASIS_QUALITY_SMOOTH:
      build.key.quality = BasisQuality::kSmooth;
      break;
    default:
      return absl::InvalidArgumentError(
          absl::StrCat("unknown basis quality ", static_cast<int>(p.quality())));
  }
  build.face_weights =
      Eigen::Map<const Eigen::VectorXd>(p.face_weights().data(), p.face_weights().size());
  return build;
}

}  // namespace fieldspace::server
