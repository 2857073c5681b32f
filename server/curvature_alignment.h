#ifndef FIELDSPACE_SERVER_CURVATURE_ALIGNMENT_H_
#define FIELDSPACE_SERVER_CURVATURE_ALIGNMENT_H_

// Curvature alignment, an application on a served basis: the target of Align and of a Design
// session's curvature data term.

#include <memory>
#include <mutex>

#include "Eigen/Core"
#include "absl/status/statusor.h"
#include "core/operators/curvature.h"
#include "core/subspace/smoothing.h"
#include "server/served_basis.h"

namespace fieldspace::server {

// The curvature-aligned target of an n-field basis with n = 2 (maximum principal direction) or
// n = 4 (principal cross): unit representation vectors per face (`dofs`) and their weights, the
// anisotropy |k1 - k2| divided by its area-weighted mean (dimensionless, like the scale-free
// weights). Used by Align and by Design's data term. InvalidArgument for other bases;
// FailedPrecondition where the surface has no anisotropy anywhere.
struct AlignmentTarget {
  Eigen::VectorXd dofs;
  Eigen::VectorXd face_weights;
};
absl::StatusOr<AlignmentTarget> CurvatureAlignmentTarget(const ServedBasis& basis,
                                                         CurvatureEstimator estimator);

// The data term (a ReducedSmoother of the basis's system) of CurvatureAlignmentTarget, computed
// once per estimator while any caller holds it (ServedBasis::alignment_cache); thread-safe.
// `computed` (optional): whether this call computed it.
absl::StatusOr<std::shared_ptr<const ReducedSmoother>> CurvatureAlignmentDataTerm(
    const ServedBasis& basis, CurvatureEstimator estimator, bool* computed = nullptr);

struct AlignmentCache {
  std::mutex mu;  // held while a data term is computed: concurrent opens wait for one
  std::weak_ptr<const ReducedSmoother> by_estimator[2];
};

}  // namespace fieldspace::server

#endif  // FIELDSPACE_SERVER_CURVATURE_ALIGNMENT_H_
