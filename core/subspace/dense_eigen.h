#ifndef FIELDSPACE_CORE_SUBSPACE_DENSE_EIGEN_H_
#define FIELDSPACE_CORE_SUBSPACE_DENSE_EIGEN_H_

#include <cstdint>

#include "Eigen/Core"
#include "absl/status/statusor.h"
#include "core/common/cancel.h"

namespace fieldspace {

// Dense symmetric eigensolvers that can be interrupted. Eigen's SelfAdjointEigenSolver runs for
// seconds at n = 1500 without a way to stop it; these do the same three steps (Householder
// tridiagonalization, implicit symmetric QR with Wilkinson shifts, back-transformation) with a
// cancellation check at every column / QR step / block, so that a cancelled request stops within
// milliseconds. Accuracy is that of Eigen's solver (same algorithm; same deflation criterion).

struct DenseEigenResult {
  Eigen::VectorXd values;   // the lowest `count`, ascending
  Eigen::MatrixXd vectors;  // n x count (empty unless requested)
};

// Lowest `count` eigenpairs of the symmetric matrix `a` (only its lower triangle is read; `a` is
// overwritten). Vectors orthonormal. InvalidArgument for a non-square matrix, count outside
// [1, n] or non-finite entries; Cancelled when *cancel becomes true; Internal when QR does not
// converge.
absl::StatusOr<DenseEigenResult> LowestSymmetricEigenpairs(Eigen::MatrixXd& a, int64_t count,
                                                           bool vectors, const CancelFlag* cancel);

// Lowest `count` solutions of S y = lambda M y (S symmetric, M symmetric positive definite; lower
// triangles read), vectors M-orthonormal. Errors as above, and FailedPrecondition when M is not
// positive definite.
absl::StatusOr<DenseEigenResult> LowestGeneralizedEigenpairs(const Eigen::MatrixXd& S,
                                                             const Eigen::MatrixXd& M,
                                                             int64_t count, bool vectors,
                                                             const CancelFlag* cancel);

}  // namespace fieldspace

#endif  // FIELDSPACE_CORE_SUBSPACE_DENSE_EIGEN_H_
