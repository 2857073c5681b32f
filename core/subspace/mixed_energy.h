#ifndef FIELDSPACE_CORE_SUBSPACE_MIXED_ENERGY_H_
#define FIELDSPACE_CORE_SUBSPACE_MIXED_ENERGY_H_

// Internal to core/subspace: the mixed biharmonic (BiharmonicForm::kMixed) as a product of
// sparse solves (docs/design-notes.md, "Mixed biharmonic edits"). Not a public API.

#include <memory>

#include "Eigen/Core"
#include "absl/status/statusor.h"
#include "absl/types/span.h"
#include "core/linalg/supernodal_cholesky.h"
#include "core/subspace/model_problem.h"
#include "core/subspace/reduced_system.h"

namespace fieldspace {

struct EnergyFactorization;

// The inverse of the mixed energy matrix (d x d, symmetric positive semi-definite)
//   A = mu_s K + mu_b K Mr^-1 K = K Mr^-1 N,   N = mu_s Mr + mu_b K,
// K = U^T S U, Mr = U^T M U of one reduced system, as the product A^-1 = N^-1 Mr K^-1: two sparse
// Cholesky solves (K's factorization shared by every weight, N's per weight) and one sparse
// product with Mr; no d x d dense matrix. K's kernel columns (zero energy) carry the diagonal
// shift of ShiftKernelColumns, in N as in K (K_s, N_s = mu_s Mr + mu_b K_s), so that the matrix
// inverted, A_s = K_s Mr^-1 N_s, stays symmetric; solves refine against the true A (Multiply),
// which removes the shift as it does for the exact form's factorization. N_s's mu_s is at least
// kKernelColumnShift mu_b min_i K_ii / Mr_ii (A_s = A + that times K_s when mu_s is below it, e.g.
// 0: pure biharmonic), so that K_s's near-zero pivots enter A_s^-1 once, not squared.
class MixedEnergyInverse {
 public:
  // `stiffness`: FactorizeEnergy(*system, {mu_s = 1, mu_b = 0}) (K_s's factorization and K's
  // panels). mu_s >= 0, mu_b > 0 (effective weights). `system` must outlive this object.
  // FailedPrecondition when N_s cannot be factorized (options' regularization policy); Cancelled.
  static absl::StatusOr<std::unique_ptr<const MixedEnergyInverse>> Create(
      const ReducedSystem* system, std::shared_ptr<const EnergyFactorization> stiffness,
      double mu_s, double mu_b, const ReducedSolveOptions& options);

  int64_t dimension() const { return mass_.rows(); }
  // B <- A_s^-1 B for B d x m (any m): per column one solve with K_s, a product with Mr and one
  // solve with N_s (blocks of columns on parallel threads).
  void SolveInPlace(Eigen::Ref<Eigen::MatrixXd> B) const;
  // B <- A_s^-1 R^T for sparse rows R (column j: vals[j][q] at cols[j][q]; B d x #rows): as
  // SolveInPlace, with the first sweep of K_s's solve over the rows' elimination-tree reach only.
  void SolveSparseInto(absl::Span<const absl::Span<const int32_t>> cols,
                       absl::Span<const absl::Span<const double>> vals,
                       Eigen::Ref<Eigen::MatrixXd> B) const;
  // A v (d) with the true K and Mr (K's panels and Mr's factorization; no shift).
  Eigen::VectorXd Multiply(const Eigen::VectorXd& v) const;

 private:
  // B <- N_s^-1 Mr B (d x m): the rest of SolveInPlace after K_s^-1.
  void FinishColumns(Eigen::Ref<Eigen::MatrixXd> B) const;
  MixedEnergyInverse(const ReducedSystem* system,
                     std::shared_ptr<const EnergyFactorization> stiffness, double mu_s, double mu_b,
                     SupernodalMatrix mass);

  const ReducedSystem* system_;
  std::shared_ptr<const EnergyFactorization> stiffness_;
  double mu_s_, mu_b_;
  SupernodalMatrix mass_;                // Mr's panels, for the products
  double mu_n_ = 0;                      // N_s's weight of Mr (see above)
  std::unique_ptr<SupernodalFactor> n_;  // N_s
};

}  // namespace fieldspace

#endif  // FIELDSPACE_CORE_SUBSPACE_MIXED_ENERGY_H_
