#ifndef FIELDSPACE_CORE_LINALG_LOCAL_CHOLESKY_H_
#define FIELDSPACE_CORE_LINALG_LOCAL_CHOLESKY_H_

#include <cstdint>
#include <vector>

#include "absl/status/status.h"
#include "core/common/cancel.h"

namespace fieldspace {

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
// Why not CHOLMOD: our platform's BLAS is the unoptimized reference BLAS, so CHOLMOD's supernodal
// kernels run at ~1 GFlop/s and its simplicial one is no faster; and its analysis around the
// ordering (transposes, a copy, a second postorder) cost as much as AMD itself on these small
// systems. Here the ordering is AMD's (amd_2 on the pattern of A + A^T) or one the caller
// derives from AMD on a part of A (MinimumDegreeOrder, BlockMinimumDegreeOrder), the analysis
// the elimination tree, column counts and fundamental supernodes of the permuted matrix, and the
// numeric factorization a left-looking supernodal method (as CHOLMOD's) on Eigen's vectorized
// dense kernels, sequential: the regions themselves run in parallel. One instance per thread,
// reused for region after region (its workspace only grows).
class LocalCholesky {
 public:
  LocalCholesky();
  ~LocalCholesky();
  LocalCholesky(const LocalCholesky&) = delete;
  LocalCholesky& operator=(const LocalCholesky&) = delete;

  // Orders, analyzes and factors `A`. FailedPrecondition when A is not numerically positive
  // definite, ResourceExhausted when it is too large for 32-bit indices, Cancelled when `cancel`
  // (checked every few hundred supernodes) is set. A system of more than kReleaseScratchRows rows
  // gives back the analysis' and the factorization's scratch once factored: the solves do not read
  // it, and on the coarse levels' regions of up to ~1.5M rows it would otherwise stay beside the
  // factor through the eigensolve (179 MiB of the 1.38M-face low-modes build's peak;
  // bench/RESULTS.md, Session 28).
  //
  // With `order` (a permutation of A's rows: row k of the factored system is row (*order)[k] of
  // A, up to a postorder of the elimination tree) that order is factored instead of AMD's, e.g.
  // one induced from MinimumDegreeOrder of a block of A (HodgeLocalOperator). InvalidArgument
  // when it is not a permutation of A's rows.
  absl::Status Factorize(const UpperCsc& A, const CancelToken& cancel,
                         const std::vector<int32_t>* order = nullptr);
  static constexpr int32_t kReleaseScratchRows = 1 << 18;

  // AMD's fill-reducing order of the leading n x n block of A (the pattern of that block's
  // A + A^T): (*order)[k] is its k-th row eliminated. Uses this instance's workspace, which the
  // next Factorize overwrites. ResourceExhausted as Factorize.
  absl::Status MinimumDegreeOrder(const UpperCsc& A, int32_t n, std::vector<int32_t>* order);
  // AMD's order of the graph of A's blocks of `block` consecutive rows (two blocks adjacent when
  // any of their rows are), each block's rows kept together and in order: for systems with
  // several unknowns per mesh element, whose rows AMD would only find indistinguishable after
  // reading block^2 times the entries. InvalidArgument unless block >= 1 divides A.n.
  absl::Status BlockMinimumDegreeOrder(const UpperCsc& A, int32_t block,
                                       std::vector<int32_t>* order);

  // X <- A^-1 X in place; X is n x p, column-major with leading dimension n.
  void SolveInPlace(double* X, int32_t p);
  // The same for right-hand sides already in the factored system's order and row-major: row k
  // (of P A P^T, i.e. row permutation()[k] of A) at x + k p. No copies: for callers that number
  // their unknowns by inverse_permutation() once and keep their vectors that way.
  void SolvePermutedInPlace(double* x, int32_t p) const;

  int32_t rows() const { return n_; }
  // The fill-reducing order of the last factorization: row k of the factored system is row
  // permutation()[k] of A, and row i of A is row inverse_permutation()[i] of the factored system.
  const std::vector<int32_t>& permutation() const { return perm_; }
  const std::vector<int32_t>& inverse_permutation() const { return pinv_; }
  // Entries of L's supernodal storage (its nonzeros and the upper triangles of the diagonal
  // blocks) and flops (the sum of its squared column counts) of the last factorization, for
  // diagnostics.
  int64_t factor_nonzeros() const { return static_cast<int64_t>(lx_.size()); }
  double flops() const { return flops_; }

 private:
  // The pattern of the leading n x n block of A + A^T without the diagonal, as CSC, into
  // adj_outer_ and adj_. ResourceExhausted when AMD's workspace for it would pass 32-bit indices.
  absl::Status BuildAdjacency(const UpperCsc& A, int32_t n);
  // AMD on adj_outer_ / adj_ (n nodes) into `order`.
  void Amd(int32_t n, std::vector<int32_t>* order);
  // The ordering (AMD's, or `order` when given) and the supernodal structure below, and C.
  absl::Status Analyze(const UpperCsc& A, const std::vector<int32_t>* order);
  // C = P A P^T (lower triangle, CSC) for perm_; sets pinv_.
  void PermuteLower(const UpperCsc& A);
  // Frees everything but the factor, its order and the solves' scratch.
  void ReleaseScratch();

  int32_t n_ = 0;
  double flops_ = 0;
  // The fill-reducing permutation (row k of the factored system is row perm_[k] of A) and its
  // inverse; the elimination tree and column counts of L; its supernodes: the first column of
  // each (super_, nsuper_ + 1 entries), the offsets of their row indices in ls_ (lpi_) and of
  // their values in lx_ (lpx_).
  std::vector<int32_t> perm_, pinv_, parent_, colcount_, super_, lpi_, ls_;
  std::vector<int64_t> lpx_;
  int32_t nsuper_ = 0;
  // Permuted lower triangle of A (CSC), the supernodal values of L, and workspace.
  std::vector<int32_t> c_outer_, c_inner_, super_map_, map_, head_, next_, lpos_;
  std::vector<int32_t> len_, amd_work_, iw_, adj_outer_, adj_;
  std::vector<double> c_values_, lx_, update_, xp_;
  UpperCsc quotient_;  // BlockMinimumDegreeOrder's graph of blocks (pattern only)
};

}  // namespace fieldspace

#endif  // FIELDSPACE_CORE_LINALG_LOCAL_CHOLESKY_H_
