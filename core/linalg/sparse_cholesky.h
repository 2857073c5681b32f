#ifndef FIELDSPACE_CORE_LINALG_SPARSE_CHOLESKY_H_
#define FIELDSPACE_CORE_LINALG_SPARSE_CHOLESKY_H_

#include <cstdint>
#include <memory>

#include "Eigen/Core"
#include "Eigen/SparseCore"
#include "absl/status/status.h"
#include "absl/status/statusor.h"

namespace fieldspace {

enum class CholeskyMethod : uint8_t {
  kSupernodal = 0,  // BLAS-3 supernodes: best for 2D/3D mesh operators beyond a few thousand rows
  kSimplicial = 1,  // up-looking LDL^T without BLAS: cheaper for tiny or very sparse systems
  kAuto = 2,        // CHOLMOD decides from the flop count of the symbolic analysis
};

enum class CholeskyOrdering : uint8_t {
  kDefault = 0,  // CHOLMOD's default: AMD, then METIS if AMD's fill is high
  kAmd = 1,      // AMD only (fast analysis; good for small systems)
  kMetis = 2,    // nested dissection (slow analysis, least fill on large meshes)
  kNatural = 3,  // no permutation
};

struct CholeskyOptions {
  CholeskyMethod method = CholeskyMethod::kSupernodal;
  CholeskyOrdering ordering = CholeskyOrdering::kDefault;
  // Verify that the input is square, finite and symmetric (O(nnz log) time, no copy) before
  // factoring; CHOLMOD itself reads only the upper triangle.
  bool check_input = true;
  double symmetry_tolerance = 1e-12;  // relative to max |A_ij|
};

// Sparse Cholesky factorization A = L L^T (CHOLMOD, with a fill-reducing permutation) of a
// symmetric positive definite matrix, reused for many solves.
//
// Thread safety: Solve*() are const and safe to call concurrently from any number of threads:
// each call runs CHOLMOD's solve with its own cholmod_common (workspace, status) and only reads
// the factor. Refactorize() must not run concurrently with anything else on the same object.
// CHOLMOD never prints (common->print = 0, no error handler).
class SparseCholesky {
 public:
  // Factorizes `A`: n x n, symmetric positive definite, both triangles or only the upper one
  // stored (only the upper triangle is read). InvalidArgument for a non-square, empty, non-finite
  // or (with options.check_input) asymmetric A; FailedPrecondition "... not positive definite ..."
  // when CHOLMOD meets a non-positive pivot; ResourceExhausted when CHOLMOD runs out of memory.
  static absl::StatusOr<SparseCholesky> Factorize(const Eigen::SparseMatrix<double>& A,
                                                  const CholeskyOptions& options = {});

  // Factorizes A + shift * B (both n x n symmetric; B sparse), e.g. S - sigma M for shift-invert.
  static absl::StatusOr<SparseCholesky> FactorizeShifted(const Eigen::SparseMatrix<double>& A,
                                                         double shift,
                                                         const Eigen::SparseMatrix<double>& B,
                                                         const CholeskyOptions& options = {});
  // Factorizes A + shift * diag(b_diagonal) (b_diagonal has n entries), e.g. a diagonal mass.
  static absl::StatusOr<SparseCholesky> FactorizeShifted(const Eigen::SparseMatrix<double>& A,
                                                         double shift,
                                                         const Eigen::VectorXd& b_diagonal,
                                                         const CholeskyOptions& options = {});

  SparseCholesky(SparseCholesky&&) noexcept;
  SparseCholesky& operator=(SparseCholesky&&) noexcept;
  ~SparseCholesky();

  // Numeric refactorization with new values on the same sparsity pattern as the original A
  // (reuses the ordering and symbolic analysis). InvalidArgument for a different size or a
  // pattern change that CHOLMOD cannot absorb; FailedPrecondition when not positive definite (the
  // object is then unusable until a successful Refactorize).
  absl::Status Refactorize(const Eigen::SparseMatrix<double>& A);

  // x = A^-1 b, b has n entries.
  absl::StatusOr<Eigen::VectorXd> Solve(const Eigen::Ref<const Eigen::VectorXd>& b) const;
  // X = A^-1 B column by column (n x m, any m >= 1), in one CHOLMOD call (blocked triangular
  // solves are faster than m single solves).
  absl::StatusOr<Eigen::MatrixXd> SolveMatrix(const Eigen::Ref<const Eigen::MatrixXd>& B) const;

  int64_t rows() const;
  // Nonzeros of L (fill-in measure).
  int64_t factor_nonzeros() const;
  bool is_supernodal() const;

 private:
  struct Impl;
  explicit SparseCholesky(std::unique_ptr<Impl> impl);
  absl::Status SolveRaw(const double* b, double* x, int64_t columns) const;

  std::unique_ptr<Impl> impl_;
};

}  // namespace fieldspace

#endif  // FIELDSPACE_CORE_LINALG_SPARSE_CHOLESKY_H_
