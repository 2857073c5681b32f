#include "core/subspace/mixed_energy.h"

#include <algorithm>
#include <utility>

#include "core/common/status_macros.h"
#include "core/subspace/design_session.h"
#include "core/subspace/kkt_solver.h"
#include "oneapi/tbb/parallel_for.h"
#include "oneapi/tbb/task_arena.h"

namespace fieldspace {

absl::StatusOr<std::unique_ptr<const MixedEnergyInverse>> MixedEnergyInverse::Create(
    const ReducedSystem* system, std::shared_ptr<const EnergyFactorization> stiffness, double mu_s,
    double mu_b, const ReducedSolveOptions& options) {
  ASSIGN_OR_RETURN(SupernodalMatrix mass,
                   SupernodalMatrix::Create(system->pattern_symbolic(), system->mass_matrix()));
  auto out = std::unique_ptr<MixedEnergyInverse>(
      new MixedEnergyInverse(system, std::move(stiffness), mu_s, mu_b, std::move(mass)));
  // N_s = mu_s' Mr + mu_b K_s, value by value on the shared pattern, with mu_s' at least
  // kKernelColumnShift mu_b min_i K_ii / Mr_ii: with mu_s = 0, N_s = mu_b K_s would put K_s's
  // near-zero pivots (harmonic fields the basis holds without kernel columns) into A_s^-1 twice.
  Eigen::SparseMatrix<double> N = ShiftKernelColumns(*system, system->stiffness());
  const Eigen::VectorXd ratio =
      system->stiffness().diagonal().cwiseQuotient(system->mass_matrix().diagonal());
  const double floor = kKernelColumnShift * mu_b * std::max(ratio.minCoeff(), 0.0);
  out->mu_n_ = std::max(mu_s, floor);
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
                                       double mu_s, double mu_b, SupernodalMatrix mass)
    : system_(system),
      stiffness_(std::move(stiffness)),
      mu_s_(mu_s),
      mu_b_(mu_b),
      mass_(std::move(mass)) {}

void MixedEnergyInverse::SolveInPlace(Eigen::Ref<Eigen::MatrixXd> B) const {
  // The columns are independent: a chunk per thread (an add's p = 2-3 columns run side by side;
  // a weight change's many columns as a few blocks, whose substitutions use matrix kernels).
  const Eigen::Index m = B.cols();
  if (m == 0) return;
  const Eigen::Index threads = std::max(1, tbb::this_task_arena::max_concurrency());
  const Eigen::Index chunk = (m + threads - 1) / threads;
  tbb::parallel_for(Eigen::Index{0}, (m + chunk - 1) / chunk, [&](Eigen::Index c) {
    const Eigen::Index j0 = c * chunk;
    auto block = B.middleCols(j0, std::min(chunk, m - j0));
    stiffness_->factor->SolveInPlace(block);
    FinishColumns(block);
  });
}

void MixedEnergyInverse::SolveSparseInto(absl::Span<const absl::Span<const int32_t>> cols,
                                         absl::Span<const absl::Span<const double>> vals,
                                         Eigen::Ref<Eigen::MatrixXd> B) const {
  if (B.cols() > 4) {
    // Many columns (a weight change re-solves every constraint): their reaches cover most of
    // the tree, and the blocked substitutions' matrix kernels win.
    B.setZero();
    for (size_t j = 0; j < cols.size(); ++j) {
      for (size_t q = 0; q < cols[j].size(); ++q) B(cols[j][q], j) += vals[j][q];
    }
    SolveInPlace(B);
    return;
  }
  // L^-1 P R^T over the rows' reach (one block pass), then per column the rest on its thread.
  const SupernodalFactor& k = *stiffness_->factor;
  k.ForwardSparseColumns(cols, vals, B);
  tbb::parallel_for(Eigen::Index{0}, B.cols(), [&](Eigen::Index j) {
    auto column = B.col(j);
    k.BackwardInPlace(column);
    column = k.PermuteOut(column);
    FinishColumns(column);
  });
}

void MixedEnergyInverse::FinishColumns(Eigen::Ref<Eigen::MatrixXd> B) const {
  for (Eigen::Index j = 0; j < B.cols(); ++j) B.col(j) = mass_.Multiply(B.col(j));
  n_->SolveInPlace(B);
}

Eigen::VectorXd MixedEnergyInverse::Multiply(const Eigen::VectorXd& v) const {
  const SupernodalMatrix& K = *stiffness_->A;
  const Eigen::VectorXd kv = K.Multiply(v);
  Eigen::VectorXd out = mu_b_ * K.Multiply(system_->mass_factor().Solve(kv));
  out.noalias() += mu_s_ * kv;
  return out;
}

}  // namespace fieldspace
