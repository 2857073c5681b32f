#include "server/mesh_intake.h"

#include <utility>

#include "absl/strings/str_cat.h"
#include "core/common/status_macros.h"

namespace fieldspace::server {

MeshIntake::MeshIntake(Registry* registry, std::string what, WorkGrant grant)
    : registry_(registry), what_(std::move(what)), grant_(std::move(grant)) {}

absl::Status MeshIntake::HoldAtLeast(int64_t bytes) {
  if (bytes <= grant_.bytes()) return absl::OkStatus();
  ASSIGN_OR_RETURN(WorkGrant more, registry_->AdmitWork(bytes - grant_.bytes(), what_));
  grant_.Merge(std::move(more));
  return absl::OkStatus();
}

void MeshIntake::AdmitArraysOf(MeshReadOptions* options, int64_t text_bytes) {
  options->reserve_memory = [this, text_bytes](int64_t array_bytes) {
    return HoldAtLeast(text_bytes + array_bytes);
  };
}

absl::StatusOr<MeshRecord> MeshIntake::Add(MeshReadResult parsed, const std::string& name) {
  const int64_t peak =
      CreateMeshPeakBytes(parsed.arrays.vertices.rows(), parsed.arrays.faces.rows());
  grant_.ShrinkTo(peak);
  if (peak > grant_.bytes()) {
    ASSIGN_OR_RETURN(WorkGrant more,
                     registry_->AdmitWork(peak - grant_.bytes(),
                                          absl::StrCat(what_, " (validating its ",
                                                       parsed.arrays.faces.rows(), " triangles)")));
    grant_.Merge(std::move(more));
  }
  return registry_->AddMesh(std::move(parsed.arrays), name,
                            static_cast<int32_t>(parsed.polygons_triangulated));
}

}  // namespace fieldspace::server
