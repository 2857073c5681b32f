#include "core/subspace/smoothing.h"

#include <chrono>
#include <cmath>
#include <utility>
#include <vector>

#include "absl/strings/str_cat.h"
#include "core/common/status_macros.h"
#include "core/subspace/kkt_solver.h"
#include "core/subspace/projection.h"

namespace fieldspace {
namespace {

double MillisecondsSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start)
      .count();
}

// `m` on the pattern of `pattern` (a superset of m's): the values of m, zeros elsewhere.
Eigen::SparseMatrix<double> OnPattern(const Eigen::SparseMatrix<double>& m,
                                      const Eigen::SparseMatrix<double>& pattern) {
  Eigen::SparseMatrix<double> sum = m + 0.0 * pattern;
  sum.makeCompressed();
  return sum;
}

}  // namespace

absl::StatusOr<ReducedSmoother> ReducedSmoother::Create(
    std::shared_ptr<const ReducedSystem> system, const Eigen::Ref<const Eigen::VectorXd>& field,
    absl::Span<const double> face_weights, const SmoothingOptions& options) {
  if (system == nullptr) return absl::InvalidArgumentError("ReducedSmoother: no reduced system");
  RETURN_IF_ERROR(ValidateSolveOptions(options.solve));
  const int64_t k = system->dofs();
  const int32_t p = system->dofs_per_face();
  const int32_t num_faces = system->num_faces();
  if (field.size() != k) {
    return absl::InvalidArgumentError(absl::StrCat("ReducedSmoother: the field has ", field.size(),
                                                   " values; the ", system->type().ToString(),
                                                   " basis has ", k, " DOFs"));
  }
  for (int64_t i = 0; i < k; ++i) {
    if (!std::isfinite(field[i])) {
      return absl::InvalidArgumentError(
          absl::StrCat("ReducedSmoother: the field has a non-finite value at face ", i / p));
    }
  }
  const bool weighted = !face_weights.empty();
  if (weighted) {
    if (static_cast<int64_t>(face_weights.size()) != num_faces) {
      return absl::InvalidArgumentError(absl::StrCat("ReducedSmoother: ", face_weights.size(),
                                                     " face weights for ", num_faces, " faces"));
    }
    bool any_positive = false;
    for (int32_t f = 0; f < num_faces; ++f) {
      if (!std::isfinite(face_weights[f]) || face_weights[f] < 0) {
        return absl::InvalidArgumentError(absl::StrCat("ReducedSmoother: weight of face ", f,
                                                       " is ", face_weights[f],
                                                       "; must be finite and >= 0"));
      }
      any_positive = any_positive || face_weights[f] > 0;
    }
    if (!any_positive) {
      return absl::InvalidArgumentError(
          "ReducedSmoother: all face weights are 0 (the data term would vanish)");
    }
  }

  ReducedSmoother smoother;
  smoother.options_ = options;
  smoother.weighted_ = weighted;
  smoother.total_area_ = system->mass().sum() / p;
  smoother.symbolic_ = system->pattern_symbolic();

  // Right-hand side U^T W M X0: one pass over U.
  const auto t_rhs = std::chrono::steady_clock::now();
  Eigen::VectorXd dof_weights;
  if (weighted) {
    dof_weights.resize(k);
    for (int64_t i = 0; i < k; ++i) dof_weights[i] = face_weights[i / p];
    const Eigen::VectorXd weighted_field = field.cwiseProduct(dof_weights);
    ASSIGN_OR_RETURN(Eigen::MatrixXd rhs,
                     MassWeightedProducts(*system, weighted_field, options.cancel));
    smoother.rhs_ = rhs.col(0);
  } else {
    ASSIGN_OR_RETURN(Eigen::MatrixXd rhs, MassWeightedProducts(*system, field, options.cancel));
    smoother.rhs_ = rhs.col(0);
  }
  smoother.setup_timings_.rhs_ms = MillisecondsSince(t_rhs);

  if (weighted) {
    const auto t_mass = std::chrono::steady_clock::now();
    WeightedMassOptions mass_options;
    mass_options.cancel = options.cancel;
    ASSIGN_OR_RETURN(smoother.weighted_mass_,
                     WeightedMassMatrix(*system, dof_weights, mass_options));
    if (!system->pattern_symbolic()->SamePattern(smoother.weighted_mass_)) {
      // Degenerate cancellation (see WeightedMassMatrix): a larger pattern with its own analysis.
      smoother.own_pattern_ = true;
      smoother.stiffness_ = OnPattern(system->stiffness(), smoother.weighted_mass_);
      smoother.bilaplacian_ = OnPattern(system->bilaplacian(), smoother.weighted_mass_);
      ASSIGN_OR_RETURN(smoother.symbolic_, SupernodalSymbolic::Analyze(smoother.weighted_mass_));
    }
    smoother.setup_timings_.weighted_mass_ms = MillisecondsSince(t_mass);
  }
  smoother.system_ = std::move(system);
  return smoother;
}

Eigen::SparseMatrix<double> ReducedSmoother::WeightedSum(double mu_s, double mu_b,
                                                         double mu_data) const {
  // Value by value on the shared pattern.
  Eigen::SparseMatrix<double> A = data_mass();
  double* a = A.valuePtr();
  const double* s = stiffness().valuePtr();
  const double* b = bilaplacian().valuePtr();
  const double* c = data_mass().valuePtr();
  const int64_t nnz = A.nonZeros();
  for (int64_t q = 0; q < nnz; ++q) a[q] = mu_s * s[q] + mu_b * b[q] + mu_data * c[q];
  return A;
}

const Eigen::SparseMatrix<double>& ReducedSmoother::stiffness() const {
  return own_pattern_ ? stiffness_ : system_->stiffness();
}
const Eigen::SparseMatrix<double>& ReducedSmoother::bilaplacian() const {
  return own_pattern_ ? bilaplacian_ : system_->bilaplacian();
}
const Eigen::SparseMatrix<double>& ReducedSmoother::data_mass() const {
  return weighted_ ? weighted_mass_ : system_->mass_matrix();
}

absl::StatusOr<SmoothingResult> ReducedSmoother::Solve(const EnergyWeights& weights) const {
  RETURN_IF_ERROR(ValidateWeightsWithoutDataTerm(weights));
  const absl::Status cancelled = absl::CancelledError("ReducedSmoother: cancelled");
  if (IsCancelled(options_.cancel)) return cancelled;
  const double mu_s = weights.mu_s;
  const double mu_b = options_.scale_free ? weights.mu_b * total_area_ : weights.mu_b;
  const double mu_c = options_.scale_free ? weights.mu_c / total_area_ : weights.mu_c;

  SmoothingResult result;
  const auto t_factor = std::chrono::steady_clock::now();
  const Eigen::SparseMatrix<double> A = WeightedSum(mu_s, mu_b, mu_c);
  ReducedSolveOptions solve_options = options_.solve;
  solve_options.cancel = options_.cancel;
  if (mu_c == 0) {
    // Without a data term only a definite energy determines x (= 0): no regularization, so that
    // a singular energy is reported rather than hidden.
    solve_options.regularization = 0;
    solve_options.max_regularization = 0;
  }
  double tau = 0;
  absl::StatusOr<SupernodalFactor> factor = FactorizeRegularized(symbolic_, A, solve_options, &tau);
  if (!factor.ok()) {
    if (IsCancelled(options_.cancel)) return cancelled;
    if (mu_c == 0 && absl::IsFailedPrecondition(factor.status())) {
      return absl::FailedPreconditionError(absl::StrCat(
          "ReducedSmoother: with mu_C = 0 the energy U^T (mu_S S + mu_B B) U alone must be "
          "positive definite, and it is singular (span(U) holds fields of zero energy, e.g. "
          "parallel or harmonic fields), so the minimizer is not unique: use mu_C > 0 (",
          factor.status().message(), ")"));
    }
    return factor.status();
  }
  result.timings.factorize_ms = MillisecondsSince(t_factor);
  result.regularization = tau;

  const auto t_solve = std::chrono::steady_clock::now();
  const Eigen::VectorXd b = mu_c * rhs_;
  Eigen::VectorXd x = factor->Solve(b);
  if (tau > 0) {
    // Iterative refinement against the unshifted matrix.
    const double norm_a = A.norm();
    const double norm_b = b.norm();
    for (int32_t step = 0;; ++step) {
      const Eigen::VectorXd r = b - A * x;
      const double denom = norm_a * x.norm() + norm_b;
      result.backward_error = denom > 0 ? r.norm() / denom : 0.0;
      if (result.backward_error <= solve_options.tolerance ||
          step >= solve_options.max_refinement_steps) {
        break;
      }
      x += factor->Solve(r);
      result.refinement_steps = step + 1;
    }
  }
  result.coefficients = std::move(x);
  result.timings.solve_ms = MillisecondsSince(t_solve);
  return result;
}

absl::StatusOr<SmoothingResult> SmoothReduced(const ReducedSystem& system,
                                              const Eigen::Ref<const Eigen::VectorXd>& field,
                                              const EnergyWeights& weights,
                                              absl::Span<const double> face_weights,
                                              const SmoothingOptions& options) {
  RETURN_IF_ERROR(ValidateWeights(weights));
  // A non-owning pointer: the smoother lives only for this call.
  std::shared_ptr<const ReducedSystem> borrowed(std::shared_ptr<const ReducedSystem>(), &system);
  ASSIGN_OR_RETURN(ReducedSmoother smoother,
                   ReducedSmoother::Create(std::move(borrowed), field, face_weights, options));
  ASSIGN_OR_RETURN(SmoothingResult result, smoother.Solve(weights));
  result.timings.rhs_ms = smoother.setup_timings().rhs_ms;
  result.timings.weighted_mass_ms = smoother.setup_timings().weighted_mass_ms;
  return result;
}

int64_t SmoothWorkingBytes(const ReducedSystem& system, int32_t threads) {
  const int64_t k = system.dofs();
  const int64_t nnz = system.stats().pattern_nonzeros;
  const int64_t factor = system.stats().factor_nonzeros;
  return 3 * k * 8 + (std::max<int32_t>(threads, 1) + 2) * nnz * 12 + 2 * factor * 8 +
         8 * int64_t{system.dimension()} * 8;
}

}  // namespace fieldspace
