#ifndef FIELDSPACE_CORE_SUBSPACE_MIXED_ENERGY_H_
#define FIELDSPACE_CORE_SUBSPACE_MIXED_ENERGY_H_

// Internal to core/subspace: the mixed biharmonic (BiharmonicForm::kMixed) inverted through two
// sparse factorizations (docs/design-notes.md, "Mixed biharmonic edits"). Not a public API.

#include <array>
#include <memory>

#include "Eigen/Core"
#include "absl/status/statusor.h"
#include "core/linalg/supernodal_cholesky.h"
#include "core/subspace/model_problem.h"
#include "core/subspace/reduced_system.h"

namespace fieldspace {

struct EnergyFactorization;

// One term of an inverse written as a weighted sum of inverses of factorized matrices,
// A^-1 = sum_k weight_k F_k^-1 (the exact form: one term of weight 1).
struct InverseTerm {
  const SupernodalFactor* factor = nullptr;
  double weight = 1.0;
};

// The inverse of the mixed energy matrix (d x d, symmetric positive semi-definite)
//   A = mu_s K + mu_b K Mr^-1 K = K Mr^-1 N,   N = mu_s Mr + mu_b K,
// K = U^T S U, Mr = U^T M U of one reduced system, in partial fractions:
//   A^-1 = N^-1 Mr K^-1 = (K^-1 - mu_b N^-1) / mu_s
// (multiply out: (K^-1 - mu_b N^-1) A = mu_s I + mu_b Mr^-1 K - mu_b N^-1 N Mr^-1 K = mu_s I), a
// signed sum of two sparse Cholesky inverses on the system's shared pattern: K's factorization
// is shared by every weight, N's is per weight, and a constraint's rows need only sparse forward
// substitutions with both (KktSolver), as with the exact form's single factorization. K's kernel
// columns (zero energy) carry the diagonal shift of ShiftKernelColumns, in N as in K (K_s,
// N_s = mu_n Mr + mu_b K_s), so that the matrix inverted, A_s = mu_n K_s + mu_b K_s Mr^-1 K_s,
// stays symmetric; solves refine against the true A (Multiply), which removes the shift as it
// does for the exact form's factorization. mu_n = max(mu_s, kKernelColumnShift mu_b
// min_i K_ii / Mr_ii) (pure biharmonic, mu_s = 0, gets that floor): the two terms cancel to a
// relative accuracy of about eps cond(K) (1 + mu_b lambda_1 / mu_n) for the lowest eigenvalue
// lambda_1 of (K, Mr), the last factor at most 1e6 at the floor, which the refinement absorbs
// (docs/design-notes.md, "Mixed biharmonic edits").
class MixedEnergyInverse {
 public:
  // `stiffness`: FactorizeEnergy(*system, {mu_s = 1, mu_b = 0}) (K_s's factorization and K's
  // panels). mu_s >= 0, mu_b > 0 (effective weights). `system` must outlive this object.
  // FailedPrecondition when N_s cannot be factorized (options' regularization policy); Cancelled.
  static absl::StatusOr<std::unique_ptr<const MixedEnergyInverse>> Create(
      const ReducedSystem* system, std::shared_ptr<const EnergyFactorization> stiffness,
      double mu_s, double mu_b, const ReducedSolveOptions& options);

  int64_t dimension() const { return n_->rows(); }
  // A_s^-1 = terms()[0] + terms()[1]: K_s^-1 / mu_n and -mu_b N_s^-1 / mu_n.
  std::array<InverseTerm, 2> terms() const;
  // A v (d) with the true K and Mr (K's panels and Mr's factorization; no shift).
  Eigen::VectorXd Multiply(const Eigen::VectorXd& v) const;

 private:
  MixedEnergyInverse(const ReducedSystem* system,
                     std::shared_ptr<const EnergyFactorization> stiffness, double mu_s,
                     double mu_b);

  const ReducedSystem* system_;
  std::shared_ptr<const EnergyFactorization> stiffness_;
  double mu_s_, mu_b_;
  double mu_n_ = 0;                      // N_s's weight of Mr (see above)
  std::unique_ptr<SupernodalFactor> n_;  // N_s
};

}  // namespace fieldspace

#endif  // FIELDSPACE_CORE_SUBSPACE_MIXED_ENERGY_H_
