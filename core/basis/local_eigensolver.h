#ifndef FIELDSPACE_CORE_BASIS_LOCAL_EIGENSOLVER_H_
#define FIELDSPACE_CORE_BASIS_LOCAL_EIGENSOLVER_H_

#include <cstdint>

#include "Eigen/Core"
#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "core/common/cancel.h"

namespace fieldspace::basis_internal {

// The local eigenproblem of one region (eq. 7): S_bar phi = lambda phi with S_bar = V^T S V
// (n x n, symmetric positive semi-definite; positive definite whenever the region misses part of
// its component, by the implied Dirichlet condition), seen through two operations.
class LocalOperator {
 public:
  virtual ~LocalOperator() = default;
  virtual int32_t size() const = 0;
  // Y = S_bar X for X n x p.
  virtual void ApplyStiffness(const Eigen::MatrixXd& X, Eigen::MatrixXd* Y) = 0;
  // Prepares ApplyShiftInverse (typically a sparse Cholesky factorization); called once, and
  // only for problems too big for the dense path.
  virtual absl::Status PrepareShiftInverse(const CancelToken& cancel) = 0;
  // Y = (S_bar + tau I)^-1 X (up to rounding) for X n x p, tau = shift() > 0.
  virtual void ApplyShiftInverse(const Eigen::MatrixXd& X, Eigen::MatrixXd* Y) = 0;
  // Y = (S_bar + tau I)^-1 X and SY = S_bar Y. Operators that get S_bar Y as a by-product
  // override this (it is the costlier part of each iteration otherwise).
  virtual void ApplyShiftInverseAndStiffness(const Eigen::MatrixXd& X, Eigen::MatrixXd* Y,
                                             Eigen::MatrixXd* SY) {
    ApplyShiftInverse(X, Y);
    ApplyStiffness(*Y, SY);
  }
  virtual double shift() const = 0;
};

struct LocalEigenOptions {
  int32_t count = 2;  // m: lowest eigenpairs wanted, 1 <= m <= n
  // Extra block vectors beyond m: they make the convergence of the m-th pair depend on the gap
  // to the (m + guard + 1)-th eigenvalue rather than the (m + 1)-th.
  int32_t guard = 1;
  // Converged when ||S_bar x_i - theta_i x_i|| <= tolerance * (theta_i + tau) for all i < m
  // (unit x_i): eigenvector errors ~ tolerance, eigenvalue errors ~ tolerance^2 (relative).
  double tolerance = 1e-5;
  int32_t max_iterations = 60;
  // Problems with at most this many unknowns are solved densely.
  int32_t dense_max_size = 200;
  uint64_t seed = 0;  // start vectors
  // Optional n x k start vectors (k <= m + guard), e.g. smooth guesses of the lowest fields; the
  // remaining block columns start random. Not owned.
  const Eigen::MatrixXd* initial = nullptr;
};

struct LocalEigenResult {
  Eigen::VectorXd values;   // m, ascending
  Eigen::MatrixXd vectors;  // n x m, orthonormal columns
  int32_t iterations = 0;   // LOBPCG iterations (0 on the dense path)
  bool dense = false;
  bool lanczos_fallback = false;  // LOBPCG did not converge; Spectra's shift-invert Lanczos did
};

// The m lowest eigenpairs of the local problem. Method: dense for tiny problems; otherwise
// LOBPCG (block size m + guard) preconditioned with the exact shift-inverse (S_bar + tau I)^-1,
// which converges in ~8-12 iterations to 1e-5 on mesh regions; if it has not converged within
// max_iterations, Spectra's shift-invert Lanczos with the same inverse. Errors: Cancelled when
// `cancel` is set, errors of PrepareShiftInverse, FailedPrecondition (advising a larger d) when
// neither method converged.
absl::StatusOr<LocalEigenResult> SolveLocalEigenproblem(LocalOperator& op,
                                                        const LocalEigenOptions& options,
                                                        const CancelToken& cancel);

}  // namespace fieldspace::basis_internal

#endif  // FIELDSPACE_CORE_BASIS_LOCAL_EIGENSOLVER_H_
