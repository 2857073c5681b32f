#include "core/subspace/spectrum.h"

#include <algorithm>
#include <cmath>
#include <utility>
#include <vector>

#include "absl/strings/str_cat.h"
#include "core/common/cancel.h"
#include "core/common/status_macros.h"
#include "core/linalg/lanczos.h"
#include "core/linalg/supernodal_cholesky.h"
#include "core/operators/reference_solvers.h"
#include "core/subspace/dense_eigen.h"

namespace fieldspace {
namespace {

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
  // (S - sigma M)^-1, factorized on the system's shared pattern.
  const Eigen::SparseMatrix<double>& S = system.stiffness();
  const Eigen::SparseMatrix<double>& M = system.mass_matrix();
  std::vector<double> values(S.nonZeros());
  for (int64_t p = 0; p < S.nonZeros(); ++p) {
    values[p] = S.valuePtr()[p] - sigma * M.valuePtr()[p];
  }
  SupernodalFactorOptions factor_options;
  factor_options.cancel = options.cancel;
  ASSIGN_OR_RETURN(const SupernodalFactor factor,
                   SupernodalFactor::Factorize(system.pattern_symbolic(), values, factor_options));
  auto inverse = [&](const double* x, double* y) {
    if (IsCancelled(options.cancel)) return absl::CancelledError("ReducedEigenpairs: cancelled");
    Eigen::Map<Eigen::VectorXd> yv(y, d);
    yv = Eigen::Map<const Eigen::VectorXd>(x, d);
    factor.SolveInPlace(yv);
    return absl::OkStatus();
  };
  auto mass = [&](const double* x, double* y) {
    Eigen::Map<Eigen::VectorXd>(y, d) = M * Eigen::Map<const Eigen::VectorXd>(x, d);
    return absl::OkStatus();
  };
  LanczosOptions lanczos;
  lanczos.count = K;
  lanczos.subspace_size = ncv;
  lanczos.max_iterations = options.max_iterations;
  lanczos.tolerance = options.tolerance;
  lanczos.context = "ReducedEigenpairs";
  ASSIGN_OR_RETURN(LanczosResult run,
                   GeneralizedShiftInvertEigenpairs(d, inverse, mass, sigma, lanczos));
  ReducedEigenResult result;
  result.method = ReducedEigenMethod::kSparse;
  result.values = std::move(run.values);
  if (options.compute_vectors) result.coefficients = std::move(run.vectors);
  return result;
}

ReducedEigenMethod ChosenMethod(int64_t d, const ReducedEigenOptions& options) {
  if (options.method != ReducedEigenMethod::kAuto) return options.method;
  const bool dense = d <= options.dense_max_dimension || options.count > d / 6 ||
                     std::max<int64_t>(2 * options.count + 1, options.count + 32) >= d;
  return dense ? ReducedEigenMethod::kDense : ReducedEigenMethod::kSparse;
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
  if (ChosenMethod(d, options) == ReducedEigenMethod::kDense) {
    return DenseEigenpairs(system, options);
  }
  return SparseEigenpairs(system, options);
}

int64_t ReducedEigenWorkingBytes(const ReducedSystem& system, const ReducedEigenOptions& options) {
  const int64_t d = system.dimension();
  const int64_t k = std::clamp<int64_t>(options.count, 1, std::max<int64_t>(d, 1));
  if (ChosenMethod(d, options) == ReducedEigenMethod::kDense) {
    // The dense stiffness and mass, the eigenvectors and the solver's workspace: d x d each.
    return 4 * d * d * 8 + 2 * d * k * 8;
  }
  const int64_t ncv =
      options.subspace_size > 0 ? options.subspace_size : std::min(d, std::max(2 * k + 1, k + 32));
  // The shift-invert factorization (factor and panels), the Lanczos basis and the eigenvectors.
  return 2 * system.stats().factor_nonzeros * 8 + (ncv + 2 * k) * d * 8;
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
