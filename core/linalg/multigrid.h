#ifndef FIELDSPACE_CORE_LINALG_MULTIGRID_H_
#define FIELDSPACE_CORE_LINALG_MULTIGRID_H_

#include <cstdint>

#include "Eigen/Core"
#include "Eigen/SparseCore"
#include "absl/status/statusor.h"
#include "core/common/cancel.h"

namespace fieldspace {

struct MultigridOptions {
  // Each column stops at ||b - A x||_2 <= tolerance ||b||_2.
  double tolerance = 1e-10;
  // FailedPrecondition past this many conjugate gradient iterations (a system the hierarchy
  // does not precondition well: the caller may fall back to a factorization).
  int32_t max_iterations = 200;
  // Levels are coarsened until at most this many rows remain, solved by a dense Cholesky.
  int32_t coarsest_rows = 800;
  // Strength of connection: a_ij couples i and j when |a_ij| >= theta sqrt(a_ii a_jj).
  double strength_threshold = 0.08;
  const CancelFlag* cancel = nullptr;
};

struct MultigridStats {
  int32_t levels = 0;  // including the finest and the dense coarsest
  int32_t coarsest_rows = 0;
  double operator_complexity = 0;  // nonzeros summed over the levels / the finest's
  int32_t iterations = 0;          // conjugate gradient iterations, summed over the panels
  double relative_residual = 0;    // largest ||b - A x|| / ||b|| over the columns at the end
  double setup_seconds = 0;
  double solve_seconds = 0;
};

using MultigridRowMatrix = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

// Solves A X = B by conjugate gradients (one recurrence per column, the columns in panels of up
// to 8 that share each matrix product) preconditioned by one W-cycle of smoothed-aggregation
// algebraic multigrid (Vanek, Mandel and Brezina 1996: aggregates of strongly coupled
// neighbours, the constant on each aggregate smoothed by one damped Jacobi step as prolongation P,
// Galerkin coarse matrices P^T A P, a dense Cholesky at the coarsest level) with one Gauss-Seidel
// sweep before and one in the opposite order after each coarse correction, so the preconditioner
// is symmetric positive definite. The cycle runs in single precision (half the memory traffic);
// the recurrence and its products with A in double, so the tolerance may go far below float's.
//
// A: n x n, sparse, symmetric positive definite with both triangles stored (a scalar Laplacian
// with a pinned vertex per component, or any matrix whose near-kernel is the constants, which is
// what the aggregates' constant prolongation assumes). B: n x q, row-major; returns X likewise.
// Converges in a number of iterations nearly independent of n for such Laplacians on meshes;
// costs O(nnz(A) q) per iteration and O(nnz(A)) memory for the hierarchy.
// InvalidArgument on mismatched sizes, non-finite entries or a non-positive diagonal of A;
// FailedPrecondition when max_iterations pass first or a coarse matrix is not positive definite;
// Cancelled.
absl::StatusOr<MultigridRowMatrix> SolveMultigridCg(const Eigen::SparseMatrix<double>& A,
                                                    const MultigridRowMatrix& B,
                                                    const MultigridOptions& options = {},
                                                    MultigridStats* stats = nullptr);

}  // namespace fieldspace

#endif  // FIELDSPACE_CORE_LINALG_MULTIGRID_H_
