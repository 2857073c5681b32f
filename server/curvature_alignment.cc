#include "server/curvature_alignment.h"

#include <utility>

#include "absl/strings/str_cat.h"
#include "core/common/status_macros.h"

namespace fieldspace::server {

absl::StatusOr<AlignmentTarget> CurvatureAlignmentTarget(const ServedBasis& basis,
                                                         CurvatureEstimator estimator) {
  const FieldType& type = basis.basis->type;
  if (type.kind != FieldKind::kNField || (type.n != 2 && type.n != 4)) {
    return absl::InvalidArgumentError(absl::StrCat(
        "curvature alignment needs an n-field basis with n = 2 (maximum principal direction) or "
        "n = 4 (principal cross), not ",
        type.ToString()));
  }
  ShapeOperatorOptions curvature;
  curvature.estimator = estimator;
  ASSIGN_OR_RETURN(Eigen::VectorXd shape, ComputeShapeOperator(*basis.mesh, curvature));
  ASSIGN_OR_RETURN(CurvatureAlignedTargets targets,
                   ComputeCurvatureAlignedTargets(*basis.mesh, shape, type.n));
  // Anisotropy |k1 - k2| is 1/length: divided by its area-weighted mean it is dimensionless.
  const Eigen::VectorXd& area = basis.mesh->face_areas();
  const double mean = targets.weights.dot(area) / area.sum();
  if (!(mean > 0)) {
    return absl::FailedPreconditionError(
        "the surface has no curvature anisotropy anywhere (umbilic, e.g. a sphere): there is no "
        "direction to align to");
  }
  AlignmentTarget out;
  out.face_weights = targets.weights / mean;
  out.dofs = std::move(targets.dofs);
  return out;
}

absl::StatusOr<std::shared_ptr<const ReducedSmoother>> CurvatureAlignmentDataTerm(
    const ServedBasis& basis, CurvatureEstimator estimator, bool* computed) {
  if (computed != nullptr) *computed = false;
  if (basis.alignment_cache == nullptr) {
    return absl::InternalError("served basis without an alignment cache");
  }
  AlignmentCache& cache = *basis.alignment_cache;
  const int slot = estimator == CurvatureEstimator::kJetFit ? 0 : 1;
  std::lock_guard<std::mutex> lock(cache.mu);
  if (std::shared_ptr<const ReducedSmoother> held = cache.by_estimator[slot].lock()) return held;
  ASSIGN_OR_RETURN(AlignmentTarget target, CurvatureAlignmentTarget(basis, estimator));
  ASSIGN_OR_RETURN(ReducedSmoother smoother,
                   ReducedSmoother::Create(basis.system, target.dofs,
                                           absl::MakeConstSpan(target.face_weights.data(),
                                                               target.face_weights.size())));
  auto shared = std::make_shared<const ReducedSmoother>(std::move(smoother));
  cache.by_estimator[slot] = shared;
  if (computed != nullptr) *computed = true;
  return shared;
}

}  // namespace fieldspace::server
