#ifndef FIELDSPACE_CORE_LINALG_SUPERNODAL_CHOLESKY_H_
#define FIELDSPACE_CORE_LINALG_SUPERNODAL_CHOLESKY_H_

#include <cstdint>
#include <memory>
#include <utility>
#include <vector>

#include "Eigen/Core"
#include "Eigen/SparseCore"
#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/types/span.h"
#include "core/common/cancel.h"

namespace fieldspace {

// Sparse Cholesky factorization for the reduced systems (d x d, d up to a few ten thousand) that
// interactive sessions refactorize whenever the energy weights change.
//
// Why not CHOLMOD's numeric factorization: the reduced matrices are small but dense-ish (100-400
// nonzeros per row at d = 2000), so nearly all the work is in a few dense fronts of 500-1000
// rows, and CHOLMOD hands those to the system BLAS, which on our platform is the unoptimized
// reference BLAS (~1 GFlop/s). Here CHOLMOD only computes the fill-reducing ordering and the
// supernodal structure (once per sparsity pattern); the numeric factorization is a multifrontal
// method whose dense kernels are Eigen's blocked, vectorized ones, parallelized with oneTBB over
// the supernodal tree and inside large fronts. That is 5-10x faster here.

struct SupernodalAnalyzeOptions {
  // Try all of CHOLMOD's orderings (AMD, METIS, nested dissection variants) and keep the one
  // with the fewest flops: ~10x the analysis time, typically 20-30% fewer flops per
  // factorization. Worth it when the analysis is shared by many factorizations.
  bool thorough = false;
};

// Fill-reducing ordering and supernodal structure of one symmetric sparsity pattern. Immutable
// after Analyze(): share it (read-only, thread-safe) between all factorizations of matrices with
// exactly that pattern.
class SupernodalSymbolic {
 public:
  // `pattern`: n x n, n >= 1, structurally symmetric, both triangles stored, compressed
  // column-major with sorted row indices (Eigen's default after makeCompressed()); values are
  // ignored. Every diagonal entry must be stored. InvalidArgument otherwise; ResourceExhausted
  // when CHOLMOD runs out of memory.
  static absl::StatusOr<std::shared_ptr<const SupernodalSymbolic>> Analyze(
      const Eigen::SparseMatrix<double>& pattern, const SupernodalAnalyzeOptions& options = {});

  int64_t rows() const { return n_; }
  // Stored entries of the analyzed pattern (both triangles): the length of a values array.
  int64_t pattern_nonzeros() const { return static_cast<int64_t>(pattern_inner_.size()); }
  // Nonzeros of the lower-triangular factor L, counting the zeros that supernodal storage keeps.
  int64_t factor_nonzeros() const { return factor_nonzeros_; }
  // Floating-point operations of one numeric factorization (CHOLMOD's estimate).
  double flops() const { return flops_; }
  int32_t num_supernodes() const { return static_cast<int32_t>(super_begin_.size()) - 1; }
  // Bytes held by the analysis.
  int64_t memory_bytes() const;
  // True when `A` has exactly the analyzed pattern (same size and stored positions).
  bool SamePattern(const Eigen::SparseMatrix<double>& A) const;

 private:
  friend class SupernodalFactor;
  friend class SupernodalMatrix;
  SupernodalSymbolic() = default;

  // Supernode s: the permuted columns [c0, c0 + nc); nr rows, the nc diagonal ones first, then
  // the m = nr - nc rows below[0 .. m); its nr x nc column-major panel starts at offset `panel`.
  struct Supernode {
    int64_t c0, nc, nr, m;
    const int32_t* below;
    int64_t panel;
  };
  Supernode supernode(int64_t s) const;
  // P b and P^T y (n values each).
  Eigen::VectorXd ToPermuted(const Eigen::VectorXd& b) const;
  Eigen::VectorXd FromPermuted(const Eigen::VectorXd& y) const;

  int64_t n_ = 0;
  std::vector<int32_t> pattern_outer_;  // n + 1, copy of the analyzed pattern's column pointers
  std::vector<int32_t> pattern_inner_;  // its row indices
  std::vector<int32_t> perm_;           // perm_[new] = old (fill-reducing permutation)
  std::vector<int32_t> iperm_;          // iperm_[old] = new
  std::vector<int32_t> col_super_;      // supernode of each permuted column
  // Supernode s owns the permuted columns [super_begin_[s], super_begin_[s + 1]); its rows are
  // rows_[rows_begin_[s] .. rows_begin_[s + 1]), ascending, starting with its own columns.
  std::vector<int32_t> super_begin_;
  std::vector<int64_t> rows_begin_;
  std::vector<int32_t> rows_;
  // For each off-diagonal row of supernode s (same indexing as rows_, entries before the off-
  // diagonal part unused), its position in the row list of parent_[s].
  std::vector<int32_t> relative_map_;
  std::vector<int32_t> parent_;          // supernodal elimination tree, -1 at roots
  std::vector<int32_t> children_begin_;  // CSR lists of children
  std::vector<int32_t> children_;
  std::vector<int32_t> roots_;
  std::vector<int32_t> first_descendant_;  // subtree of s = supernodes [first_descendant_[s], s]
  bool postordered_ = false;               // whether the contiguous-subtree property holds
  std::vector<double> subtree_flops_;      // work below and at each supernode (for scheduling)
  std::vector<int64_t> panel_begin_;       // offsets of each supernode's nr x nc panel of L
  // Scatter of the values array into the fronts: entries [assembly_begin_[s], [s + 1]) name a
  // value index and its offset in supernode s's nr x nr column-major front (lower triangle).
  std::vector<int64_t> assembly_begin_;
  std::vector<int64_t> assembly_value_;
  std::vector<int64_t> assembly_offset_;
  int64_t factor_nonzeros_ = 0;
  double flops_ = 0;
};

struct SupernodalFactorOptions {
  // Each diagonal entry is multiplied by (1 + diagonal_shift) before factoring: a scale-invariant
  // Tikhonov regularization for positive semi-definite matrices (0: none). Must be >= 0.
  double diagonal_shift = 0.0;
  bool parallel = true;  // oneTBB over the supernodal tree and inside large fronts
  // Checked before each front: Cancelled (and an unusable factor) once *cancel is true. Not owned.
  const CancelFlag* cancel = nullptr;
};

// Numeric factorization P A P^T = L L^T of a symmetric positive definite matrix with an analyzed
// pattern. Solve() is const and safe to call concurrently; Factorize/Refactorize are not.
class SupernodalFactor {
 public:
  // `values`: the matrix's stored values in the order of the analyzed pattern (pattern_nonzeros()
  // entries; e.g. A.valuePtr() of a matrix for which SamePattern() is true). InvalidArgument for a
  // wrong length, non-finite values or a bad option; FailedPrecondition when the matrix (with the
  // shift) is not numerically positive definite; Cancelled (options.cancel).
  static absl::StatusOr<SupernodalFactor> Factorize(
      std::shared_ptr<const SupernodalSymbolic> symbolic, absl::Span<const double> values,
      const SupernodalFactorOptions& options = {});
  // Convenience: `A` must have the analyzed pattern (InvalidArgument otherwise).
  static absl::StatusOr<SupernodalFactor> Factorize(
      std::shared_ptr<const SupernodalSymbolic> symbolic, const Eigen::SparseMatrix<double>& A,
      const SupernodalFactorOptions& options = {});

  // New values on the same pattern. On error the object is left unusable (is_valid() false).
  absl::Status Refactorize(absl::Span<const double> values,
                           const SupernodalFactorOptions& options = {});

  // B <- A^-1 B in place; B is n x m (any m >= 0). Precondition: is_valid().
  void SolveInPlace(Eigen::Ref<Eigen::MatrixXd> B) const;
  Eigen::VectorXd Solve(const Eigen::VectorXd& b) const;

  // The two halves of a solve, in the permuted numbering (P A P^T = L L^T, so
  // A^-1 b = PermuteOut(L^-T L^-1 PermuteIn(b))), for callers that keep L^-1-transformed vectors:
  // with W = L^-1 P R^T, R A^-1 R^T = W^T W and A^-1 R^T nu = P^T L^-T (W nu).
  Eigen::VectorXd PermuteIn(const Eigen::VectorXd& b) const;   // P b
  Eigen::VectorXd PermuteOut(const Eigen::VectorXd& y) const;  // P^T y
  void ForwardInPlace(Eigen::Ref<Eigen::VectorXd> y) const;    // y <- L^-1 y
  void BackwardInPlace(Eigen::Ref<Eigen::VectorXd> y) const;   // y <- L^-T y
  // y = L^-1 P b for a sparse b: vals[q] at (original) row rows[q], repeated rows summed; rows
  // must be in [0, n). Visits only the supernodes on the elimination-tree paths from those rows
  // to the roots (L^-1 P b is zero elsewhere), so a few nonzeros cost a fraction of a full
  // substitution. Returns the number of rows of L visited (the work done). y: n values, written.
  int64_t ForwardSparse(absl::Span<const int32_t> rows, absl::Span<const double> vals,
                        Eigen::Ref<Eigen::VectorXd> y) const;
  // The same for k sparse columns at once (column j: vals[j][q] at row rows[j][q]): one pass over
  // the union of their reaches with the k columns as one block, so each supernode costs one
  // matrix-matrix product instead of k matrix-vector products. Y: n x k, written. With
  // `reach_rows`, the ranges [begin, end) of permuted rows outside which the result is zero (the
  // columns of the reach's supernodes), ascending and merged; only those rows of Y are written
  // then (callers that keep the reach skip zeroing the rest).
  void ForwardSparseColumns(absl::Span<const absl::Span<const int32_t>> rows,
                            absl::Span<const absl::Span<const double>> vals,
                            Eigen::Ref<Eigen::MatrixXd> Y,
                            std::vector<std::pair<int64_t, int64_t>>* reach_rows = nullptr) const;

  bool is_valid() const { return valid_; }
  int64_t rows() const { return symbolic_->rows(); }
  const SupernodalSymbolic& symbolic() const { return *symbolic_; }
  // log det(A) (of the shifted matrix): 2 sum log L_ii.
  double LogDeterminant() const;

 private:
  SupernodalFactor() = default;
  // L y = X, then L^T x = y, in place on X (rows in the permuted order): a column vector, for
  // which Eigen uses matrix-vector kernels, or a row-major block of right-hand sides.
  template <typename Block>
  void Substitute(Block& X) const;
  template <typename Block>
  void Forward(Block& X) const;
  template <typename Block>
  void Backward(Block& X) const;
  template <typename Block>
  void ForwardSupernode(int64_t s, Block& X, Block& tmp) const;

  std::shared_ptr<const SupernodalSymbolic> symbolic_;
  std::vector<double> panels_;  // L: per supernode nr x nc column-major (upper part unused)
  bool valid_ = false;
};

// A symmetric matrix with an analyzed pattern, its lower triangle kept in the supernodal panel
// layout of the factor (zeros where L fills in). Products y = A x run dense matrix-vector kernels
// panel by panel: for the dense-ish reduced matrices that is several times faster than a
// compressed-column product, which gathers or scatters entry by entry (it serves the residuals
// of KktSolver's iterative refinement, computed after every design edit). Immutable; Multiply()
// is safe to call concurrently.
class SupernodalMatrix {
 public:
  // `values` as for SupernodalFactor::Factorize (the analyzed pattern's order, both triangles;
  // only the lower triangle in the permuted order is read). InvalidArgument for a wrong length.
  static absl::StatusOr<SupernodalMatrix> Create(std::shared_ptr<const SupernodalSymbolic> symbolic,
                                                 absl::Span<const double> values);
  // `A` must have the analyzed pattern (InvalidArgument otherwise).
  static absl::StatusOr<SupernodalMatrix> Create(std::shared_ptr<const SupernodalSymbolic> symbolic,
                                                 const Eigen::SparseMatrix<double>& A);

  int64_t rows() const { return symbolic_->rows(); }
  // A x (x: n values, original numbering).
  Eigen::VectorXd Multiply(const Eigen::VectorXd& x) const;

 private:
  SupernodalMatrix() = default;

  std::shared_ptr<const SupernodalSymbolic> symbolic_;
  std::vector<double> panels_;  // per supernode nr x nc column-major, lower triangle of P A P^T
};

}  // namespace fieldspace

#endif  // FIELDSPACE_CORE_LINALG_SUPERNODAL_CHOLESKY_H_
