#include "core/linalg/sparse_cholesky.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <utility>
#include <vector>

#include "absl/strings/str_format.h"
#include "cholmod.h"
#include "core/common/status_macros.h"
#include "core/linalg/cholmod_util.h"
#include "core/linalg/eigen_blas.h"
#include "core/linalg/sparse_checks.h"

namespace fieldspace {
namespace {

using linalg_internal::Analyze;
using linalg_internal::CholmodCommon;
using linalg_internal::StatusFromCholmod;
using linalg_internal::UpperView;
using SpMat = Eigen::SparseMatrix<double>;

// Non-owning CHOLMOD view of a compressed Eigen matrix; CHOLMOD reads only its upper triangle.
cholmod_sparse ViewOf(const SpMat& A) {
  return UpperView(A.rows(), A.outerIndexPtr(), A.innerIndexPtr(), A.valuePtr(), /*sorted=*/true);
}

absl::Status ValidateInput(const SpMat& A, const CholeskyOptions& options) {
  if (A.rows() != A.cols()) {
    return absl::InvalidArgumentError(
        absl::StrFormat("Cholesky: matrix is not square (%d x %d)", A.rows(), A.cols()));
  }
  if (A.rows() == 0) return absl::InvalidArgumentError("Cholesky: matrix is empty");
  if (options.check_input) {
    RETURN_IF_ERROR(CheckFiniteValues(A, "Cholesky input"));
    RETURN_IF_ERROR(CheckSymmetric(A, options.symmetry_tolerance, "Cholesky input"));
  }
  return absl::OkStatus();
}

}  // namespace

struct SparseCholesky::Impl {
  CholmodCommon common;
  cholmod_factor* factor = nullptr;
  int64_t n = 0;
  int64_t lnz = 0;
  // Pattern of the analyzed matrix: Refactorize() accepts only the same pattern, because the
  // symbolic factor is only valid for it.
  std::vector<int> outer;
  std::vector<int> inner;

  Impl() = default;
  ~Impl() {
    if (factor != nullptr) cholmod_free_factor(&factor, common.get());
  }
  Impl(const Impl&) = delete;
  Impl& operator=(const Impl&) = delete;

  // Numeric factorization of `view` into `factor`.
  absl::Status Numeric(cholmod_sparse* view) {
    cholmod_factorize(view, factor, common.get());
    if (common->status == CHOLMOD_NOT_POSDEF || factor->minor < factor->n) {
      return absl::FailedPreconditionError(absl::StrFormat(
          "Cholesky: matrix is not positive definite (non-positive pivot at column %d of %d)",
          static_cast<int64_t>(factor->minor), n));
    }
    return StatusFromCholmod(*common, "Cholesky", "factorize");
  }
};

SparseCholesky::SparseCholesky(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
SparseCholesky::SparseCholesky(SparseCholesky&&) noexcept = default;
SparseCholesky& SparseCholesky::operator=(SparseCholesky&&) noexcept = default;
SparseCholesky::~SparseCholesky() = default;

absl::StatusOr<SparseCholesky> SparseCholesky::Factorize(const SpMat& A_in,
                                                         const CholeskyOptions& options) {
  RETURN_IF_ERROR(ValidateInput(A_in, options));
  // CHOLMOD needs packed storage; copy only when the caller's matrix is not compressed.
  SpMat compressed;
  const SpMat* A = &CompressedOrCopy(A_in, &compressed);

  // CHOLMOD rejects the null index arrays of an entry-free matrix as invalid input.
  if (A->nonZeros() == 0) {
    return absl::FailedPreconditionError(
        "Cholesky: matrix is not positive definite (it has no entries)");
  }
  // Keeps the Eigen BLAS (eigen_blas.cc) linked in: CHOLMOD's BLAS calls bind to it.
  [[maybe_unused]] static const bool eigen_blas = linalg_internal::EigenBlasLinked();
  auto impl = std::make_unique<Impl>();
  impl->n = A->rows();
  cholmod_common& c = *impl->common;
  switch (options.method) {
    case CholeskyMethod::kSupernodal:
      c.supernodal = CHOLMOD_SUPERNODAL;
      break;
    case CholeskyMethod::kSimplicial:
      c.supernodal = CHOLMOD_SIMPLICIAL;
      // LL^T rather than LDL^T, so that an indefinite matrix is reported as such instead of
      // being factored with negative pivots.
      c.final_ll = 1;
      break;
    case CholeskyMethod::kAuto:
      c.supernodal = CHOLMOD_AUTO;
      c.final_ll = 1;
      break;
  }
  switch (options.ordering) {
    case CholeskyOrdering::kDefault:
      break;
    case CholeskyOrdering::kAmd:
      c.nmethods = 1;
      c.method[0].ordering = CHOLMOD_AMD;
      c.postorder = 1;
      break;
    case CholeskyOrdering::kMetis:
      c.nmethods = 1;
      c.method[0].ordering = CHOLMOD_METIS;
      c.postorder = 1;
      break;
    case CholeskyOrdering::kNatural:
      c.nmethods = 1;
      c.method[0].ordering = CHOLMOD_NATURAL;
      c.postorder = 0;
      break;
  }
  // Stop at the first bad pivot instead of finishing a useless factorization.
  c.quick_return_if_not_posdef = 1;

  cholmod_sparse view = ViewOf(*A);
  ASSIGN_OR_RETURN(impl->factor, Analyze(&view, &c, "Cholesky"));
  RETURN_IF_ERROR(impl->Numeric(&view));
  impl->lnz = static_cast<int64_t>(c.lnz);
  impl->outer.assign(A->outerIndexPtr(), A->outerIndexPtr() + A->cols() + 1);
  impl->inner.assign(A->innerIndexPtr(), A->innerIndexPtr() + A->nonZeros());
  return SparseCholesky(std::move(impl));
}

absl::StatusOr<SparseCholesky> SparseCholesky::FactorizeShifted(const SpMat& A, double shift,
                                                                const SpMat& B,
                                                                const CholeskyOptions& options) {
  if (B.rows() != A.rows() || B.cols() != A.cols()) {
    return absl::InvalidArgumentError(
        absl::StrFormat("Cholesky: shift matrix is %d x %d, expected %d x %d", B.rows(), B.cols(),
                        A.rows(), A.cols()));
  }
  if (!std::isfinite(shift)) return absl::InvalidArgumentError("Cholesky: shift is not finite");
  SpMat shifted = A + shift * B;
  return Factorize(shifted, options);
}

absl::StatusOr<SparseCholesky> SparseCholesky::FactorizeShifted(const SpMat& A, double shift,
                                                                const Eigen::VectorXd& b_diagonal,
                                                                const CholeskyOptions& options) {
  if (b_diagonal.size() != A.rows() || A.rows() != A.cols()) {
    return absl::InvalidArgumentError(
        absl::StrFormat("Cholesky: shift diagonal has %d entries for a %d x %d matrix",
                        b_diagonal.size(), A.rows(), A.cols()));
  }
  if (!std::isfinite(shift) || !b_diagonal.allFinite()) {
    return absl::InvalidArgumentError("Cholesky: shift or shift diagonal is not finite");
  }
  SpMat D(A.rows(), A.cols());
  D.reserve(Eigen::VectorXi::Constant(A.cols(), 1));
  for (Eigen::Index i = 0; i < A.rows(); ++i) D.insert(i, i) = shift * b_diagonal[i];
  SpMat shifted = A + D;
  return Factorize(shifted, options);
}

absl::Status SparseCholesky::Refactorize(const SpMat& A_in) {
  if (A_in.rows() != impl_->n || A_in.cols() != impl_->n) {
    return absl::InvalidArgumentError(
        absl::StrFormat("Cholesky: refactorize with a %d x %d matrix, factor is %d x %d",
                        A_in.rows(), A_in.cols(), impl_->n, impl_->n));
  }
  SpMat compressed;
  const SpMat* A = &CompressedOrCopy(A_in, &compressed);
  if (A->nonZeros() != static_cast<int64_t>(impl_->inner.size()) ||
      !std::equal(impl_->outer.begin(), impl_->outer.end(), A->outerIndexPtr()) ||
      !std::equal(impl_->inner.begin(), impl_->inner.end(), A->innerIndexPtr())) {
    return absl::InvalidArgumentError(
        "Cholesky: refactorize needs the same sparsity pattern as the analyzed matrix");
  }
  RETURN_IF_ERROR(CheckFiniteValues(*A, "Cholesky input"));
  cholmod_sparse view = ViewOf(*A);
  return impl_->Numeric(&view);
}

absl::Status SparseCholesky::SolveRaw(const double* b, double* x, int64_t columns) const {
  if (impl_->factor->minor < impl_->factor->n) {
    return absl::FailedPreconditionError("Cholesky: the last factorization failed");
  }
  // A private cholmod_common per call: CHOLMOD writes status and workspace into its common, so
  // sharing the factor's common between threads would race. The factor itself is only read.
  CholmodCommon common;
  cholmod_common& c = *common;
  cholmod_dense rhs;
  std::memset(&rhs, 0, sizeof(rhs));
  rhs.nrow = static_cast<size_t>(impl_->n);
  rhs.ncol = static_cast<size_t>(columns);
  rhs.nzmax = rhs.nrow * rhs.ncol;
  rhs.d = rhs.nrow;
  rhs.x = const_cast<double*>(b);
  rhs.z = nullptr;
  rhs.xtype = CHOLMOD_REAL;
  rhs.dtype = CHOLMOD_DOUBLE;
  cholmod_dense* solution = nullptr;
  cholmod_dense* work_y = nullptr;
  cholmod_dense* work_e = nullptr;
  const int ok = cholmod_solve2(CHOLMOD_A, impl_->factor, &rhs, nullptr, &solution, nullptr,
                                &work_y, &work_e, &c);
  absl::Status status;
  if (!ok || solution == nullptr) {
    status = StatusFromCholmod(c, "Cholesky", "solve");
    if (status.ok()) status = absl::InternalError("CHOLMOD solve failed");
  } else {
    std::memcpy(x, solution->x, sizeof(double) * rhs.nzmax);
  }
  cholmod_free_dense(&solution, &c);
  cholmod_free_dense(&work_y, &c);
  cholmod_free_dense(&work_e, &c);
  return status;
}

absl::StatusOr<Eigen::VectorXd> SparseCholesky::Solve(
    const Eigen::Ref<const Eigen::VectorXd>& b) const {
  if (b.size() != impl_->n) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "Cholesky solve: right-hand side has %d entries, expected %d", b.size(), impl_->n));
  }
  Eigen::VectorXd x(impl_->n);
  RETURN_IF_ERROR(SolveRaw(b.data(), x.data(), 1));
  return x;
}

absl::StatusOr<Eigen::MatrixXd> SparseCholesky::SolveMatrix(
    const Eigen::Ref<const Eigen::MatrixXd>& B) const {
  if (B.rows() != impl_->n || B.cols() < 1) {
    return absl::InvalidArgumentError(
        absl::StrFormat("Cholesky solve: right-hand side is %d x %d, expected %d rows", B.rows(),
                        B.cols(), impl_->n));
  }
  // CHOLMOD wants a contiguous column-major block; a Ref may carry an outer stride.
  Eigen::MatrixXd contiguous;
  const double* data = B.data();
  if (B.outerStride() != B.rows()) {
    contiguous = B;
    data = contiguous.data();
  }
  Eigen::MatrixXd X(B.rows(), B.cols());
  RETURN_IF_ERROR(SolveRaw(data, X.data(), B.cols()));
  return X;
}

int64_t SparseCholesky::rows() const { return impl_->n; }
int64_t SparseCholesky::factor_nonzeros() const { return impl_->lnz; }
bool SparseCholesky::is_supernodal() const { return impl_->factor->is_super != 0; }

}  // namespace fieldspace
