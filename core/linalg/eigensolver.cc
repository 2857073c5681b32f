#include "core/linalg/eigensolver.h"

#include <algorithm>
#include <cmath>
#include <utility>
#include <vector>

#include "Eigen/Eigenvalues"
#include "Eigen/QR"
#include "absl/strings/str_format.h"
#include "core/common/status_macros.h"
#include "core/linalg/lanczos.h"
#include "core/linalg/sparse_checks.h"

namespace fieldspace {
namespace {

using SpMat = Eigen::SparseMatrix<double>;

// Problems beyond this size are never solved densely (k^2 doubles).
constexpr int64_t kDenseHardLimit = 8192;

// y = (A - sigma I)^-1 x with A = M^-1/2 S M^-1/2, i.e. y = M^1/2 (S - sigma M)^-1 M^1/2 x: the
// shift-inverted operator that Lanczos runs on. x and y: n values each.
class ShiftInvertOp {
 public:
  ShiftInvertOp(const SparseCholesky& factor, const Eigen::VectorXd& sqrt_mass)
      : factor_(factor), sqrt_mass_(sqrt_mass) {}

  Eigen::Index rows() const { return sqrt_mass_.size(); }

  absl::Status Apply(const double* x_in, double* y_out) const {
    Eigen::Map<const Eigen::VectorXd> x(x_in, rows());
    Eigen::Map<Eigen::VectorXd> y(y_out, rows());
    const Eigen::VectorXd rhs = sqrt_mass_.cwiseProduct(x);
    absl::StatusOr<Eigen::VectorXd> solved = factor_.Solve(rhs);
    if (!solved.ok()) return solved.status();
    y = sqrt_mass_.cwiseProduct(*solved);
    return absl::OkStatus();
  }

 private:
  const SparseCholesky& factor_;
  const Eigen::VectorXd& sqrt_mass_;
};

// Applies `op` to every column of X.
absl::StatusOr<Eigen::MatrixXd> ApplyColumns(const ShiftInvertOp& op, const Eigen::MatrixXd& X) {
  Eigen::MatrixXd Y(X.rows(), X.cols());
  for (Eigen::Index j = 0; j < X.cols(); ++j) {
    RETURN_IF_ERROR(op.Apply(X.col(j).data(), Y.col(j).data()));
  }
  return Y;
}

// Looks for eigenpairs of T = (A - sigma I)^-1 that the first run missed: any eigenvalue of the
// deflated operator P T P, P = I - Y Y^T (T restricted to the complement of the pairs found),
// above the smallest accepted nu (i.e. any lambda below the K-th) is merged into (Y, nu) by
// Rayleigh-Ritz on span[Y, Z], keeping the K largest nu. Returns the number of pairs recovered.
absl::StatusOr<int32_t> RecoverMissedPairs(const ShiftInvertOp& op, const EigenOptions& options,
                                           Eigen::MatrixXd* Y, Eigen::VectorXd* nu,
                                           int64_t* operations) {
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
    const Eigen::MatrixXd& Yd = *Y;
    absl::Status op_status;
    auto deflated = [&](const double* x_in, double* y_out) {
      Eigen::Map<const Eigen::VectorXd> x(x_in, k);
      Eigen::Map<Eigen::VectorXd> y(y_out, k);
      const Eigen::VectorXd projected = x - Yd * (Yd.transpose() * x);
      op_status = op.Apply(projected.data(), y_out);
      if (op_status.ok()) y -= Yd * (Yd.transpose() * y);
      return op_status;
    };
    LanczosOptions lanczos;
    lanczos.count = m;
    lanczos.subspace_size = ncv;
    lanczos.max_iterations = options.max_iterations;
    lanczos.tolerance = std::max(options.tolerance, 1e-6);
    lanczos.context = "eigensolver";
    absl::StatusOr<LanczosResult> run = LargestEigenpairs(k, deflated, lanczos);
    if (!run.ok()) {
      if (!op_status.ok()) return op_status;
      // Best effort: an unconverged check leaves the (converged) first result as it is.
      break;
    }
    *operations += run->operations;
    // Missing values equal to the K-th one are interchangeable with it: only strictly smaller
    // lambda (larger nu, beyond the solver's accuracy) count as missed.
    const double threshold = nu->minCoeff() * (1.0 + std::max(1e-8, 100.0 * options.tolerance));
    const Eigen::VectorXd& found = run->values;
    const Eigen::MatrixXd& Z = run->vectors;
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
    ASSIGN_OR_RETURN(const Eigen::MatrixXd TW, ApplyColumns(op, W));
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
  ShiftInvertOp op(*factor, sqrt_mass);
  LanczosOptions lanczos;
  lanczos.count = options.count;
  lanczos.subspace_size = ncv;
  lanczos.max_iterations = options.max_iterations;
  lanczos.tolerance = options.tolerance;
  lanczos.context = "eigensolver";
  ASSIGN_OR_RETURN(
      LanczosResult run,
      ShiftInvertEigenpairs(
          k, [&op](const double* x, double* y) { return op.Apply(x, y); }, sigma, lanczos));
  EigenResult result;
  result.shift = sigma;
  result.iterations = run.iterations;
  result.operations = run.operations;
  // Ritz values of T = (A - sigma I)^-1 and its orthonormal eigenvectors (the adapter has already
  // mapped the values back to lambda = sigma + 1 / nu).
  Eigen::VectorXd nu = (run.values.array() - sigma).inverse().matrix();
  Eigen::MatrixXd Y = std::move(run.vectors);
  if (options.verify_multiplicities) {
    ASSIGN_OR_RETURN(result.recovered,
                     RecoverMissedPairs(op, options, &Y, &nu, &result.operations));
  }
  result.values = (sigma + nu.array().inverse()).matrix();
  if (options.compute_vectors) result.vectors = inv_sqrt_mass.asDiagonal() * Y;
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
