#include "core/subspace/design_session.h"

#include <algorithm>
#include <tuple>
#include <utility>

#include "absl/strings/str_cat.h"
#include "core/common/status_macros.h"
#include "core/subspace/kkt_solver.h"
#include "core/subspace/mixed_energy.h"
#include "core/subspace/projection.h"

namespace fieldspace {

absl::StatusOr<std::shared_ptr<const EnergyFactorization>> FactorizeEnergy(
    const ReducedSystem& system, const EnergyWeights& weights, const ReducedSolveOptions& options,
    const ReducedSmoother* data) {
  RETURN_IF_ERROR(data != nullptr ? ValidateWeights(weights)
                                  : ValidateWeightsWithoutDataTerm(weights));
  if (data != nullptr && &data->system() != &system) {
    return absl::InvalidArgumentError("FactorizeEnergy: the data term belongs to another system");
  }
  auto out = std::make_shared<EnergyFactorization>();
  Eigen::SparseMatrix<double> A;
  std::shared_ptr<const SupernodalSymbolic> symbolic = system.pattern_symbolic();
  if (data != nullptr) {
    A = data->WeightedSum(weights.mu_s, weights.mu_b, weights.mu_a);
    symbolic = data->symbolic();
  } else {
    A = system.stiffness();
    const double* s = system.stiffness().valuePtr();
    const double* b = system.bilaplacian().valuePtr();
    double* v = A.valuePtr();
    for (int64_t p = 0; p < A.nonZeros(); ++p) {
      v[p] = weights.mu_s * s[p] + weights.mu_b * b[p];
    }
  }
  ASSIGN_OR_RETURN(SupernodalFactor f, FactorizeRegularized(symbolic, ShiftKernelColumns(system, A),
                                                            options, &out->regularization));
  out->factor = std::make_unique<SupernodalFactor>(std::move(f));
  ASSIGN_OR_RETURN(SupernodalMatrix panels, SupernodalMatrix::Create(symbolic, A));
  out->A = std::make_unique<SupernodalMatrix>(std::move(panels));
  return std::shared_ptr<const EnergyFactorization>(std::move(out));
}

bool EnergyFactorCache::Key::operator<(const Key& o) const {
  return std::tie(system, data, mu_s, mu_b, mu_a, regularization, max_regularization, parallel) <
         std::tie(o.system, o.data, o.mu_s, o.mu_b, o.mu_a, o.regularization, o.max_regularization,
                  o.parallel);
}

absl::StatusOr<std::shared_ptr<const EnergyFactorization>> EnergyFactorCache::Get(
    const ReducedSystem& system, const EnergyWeights& weights, const ReducedSolveOptions& options,
    bool* factorized, const ReducedSmoother* data) {
  if (factorized != nullptr) *factorized = false;
  const Key key{&system,
                data,
                weights.mu_s,
                weights.mu_b,
                data != nullptr ? weights.mu_a : 0.0,
                options.regularization,
                options.max_regularization,
                options.parallel};
  std::shared_ptr<Entry> entry;
  {
    std::lock_guard<std::mutex> lock(mu_);
    // Drop entries nobody holds (and nobody is computing: their Entry is referenced only here).
    for (auto it = entries_.begin(); it != entries_.end();) {
      if (it->second.use_count() == 1 && it->second->value.expired()) {
        it = entries_.erase(it);
      } else {
        ++it;
      }
    }
    std::shared_ptr<Entry>& slot = entries_[key];
    if (slot == nullptr) slot = std::make_shared<Entry>();
    entry = slot;
  }
  std::lock_guard<std::mutex> lock(entry->mu);
  if (std::shared_ptr<const EnergyFactorization> value = entry->value.lock()) return value;
  // On error (or cancellation) nothing is stored; the next caller tries again.
  ASSIGN_OR_RETURN(std::shared_ptr<const EnergyFactorization> value,
                   FactorizeEnergy(system, weights, options, data));
  entry->value = value;
  if (factorized != nullptr) *factorized = true;
  return value;
}

int32_t EnergyFactorCache::live_entries() const {
  std::lock_guard<std::mutex> lock(mu_);
  int32_t n = 0;
  for (const auto& [key, entry] : entries_) n += entry->value.expired() ? 0 : 1;
  return n;
}

DesignSession::DesignSession(std::shared_ptr<const ReducedSystem> system,
                             const DesignSessionOptions& options)
    : system_(std::move(system)), options_(options) {}

DesignSession::~DesignSession() = default;

absl::StatusOr<std::unique_ptr<DesignSession>> DesignSession::Create(
    std::shared_ptr<const ReducedSystem> system, const EnergyWeights& weights,
    const DesignSessionOptions& options) {
  if (system == nullptr) return absl::InvalidArgumentError("DesignSession: no reduced system");
  RETURN_IF_ERROR(ValidateSessionWeights(weights, options.data_term != nullptr));
  if (options.data_term != nullptr && &options.data_term->system() != system.get()) {
    return absl::InvalidArgumentError("DesignSession: the data term belongs to another basis");
  }
  RETURN_IF_ERROR(ValidateSolveOptions(options.solve));
  if (options.verify_interval < 1) {
    return absl::InvalidArgumentError("DesignSession: verify_interval must be >= 1");
  }
  std::unique_ptr<DesignSession> session(new DesignSession(std::move(system), options));
  ASSIGN_OR_RETURN(session->energy_, session->Energy(weights));
  session->weights_ = weights;
  session->UpdateDataRhs();
  session->kkt_ = std::make_unique<KktSolver>(session->system_->dimension(),
                                              session->system_->dofs_per_face(), options.solve);
  RETURN_IF_ERROR(session->AttachEnergy(weights));
  RETURN_IF_ERROR(session->kkt_->FactorizeSchur());
  session->Resolve();
  return session;
}

absl::StatusOr<std::shared_ptr<const EnergyFactorization>> DesignSession::Energy(
    const EnergyWeights& weights) {
  last_factorized_ = false;
  EnergyWeights effective = EffectiveEnergyWeights(*system_, weights, options_.scale_free);
  const ReducedSmoother* data = options_.data_term.get();
  if (data != nullptr && options_.scale_free) effective.mu_a /= data->total_area();
  return SharedFactorization(effective, data, &last_factorized_);
}

absl::StatusOr<std::shared_ptr<const EnergyFactorization>> DesignSession::SharedFactorization(
    const EnergyWeights& effective, const ReducedSmoother* data, bool* factorized,
    const ReducedSolveOptions* solve) const {
  if (solve == nullptr) solve = &options_.solve;
  if (options_.energy_cache != nullptr) {
    return options_.energy_cache->Get(*system_, effective, *solve, factorized, data);
  }
  *factorized = true;
  return FactorizeEnergy(*system_, effective, *solve, data);
}

absl::StatusOr<double> DesignSession::Stiffness(const std::vector<SparseRow>& rows) const {
  if (!options_.scale_free) return 1.0;
  // With a data term the kernel columns have energy (its mass) like the others.
  const bool data_energy = has_data_term() && weights_.mu_a > 0;
  return FaceStiffness(*system_, *energy_->factor, rows, /*skip_kernel_columns=*/!data_energy);
}

absl::Status DesignSession::AttachEnergy(const EnergyWeights& weights) {
  const EnergyWeights effective = EffectiveEnergyWeights(*system_, weights, options_.scale_free);
  const double mu_b = options_.biharmonic == BiharmonicForm::kMixed ? effective.mu_b : 0.0;
  // The mixed energy K Mr^-1 (mu_S Mr + mu_B K) is inverted through its partial fractions
  // (K^-1 - mu_B N^-1) / mu_S (mixed_energy.h), K's factorization shared by every weight. A data
  // term's mass breaks that form: then the exact form's factorization preconditions conjugate
  // gradients (KktSolver::Solve). So does mu_S = 0 with kernel columns: their shift would enter
  // A_s^-1 squared, and hard constraints on the harmonic directions would read as dependent.
  if (mu_b > 0 && !(has_data_term() && weights.mu_a > 0) &&
      (effective.mu_s > 0 || system_->basis().kernel_columns == 0)) {
    // Both factorizations start without the regularization's diagonal scaling (the policy's
    // shift still follows a failure): the fractions' cancellation amplifies it, and with it the
    // first solve missed the tolerance and was refined on every edit with a low-modes basis.
    ReducedSolveOptions unshifted = options_.solve;
    unshifted.regularization = 0;
    if (stiffness_energy_ == nullptr) {
      bool factorized = false;
      ASSIGN_OR_RETURN(stiffness_energy_, SharedFactorization({.mu_s = 1.0, .mu_b = 0.0}, nullptr,
                                                              &factorized, &unshifted));
    }
    ASSIGN_OR_RETURN(std::unique_ptr<const MixedEnergyInverse> inverse,
                     MixedEnergyInverse::Create(system_.get(), stiffness_energy_, effective.mu_s,
                                                mu_b, unshifted));
    return kkt_->SetMixed(std::move(inverse));
  }
  RETURN_IF_ERROR(kkt_->SetMatrix(energy_->A.get(), energy_->factor.get()));
  kkt_->SetMixedBiharmonic(system_.get(), mu_b);
  return absl::OkStatus();
}

void DesignSession::UpdateDataRhs() {
  const ReducedSmoother* data = options_.data_term.get();
  if (data == nullptr) return;
  const double mu_a = options_.scale_free ? weights_.mu_a / data->total_area() : weights_.mu_a;
  data_rhs_ = mu_a * data->rhs();
}

void DesignSession::Resolve() {
  // Below this pivot of the scaled Schur complement the constraints are nearly dependent.
  constexpr double kNearlyDependentPivot = 1e-6;
  ++solves_since_check_;
  // A basis with kernel columns is factorized with their zero-energy diagonal shifted
  // (ShiftKernelColumns): only the refinement against the true system removes the shift's effect
  // along the harmonic directions, so every solve is checked and refined (measured: unchecked
  // solves were off by 8e-6 relative on a torus).
  const bool shifted = system_->basis().kernel_columns > 0;
  const bool verify = shifted || solves_since_check_ >= options_.verify_interval ||
                      !verified_since_factorization_ || last_check_close_ ||
                      kkt_->schur_min_pivot() < kNearlyDependentPivot;
  ReducedSolution sol = kkt_->Solve(has_data_term() ? &data_rhs_ : nullptr, verify);
  if (verify) {
    verified_since_factorization_ = true;
    // The default diagonal shift (1e-13) alone gives backward errors of ~5e-14: a margin of 4
    // below the default tolerance separates that from a drifting solve.
    last_check_close_ =
        sol.refinement_steps > 0 || !(sol.backward_error <= options_.solve.tolerance / 4);
    solves_since_check_ = 0;
  }
  coefficients_ = std::move(sol.coefficients);
  last_backward_error_ = sol.backward_error;
  last_refinement_steps_ = sol.refinement_steps;
}

absl::Status DesignSession::RestoreCoefficients(const Eigen::VectorXd& x) {
  constexpr double kSameSolution = 1e-6;
  if (x.size() != coefficients_.size() ||
      !((x - coefficients_).norm() <= kSameSolution * coefficients_.norm())) {
    return absl::FailedPreconditionError(
        "RestoreCoefficients: not a solution of the session's current problem");
  }
  coefficients_ = x;
  return absl::OkStatus();
}

absl::StatusOr<std::vector<double>> DesignSession::PrepareConstraints(
    int64_t id, absl::Span<const FieldConstraint> constraints) const {
  auto it = entries_.find(id);
  const std::vector<int32_t>* slots = it == entries_.end() ? nullptr : &it->second.slots;
  std::vector<double> stiffness(constraints.size(), 1.0);
  for (size_t i = 0; i < constraints.size(); ++i) {
    const FieldConstraint& c = constraints[i];
    if (absl::Status st = ValidateConstraint(c, system_->num_faces(), system_->type()); !st.ok()) {
      if (constraints.size() == 1) return st;
      return absl::Status(st.code(),
                          absl::StrCat("constraint ", i, " of group ", id, ": ", st.message()));
    }
    if (c.hard()) continue;
    if (slots != nullptr && i < slots->size() && records_[(*slots)[i]].face == c.face &&
        !records_[(*slots)[i]].hard()) {
      stiffness[i] = stiffness_[(*slots)[i]];
      continue;
    }
    ASSIGN_OR_RETURN(stiffness[i], Stiffness(BasisRowsOfFace(*system_, c.face)));
  }
  return stiffness;
}

void DesignSession::RemoveSlot(int32_t slot) {
  const int32_t last = static_cast<int32_t>(ids_by_slot_.size()) - 1;
  if (records_[slot].hard()) --num_hard_;
  kkt_->RemoveSwapLast(slot);
  if (slot != last) {
    ids_by_slot_[slot] = ids_by_slot_[last];
    position_by_slot_[slot] = position_by_slot_[last];
    records_[slot] = std::move(records_[last]);
    stiffness_[slot] = stiffness_[last];
    entries_.at(ids_by_slot_[slot]).slots[position_by_slot_[slot]] = slot;
  }
  ids_by_slot_.pop_back();
  position_by_slot_.pop_back();
  records_.pop_back();
  stiffness_.pop_back();
}

bool DesignSession::SetSlots(int64_t id, absl::Span<const FieldConstraint> constraints,
                             absl::Span<const double> stiffness) {
  std::vector<int32_t>& slots = entries_.at(id).slots;
  bool changed = false;
  const size_t kept = std::min(slots.size(), constraints.size());
  std::vector<int32_t> replaced_slots;
  std::vector<KktSolver::NewGroup> replaced;
  for (size_t i = 0; i < kept; ++i) {
    const int32_t slot = slots[i];
    const FieldConstraint& c = constraints[i];
    FieldConstraint& record = records_[slot];
    const double e = c.hard() ? 0.0 : SoftE(c.weight, stiffness[i]);
    if (c.face == record.face && c.hard() == record.hard()) {
      kkt_->SetTarget(slot, c.value);
      if (!c.hard() && (c.weight != record.weight || stiffness[i] != stiffness_[slot])) {
        kkt_->SetE(slot, e);
        changed = true;
      }
    } else {
      replaced_slots.push_back(slot);
      replaced.push_back({BasisRowsOfFace(*system_, c.face), c.value, e, c.hard()});
      num_hard_ += (c.hard() ? 1 : 0) - (record.hard() ? 1 : 0);
      changed = true;
    }
    record = c;
    stiffness_[slot] = stiffness[i];
  }
  // Before any slot moves (RemoveSlot below).
  kkt_->ReplaceGroups(replaced_slots, std::move(replaced));
  if (slots.size() > kept) {
    // Highest slot first: the last slot, which moves into the removed one's place, is then never
    // one still to be removed.
    std::vector<int32_t> surplus(slots.begin() + kept, slots.end());
    slots.resize(kept);
    std::sort(surplus.rbegin(), surplus.rend());
    for (int32_t slot : surplus) RemoveSlot(slot);
    changed = true;
  }
  std::vector<KktSolver::NewGroup> appended;
  for (size_t i = kept; i < constraints.size(); ++i) {
    const FieldConstraint& c = constraints[i];
    appended.push_back({BasisRowsOfFace(*system_, c.face), c.value,
                        c.hard() ? 0.0 : SoftE(c.weight, stiffness[i]), c.hard()});
    slots.push_back(static_cast<int32_t>(ids_by_slot_.size()));
    ids_by_slot_.push_back(id);
    position_by_slot_.push_back(static_cast<int32_t>(i));
    records_.push_back(c);
    stiffness_.push_back(stiffness[i]);
    num_hard_ += c.hard() ? 1 : 0;
    changed = true;
  }
  kkt_->AppendGroups(std::move(appended));
  return changed;
}

absl::Status DesignSession::CommitSlots(int64_t id, absl::Span<const FieldConstraint> constraints,
                                        absl::Span<const double> stiffness,
                                        absl::Span<const FieldConstraint> old_constraints,
                                        absl::Span<const double> old_stiffness) {
  if (!SetSlots(id, constraints, stiffness)) return absl::OkStatus();
  absl::Status st = kkt_->FactorizeSchur();
  if (st.ok()) return st;
  // The previous factorization of H is still in place and matches the restored state.
  SetSlots(id, old_constraints, old_stiffness);
  RETURN_IF_ERROR(kkt_->FactorizeSchur());
  return st;
}

absl::Status DesignSession::AddConstraint(int64_t id, const FieldConstraint& constraint) {
  if (entries_.count(id)) {
    return absl::AlreadyExistsError(absl::StrCat("constraint id ", id, " already exists"));
  }
  ASSIGN_OR_RETURN(std::vector<double> stiffness, PrepareConstraints(id, {&constraint, 1}));
  entries_[id] = Entry{};
  if (absl::Status st = CommitSlots(id, {&constraint, 1}, stiffness, {}, {}); !st.ok()) {
    entries_.erase(id);
    return st;
  }
  Resolve();
  return absl::OkStatus();
}

absl::Status DesignSession::AddConstraintGroup(int64_t id,
                                               absl::Span<const FieldConstraint> constraints) {
  if (entries_.count(id)) {
    return absl::AlreadyExistsError(absl::StrCat("constraint id ", id, " already exists"));
  }
  if (constraints.empty()) {
    return absl::InvalidArgumentError(absl::StrCat("constraint group ", id, " is empty"));
  }
  ASSIGN_OR_RETURN(std::vector<double> stiffness, PrepareConstraints(id, constraints));
  entries_[id] = Entry{.slots = {}, .group = true};
  if (absl::Status st = CommitSlots(id, constraints, stiffness, {}, {}); !st.ok()) {
    entries_.erase(id);
    return st;
  }
  Resolve();
  return absl::OkStatus();
}

absl::Status DesignSession::MoveConstraint(int64_t id, int32_t face, Eigen::VectorXd value) {
  ASSIGN_OR_RETURN(FieldConstraint moved, GetConstraint(id));
  moved.face = face;
  moved.value = std::move(value);
  return MoveConstraint(id, moved);
}

absl::Status DesignSession::MoveConstraint(int64_t id, const FieldConstraint& target) {
  ASSIGN_OR_RETURN(FieldConstraint old, GetConstraint(id));
  FieldConstraint constraint = target;
  constraint.kind = old.kind;  // a move keeps the kind
  ASSIGN_OR_RETURN(std::vector<double> stiffness, PrepareConstraints(id, {&constraint, 1}));
  const double old_stiffness = stiffness_[entries_.at(id).slots[0]];
  RETURN_IF_ERROR(CommitSlots(id, {&constraint, 1}, stiffness, {&old, 1}, {&old_stiffness, 1}));
  Resolve();
  return absl::OkStatus();
}

absl::Status DesignSession::MoveConstraintGroup(int64_t id,
                                                absl::Span<const FieldConstraint> constraints) {
  auto it = entries_.find(id);
  if (it == entries_.end()) {
    return absl::NotFoundError(absl::StrCat("constraint id ", id, " does not exist"));
  }
  if (!it->second.group) {
    return absl::FailedPreconditionError(
        absl::StrCat("constraint id ", id, " is a single constraint, not a group: move it alone"));
  }
  if (constraints.empty()) {
    return absl::InvalidArgumentError(absl::StrCat("constraint group ", id, " is empty"));
  }
  ASSIGN_OR_RETURN(std::vector<double> stiffness, PrepareConstraints(id, constraints));
  std::vector<FieldConstraint> old;
  std::vector<double> old_stiffness;
  for (int32_t slot : it->second.slots) {
    old.push_back(records_[slot]);
    old_stiffness.push_back(stiffness_[slot]);
  }
  RETURN_IF_ERROR(CommitSlots(id, constraints, stiffness, old, old_stiffness));
  Resolve();
  return absl::OkStatus();
}

absl::Status DesignSession::RemoveConstraint(int64_t id) {
  if (!entries_.count(id)) {
    return absl::NotFoundError(absl::StrCat("constraint id ", id, " does not exist"));
  }
  SetSlots(id, {}, {});
  entries_.erase(id);
  // Removing rows keeps the remaining hard rows independent, so this cannot fail.
  RETURN_IF_ERROR(kkt_->FactorizeSchur());
  Resolve();
  return absl::OkStatus();
}

void DesignSession::ClearConstraints() {
  while (kkt_->num_groups() > 0) kkt_->RemoveSwapLast(kkt_->num_groups() - 1);
  entries_.clear();
  ids_by_slot_.clear();
  position_by_slot_.clear();
  records_.clear();
  stiffness_.clear();
  num_hard_ = 0;
  (void)kkt_->FactorizeSchur();  // empty: always succeeds
  Resolve();
}

absl::Status DesignSession::SetWeights(const EnergyWeights& weights) {
  RETURN_IF_ERROR(ValidateSessionWeights(weights, has_data_term()));
  const EnergyWeights old_weights = weights_;
  const bool energy_changed = weights.mu_s != weights_.mu_s || weights.mu_b != weights_.mu_b ||
                              (has_data_term() && weights.mu_a != weights_.mu_a);
  std::shared_ptr<const EnergyFactorization> old_energy = energy_;
  std::vector<double> old_stiffness = stiffness_;
  last_factorized_ = false;
  // Puts the session back as it was (the old factorization of H matches it again).
  const auto restore = [&]() -> absl::Status {
    weights_ = old_weights;
    stiffness_ = old_stiffness;
    UpdateDataRhs();
    if (energy_changed) {
      energy_ = old_energy;
      // The old energy was attached before: its spectrum, if any, is cached.
      RETURN_IF_ERROR(AttachEnergy(old_weights));
      verified_since_factorization_ = false;
    }
    for (int32_t slot = 0; slot < static_cast<int32_t>(records_.size()); ++slot) {
      if (!records_[slot].hard()) kkt_->SetE(slot, SoftE(records_[slot].weight, stiffness_[slot]));
    }
    return kkt_->FactorizeSchur();
  };
  if (energy_changed) {
    ASSIGN_OR_RETURN(std::shared_ptr<const EnergyFactorization> energy, Energy(weights));
    energy_ = std::move(energy);
    if (absl::Status st = AttachEnergy(weights); !st.ok()) {
      RETURN_IF_ERROR(restore());
      return st;
    }
    verified_since_factorization_ = false;
    weights_ = weights;  // Stiffness() reads mu_a; restore() puts the old weights back
    // Scale-free soft weights are relative to the faces' stiffness under the new energy.
    for (int32_t slot = 0; slot < static_cast<int32_t>(records_.size()); ++slot) {
      if (records_[slot].hard()) continue;
      absl::StatusOr<double> g = Stiffness(kkt_->GroupRows(slot));
      if (!g.ok()) {
        RETURN_IF_ERROR(restore());
        return g.status();
      }
      stiffness_[slot] = *g;
    }
  }
  weights_ = weights;
  UpdateDataRhs();
  for (int32_t slot = 0; slot < static_cast<int32_t>(records_.size()); ++slot) {
    if (!records_[slot].hard()) kkt_->SetE(slot, SoftE(records_[slot].weight, stiffness_[slot]));
  }
  if (absl::Status st = kkt_->FactorizeSchur(); !st.ok()) {
    RETURN_IF_ERROR(restore());
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

absl::StatusOr<FieldConstraint> DesignSession::GetConstraint(int64_t id) const {
  auto it = entries_.find(id);
  if (it == entries_.end()) {
    return absl::NotFoundError(absl::StrCat("constraint id ", id, " does not exist"));
  }
  if (it->second.group) {
    return absl::FailedPreconditionError(absl::StrCat("constraint id ", id, " is a group of ",
                                                      it->second.slots.size(), " constraints"));
  }
  return records_[it->second.slots[0]];
}

absl::StatusOr<std::vector<FieldConstraint>> DesignSession::GetConstraintGroup(int64_t id) const {
  auto it = entries_.find(id);
  if (it == entries_.end()) {
    return absl::NotFoundError(absl::StrCat("constraint id ", id, " does not exist"));
  }
  std::vector<FieldConstraint> out;
  out.reserve(it->second.slots.size());
  for (int32_t slot : it->second.slots) out.push_back(records_[slot]);
  return out;
}

ModelProblem DesignSession::problem() const {
  ModelProblem problem;
  problem.weights = weights_;
  problem.weights.mu_a = 0;  // the data term is the session's own
  problem.scale_free = options_.scale_free;
  problem.biharmonic = options_.biharmonic;
  for (const auto& [id, entry] : entries_) {
    for (int32_t slot : entry.slots) problem.constraints.push_back(records_[slot]);
  }
  return problem;
}

int64_t DesignSessionOpenBytes(const ReducedSystem& system) {
  // The exact form's factorization and panels; with the mixed form also N's factorization and
  // K's factorization and panels (shared between sessions, counted by each; mixed_energy.h):
  // five factor-sized arrays at most.
  return 5 * system.stats().factor_nonzeros * 8 + 16 * int64_t{system.dimension()} * 8;
}

int64_t DesignSessionConstraintBytes(const ReducedSystem& system, int64_t constraints) {
  const int64_t r = std::max<int64_t>(constraints, 0) * system.dofs_per_face();
  return 8 * (4 * int64_t{system.dimension()} * r + 6 * r * r);
}

}  // namespace fieldspace
