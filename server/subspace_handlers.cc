// The handlers of the subspace methods: Project, Solve, Lift, Eigenfields (handlers.h).

#include <algorithm>
#include <chrono>
#include <numeric>
#include <optional>
#include <thread>
#include <utility>
#include <vector>

#include "absl/strings/str_cat.h"
#include "core/common/index_check.h"
#include "core/common/status_macros.h"
#include "core/subspace/design_session.h"
#include "core/subspace/model_problem.h"
#include "core/subspace/projection.h"
#include "core/subspace/spectrum.h"
#include "server/clock.h"
#include "server/design_tools_convert.h"
#include "server/field_answers.h"
#include "server/handlers.h"
#include "server/proto_convert.h"

namespace fieldspace::server {
namespace {

constexpr int32_t kMaxConstraints = 1 << 20;
// Up to this many constraints, a Solve with the mixed biharmonic goes through a design session
// (SolveThroughSession); beyond, the constraints' dense Woodbury and Schur blocks cost more than
// core's conjugate gradients, which take any number (1.38M faces, d = 2000: 100 constraints
// 49-58 ms against 229-234 ms, 300 about even at 107-136 ms, 1000 850-930 ms against
// 123-178 ms; bench/RESULTS.md, Session 22).
constexpr int64_t kSessionSolveMaxConstraints = 256;

double SecondsSince(Clock::time_point start) { return MsSince(start) / 1000; }

// A Solve with the mixed biharmonic (mu_B > 0) as a design session with all its constraints in
// one group: the mixed energy inverted through its partial fractions (two sparse factorizations,
// the second per weights, shared through the basis's energy cache with the design sessions open
// on it), as every design edit is, instead of core's conjugate gradients preconditioned by the
// exact form (~370 iterations, ~0.3 s at d = 2000 on 1.38M faces). The same minimizer
// (DesignSession's contract, tested against SolveReducedModelProblem in core). Not applicable
// (nullopt): other forms, mu_B = 0, no or too many constraints, weights a session refuses
// (mu_C = 0); and any refusal of the session (e.g. dependent hard constraints) leaves the Solve to
// core, which reports it as it always has.
std::optional<ReducedSolution> SolveThroughSession(const ServedBasis& basis,
                                                   const ModelProblem& problem,
                                                   const ReducedSolveOptions& solve_options) {
  if (problem.biharmonic != BiharmonicForm::kMixed || problem.constraints.empty() ||
      static_cast<int64_t>(problem.constraints.size()) > kSessionSolveMaxConstraints ||
      !ValidateSessionWeights(problem.weights, /*data_term=*/false).ok() ||
      !(EffectiveEnergyWeights(*basis.system, problem.weights, problem.scale_free).mu_b > 0)) {
    return std::nullopt;
  }
  DesignSessionOptions options;
  options.solve = solve_options;
  options.verify_interval = 1;  // the answer's backward error is always measured
  options.energy_cache = basis.energy_cache;
  options.scale_free = problem.scale_free;
  options.biharmonic = problem.biharmonic;
  absl::StatusOr<std::unique_ptr<DesignSession>> session =
      DesignSession::Create(basis.system, problem.weights, options);
  if (!session.ok() || !(*session)->AddConstraintGroup(0, problem.constraints).ok()) {
    return std::nullopt;
  }
  ReducedSolution solution;
  solution.coefficients = (*session)->coefficients();
  solution.backward_error = (*session)->last_backward_error();
  solution.refinement_steps = (*session)->last_refinement_steps();
  solution.regularization = (*session)->regularization();
  return solution;
}

}  // namespace

int32_t HardwareThreads() {
  return static_cast<int32_t>(std::max(1u, std::thread::hardware_concurrency()));
}

absl::Status Project(const HandlerContext& ctx, const v1::ProjectRequest& request,
                     v1::ProjectResponse* response) {
  const auto start = Clock::now();
  ASSIGN_OR_RETURN(std::shared_ptr<const ServedBasis> basis, ctx.GetBasis(request.basis_id()));
  // The field in double and its reconstruction for the relative error.
  ASSIGN_OR_RETURN(WorkGrant grant, ctx.AdmitWork(16 * basis->system->dofs(), "this Project"));
  ASSIGN_OR_RETURN(Eigen::VectorXd X, FieldFromProto(request.field(), *basis));
  ASSIGN_OR_RETURN(ProjectionResult result, fieldspace::Project(*basis->system, X, ctx.cancel));
  response->mutable_coefficients()->Add(result.coefficients.data(),
                                        result.coefficients.data() + result.coefficients.size());
  response->set_relative_error(result.relative_error);
  response->set_seconds(SecondsSince(start));
  return absl::OkStatus();
}

absl::Status Solve(const HandlerContext& ctx, const v1::SolveRequest& request,
                   v1::SolveResponse* response) {
  const auto start = Clock::now();
  ASSIGN_OR_RETURN(std::shared_ptr<const ServedBasis> basis, ctx.GetBasis(request.basis_id()));
  ModelProblem problem;
  problem.weights = WeightsFromProto(request.weights(), EnergyWeights{});
  problem.scale_free = !request.raw_weights();
  ASSIGN_OR_RETURN(problem.biharmonic, BiharmonicFormFromProto(request.biharmonic()));
  RETURN_IF_ERROR(ValidateWeightsWithoutDataTerm(problem.weights));
  std::vector<FieldConstraint> groups;  // the designer's tools' constraints
  RETURN_IF_ERROR(AppendConstraintGroups(*basis, request.constraint_groups(), &groups));
  const int64_t total = request.constraints_size() + static_cast<int64_t>(groups.size());
  if (total > kMaxConstraints) {
    return absl::ResourceExhaustedError(
        absl::StrCat("at most ", kMaxConstraints, " constraints per request"));
  }
  int64_t hard = 0;
  for (const v1::Constraint& c : request.constraints()) hard += c.hard() ? 1 : 0;
  for (const FieldConstraint& c : groups) hard += c.hard() ? 1 : 0;
  int64_t work =
      SolveWorkingBytes(*basis->system, total - hard, hard, problem.scale_free, HardwareThreads());
  if (request.return_field()) {
    work += int64_t{12} * basis->basis->type.dofs_per_face() * basis->mesh->num_faces();
  }
  ASSIGN_OR_RETURN(WorkGrant grant, ctx.AdmitWork(work, "this Solve"));
  problem.constraints.reserve(request.constraints_size());
  for (int i = 0; i < request.constraints_size(); ++i) {
    ASSIGN_OR_RETURN(FieldConstraint c, ConstraintFromProto(*basis, request.constraints(i),
                                                            absl::StrCat("constraint ", i)));
    problem.constraints.push_back(std::move(c));
  }
  for (FieldConstraint& c : groups) problem.constraints.push_back(std::move(c));
  ASSIGN_OR_RETURN(FieldEncoding encoding, EncodingFromProto(request.field_encoding()));
  if (request.return_field()) {
    RETURN_IF_ERROR(CheckFieldFits(*basis, encoding, ctx.options->message_room()));
  }
  const auto solve_start = Clock::now();
  ReducedSolveOptions options;
  options.cancel = ctx.cancel;
  std::optional<ReducedSolution> through_session = SolveThroughSession(*basis, problem, options);
  if (IsCancelled(ctx.cancel)) return absl::CancelledError("Solve cancelled");
  ASSIGN_OR_RETURN(ReducedSolution result,
                   through_session.has_value()
                       ? absl::StatusOr<ReducedSolution>(*std::move(through_session))
                       : SolveReducedModelProblem(*basis->system, problem, options));
  const double solve_ms = MsSince(solve_start);
  RETURN_IF_ERROR(CheckSolutionFinite(result.coefficients));
  response->mutable_coefficients()->Add(result.coefficients.data(),
                                        result.coefficients.data() + result.coefficients.size());
  response->set_backward_error(result.backward_error);
  response->set_iterations(result.refinement_steps);
  ASSIGN_OR_RETURN(
      const double lift_ms,
      AnswerField(*basis, result.coefficients, encoding,
                  request.return_field() ? response->mutable_field() : nullptr,
                  request.singularities() ? response->mutable_singularities() : nullptr));
  v1::SolveTimings* t = response->mutable_timings();
  t->set_solve_ms(solve_ms);
  t->set_lift_ms(lift_ms);
  t->set_total_ms(MsSince(start));
  return absl::OkStatus();
}

absl::Status Eigenfields(const HandlerContext& ctx, const v1::EigenfieldsRequest& request,
                         v1::EigenfieldsResponse* response) {
  const auto start = Clock::now();
  ASSIGN_OR_RETURN(std::shared_ptr<const ServedBasis> basis, ctx.GetBasis(request.basis_id()));
  const int32_t d = basis->basis->dimension();
  if (request.count() < 1 || request.count() > d) {
    return absl::InvalidArgumentError(
        absl::StrCat("count must be in [1, ", d, "] (the basis dimension), got ", request.count()));
  }
  if (int64_t{8} * (d + 1) * request.count() > ctx.options->message_room()) {
    return absl::ResourceExhaustedError(
        "count x dimension coefficients exceed the message size limit");
  }
  ReducedEigenOptions options;
  options.count = request.count();
  options.cancel = ctx.cancel;
  ASSIGN_OR_RETURN(WorkGrant grant, ctx.AdmitWork(ReducedEigenWorkingBytes(*basis->system, options),
                                                  "this Eigenfields call"));
  ASSIGN_OR_RETURN(ReducedEigenResult result, ReducedEigenpairs(*basis->system, options));
  response->mutable_eigenvalues()->Add(result.values.data(),
                                       result.values.data() + result.values.size());
  for (Eigen::Index j = 0; j < result.coefficients.cols(); ++j) {
    const double* col = result.coefficients.col(j).data();
    response->mutable_coefficients()->Add(col, col + result.coefficients.rows());
  }
  response->set_dimension(d);
  response->set_seconds(SecondsSince(start));
  return absl::OkStatus();
}

namespace {

// A subset of faces is lifted chunk by chunk; all faces are lifted at once (one parallel pass of
// the LiftPlan) when the stream opens, and the chunks only encode slices of it.
class LiftStream final : public ChunkStream<v1::FieldChunk> {
 public:
  absl::Status Open(const HandlerContext& ctx, const v1::LiftRequest& request) {
    request_ = request;
    ASSIGN_OR_RETURN(basis_, ctx.GetBasis(request_.basis_id()));
    ASSIGN_OR_RETURN(x_, CoefficientsFromProto(request_.coefficients(), *basis_));
    ASSIGN_OR_RETURN(encoding_, EncodingFromProto(request_.encoding()));
    if (request_.chunk_faces() < 0) {
      return absl::InvalidArgumentError("chunk_faces must not be negative");
    }
    RETURN_IF_ERROR(CheckFaces(request_.faces(), basis_->mesh->num_faces(), "lift"));
    // Per face: its values (float) and, for subset lifts, its index.
    chunk_ = ctx.options->ChunkFaces(
        request_.chunk_faces(),
        4 * ValuesPerFace(basis_->basis->type, encoding_) + (request_.faces().empty() ? 0 : 4));
    subset_ = !request_.faces().empty();
    total_ = subset_ ? request_.faces().size() : basis_->mesh->num_faces();
    if (subset_) return absl::OkStatus();
    // The DOF encoding is the lift narrowed to float, done in the lift's own pass.
    const int64_t dofs = basis_->system->dofs();
    ASSIGN_OR_RETURN(grant_,
                     ctx.AdmitWork((encoding_ == FieldEncoding::kDof ? 4 : 8) * dofs, "this Lift"));
    const auto start = Clock::now();
    if (encoding_ == FieldEncoding::kDof) {
      // Uninitialized: the lift writes every value (no zero-fill pass over 11 MB at 1.38M faces).
      all_values_.reset(new float[dofs]);
      RETURN_IF_ERROR(LiftIntoFloat(*basis_->system, x_, absl::MakeSpan(all_values_.get(), dofs)));
    } else {
      ASSIGN_OR_RETURN(all_dofs_, fieldspace::Lift(*basis_->system, x_));
    }
    server_ms_ = MsSince(start);
    return absl::OkStatus();
  }

  absl::StatusOr<bool> Next(v1::FieldChunk* out) override {
    if (next_ >= total_ && sent_any_) return false;
    const auto start = Clock::now();
    sent_any_ = true;
    const int32_t count = std::min(chunk_, total_ - next_);
    if (subset_) {
      faces_.assign(request_.faces().data() + next_, request_.faces().data() + next_ + count);
      out->mutable_field()->mutable_faces()->Add(faces_.begin(), faces_.end());
    } else if (encoding_ != FieldEncoding::kDof) {
      faces_.resize(count);
      std::iota(faces_.begin(), faces_.end(), next_);
    }
    out->set_start_face(subset_ ? 0 : next_);
    out->set_total_faces(total_);
    out->mutable_field()->set_encoding(EncodingToProto(encoding_));
    const int64_t dpf = basis_->basis->type.dofs_per_face();
    if (subset_) {
      RETURN_IF_ERROR(
          LiftToValues(*basis_, x_, faces_, encoding_, out->mutable_field()->mutable_values()));
    } else if (encoding_ == FieldEncoding::kDof) {
      out->mutable_field()->mutable_values()->Add(all_values_.get() + dpf * next_,
                                                  all_values_.get() + dpf * (next_ + count));
    } else {
      RETURN_IF_ERROR(EncodeDofs(*basis_, faces_,
                                 absl::MakeConstSpan(all_dofs_.data() + dpf * next_, dpf * count),
                                 encoding_, out->mutable_field()->mutable_values()));
    }
    next_ += count;
    server_ms_ += MsSince(start);
    out->set_server_ms(server_ms_);
    return true;
  }

 private:
  v1::LiftRequest request_;
  std::shared_ptr<const ServedBasis> basis_;
  Eigen::VectorXd x_;
  // All-faces lifts: the whole field, lifted in Open (as float for the DOF encoding).
  Eigen::VectorXd all_dofs_;
  std::unique_ptr<float[]> all_values_;
  WorkGrant grant_;  // the whole-field buffers' memory
  FieldEncoding encoding_ = FieldEncoding::kDof;
  std::vector<int32_t> faces_;
  bool subset_ = false;
  int32_t chunk_ = 0;
  int32_t total_ = 0;
  int32_t next_ = 0;
  bool sent_any_ = false;
  double server_ms_ = 0;
};

}  // namespace

absl::StatusOr<std::unique_ptr<ChunkStream<v1::FieldChunk>>> OpenLift(
    const HandlerContext& ctx, const v1::LiftRequest& request) {
  auto stream = std::make_unique<LiftStream>();
  RETURN_IF_ERROR(stream->Open(ctx, request));
  return stream;
}

}  // namespace fieldspace::server
