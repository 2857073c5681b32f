#include "core/subspace/design_session.h"

#include <utility>

#include "absl/strings/str_cat.h"
#include "core/common/status_macros.h"
#include "core/subspace/kkt_solver.h"
#include "core/subspace/projection.h"

namespace fieldspace {

DesignSession::DesignSession(std::shared_ptr<const ReducedSystem> system,
                             const DesignSessionOptions& options)
    : system_(std::move(system)), options_(options) {}

DesignSession::~DesignSession() = default;

absl::StatusOr<std::unique_ptr<DesignSession>> DesignSession::Create(
    std::shared_ptr<const ReducedSystem> system, const EnergyWeights& weights,
    const DesignSessionOptions& options) {
  if (system == nullptr) return absl::InvalidArgumentError("DesignSession: no reduced system");
  RETURN_IF_ERROR(ValidateWeights(weights));
  RETURN_IF_ERROR(ValidateSolveOptions(options.solve));
  std::unique_ptr<DesignSession> session(new DesignSession(std::move(system), options));
  RETURN_IF_ERROR(session->FactorizeEnergy(weights, &session->A_, &session->factor_,
                                           &session->regularization_));
  session->weights_ = weights;
  session->kkt_ = std::make_unique<KktSolver>(session->system_->dimension(),
                                              session->system_->dofs_per_face(), options.solve);
  session->kkt_->SetMatrix(&session->A_, session->factor_.get());
  RETURN_IF_ERROR(session->kkt_->FactorizeSchur());
  session->Resolve();
  return session;
}

absl::Status DesignSession::FactorizeEnergy(const EnergyWeights& weights,
                                            Eigen::SparseMatrix<double>* A,
                                            std::unique_ptr<SupernodalFactor>* factor,
                                            double* tau) const {
  Eigen::SparseMatrix<double> a = system_->stiffness();
  const double* s = system_->stiffness().valuePtr();
  const double* b = system_->bilaplacian().valuePtr();
  double* v = a.valuePtr();
  for (int64_t p = 0; p < a.nonZeros(); ++p) {
    v[p] = weights.harmonic * s[p] + weights.biharmonic * b[p];
  }
  ASSIGN_OR_RETURN(SupernodalFactor f,
                   FactorizeRegularized(system_->pattern_symbolic(), a, options_.solve, tau));
  *A = std::move(a);
  *factor = std::make_unique<SupernodalFactor>(std::move(f));
  return absl::OkStatus();
}

void DesignSession::Resolve() {
  ReducedSolution sol = kkt_->Solve(nullptr);
  coefficients_ = std::move(sol.coefficients);
  last_backward_error_ = sol.backward_error;
  last_refinement_steps_ = sol.refinement_steps;
}

absl::Status DesignSession::AddConstraint(int64_t id, ConstraintKind kind,
                                          const FieldConstraint& constraint) {
  if (slot_by_id_.count(id)) {
    return absl::AlreadyExistsError(absl::StrCat("constraint id ", id, " already exists"));
  }
  const bool soft = kind == ConstraintKind::kSoft;
  RETURN_IF_ERROR(ValidateConstraint(*system_, constraint, soft));
  kkt_->Append(BasisRowsOfFace(*system_, constraint.face), constraint.value,
               soft ? SoftE(constraint.weight) : 0.0, !soft);
  if (absl::Status st = kkt_->FactorizeSchur(); !st.ok()) {
    // The previous factorization of H is still in place and matches the restored state.
    kkt_->RemoveSwapLast(kkt_->num_groups() - 1);
    RETURN_IF_ERROR(kkt_->FactorizeSchur());
    return st;
  }
  slot_by_id_[id] = static_cast<int32_t>(ids_by_slot_.size());
  ids_by_slot_.push_back(id);
  records_.push_back({kind, constraint});
  num_hard_ += soft ? 0 : 1;
  Resolve();
  return absl::OkStatus();
}

absl::Status DesignSession::MoveConstraint(int64_t id, const FieldConstraint& constraint) {
  auto it = slot_by_id_.find(id);
  if (it == slot_by_id_.end()) {
    return absl::NotFoundError(absl::StrCat("constraint id ", id, " does not exist"));
  }
  const int32_t slot = it->second;
  Record& record = records_[slot];
  const bool soft = record.kind == ConstraintKind::kSoft;
  RETURN_IF_ERROR(ValidateConstraint(*system_, constraint, soft));
  const double e = soft ? SoftE(constraint.weight) : 0.0;
  if (constraint.face == record.constraint.face) {
    kkt_->SetTarget(slot, constraint.value);
    if (soft && constraint.weight != record.constraint.weight) {
      kkt_->SetE(slot, e);
      // A positive change of a soft row's diagonal cannot create a dependence.
      RETURN_IF_ERROR(kkt_->FactorizeSchur());
    }
  } else {
    kkt_->Replace(slot, BasisRowsOfFace(*system_, constraint.face), constraint.value, e);
    if (absl::Status st = kkt_->FactorizeSchur(); !st.ok()) {
      const FieldConstraint& old = record.constraint;
      kkt_->Replace(slot, BasisRowsOfFace(*system_, old.face), old.value,
                    soft ? SoftE(old.weight) : 0.0);
      RETURN_IF_ERROR(kkt_->FactorizeSchur());
      return st;
    }
  }
  record.constraint = constraint;
  Resolve();
  return absl::OkStatus();
}

absl::Status DesignSession::RemoveConstraint(int64_t id) {
  auto it = slot_by_id_.find(id);
  if (it == slot_by_id_.end()) {
    return absl::NotFoundError(absl::StrCat("constraint id ", id, " does not exist"));
  }
  const int32_t slot = it->second;
  const int32_t last = static_cast<int32_t>(ids_by_slot_.size()) - 1;
  if (records_[slot].kind == ConstraintKind::kHard) --num_hard_;
  kkt_->RemoveSwapLast(slot);
  slot_by_id_.erase(it);
  if (slot != last) {
    ids_by_slot_[slot] = ids_by_slot_[last];
    records_[slot] = std::move(records_[last]);
    slot_by_id_[ids_by_slot_[slot]] = slot;
  }
  ids_by_slot_.pop_back();
  records_.pop_back();
  // Removing rows keeps the remaining hard rows independent, so this cannot fail.
  RETURN_IF_ERROR(kkt_->FactorizeSchur());
  Resolve();
  return absl::OkStatus();
}

void DesignSession::ClearConstraints() {
  while (kkt_->num_groups() > 0) kkt_->RemoveSwapLast(kkt_->num_groups() - 1);
  slot_by_id_.clear();
  ids_by_slot_.clear();
  records_.clear();
  num_hard_ = 0;
  (void)kkt_->FactorizeSchur();  // empty: always succeeds
  Resolve();
}

absl::Status DesignSession::SetWeights(const EnergyWeights& weights) {
  RETURN_IF_ERROR(ValidateWeights(weights));
  const EnergyWeights old_weights = weights_;
  const bool energy_changed =
      weights.harmonic != weights_.harmonic || weights.biharmonic != weights_.biharmonic;
  Eigen::SparseMatrix<double> old_A;
  std::unique_ptr<SupernodalFactor> old_factor;
  double old_tau = regularization_;
  if (energy_changed) {
    Eigen::SparseMatrix<double> A;
    std::unique_ptr<SupernodalFactor> factor;
    double tau = 0;
    RETURN_IF_ERROR(FactorizeEnergy(weights, &A, &factor, &tau));
    old_A = std::move(A_);
    old_factor = std::move(factor_);
    A_ = std::move(A);
    factor_ = std::move(factor);
    regularization_ = tau;
    kkt_->SetMatrix(&A_, factor_.get());
  }
  weights_ = weights;
  for (int32_t slot = 0; slot < static_cast<int32_t>(records_.size()); ++slot) {
    if (records_[slot].kind == ConstraintKind::kSoft) {
      kkt_->SetE(slot, SoftE(records_[slot].constraint.weight));
    }
  }
  if (absl::Status st = kkt_->FactorizeSchur(); !st.ok()) {
    weights_ = old_weights;
    if (energy_changed) {
      A_ = std::move(old_A);
      factor_ = std::move(old_factor);
      regularization_ = old_tau;
      kkt_->SetMatrix(&A_, factor_.get());
    }
    for (int32_t slot = 0; slot < static_cast<int32_t>(records_.size()); ++slot) {
      if (records_[slot].kind == ConstraintKind::kSoft) {
        kkt_->SetE(slot, SoftE(records_[slot].constraint.weight));
      }
    }
    RETURN_IF_ERROR(kkt_->FactorizeSchur());
    return st;
  }
  Resolve();
  return absl::OkStatus();
}

absl::StatusOr<Eigen::VectorXd> DesignSession::LiftFaces(absl::Span<const int32_t> faces) const {
  return fieldspace::LiftFaces(*system_, coefficients_, faces);
}

absl::StatusOr<Eigen::VectorXd> DesignSession::LiftAll() const {
  return Lift(*system_, coefficients_);
}

absl::StatusOr<ConstraintInfo> DesignSession::GetConstraint(int64_t id) const {
  auto it = slot_by_id_.find(id);
  if (it == slot_by_id_.end()) {
    return absl::NotFoundError(absl::StrCat("constraint id ", id, " does not exist"));
  }
  return records_[it->second];
}

ModelProblem DesignSession::problem() const {
  ModelProblem problem;
  problem.mu_s = weights_.harmonic;
  problem.mu_b = weights_.biharmonic;
  problem.mu_c = weights_.constraint;
  for (const auto& [id, slot] : slot_by_id_) {
    const FieldConstraint& c = records_[slot].constraint;
    if (records_[slot].kind == ConstraintKind::kSoft) {
      problem.soft.push_back({c.face, c.value, c.weight});
    } else {
      problem.hard.push_back({c.face, c.value});
    }
  }
  return problem;
}

}  // namespace fieldspace
