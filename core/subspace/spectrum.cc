#include "core/subspace/spectrum.h"

#include <algorithm>
#include <cmath>
#include <exception>
#include <memory>
#include <utility>
#include <vector>

#include "Spectra/SymGEigsShiftSolver.h"
#include "absl/strings/str_cat.h"
#include "core/common/cancel.h"
#include "core/common/status_macros.h"
#include "core/linalg/supernodal_cholesky.h"
#include "core/operators/reference_solvers.h"
#include "core/subspace/dense_eigen.h"

namespace fieldspace {
namespace {

// Thrown out of Spectra (from perform_op) to stop a cancelled solve.
struct LanczosCancelled {};

// (S - sigma M)^-1 for Spectra, factorized on the system's shared pattern.
class ShiftInvertOp {
 public:
  using Scalar = double;
  ShiftInvertOp(const ReducedSystem& system, const std::atomic<bool>* cancel)
      : system_(system), cancel_(cancel) {}

  Eigen::Index rows() const { return system_.dimension(); }
  Eigen::Index cols() const { return system_.dimension(); }
  void set_shift(double sigma) {
    const Eigen::SparseMatrix<double>& S = system_.stiffness();
    const Eigen::SparseMatrix<double>& M = system_.mass_matrix();
    std::vector<double> values(S.nonZeros());
    for (int64_t p = 0; p < S.nonZeros(); ++p) {
      values[p] = S.valuePtr()[p] - sigma * M.valuePtr()[p];
    }
    SupernodalFactorOptions factor_options;
    factor_options.cancel = cancel_;
    auto factor = SupernodalFactor::Factorize(system_.pattern_symbolic(), values, factor_options);
    if (factor.ok()) {
      factor_ = std::make_unique<SupernodalFactor>(*std::move(factor));
      status_ = absl::OkStatus();
    } else {
      factor_.reset();
      status_ = factor.status();
    }
  }
  void perform_op(const double* x_in, double* y_out) const {
    if (IsCancelled(cancel_)) throw LanczosCancelled{};
    Eigen::Map<Eigen::VectorXd> y(y_out, rows());
    y = Eigen::Map<const Eigen::VectorXd>(x_in, rows());
    factor_->SolveInPlace(y);
  }
  const absl::Status& status() const { return status_; }

 private:
  const ReducedSystem& system_;
  const std::atomic<bool>* const cancel_;
  std::unique_ptr<SupernodalFactor> factor_;
  absl::Status status_ = absl::FailedPreconditionError("shift not set");
};

// y = (U^T M U) x for Spectra.
class MassOp {
 public:
  using Scalar = double;
  explicit MassOp(const Eigen::SparseMatrix<double>& M) : M_(M) {}
  Eigen::Index rows() const { return M_.rows(); }
  Eigen::Index cols() const { return M_.cols(); }
  void perform_op(const double* x_in, double* y_out) const {
    Eigen::Map<Eigen::VectorXd>(y_out, M_.rows()) =
        M_ * Eigen::Map<const Eigen::VectorXd>(x_in, M_.cols());
  }

 private:
  const Eigen::SparseMatrix<double>& M_;
};

absl::StatusOr<ReducedEigenResult> DenseEigenpairs(const ReducedSystem& system,
                                                   const ReducedEigenOptions& options) {
  const Eigen::MatrixXd S = system.stiffness();
  const Eigen::MatrixXd M = system.mass_matrix();
  auto solved =
      LowestGeneralizedEigenpairs(S, M, options.count, options.compute_vectors, options.cancel);
  if (absl::IsFailedPrecondition(solved.status())) {
    return absl::FailedPreconditionError(
        "ReducedEigenpairs: dense generalized eigensolver failed (is U^T M U positive "
        "definite?)");
  }
  if (!solved.ok()) return solved.status();
  ReducedEigenResult result;
  result.method = ReducedEigenMethod::kDense;
  result.values = std::move(solved->values);
  if (options.compute_vectors) result.coefficients = std::move(solved->vectors);
  return result;
}

absl::StatusOr<ReducedEigenResult> SparseEigenpairs(const ReducedSystem& system,
                                                    const ReducedEigenOptions& options) {
  const int64_t d = system.dimension();
  const int64_t K = options.count;
  int64_t ncv =
      options.subspace_size > 0 ? options.subspace_size : std::max<int64_t>(2 * K + 1, K + 32);
  ncv = std::min(ncv, d);
  if (ncv <= K) {
    return absl::InvalidArgumentError(absl::StrCat(
        "ReducedEigenpairs: the sparse method needs a Lanczos basis larger than K = ", K,
        " and at most d = ", d, "; use the dense method"));
  }
  // A shift just below the spectrum keeps S - sigma M positive definite even when S has a
  // kernel; its size follows the largest diagonal ratio so that the shifted matrix stays well
  // conditioned.
  const Eigen::VectorXd sd = system.stiffness().diagonal();
  const Eigen::VectorXd md = system.mass_matrix().diagonal();
  double scale = 0;
  for (int64_t i = 0; i < d; ++i) scale = std::max(scale, sd[i] / md[i]);
  const double sigma = -1e-8 * std::max(scale, 1e-300);
  ShiftInvertOp op(system, options.cancel);
  MassOp bop(system.mass_matrix());
  try {
    Spectra::SymGEigsShiftSolver<ShiftInvertOp, MassOp, Spectra::GEigsMode::ShiftInvert> solver(
        op, bop, K, ncv, sigma);
    if (!op.status().ok()) return op.status();
    solver.init();
    solver.compute(Spectra::SortRule::LargestMagn, options.max_iterations, options.tolerance,
                   Spectra::SortRule::SmallestAlge);
    if (solver.info() == Spectra::CompInfo::NotConverging) {
      return absl::ResourceExhaustedError(absl::StrCat(
          "ReducedEigenpairs: Lanczos did not converge in ", options.max_iterations, " restarts"));
    }
    if (solver.info() != Spectra::CompInfo::Successful) {
      return absl::InternalError("ReducedEigenpairs: Spectra failed");
    }
    ReducedEigenResult result;
    result.method = ReducedEigenMethod::kSparse;
    result.values = solver.eigenvalues();
    if (options.compute_vectors) result.coefficients = solver.eigenvectors();
    return result;
  } catch (const LanczosCancelled&) {
    return absl::CancelledError("ReducedEigenpairs: cancelled");
  } catch (const std::exception& e) {
    return absl::InternalError(absl::StrCat("ReducedEigenpairs: Spectra: ", e.what()));
  }
}

}  // namespace

absl::StatusOr<ReducedEigenResult> ReducedEigenpairs(const ReducedSystem& system,
                                                     const ReducedEigenOptions& options) {
  const int64_t d = system.dimension();
  if (options.count < 1 || options.count > d) {
    return absl::InvalidArgumentError(
        absl::StrCat("ReducedEigenpairs: count ", options.count, " is outside [1, d = ", d, "]"));
  }
  if (options.dense_max_dimension < 0 || options.subspace_size < 0 || !(options.tolerance > 0) ||
      options.max_iterations < 1) {
    return absl::InvalidArgumentError("ReducedEigenpairs: invalid options");
  }
  ReducedEigenMethod method = options.method;
  if (method == ReducedEigenMethod::kAuto) {
    const bool dense = d <= options.dense_max_dimension || options.count > d / 6 ||
                       std::max<int64_t>(2 * options.count + 1, options.count + 32) >= d;
    method = dense ? ReducedEigenMethod::kDense : ReducedEigenMethod::kSparse;
  }
  if (method == ReducedEigenMethod::kDense) return DenseEigenpairs(system, options);
  return SparseEigenpairs(system, options);
}

absl::StatusOr<Basis> BuildEigenBasis(const FieldOperator& op, int32_t count) {
  EigenOptions options;
  options.count = count;
  options.compute_vectors = true;
  ASSIGN_OR_RETURN(EigenResult eig, ReferenceEigenpairs(op, options));
  Basis basis;
  basis.type = op.type;
  basis.params.dimension = count;
  basis.local_eigenvalues.assign(eig.values.data(), eig.values.data() + eig.values.size());
  const Eigen::MatrixXf dense = eig.vectors.cast<float>();
  basis.U = dense.sparseView(0.0f, 0.0f);
  basis.U.makeCompressed();
  return basis;
}

}  // namespace fieldspace
