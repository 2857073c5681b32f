#ifndef FIELDSPACE_CORE_SUBSPACE_DESIGN_SESSION_H_
#define FIELDSPACE_CORE_SUBSPACE_DESIGN_SESSION_H_

#include <cstdint>
#include <map>
#include <memory>
#include <mutex>
#include <vector>

#include "Eigen/Core"
#include "Eigen/SparseCore"
#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/types/span.h"
#include "core/linalg/supernodal_cholesky.h"
#include "core/subspace/model_problem.h"
#include "core/subspace/reduced_system.h"
#include "core/subspace/smoothing.h"

namespace fieldspace {

class KktSolver;
struct SparseRow;

// The energy matrix A = U^T (mu_S S + mu_B B) U (+ mu_A U^T W M U with a data term) of one
// reduced system for one (mu_S, mu_B[, mu_A]), and its (possibly regularized) factorization.
// Immutable; shared by sessions.
struct EnergyFactorization {
  std::unique_ptr<SupernodalMatrix> A;  // d x d, on the system's shared pattern
  std::unique_ptr<SupernodalFactor> factor;
  double regularization = 0;  // the diagonal shift that was needed
};

// Factorizes A for `weights` (mu_S, mu_B as given: callers apply EffectiveEnergyWeights) with
// the regularization policy of `options`; with `data` (not null; of the same system), plus
// weights.mu_a times the data term's weighted mass (as given, too). FailedPrecondition when it
// cannot be factorized; Cancelled (options.cancel).
absl::StatusOr<std::shared_ptr<const EnergyFactorization>> FactorizeEnergy(
    const ReducedSystem& system, const EnergyWeights& weights, const ReducedSolveOptions& options,
    const ReducedSmoother* data = nullptr);

// Energy factorizations shared by the design sessions of a reduced system: sessions with the
// same (mu_S, mu_B) and regularization policy use one factorization while any of them holds it,
// so a server with many sessions on one basis keeps one factor in memory (and in cache), and
// opening a session with weights already in use costs no factorization. Concurrent requests for
// the same weights wait for one factorization instead of repeating it. Thread-safe. Entries are
// kept only while a holder exists (weak references).
class EnergyFactorCache {
 public:
  // As FactorizeEnergy(system, weights, options), shared. The system's address is part of the
  // key, so one cache may serve several systems (each entry keeps none of them alive).
  // *factorized (optional): whether this call computed the factorization.
  absl::StatusOr<std::shared_ptr<const EnergyFactorization>> Get(
      const ReducedSystem& system, const EnergyWeights& weights, const ReducedSolveOptions& options,
      bool* factorized = nullptr, const ReducedSmoother* data = nullptr);
  // Entries with a live factorization.
  int32_t live_entries() const;

 private:
  struct Key {
    const ReducedSystem* system;
    const ReducedSmoother* data;
    double mu_s, mu_b, mu_a, regularization, max_regularization;
    bool parallel;
    bool operator<(const Key& o) const;
  };
  struct Entry {
    std::mutex mu;  // held while the factorization is computed
    std::weak_ptr<const EnergyFactorization> value;
  };
  mutable std::mutex mu_;
  std::map<Key, std::shared_ptr<Entry>> entries_;
};

// The weights of a session with a data term when a caller gives none: smoothing's
// (kDefaultSmoothingWeights, with the data term as mu_a) plus soft constraints at mu_c = 1.
inline constexpr EnergyWeights kDefaultDataTermSessionWeights{
    .mu_s = kDefaultSmoothingWeights.mu_s, .mu_b = 0.0, .mu_c = 1.0, .mu_a = 1.0};

struct DesignSessionOptions {
  ReducedSolveOptions solve;
  // How often an edit's solution is checked against the true energy matrix (its backward error,
  // and iterative refinement when that exceeds solve.tolerance). The check (a product with A plus
  // sparse products) costs about as much as the edit's solve. 1: every solve. k > 1: the first
  // solve after every factorization of A, every solve while the last check needed refinement or
  // was within 4x of the tolerance, every solve while the constraints are nearly dependent
  // (smallest pivot of the scaled Schur complement below 1e-6), and otherwise every k-th solve.
  // The checks that pass show that the factorization solves to the tolerance; the solves in
  // between use the same factorization and well-conditioned constraints.
  int32_t verify_interval = 1;
  // Where energy factorizations come from; null: the session factorizes its own.
  std::shared_ptr<EnergyFactorCache> energy_cache;
  // Scale-free weights (ModelProblem::scale_free): mu_B times the total area, each soft
  // constraint's weight divided by its face's stiffness (FaceStiffness), a data term's mu_A
  // divided by the total area (as SmoothingOptions::scale_free).
  bool scale_free = false;
  // The biharmonic term's form (ModelProblem::biharmonic; the default kMixed). With kMixed and
  // mu_B > 0 the session inverts K Mr^-1 (mu_S Mr + mu_B K) through its partial fractions
  // (K^-1 - mu_B N^-1) / mu_S, two sparse factorizations (mixed_energy.h: K's once per session,
  // or shared through energy_cache; N's per weight change), each used as the exact form uses its
  // one: an add or a move to another face costs sparse forward substitutions with both, an
  // edit's solve a backward substitution with each. With a data term
  // (mu_A > 0) the exact form's factorization preconditions a conjugate gradient solve per edit
  // instead (15-150 solves with it).
  BiharmonicForm biharmonic = BiharmonicForm::kMixed;
  // A data (alignment) term mu_A (X - X0)^T W M (X - X0) in the energy (paper section 8, Fig. 16:
  // a field aligned to curvature, then interpolation constraints on top), with X0, W and their
  // passes over U from the smoother (of the same system; its own scale_free is not used). Null:
  // none, and mu_A must be 0.
  std::shared_ptr<const ReducedSmoother> data_term;
};

// An interactive design session on one basis (paper section 8; docs/conventions.md, Model
// problem): the model problem (eq. 8) reduced to the subspace (eq. 10, 11), with soft and hard
// constraints edited one at a time, optionally plus a data term (DesignSessionOptions::data_term;
// its matrix joins A and its right-hand side mu_A U^T W M X0 every solve).
//
// Cost model: the energy matrix A = U^T (mu_S S + mu_B B) U is factorized once per (mu_S, mu_B)
// (sparse supernodal Cholesky P A P^T = L L^T on the basis's shared symbolic analysis; shared
// between sessions through an EnergyFactorCache). Constraints never touch that factorization:
// each one keeps W = L^-1 P U_f^T (2-3 columns, sparse forward substitutions when it is added or
// moved to another face; a group edit such as a stroke keeps one column per basis column its
// rows touch instead, KktSolver), and every edit refactorizes only the small dense matrix
// H = U_C A^-1 U_C^T + E = W^T W + E over the current constraint rows (Woodbury for soft
// constraints, Schur complement for hard ones; see KktSolver). An edit costs
// O(nnz(L) + d r + r^3) for r constraint rows instead of a refactorization. Changing mu_S, mu_B
// or mu_A refactorizes A and recomputes W; changing only mu_C does not.
//
// Every successful call leaves coefficients() = the minimizer for the current weights and
// constraint set, equal (up to the solver tolerance) to SolveReducedModelProblem(problem()).
// A failed call leaves the session exactly as it was.
//
// The weights a session takes: ValidateSessionWeights (core/subspace/problem.h).

// Thread-compatible: one session per thread (or external locking); any number of sessions share
// the immutable ReducedSystem.
class DesignSession {
 public:
  // InvalidArgument for invalid weights (see ValidateWeights; a session also needs mu_c > 0),
  // invalid options or a null system;
  // FailedPrecondition when the energy matrix cannot be factorized.
  static absl::StatusOr<std::unique_ptr<DesignSession>> Create(
      std::shared_ptr<const ReducedSystem> system, const EnergyWeights& weights,
      const DesignSessionOptions& options = {});
  ~DesignSession();
  DesignSession(const DesignSession&) = delete;
  DesignSession& operator=(const DesignSession&) = delete;

  // Adds constraint `id` (any caller-chosen integer). AlreadyExists for an id in use;
  // InvalidArgument for a bad face id, value size, non-finite value or non-positive soft weight;
  // FailedPrecondition when a hard constraint would make the hard constraints linearly dependent
  // in the subspace (e.g. a second hard constraint on the same face).
  absl::Status AddConstraint(int64_t id, const FieldConstraint& constraint);
  // Replaces constraint `id`'s face, value and weight (its kind stays: constraint.kind is
  // ignored). NotFound for an unknown id; FailedPrecondition for a group's id (use
  // MoveConstraintGroup); otherwise the errors of AddConstraint. Moving within
  // the same face (new value or weight) needs no solve with A.
  absl::Status MoveConstraint(int64_t id, const FieldConstraint& constraint);
  // The same, keeping the constraint's weight too (an interactive drag).
  absl::Status MoveConstraint(int64_t id, int32_t face, Eigen::VectorXd value);
  // Adds a group of constraints under one id (a designer's tool: a stroke's faces, a placed
  // singularity's fan; see core/subspace/design_tools.h): one edit that appends the group's rows
  // and refactorizes H once. Each constraint keeps its own kind and weight. AlreadyExists for an id
  // in use; InvalidArgument for an empty group or an invalid constraint (as AddConstraint, naming
  // its position); FailedPrecondition when the hard constraints would become dependent (two hard
  // ones on a face, within the group or with the session's). All or nothing.
  absl::Status AddConstraintGroup(int64_t id, absl::Span<const FieldConstraint> constraints);
  // Replaces group `id`'s constraints by `constraints` (any number, faces, values, weights and
  // kinds) in one edit: rows on the same face at the same position only change their value (and
  // weight), others are replaced, appended or removed; H is refactorized once, and not at all when
  // only values changed. NotFound for an unknown id; FailedPrecondition for the id of a single
  // constraint (use MoveConstraint); otherwise the errors of AddConstraintGroup. All or nothing.
  absl::Status MoveConstraintGroup(int64_t id, absl::Span<const FieldConstraint> constraints);
  // Removes constraint or group `id` (a group as one edit). NotFound for an unknown id.
  absl::Status RemoveConstraint(int64_t id);
  // Removes every constraint (the solution becomes 0, or the data term's minimizer).
  void ClearConstraints();
  // New weights (InvalidArgument if invalid, see ValidateWeights). Refactorizes A when mu_S, mu_B
  // or mu_A change; FailedPrecondition (session unchanged) if that factorization fails.
  absl::Status SetWeights(const EnergyWeights& weights);

  // d: the current reduced solution x.
  const Eigen::VectorXd& coefficients() const { return coefficients_; }
  // Takes back `x`, the solution this session gave for its current problem earlier: after an
  // edit and its inverse (a caller rejecting an edit's result), the re-solved coefficients agree
  // with x only to rounding, and a session "as it was" answers x itself. FailedPrecondition,
  // session unchanged, when x differs from the current coefficients by more than 1e-6 relative
  // (it is then not a solution of the current problem).
  absl::Status RestoreCoefficients(const Eigen::VectorXd& x);
  // The lifted field U x at the given faces (see LiftFaces in projection.h), or at all faces.
  absl::StatusOr<Eigen::VectorXd> LiftFaces(absl::Span<const int32_t> faces) const;
  absl::StatusOr<Eigen::VectorXd> LiftAll() const;

  const EnergyWeights& weights() const { return weights_; }
  // Per-face constraints, a group's counted one by one.
  int32_t num_constraints() const { return static_cast<int32_t>(ids_by_slot_.size()); }
  int32_t num_hard_constraints() const { return num_hard_; }
  bool HasConstraint(int64_t id) const { return entries_.count(id) > 0; }
  bool IsConstraintGroup(int64_t id) const {
    auto it = entries_.find(id);
    return it != entries_.end() && it->second.group;
  }
  // NotFound for an unknown id; FailedPrecondition for a group's id (see GetConstraintGroup).
  absl::StatusOr<FieldConstraint> GetConstraint(int64_t id) const;
  // The constraints of group `id` in their order (of a single constraint: that one). NotFound for
  // an unknown id.
  absl::StatusOr<std::vector<FieldConstraint>> GetConstraintGroup(int64_t id) const;
  // The current problem (soft and hard constraints in increasing id order), as solved by
  // SolveReducedModelProblem or, in the full space, SolveModelProblem (without the data term,
  // which neither has).
  ModelProblem problem() const;
  bool has_data_term() const { return options_.data_term != nullptr; }
  const ReducedSystem& system() const { return *system_; }
  // Of the last solve: backward error and refinement steps; of the factorization: the diagonal
  // shift that was needed.
  // NaN when the last solve was not checked (verify_interval).
  double last_backward_error() const { return last_backward_error_; }
  int32_t last_refinement_steps() const { return last_refinement_steps_; }
  double regularization() const { return energy_->regularization; }
  // Whether the last Create() or SetWeights() computed a factorization of A (false when the
  // weights kept mu_S and mu_B, or the factorization came from the cache).
  bool last_factorized() const { return last_factorized_; }

 private:
  DesignSession(std::shared_ptr<const ReducedSystem> system, const DesignSessionOptions& options);
  // mu_S U^T S U + mu_B U^T B U (+ mu_A U^T W M U) with the effective weights, from the cache
  // when there is one; sets last_factorized_.
  absl::StatusOr<std::shared_ptr<const EnergyFactorization>> Energy(const EnergyWeights& weights);
  // FactorizeEnergy for `effective` weights, from the cache when there is one; *factorized:
  // whether this call factorized. `solve`: the regularization policy (null: the session's).
  absl::StatusOr<std::shared_ptr<const EnergyFactorization>> SharedFactorization(
      const EnergyWeights& effective, const ReducedSmoother* data, bool* factorized,
      const ReducedSolveOptions* solve = nullptr) const;
  // The diagonal of a soft constraint's rows in the KKT system: stiffness / (mu_C weight).
  double SoftE(double weight, double stiffness) const {
    return stiffness / (weights_.mu_c * weight);
  }
  // 1 with raw weights; else FaceStiffness of `rows` under the current energy factorization.
  absl::StatusOr<double> Stiffness(const std::vector<SparseRow>& rows) const;
  // Hands energy_ to the KKT solver, with the mixed biharmonic's weight for `weights` (with
  // mu_B > 0 and no data term: the partial fractions of mixed_energy.h, K's factorization made
  // on first use; FailedPrecondition or Cancelled when a factorization fails).
  absl::Status AttachEnergy(const EnergyWeights& weights);
  // mu_A' U^T W M X0 for the current weights (empty without a data term).
  void UpdateDataRhs();
  void Resolve();
  // Validates `constraints` (InvalidArgument naming the position) and gives each soft one its
  // stiffness, reusing that of the slot at the same position of entry `id` (if any) on the same
  // face.
  absl::StatusOr<std::vector<double>> PrepareConstraints(
      int64_t id, absl::Span<const FieldConstraint> constraints) const;
  // Makes entry `id`'s slots hold `constraints` (with `stiffness`): same face and kind at the same
  // position: new value and weight only; otherwise the slot's rows are replaced, appended or
  // removed. Does not factorize H. Returns whether H changed.
  bool SetSlots(int64_t id, absl::Span<const FieldConstraint> constraints,
                absl::Span<const double> stiffness);
  // Removes one slot; the last slot moves into its place.
  void RemoveSlot(int32_t slot);
  // SetSlots for an edit of entry `id` whose previous state is `old_*`: factorizes H when it
  // changed and on failure puts the old constraints back (status of the failure).
  absl::Status CommitSlots(int64_t id, absl::Span<const FieldConstraint> constraints,
                           absl::Span<const double> stiffness,
                           absl::Span<const FieldConstraint> old_constraints,
                           absl::Span<const double> old_stiffness);

  std::shared_ptr<const ReducedSystem> system_;
  DesignSessionOptions options_;
  EnergyWeights weights_;
  std::shared_ptr<const EnergyFactorization> energy_;
  // K = U^T S U's factorization (weights mu_S = 1, mu_B = 0) for the mixed form; null until a
  // mixed energy is attached, then kept across weight changes.
  std::shared_ptr<const EnergyFactorization> stiffness_energy_;
  std::unique_ptr<KktSolver> kkt_;
  // A constraint id: its slots (rows of the KKT solver), in the group's order.
  struct Entry {
    std::vector<int32_t> slots;
    bool group = false;
  };
  std::map<int64_t, Entry> entries_;
  std::vector<int64_t> ids_by_slot_;
  std::vector<int32_t> position_by_slot_;  // in its entry's slots
  std::vector<FieldConstraint> records_;   // by slot
  std::vector<double> stiffness_;          // by slot: see Stiffness()
  Eigen::VectorXd data_rhs_;
  int32_t num_hard_ = 0;
  Eigen::VectorXd coefficients_;
  double last_backward_error_ = 0;
  int32_t last_refinement_steps_ = 0;
  bool last_factorized_ = false;
  // Verification state (see DesignSessionOptions::verify_interval).
  bool verified_since_factorization_ = false;
  bool last_check_close_ = false;
  int32_t solves_since_check_ = 0;
};

// An estimate of the bytes an open DesignSession on `system` holds before its first constraint
// (its own factorizations and panels when its weights are not shared: the exact form's, and the
// mixed form's of N and of K with K's panels; and its working vectors);
// each constraint adds about d x dofs-per-face doubles per factorization it is solved with. For
// admission against a memory budget.
int64_t DesignSessionOpenBytes(const ReducedSystem& system);

// The bytes `constraints` constraints add to a DesignSession on `system`, for r = constraints x
// dofs-per-face rows: W's substitutions V (d x at most r, one per factorization: two in the mixed
// form) and K (r x r) at up to twice r (their capacity doubles), and the r x r matrix H with its
// Cholesky factor: 8 (4 d r + 6 r^2). An upper bound but for V's holes (KktSolver), which can
// add a third to V's columns before they are moved out. The r^2 terms dominate beyond
// r ~ 2 d / 3 (e.g. 4,700 vector constraints take ~4.5 GiB at d = 2000).
int64_t DesignSessionConstraintBytes(const ReducedSystem& system, int64_t constraints);

}  // namespace fieldspace

#endif  // FIELDSPACE_CORE_SUBSPACE_DESIGN_SESSION_H_
