#ifndef FIELDSPACE_CORE_SUBSPACE_SMOOTHING_H_
#define FIELDSPACE_CORE_SUBSPACE_SMOOTHING_H_

// Reduced smoothing of a given field (paper eq. 8-11 with C = I; section 8, "Tensor field
// smoothing"): for an input field X0 (k DOFs, any field type) find the coefficients x (d) that
// minimize
//
//   E(x) = mu_S x^T (U^T S U) x + mu_B x^T (U^T B U) x + mu_C (U x - X0)^T W M (U x - X0)
//
// with W = diag(w_f) per-face weights (each face's DOFs get its weight; default all 1). The
// normal equations, a d x d sparse SPD system on the reduced system's shared pattern, are
//
//   (mu_S U^T S U + mu_B U^T B U + mu_C U^T W M U) x = mu_C U^T W M X0.
//
// Unlike eq. 8 (and the soft constraints of model_problem.h), the data term is weighted by the
// mass M (face areas): it measures the L2 distance of the fields, so the result does not depend on
// how finely the mesh samples the surface. It is the reduced form of SmoothField
// (core/operators/reference_solvers.h) with a biharmonic term and per-face weights.
//
// What the weights mean (L a length of the mesh's coordinates; docs/conventions.md, Model
// problem): X^T S X is scale invariant, X^T B X scales like 1 / L^2 and the M-weighted data term
// like L^2. With the raw weights (scale_free = false), as in the paper, sqrt(mu_S / mu_C) is the
// length over which the input is averaged and sqrt(mu_B / mu_C) the square of such a length: the
// same weights smooth a mesh scaled by s relatively s times less. With scale_free = true the
// biharmonic term is multiplied by the total area A and the data term divided by A:
//
//   mu_S x^T S^ x + mu_B A x^T B^ x + (mu_C / A) (U x - X0)^T W M (U x - X0),
//
// so all three weights are dimensionless: the same weights give the same field DOFs on a
// uniformly scaled mesh (smoothing lengths become fractions of sqrt(A)).

#include <cstdint>
#include <memory>

#include "Eigen/Core"
#include "Eigen/SparseCore"
#include "absl/status/statusor.h"
#include "absl/types/span.h"
#include "core/common/cancel.h"
#include "core/linalg/supernodal_cholesky.h"
#include "core/subspace/model_problem.h"
#include "core/subspace/problem.h"
#include "core/subspace/reduced_system.h"

namespace fieldspace {

// The weights smoothing and curvature alignment use when a caller gives none (with
// SmoothingOptions::scale_free: features smaller than about sqrt(mu_s / mu_c) sqrt(A) are
// smoothed away).
inline constexpr EnergyWeights kDefaultSmoothingWeights{.mu_s = 0.001, .mu_b = 0.0, .mu_c = 1.0};

struct SmoothingOptions {
  // Multiply mu_B by the total area A and mu_C by 1 / A (see above).
  bool scale_free = false;
  // Factorization and refinement policy (regularization, tolerance, max_refinement_steps,
  // parallel); its `cancel` is ignored in favor of `cancel` below. With mu_C = 0 no
  // regularization is applied (see ReducedSmoother::Solve).
  ReducedSolveOptions solve;
  // Checked in the passes over U (right-hand side, weighted mass) and before every front of a
  // factorization: Cancelled once true. Not owned; may be null; must outlive the smoother.
  const CancelFlag* cancel = nullptr;
};

// Wall-clock milliseconds of the phases; a phase that did not run is 0.
struct SmoothingTimings {
  double rhs_ms = 0;            // U^T W M X0: one pass over U
  double weighted_mass_ms = 0;  // U^T W M U (only with per-face weights): one pass over U
  double factorize_ms = 0;      // forming the weighted sum and its numeric factorization
  double solve_ms = 0;          // substitutions and refinement
};

struct SmoothingResult {
  Eigen::VectorXd coefficients;  // d: the minimizer x; the field is U x (Lift)
  SmoothingTimings timings;
  double backward_error = 0;  // ||b - A x|| / (||A||_F ||x|| + ||b||) of the final x
  int32_t refinement_steps = 0;
  double regularization = 0;  // the relative diagonal shift the factorization needed
};

// Smoothing of one input field under changing weights: the constructor does the two passes over
// U (the right-hand side U^T W M X0 and, with per-face weights, U^T W M U); each Solve is one
// numeric factorization of the d x d matrix on the reduced system's symbolic analysis plus a
// solve, independent of the mesh size. Immutable after Create: Solve is const and may run
// concurrently.
class ReducedSmoother {
 public:
  // system: the reduced system of the basis (kept alive by the smoother). field: X0, k = dofs()
  // finite values in the DOF layout of system.type(). face_weights: empty (all 1) or #F values,
  // finite, >= 0, not all 0. InvalidArgument for wrong sizes, non-finite values, negative weights
  // or invalid options; Cancelled.
  static absl::StatusOr<ReducedSmoother> Create(std::shared_ptr<const ReducedSystem> system,
                                                const Eigen::Ref<const Eigen::VectorXd>& field,
                                                absl::Span<const double> face_weights = {},
                                                const SmoothingOptions& options = {});

  // Factorizes mu_S U^T S U + mu_B' U^T B U + mu_C' U^T W M U (mu_B', mu_C' as scaled by
  // scale_free) and solves for the minimizer. Weights: ValidateWeights (finite, >= 0,
  // mu_S + mu_B > 0), else InvalidArgument. mu_C = 0 is allowed only if the energy alone is
  // positive definite in span(U) (then x = 0); otherwise FailedPrecondition saying so. With
  // mu_C > 0 the matrix is positive definite when all face weights are positive; with zero
  // weights it may be singular, and the regularization of ReducedSolveOptions applies.
  // The result's rhs_ms and weighted_mass_ms are 0 (nothing is recomputed); see
  // setup_timings(). Cancelled.
  absl::StatusOr<SmoothingResult> Solve(const EnergyWeights& weights) const;

  const ReducedSystem& system() const { return *system_; }
  // mu_s U^T S U + mu_b U^T B U + mu_data U^T W M U as given (no scale_free scaling), on
  // symbolic()'s pattern: the system's shared one unless the weighted mass needed a larger one.
  Eigen::SparseMatrix<double> WeightedSum(double mu_s, double mu_b, double mu_data) const;
  const std::shared_ptr<const SupernodalSymbolic>& symbolic() const { return symbolic_; }
  // rhs_ms and weighted_mass_ms of Create (the other fields 0).
  const SmoothingTimings& setup_timings() const { return setup_timings_; }
  // d: U^T W M X0 (without mu_C).
  const Eigen::VectorXd& rhs() const { return rhs_; }
  // Whether per-face weights were given (else U^T M U is the system's mass_matrix()).
  bool weighted() const { return weighted_; }
  // The total area A of the mesh (sum of the face areas), used by scale_free.
  double total_area() const { return total_area_; }

 private:
  ReducedSmoother() = default;

  const Eigen::SparseMatrix<double>& stiffness() const;
  const Eigen::SparseMatrix<double>& bilaplacian() const;
  const Eigen::SparseMatrix<double>& data_mass() const;

  std::shared_ptr<const ReducedSystem> system_;
  SmoothingOptions options_;
  Eigen::VectorXd rhs_;
  bool weighted_ = false;
  double total_area_ = 0;
  SmoothingTimings setup_timings_;
  // U^T W M U when weighted_. On the system's pattern, unless WeightedMassMatrix returned a larger
  // one: then own_pattern_, and the three matrices below are stored on that pattern with its own
  // analysis.
  Eigen::SparseMatrix<double> weighted_mass_;
  bool own_pattern_ = false;
  Eigen::SparseMatrix<double> stiffness_;
  Eigen::SparseMatrix<double> bilaplacian_;
  std::shared_ptr<const SupernodalSymbolic> symbolic_;
};

// One-shot smoothing: ReducedSmoother::Create + Solve, with all four timings filled in. `system`
// must outlive the call only.
// An upper estimate of the bytes SmoothReduced allocates on `system`: the field and its
// right-hand side, the weighted mass and energy on the shared pattern (per thread while they are
// summed) and the factorization. For admission against a memory budget.
int64_t SmoothWorkingBytes(const ReducedSystem& system, int32_t threads);

absl::StatusOr<SmoothingResult> SmoothReduced(const ReducedSystem& system,
                                              const Eigen::Ref<const Eigen::VectorXd>& field,
                                              const EnergyWeights& weights,
                                              absl::Span<const double> face_weights = {},
                                              const SmoothingOptions& options = {});

}  // namespace fieldspace

#endif  // FIELDSPACE_CORE_SUBSPACE_SMOOTHING_H_
