#include "core/subspace/mixed_energy.h"

#include <algorithm>
#include <utility>

#include "core/common/status_macros.h"
#include "core/subspace/design_session.h"
#include "core/subspace/kkt_solver.h"

namespace fieldspace {

absl::StatusOr<std::unique_ptr<const MixedEnergyInverse>> MixedEnergyInverse::Create(
    const ReducedSystem* system, std::shared_ptr<const EnergyFactorization> stiffness, double mu_s,
    double mu_b, const ReducedSolveOptions& options) {
  auto out = std::unique_ptr<MixedEnergyInverse>(
      new MixedEnergyInverse(system, std::move(stiffness), mu_s, mu_b));
  // N_s = mu_n Mr + mu_b K_s, value by value on the shared pattern, with mu_n at least
  // kKernelColumnShift mu_b min_i K_ii / Mr_ii: with mu_s = 0 the partial fractions would divide
  // by zero (and N_s = mu_b K_s would put K_s's near-zero pivots into A_s^-1 twice).
  Eigen::SparseMatrix<double> N = ShiftKernelColumns(*system, system->stiffness());
  const Eigen::VectorXd ratio =
      system->stiffness().diagonal().cwiseQuotient(system->mass_matrix().diagonal());
  const double floor = kKernelColumnShift * mu_b * std::max(ratio.minCoeff(), 0.0);
  out->mu_n_ = std::max(mu_s, floor);
  if (!(out->mu_n_ > 0)) {
    return absl::FailedPreconditionError(
        "mixed biharmonic: the reduced stiffness has no positive diagonal entry");
  }
  const double* m = system->mass_matrix().valuePtr();
  double* v = N.valuePtr();
  for (int64_t q = 0; q < N.nonZeros(); ++q) v[q] = out->mu_n_ * m[q] + mu_b * v[q];
  double tau = 0;
  ASSIGN_OR_RETURN(SupernodalFactor n,
                   FactorizeRegularized(system->pattern_symbolic(), N, options, &tau));
  out->n_ = std::make_unique<SupernodalFactor>(std::move(n));
  return std::unique_ptr<const MixedEnergyInverse>(std::move(out));
}

MixedEnergyInverse::MixedEnergyInverse(const ReducedSystem* system,
                                       std::shared_ptr<const EnergyFactorization> stiffness,
                                       double mu_s, double mu_b)
    : system_(system), stiffness_(std::move(stiffness)), mu_s_(mu_s), mu_b_(mu_b) {}

std::array<InverseTerm, 2> MixedEnergyInverse::terms() const {
  return {InverseTerm{stiffness_->factor.get(), 1.0 / mu_n_},
          InverseTerm{n_.get(), -mu_b_ / mu_n_}};
}

Eigen::VectorXd MixedEnergyInverse::Multiply(const Eigen::VectorXd& v) const {
  const SupernodalMatrix& K = *stiffness_->A;
  const Eigen::VectorXd kv = K.Multiply(v);
  Eigen::VectorXd out = mu_b_ * K.Multiply(system_->mass_factor().Solve(kv));
  out.noalias() += mu_s_ * kv;
  return out;
}

}  // namespace fieldspace
