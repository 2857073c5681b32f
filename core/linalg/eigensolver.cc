#include "core/linalg/eigensolver.h"

#include <algorithm>
#include <cmath>
#include <exception>
#include <stdexcept>
#include <utility>
#include <vector>

#include "Eigen/Eigenvalues"
#include "Eigen/QR"
#include "Spectra/SymEigsShiftSolver.h"
#include "Spectra/SymEigsSolver.h"
#include "absl/strings/str_format.h"
#include "core/common/status_macros.h"
#include "core/linalg/sparse_checks.h"

namespace fieldspace {
namespace {

using SpMat = Eigen::SparseMatrix<double>;

// Problems beyond this size are never solved densely (k^2 doubles).
constexpr int64_t kDenseHardLimit = 8192;

// Carries a Status out of Spectra's callback, which cannot return one.
class StatusException : public std::exception {
 public:
  explicit StatusException(absl::Status status) : status_(std::move(status)) {}
  const char* what() const noexcept override { return "status exception"; }
  const absl::Status& status() const { return status_; }

 private:
  absl::Status status_;
};

// y = (A - sigma I)^-1 x with A = M^-1/2 S M^-1/2, i.e. y = M^1/2 (S - sigma M)^-1 M^1/2 x: the
// operator Spectra's SymEigsShiftSolver expects (its "shift-solve" interface).
class ShiftInvertOp {
 public:
  using Scalar = double;

  ShiftInvertOp(const SparseCholesky& factor, const Eigen::VectorXd& sqrt_mass, double sigma)
      : factor_(factor), sqrt_mass_(sqrt_mass), sigma_(sigma) {}

  Eigen::Index rows() const { return sqrt_mass_.size(); }

  // The factorization was built for sigma_; Spectra passes the same value back.
  void set_shift(const Scalar& sigma) {
    if (sigma != sigma_) {
      throw StatusException(absl::InternalError("eigensolver: shift mismatch"));
    }
  }

  void perform_op(const Scalar* x_in, Scalar* y_out) const {
    Eigen::Map<const Eigen::VectorXd> x(x_in, rows());
    Eigen::Map<Eigen::VectorXd> y(y_out, rows());
    const Eigen::VectorXd rhs = sqrt_mass_.cwiseProduct(x);
    absl::StatusOr<Eigen::VectorXd> solved = factor_.Solve(rhs);
    if (!solved.ok()) throw StatusException(solved.status());
    y = sqrt_mass_.cwiseProduct(*solved);
  }

 private:
  const SparseCholesky& factor_;
  const Eigen::VectorXd& sqrt_mass_;
  const double sigma_;
};

// P T P with P = I - Y Y^T (Y orthonormal): T restricted to the complement of the pairs found,
// whose largest eigenvalues are the ones the first Lanczos run missed.
class DeflatedOp {
 public:
  using Scalar = double;

  DeflatedOp(const ShiftInvertOp& op, const Eigen::MatrixXd& Y) : op_(op), Y_(Y) {}

  Eigen::Index rows() const { return op_.rows(); }

  void perform_op(const Scalar* x_in, Scalar* y_out) const {
    Eigen::Map<const Eigen::VectorXd> x(x_in, rows());
    Eigen::Map<Eigen::VectorXd> y(y_out, rows());
    const Eigen::VectorXd projected = x - Y_ * (Y_.transpose() * x);
    op_.perform_op(projected.data(), y_out);
    y -= Y_ * (Y_.transpose() * y);
  }

 private:
  const ShiftInvertOp& op_;
  const Eigen::MatrixXd& Y_;
};

// Applies `op` to every column of X.
Eigen::MatrixXd ApplyColumns(const ShiftInvertOp& op, const Eigen::MatrixXd& X) {
  Eigen::MatrixXd Y(X.rows(), X.cols());
  for (Eigen::Index j = 0; j < X.cols(); ++j) op.perform_op(X.col(j).data(), Y.col(j).data());
  return Y;
}

// Looks for eigenpairs of T = (A - sigma I)^-1 that the first run missed: any eigenvalue of the
// deflated operator above the smallest accepted nu (i.e. any lambda below the K-th) is merged
// into (Y, nu) by Rayleigh-Ritz on span[Y, Z], keeping the K largest nu. Throws StatusException.
int32_t RecoverMissedPairs(const ShiftInvertOp& op, const EigenOptions& options, Eigen::MatrixXd* Y,
                           Eigen::VectorXd* nu, int64_t* operations) {
  constexpr int kMaxRounds = 6;
  const int64_t k = op.rows();
  const int64_t K = Y->cols();
  int32_t recovered = 0;
  for (int round = 0; round < kMaxRounds; ++round) {
    // A small, loosely converged run suffices: a missed value is typically separated from the
    // accepted K-th one (it sits inside a cluster the first run only partly resolved), and the
    // Rayleigh-Ritz merge below squares the Ritz vector error (1e-6 -> 1e-12 in nu).
    const int64_t m = std::min<int64_t>({2, K, k - K - 1});
    if (m < 1) break;
    const int64_t ncv = std::min<int64_t>(k - K, 20);
    if (ncv <= m) break;
    DeflatedOp deflated(op, *Y);
    Spectra::SymEigsSolver<DeflatedOp> solver(deflated, m, ncv);
    solver.init();
    solver.compute(Spectra::SortRule::LargestAlge, options.max_iterations,
                   std::max(options.tolerance, 1e-6), Spectra::SortRule::LargestAlge);
    *operations += solver.num_operations();
    // Best effort: an unconverged check leaves the (converged) first result as it is.
    if (solver.info() != Spectra::CompInfo::Successful) break;
    // Missing values equal to the K-th one are interchangeable with it: only strictly smaller
    // lambda (larger nu, beyond the solver's accuracy) count as missed.
    const double threshold = nu->minCoeff() * (1.0 + std::max(1e-8, 100.0 * options.tolerance));
    const Eigen::VectorXd found = solver.eigenvalues();
    const Eigen::MatrixXd Z = solver.eigenvectors();
    std::vector<Eigen::Index> keep;
    for (Eigen::Index i = 0; i < found.size(); ++i) {
      if (found[i] > threshold) keep.push_back(i);
    }
    if (keep.empty()) break;
    recovered += static_cast<int32_t>(keep.size());
    Eigen::MatrixXd W(k, K + static_cast<int64_t>(keep.size()));
    W.leftCols(K) = *Y;
    for (size_t i = 0; i < keep.size(); ++i) W.col(K + i) = Z.col(keep[i]);
    // Re-orthonormalize (Z is orthogonal to Y only up to the solver tolerance).
    Eigen::HouseholderQR<Eigen::MatrixXd> qr(W);
    W = qr.householderQ() * Eigen::MatrixXd::Identity(W.rows(), W.cols());
    const Eigen::MatrixXd TW = ApplyColumns(op, W);
    *operations += W.cols();
    Eigen::MatrixXd H = W.transpose() * TW;
    H = 0.5 * (H + H.transpose()).eval();
    Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> small(H);
    // Ascending nu: the K largest are the last K.
    *nu = small.eigenvalues().tail(K);
    *Y = W * small.eigenvectors().rightCols(K);
  }
  return recovered;
}

absl::Status ValidateOptions(const EigenOptions& o, int64_t k) {
  if (o.count < 1 || o.count > k) {
    return absl::InvalidArgumentError(
        absl::StrFormat("eigensolver: count %d outside [1, %d]", o.count, k));
  }
  if (!(o.tolerance > 0.0) || !std::isfinite(o.tolerance)) {
    return absl::InvalidArgumentError("eigensolver: tolerance must be finite and > 0");
  }
  if (o.max_iterations < 1) {
    return absl::InvalidArgumentError("eigensolver: max_iterations must be >= 1");
  }
  if (o.shift.has_value() && !std::isfinite(*o.shift)) {
    return absl::InvalidArgumentError("eigensolver: shift is not finite");
  }
  if (!(o.relative_shift > 0.0) || !std::isfinite(o.relative_shift)) {
    return absl::InvalidArgumentError("eigensolver: relative_shift must be finite and > 0");
  }
  if (o.subspace_size != 0 && (o.subspace_size <= o.count || o.subspace_size > k)) {
    return absl::InvalidArgumentError(
        absl::StrFormat("eigensolver: subspace_size %d must be in (count, k] = (%d, %d]",
                        o.subspace_size, o.count, k));
  }
  return absl::OkStatus();
}

absl::StatusOr<EigenResult> DenseLowest(const SpMat& S, const Eigen::VectorXd& inv_sqrt_mass,
                                        double sigma, const EigenOptions& options) {
  const int64_t k = S.rows();
  if (k > kDenseHardLimit) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "eigensolver: count %d needs a dense solve, too large for k = %d", options.count, k));
  }
  Eigen::MatrixXd A = inv_sqrt_mass.asDiagonal() * Eigen::MatrixXd(S) * inv_sqrt_mass.asDiagonal();
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> solver(
      A, options.compute_vectors ? Eigen::ComputeEigenvectors : Eigen::EigenvaluesOnly);
  if (solver.info() != Eigen::Success) {
    return absl::InternalError("eigensolver: dense symmetric eigensolver failed");
  }
  // Same contract as the shift-invert path: every eigenvalue must lie above sigma.
  if (solver.eigenvalues()[0] <= sigma) {
    return absl::FailedPreconditionError(absl::StrFormat(
        "eigensolver: S - sigma M is not positive definite (eigenvalue %g <= shift %g)",
        solver.eigenvalues()[0], sigma));
  }
  EigenResult result;
  result.shift = sigma;
  result.values = solver.eigenvalues().head(options.count);
  if (options.compute_vectors) {
    result.vectors = inv_sqrt_mass.asDiagonal() * solver.eigenvectors().leftCols(options.count);
  }
  return result;
}

}  // namespace

absl::StatusOr<EigenResult> LowestEigenpairs(const SpMat& S, const Eigen::VectorXd& mass,
                                             const EigenOptions& options) {
  if (S.rows() != S.cols() || S.rows() == 0) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "eigensolver: S must be square and non-empty, is %d x %d", S.rows(), S.cols()));
  }
  const int64_t k = S.rows();
  RETURN_IF_ERROR(CheckPositiveVector(mass, k, "eigensolver: mass"));
  RETURN_IF_ERROR(ValidateOptions(options, k));
  RETURN_IF_ERROR(CheckFiniteValues(S, "eigensolver: S"));
  RETURN_IF_ERROR(CheckSymmetric(S, options.cholesky.symmetry_tolerance, "eigensolver: S"));

  double sigma = 0.0;
  if (options.shift.has_value()) {
    sigma = *options.shift;
  } else {
    double max_ratio = 0.0;
    for (Eigen::Index j = 0; j < S.outerSize(); ++j) {
      for (SpMat::InnerIterator it(S, j); it; ++it) {
        if (it.row() == j) max_ratio = std::max(max_ratio, it.value() / mass[j]);
      }
    }
    // S = 0 has only zero eigenvalues: any negative shift works.
    sigma = max_ratio > 0.0 ? -options.relative_shift * max_ratio : -1.0;
  }
  const Eigen::VectorXd sqrt_mass = mass.cwiseSqrt();
  const Eigen::VectorXd inv_sqrt_mass = sqrt_mass.cwiseInverse();

  if (k <= options.dense_max_size || options.count >= k) {
    return DenseLowest(S, inv_sqrt_mass, sigma, options);
  }

  CholeskyOptions chol_options = options.cholesky;
  chol_options.check_input = false;  // checked above
  auto factor = SparseCholesky::FactorizeShifted(S, -sigma, mass, chol_options);
  if (!factor.ok()) {
    if (absl::IsFailedPrecondition(factor.status())) {
      return absl::FailedPreconditionError(absl::StrFormat(
          "eigensolver: S - sigma M (sigma = %g) is not positive definite: S is not positive "
          "semi-definite or the shift is not below the spectrum (%s)",
          sigma, factor.status().message()));
    }
    return factor.status();
  }

  const int64_t ncv =
      options.subspace_size != 0
          ? options.subspace_size
          : std::min<int64_t>(k, std::max<int64_t>(2 * options.count + 1, options.count + 20));
  ShiftInvertOp op(*factor, sqrt_mass, sigma);
  EigenResult result;
  result.shift = sigma;
  try {
    Spectra::SymEigsShiftSolver<ShiftInvertOp> solver(op, options.count, ncv, sigma);
    solver.init();
    solver.compute(Spectra::SortRule::LargestMagn, options.max_iterations, options.tolerance,
                   Spectra::SortRule::SmallestAlge);
    result.iterations = solver.num_iterations();
    result.operations = solver.num_operations();
    if (solver.info() == Spectra::CompInfo::NotConverging) {
      return absl::ResourceExhaustedError(absl::StrFormat(
          "eigensolver: %d of %d eigenpairs not converged after %d iterations (tolerance %g)",
          options.count - solver.eigenvalues().size(), options.count, options.max_iterations,
          options.tolerance));
    }
    if (solver.info() != Spectra::CompInfo::Successful) {
      return absl::InternalError("eigensolver: Spectra reported a numerical failure");
    }
    // Ritz values of T = (A - sigma I)^-1 and its orthonormal eigenvectors; Spectra has already
    // mapped the values back to lambda = sigma + 1 / nu.
    const Eigen::VectorXd lambda = solver.eigenvalues();
    if (lambda.size() != options.count) {
      return absl::InternalError("eigensolver: Spectra returned the wrong number of eigenvalues");
    }
    Eigen::VectorXd nu = (lambda.array() - sigma).inverse().matrix();
    Eigen::MatrixXd Y = solver.eigenvectors();
    if (options.verify_multiplicities) {
      result.recovered = RecoverMissedPairs(op, options, &Y, &nu, &result.operations);
    }
    result.values = (sigma + nu.array().inverse()).matrix();
    if (options.compute_vectors) result.vectors = inv_sqrt_mass.asDiagonal() * Y;
  } catch (const StatusException& e) {
    return e.status();
  } catch (const std::exception& e) {
    return absl::InternalError(absl::StrFormat("eigensolver: Spectra failed: %s", e.what()));
  }
  // Ascending lambda (the Rayleigh-Ritz merge returns them in nu order).
  std::vector<int> order(result.values.size());
  for (int i = 0; i < static_cast<int>(order.size()); ++i) order[i] = i;
  std::stable_sort(order.begin(), order.end(),
                   [&](int a, int b) { return result.values[a] < result.values[b]; });
  bool sorted = true;
  for (int i = 0; i < static_cast<int>(order.size()); ++i) sorted = sorted && order[i] == i;
  if (!sorted) {
    Eigen::VectorXd values(result.values.size());
    Eigen::MatrixXd vectors(result.vectors.rows(), result.vectors.cols());
    for (int i = 0; i < static_cast<int>(order.size()); ++i) {
      values[i] = result.values[order[i]];
      if (options.compute_vectors) vectors.col(i) = result.vectors.col(order[i]);
    }
    result.values = std::move(values);
    result.vectors = std::move(vectors);
  }
  return result;
}

}  // namespace fieldspace
