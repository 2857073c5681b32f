#ifndef FIELDSPACE_CORE_LINALG_LOCAL_CHOLESKY_H_
#define FIELDSPACE_CORE_LINALG_LOCAL_CHOLESKY_H_

#include <cstdint>
#include <memory>
#include <vector>

#include "absl/status/status.h"
#include "core/common/cancel.h"

struct cholmod_factor_struct;

namespace fieldspace {
namespace linalg_internal {
class CholmodCommon;
}  // namespace linalg_internal

// A symmetric positive definite matrix in compressed sparse columns, upper triangle only (every
// stored entry has row <= column; each column holds its diagonal), int32 indices. Rows within a
// column need not be sorted; duplicates are not allowed.
struct UpperCsc {
  int32_t n = 0;
  std::vector<int32_t> outer;  // n + 1
  std::vector<int32_t> inner;
  std::vector<double> values;
};

// Sparse Cholesky P A P^T = L L^T for the many small, one-off local systems of the basis
// construction (one per region, 10^3-10^5 rows), solved a few dozen times each.
//
// Why not CHOLMOD's numeric factorization: our platform's BLAS is the unoptimized reference BLAS,
// so CHOLMOD's supernodal kernels run at ~1 GFlop/s and its simplicial one is no faster. CHOLMOD
// computes the AMD ordering and the supernodal structure; the numeric factorization here is a
// left-looking supernodal method (as CHOLMOD's) on Eigen's vectorized dense kernels, sequential:
// the regions themselves run in parallel. One instance per thread, reused for region after region
// (its workspace only grows).
class LocalCholesky {
 public:
  LocalCholesky();
  ~LocalCholesky();
  LocalCholesky(const LocalCholesky&) = delete;
  LocalCholesky& operator=(const LocalCholesky&) = delete;

  // Orders, analyzes and factors `A`. FailedPrecondition when A is not numerically positive
  // definite, ResourceExhausted when CHOLMOD runs out of memory, Cancelled when `cancel` (checked
  // every few hundred supernodes) is set.
  absl::Status Factorize(const UpperCsc& A, const CancelToken& cancel);

  // X <- A^-1 X in place; X is n x p, column-major with leading dimension n.
  void SolveInPlace(double* X, int32_t p);

  int32_t rows() const { return n_; }
  // Nonzeros of L (supernodal storage, including the zeros it keeps) and flops of the last
  // factorization, for diagnostics.
  int64_t factor_nonzeros() const { return static_cast<int64_t>(lx_.size()); }
  double flops() const { return flops_; }

 private:
  void FreeSymbolic();

  std::unique_ptr<linalg_internal::CholmodCommon> common_;
  cholmod_factor_struct* symbolic_ = nullptr;
  int32_t n_ = 0;
  double flops_ = 0;
  // Permuted lower triangle of A (CSC), the supernodal values of L, and workspace.
  std::vector<int32_t> c_outer_, c_inner_, pinv_, super_map_, map_, head_, next_, lpos_;
  std::vector<double> c_values_, lx_, update_, xp_;
};

}  // namespace fieldspace

#endif  // FIELDSPACE_CORE_LINALG_LOCAL_CHOLESKY_H_
