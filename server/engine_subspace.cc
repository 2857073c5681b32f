// The subspace methods (core/subspace): per-basis precomputation, projection, the reduced model
// problem, lifting, the reduced eigenproblem and interactive sessions.

#include <chrono>
#include <map>

#include "absl/strings/str_cat.h"
#include "core/common/cancel.h"
#include "core/common/status_macros.h"
#include "core/operators/field_operator.h"
#include "core/subspace/design_session.h"
#include "core/subspace/model_problem.h"
#include "core/subspace/projection.h"
#include "core/subspace/reduced_system.h"
#include "core/subspace/spectrum.h"
#include "server/engine.h"

namespace fieldspace::server {

class SubspaceModel {
 public:
  explicit SubspaceModel(std::shared_ptr<const ReducedSystem> system)
      : system_(std::move(system)), energy_cache_(std::make_shared<EnergyFactorCache>()) {}
  const std::shared_ptr<const ReducedSystem>& system() const { return system_; }
  // Design sessions on this basis with equal (mu_S, mu_B) share one factorization.
  const std::shared_ptr<EnergyFactorCache>& energy_cache() const { return energy_cache_; }

 private:
  std::shared_ptr<const ReducedSystem> system_;
  std::shared_ptr<EnergyFactorCache> energy_cache_;
};

namespace {

using Clock = std::chrono::steady_clock;

double MsSince(Clock::time_point start) {
  return std::chrono::duration<double, std::milli>(Clock::now() - start).count();
}

absl::StatusOr<const ReducedSystem*> SystemOf(const ServedBasis& basis) {
  if (basis.model == nullptr || basis.model->system() == nullptr) {
    return absl::InternalError("basis has no reduced system");
  }
  return basis.model->system().get();
}

Eigen::VectorXd ValueOf(const ConstraintSpec& c, int32_t dofs_per_face) {
  return c.dofs.head(dofs_per_face);
}

// core DesignSession behind the server's session interface; remembers each constraint's weight
// and kind so that a move keeps them.
class CoreSession final : public InteractiveSession {
 public:
  CoreSession(std::shared_ptr<const ServedBasis> basis, std::unique_ptr<DesignSession> session,
              const ModelWeights& weights)
      : basis_(std::move(basis)), session_(std::move(session)), weights_(weights) {}

  absl::StatusOr<EditResult> Add(int32_t id, const ConstraintSpec& spec) override {
    const auto start = Clock::now();
    FieldConstraint c{spec.face, ValueOf(spec, dpf()), spec.weight};
    RETURN_IF_ERROR(
        session_->AddConstraint(id, spec.hard ? ConstraintKind::kHard : ConstraintKind::kSoft, c));
    meta_[id] = {spec.weight, spec.hard};
    return EditResult{MsSince(start), false};
  }

  absl::StatusOr<EditResult> Move(int32_t id, int32_t face, const Eigen::Vector3d& dofs) override {
    const auto start = Clock::now();
    auto it = meta_.find(id);
    if (it == meta_.end()) {
      return absl::NotFoundError(absl::StrCat("no constraint with id ", id, " in this session"));
    }
    FieldConstraint c{face, dofs.head(dpf()), it->second.weight};
    RETURN_IF_ERROR(session_->MoveConstraint(id, c));
    return EditResult{MsSince(start), false};
  }

  absl::StatusOr<EditResult> Remove(int32_t id) override {
    const auto start = Clock::now();
    if (meta_.count(id) == 0) {
      return absl::NotFoundError(absl::StrCat("no constraint with id ", id, " in this session"));
    }
    RETURN_IF_ERROR(session_->RemoveConstraint(id));
    meta_.erase(id);
    return EditResult{MsSince(start), false};
  }

  absl::StatusOr<EditResult> SetWeights(const ModelWeights& w) override {
    const auto start = Clock::now();
    RETURN_IF_ERROR(session_->SetWeights(EnergyWeights{w.mu_s, w.mu_b, w.mu_c}));
    weights_ = w;
    return EditResult{MsSince(start), session_->last_factorized()};
  }

  const Eigen::VectorXd& coefficients() const override { return session_->coefficients(); }
  int32_t num_constraints() const override { return session_->num_constraints(); }
  int32_t num_hard_constraints() const override {
    int32_t n = 0;
    for (const auto& [id, m] : meta_) n += m.hard ? 1 : 0;
    return n;
  }

 private:
  struct Meta {
    double weight = 1.0;
    bool hard = false;
  };
  int32_t dpf() const { return basis_->basis->type.dofs_per_face(); }

  std::shared_ptr<const ServedBasis> basis_;  // keeps the reduced system alive
  std::unique_ptr<DesignSession> session_;
  ModelWeights weights_;
  std::map<int32_t, Meta> meta_;
};

}  // namespace

absl::StatusOr<std::shared_ptr<const SubspaceModel>> PrepareModel(
    const TriangleMesh& mesh, std::shared_ptr<const Basis> basis, const FieldOperator* op,
    const BuildContext& context) {
  FieldOperator assembled;
  if (op == nullptr) {
    ASSIGN_OR_RETURN(assembled, BuildFieldOperator(mesh, basis->type));
    op = &assembled;
  }
  if (IsCancelled(context.cancel)) {
    return absl::CancelledError("cancelled");
  }
  if (context.progress) context.progress(BuildStage::kPrecompute, 0.5);
  ReducedSystemOptions options;
  options.threads = context.threads;
  ASSIGN_OR_RETURN(std::shared_ptr<const ReducedSystem> system,
                   ReducedSystem::Build(std::move(basis), *op, options));
  return std::make_shared<const SubspaceModel>(std::move(system));
}

int64_t ModelBytes(const SubspaceModel& model) {
  const ReducedSystem& s = *model.system();
  const int64_t reduced_nnz =
      s.stiffness().nonZeros() + s.bilaplacian().nonZeros() + s.mass_matrix().nonZeros();
  return reduced_nnz * 12 + s.stats().factor_nonzeros * 8 + s.mass().size() * 8;
}

absl::StatusOr<ProjectResult> ProjectField(const ServedBasis& basis, const Eigen::VectorXd& X,
                                           const std::atomic<bool>* cancel) {
  ASSIGN_OR_RETURN(const ReducedSystem* system, SystemOf(basis));
  ASSIGN_OR_RETURN(ProjectionResult r, Project(*system, X, cancel));
  return ProjectResult{std::move(r.coefficients), r.relative_error};
}

absl::StatusOr<SolveResult> SolveModel(const ServedBasis& basis, const ModelWeights& weights,
                                       const std::vector<ConstraintSpec>& constraints,
                                       const std::atomic<bool>* cancel) {
  ASSIGN_OR_RETURN(const ReducedSystem* system, SystemOf(basis));
  const int32_t dpf = basis.basis->type.dofs_per_face();
  ModelProblem problem;
  problem.mu_s = weights.mu_s;
  problem.mu_b = weights.mu_b;
  problem.mu_c = weights.mu_c;
  for (const ConstraintSpec& c : constraints) {
    if (c.hard) {
      problem.hard.push_back({c.face, ValueOf(c, dpf)});
    } else {
      problem.soft.push_back({c.face, ValueOf(c, dpf), c.weight});
    }
  }
  const auto start = Clock::now();
  ReducedSolveOptions options;
  options.cancel = cancel;
  ASSIGN_OR_RETURN(ReducedSolution solution, SolveReducedModelProblem(*system, problem, options));
  SolveResult result;
  result.coefficients = std::move(solution.coefficients);
  result.solve_ms = MsSince(start);
  return result;
}

absl::Status LiftFaces(const ServedBasis& basis, const Eigen::VectorXd& coefficients,
                       absl::Span<const int32_t> faces, absl::Span<double> out) {
  return LiftFacesInto(*basis.basis, coefficients, faces, out);
}

absl::StatusOr<ReducedEigenfieldsResult> ReducedEigenfields(const ServedBasis& basis, int32_t count,
                                                            const std::atomic<bool>* cancel) {
  ASSIGN_OR_RETURN(const ReducedSystem* system, SystemOf(basis));
  ReducedEigenOptions options;
  options.count = count;
  options.cancel = cancel;
  ASSIGN_OR_RETURN(ReducedEigenResult r, ReducedEigenpairs(*system, options));
  return ReducedEigenfieldsResult{std::move(r.values), std::move(r.coefficients)};
}

absl::StatusOr<OpenSessionResult> OpenDesignSession(std::shared_ptr<const ServedBasis> basis,
                                                    const ModelWeights& weights,
                                                    int32_t verify_interval) {
  ASSIGN_OR_RETURN(const ReducedSystem* system, SystemOf(*basis));
  (void)system;
  const auto start = Clock::now();
  DesignSessionOptions options;
  options.energy_cache = basis->model->energy_cache();
  options.verify_interval = verify_interval;
  ASSIGN_OR_RETURN(
      std::unique_ptr<DesignSession> session,
      DesignSession::Create(basis->model->system(),
                            EnergyWeights{weights.mu_s, weights.mu_b, weights.mu_c}, options));
  OpenSessionResult out;
  out.timings = {MsSince(start), session->last_factorized()};
  out.session = std::make_unique<CoreSession>(std::move(basis), std::move(session), weights);
  return out;
}

}  // namespace fieldspace::server
