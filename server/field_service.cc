#include "server/field_service.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <map>
#include <numeric>
#include <optional>
#include <thread>
#include <utility>
#include <vector>

#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "core/common/status_macros.h"
#include "core/mesh/mesh_io.h"
#include "core/operators/curvature.h"
#include "core/operators/singularities.h"
#include "core/subspace/model_problem.h"
#include "core/subspace/projection.h"
#include "core/subspace/smoothing.h"
#include "core/subspace/spectrum.h"
#include "server/data_root.h"
#include "server/design_tools_convert.h"
#include "server/proto_convert.h"
#include "server/reactors.h"
#include "server/rpc_util.h"

namespace fieldspace::server {
namespace {

constexpr int32_t kMaxConstraints = 1 << 20;

// Admits working memory that scales with the field: `per_dof` bytes per DOF of `basis`, plus
// `extra` bytes.
absl::StatusOr<WorkGrant> AdmitFieldWork(Registry* registry, const ServedBasis& basis,
                                         int64_t per_dof, int64_t extra, absl::string_view what) {
  return registry->AdmitWork(per_dof * basis.system->dofs() + extra, what);
}

// Threads of oneTBB's default arena, which core's parallel loops use.
int32_t HardwareThreads() {
  return static_cast<int32_t>(std::max(1u, std::thread::hardware_concurrency()));
}

}  // namespace

int32_t ServiceOptions::ChunkFaces(int32_t requested, int64_t bytes_per_face) const {
  constexpr int32_t kDefaultChunkFaces = 65536;
  constexpr int32_t kMaxChunkFaces = 1 << 19;
  const int32_t wanted = requested == 0 ? kDefaultChunkFaces : std::min(requested, kMaxChunkFaces);
  const int64_t fits = std::max<int64_t>(1, message_room() / std::max<int64_t>(1, bytes_per_face));
  return static_cast<int32_t>(std::min<int64_t>(wanted, fits));
}

FieldService::FieldService(Registry* registry, ComputePool* pool, ServiceOptions options)
    : registry_(registry), pool_(pool), options_(std::move(options)) {}

absl::Status FieldService::Admit() const {
  if (draining_.load()) return absl::UnavailableError("server is shutting down");
  return absl::OkStatus();
}

void FieldService::BeginDrain() {
  draining_.store(true);
  std::vector<DrainableStream*> streams;
  {
    std::lock_guard<std::mutex> lock(streams_mu_);
    for (DrainableStream* s : streams_) {
      s->AddRef();
      streams.push_back(s);
    }
  }
  for (DrainableStream* s : streams) {
    s->Drain();
    s->DropRef();
  }
}

bool FieldService::AcquireDesignSession() {
  int32_t n = design_sessions_.load();
  do {
    if (n >= options_.max_design_sessions) return false;
  } while (!design_sessions_.compare_exchange_weak(n, n + 1));
  return true;
}

void FieldService::ReleaseDesignSession() { design_sessions_.fetch_sub(1); }

void FieldService::RegisterStream(DrainableStream* stream) {
  std::lock_guard<std::mutex> lock(streams_mu_);
  streams_.insert(stream);
}

void FieldService::UnregisterStream(DrainableStream* stream) {
  std::lock_guard<std::mutex> lock(streams_mu_);
  streams_.erase(stream);
}

// --- meshes ------------------------------------------------------------------------------------

grpc::ServerReadReactor<grpc::ByteBuffer>* FieldService::UploadMesh(
    grpc::CallbackServerContext* /*context*/, grpc::ByteBuffer* response) {
  return NewUploadReactor(this, response);
}

grpc::ServerUnaryReactor* FieldService::LoadMesh(grpc::CallbackServerContext* /*context*/,
                                                 const v1::LoadMeshRequest* request,
                                                 v1::MeshInfo* response) {
  return RunUnary(this, Where::kPool, [this, request, response](const std::atomic<bool>*) {
    ASSIGN_OR_RETURN(ReadableFile file, OpenDataFile(options_.data_root, request->path()));
    // The same size limit as an upload, and the same memory: the bytes and the parsed arrays.
    MeshReadOptions read;
    read.max_file_bytes = options_.max_upload_bytes;
    ASSIGN_OR_RETURN(
        WorkGrant grant,
        registry_->AdmitWork(2 * std::min(file.size, read.max_file_bytes), "this LoadMesh"));
    ASSIGN_OR_RETURN(MeshReadResult parsed, ReadMeshFile(std::move(file), request->path(), read));
    const std::string name = request->name().empty() ? request->path() : request->name();
    ASSIGN_OR_RETURN(MeshRecord record,
                     registry_->AddMesh(std::move(parsed.arrays), name,
                                        static_cast<int32_t>(parsed.polygons_triangulated)));
    MeshInfoFromRecord(record, registry_->IsMeshLoaded(record.id), response);
    return absl::OkStatus();
  });
}

grpc::ServerUnaryReactor* FieldService::GetMesh(grpc::CallbackServerContext* /*context*/,
                                                const v1::GetMeshRequest* request,
                                                v1::MeshInfo* response) {
  return RunUnary(this, Where::kInline, [this, request, response](const std::atomic<bool>*) {
    ASSIGN_OR_RETURN(MeshRecord record, registry_->GetMeshRecord(request->mesh_id()));
    MeshInfoFromRecord(record, registry_->IsMeshLoaded(record.id), response);
    return absl::OkStatus();
  });
}

grpc::ServerUnaryReactor* FieldService::ListMeshes(grpc::CallbackServerContext* /*context*/,
                                                   const v1::ListMeshesRequest*,
                                                   v1::ListMeshesResponse* response) {
  return RunUnary(this, Where::kInline, [this, response](const std::atomic<bool>*) {
    for (const MeshRecord& r : registry_->ListMeshes()) {
      MeshInfoFromRecord(r, registry_->IsMeshLoaded(r.id), response->add_meshes());
    }
    return absl::OkStatus();
  });
}

grpc::ServerUnaryReactor* FieldService::DeleteMesh(grpc::CallbackServerContext* /*context*/,
                                                   const v1::DeleteMeshRequest* request,
                                                   v1::DeleteMeshResponse* response) {
  return RunUnary(this, Where::kPool, [this, request, response](const std::atomic<bool>*) {
    ASSIGN_OR_RETURN(std::vector<std::string> deleted,
                     registry_->DeleteMesh(request->mesh_id(), request->cascade()));
    for (std::string& id : deleted) response->add_deleted_basis_ids(std::move(id));
    return absl::OkStatus();
  });
}

grpc::ServerWriteReactor<v1::MeshGeometryChunk>* FieldService::GetMeshGeometry(
    grpc::CallbackServerContext* /*context*/, const v1::GetMeshGeometryRequest* request) {
  return NewGeometryWriter(this, *request);
}

// --- bases -------------------------------------------------------------------------------------

grpc::ServerWriteReactor<v1::BuildBasisProgress>* FieldService::BuildBasis(
    grpc::CallbackServerContext* /*context*/, const v1::BuildBasisRequest* request) {
  return NewBuildWatcher(this, *request);
}

grpc::ServerUnaryReactor* FieldService::CancelBuild(grpc::CallbackServerContext* /*context*/,
                                                    const v1::CancelBuildRequest* request,
                                                    v1::CancelBuildResponse*) {
  return RunUnary(this, Where::kInline, [this, request](const std::atomic<bool>*) {
    return registry_->CancelBuild(request->basis_id());
  });
}

grpc::ServerUnaryReactor* FieldService::GetBasis(grpc::CallbackServerContext* /*context*/,
                                                 const v1::GetBasisRequest* request,
                                                 v1::BasisInfo* response) {
  return RunUnary(this, Where::kInline, [this, request, response](const std::atomic<bool>*) {
    ASSIGN_OR_RETURN(BasisStatus status, registry_->GetBasisStatus(request->basis_id()));
    BasisInfoFromStatus(status, response);
    return absl::OkStatus();
  });
}

grpc::ServerUnaryReactor* FieldService::ListBases(grpc::CallbackServerContext* /*context*/,
                                                  const v1::ListBasesRequest* request,
                                                  v1::ListBasesResponse* response) {
  return RunUnary(this, Where::kInline, [this, request, response](const std::atomic<bool>*) {
    for (const BasisStatus& s : registry_->ListBases(request->mesh_id())) {
      BasisInfoFromStatus(s, response->add_bases());
    }
    return absl::OkStatus();
  });
}

grpc::ServerUnaryReactor* FieldService::DeleteBasis(grpc::CallbackServerContext* /*context*/,
                                                    const v1::DeleteBasisRequest* request,
                                                    v1::DeleteBasisResponse*) {
  return RunUnary(this, Where::kPool, [this, request](const std::atomic<bool>*) {
    return registry_->DeleteBasis(request->basis_id());
  });
}

// --- subspace methods ----------------------------------------------------------------------------

grpc::ServerUnaryReactor* FieldService::Project(grpc::CallbackServerContext* /*context*/,
                                                const v1::ProjectRequest* request,
                                                v1::ProjectResponse* response) {
  return RunUnary(
      this, Where::kPool,
      [this, request, response](const std::atomic<bool>* cancel) -> absl::Status {
        const auto start = Clock::now();
        ASSIGN_OR_RETURN(std::shared_ptr<const ServedBasis> basis,
                         registry_->GetBasis(request->basis_id()));
        // The field in double and its reconstruction for the relative error.
        ASSIGN_OR_RETURN(WorkGrant grant, AdmitFieldWork(registry_, *basis, 16, 0, "this Project"));
        ASSIGN_OR_RETURN(Eigen::VectorXd X, FieldFromProto(request->field(), *basis));
        ASSIGN_OR_RETURN(ProjectionResult result, fieldspace::Project(*basis->system, X, cancel));
        response->mutable_coefficients()->Add(
            result.coefficients.data(), result.coefficients.data() + result.coefficients.size());
        response->set_relative_error(result.relative_error);
        response->set_seconds(std::chrono::duration<double>(Clock::now() - start).count());
        return absl::OkStatus();
      });
}

grpc::ServerUnaryReactor* FieldService::Solve(grpc::CallbackServerContext* /*context*/,
                                              const v1::SolveRequest* request,
                                              v1::SolveResponse* response) {
  return RunUnary(
      this, Where::kPool,
      [this, request, response](const std::atomic<bool>* cancel) -> absl::Status {
        const auto start = Clock::now();
        ASSIGN_OR_RETURN(std::shared_ptr<const ServedBasis> basis,
                         registry_->GetBasis(request->basis_id()));
        ModelProblem problem;
        problem.weights = WeightsFromProto(request->weights(), EnergyWeights{});
        problem.scale_free = !request->raw_weights();
        ASSIGN_OR_RETURN(problem.biharmonic, BiharmonicFormFromProto(request->biharmonic()));
        RETURN_IF_ERROR(ValidateWeightsWithoutDataTerm(problem.weights));
        std::vector<FieldConstraint> groups;  // the designer's tools' constraints
        RETURN_IF_ERROR(AppendConstraintGroups(*basis, request->constraint_groups(), &groups));
        const int64_t total = request->constraints_size() + static_cast<int64_t>(groups.size());
        if (total > kMaxConstraints) {
          return absl::ResourceExhaustedError(
              absl::StrCat("at most ", kMaxConstraints, " constraints per request"));
        }
        int64_t hard = 0;
        for (const v1::Constraint& c : request->constraints()) hard += c.hard() ? 1 : 0;
        for (const FieldConstraint& c : groups) hard += c.hard() ? 1 : 0;
        int64_t work = SolveWorkingBytes(*basis->system, total - hard, hard, problem.scale_free,
                                         HardwareThreads());
        if (request->return_field()) {
          work += int64_t{12} * basis->basis->type.dofs_per_face() * basis->mesh->num_faces();
        }
        ASSIGN_OR_RETURN(WorkGrant grant, registry_->AdmitWork(work, "this Solve"));
        problem.constraints.reserve(request->constraints_size());
        for (int i = 0; i < request->constraints_size(); ++i) {
          ASSIGN_OR_RETURN(FieldConstraint c, ConstraintFromProto(*basis, request->constraints(i),
                                                                  absl::StrCat("constraint ", i)));
          problem.constraints.push_back(std::move(c));
        }
        for (FieldConstraint& c : groups) problem.constraints.push_back(std::move(c));
        ASSIGN_OR_RETURN(FieldEncoding encoding, EncodingFromProto(request->field_encoding()));
        if (request->return_field()) {
          const int64_t bytes =
              int64_t{4} * ValuesPerFace(basis->basis->type, encoding) * basis->mesh->num_faces();
          if (bytes > options_.message_room()) {
            return absl::ResourceExhaustedError(absl::StrCat(
                "the lifted field (", bytes, " bytes) exceeds the message size limit; use Lift"));
          }
        }
        const auto solve_start = Clock::now();
        ReducedSolveOptions options;
        options.cancel = cancel;
        ASSIGN_OR_RETURN(ReducedSolution result,
                         SolveReducedModelProblem(*basis->system, problem, options));
        const double solve_ms = MsSince(solve_start);
        RETURN_IF_ERROR(CheckSolutionFinite(result.coefficients));
        response->mutable_coefficients()->Add(
            result.coefficients.data(), result.coefficients.data() + result.coefficients.size());
        response->set_backward_error(result.backward_error);
        response->set_iterations(result.refinement_steps);
        double lift_ms = 0;
        Eigen::VectorXd dofs;  // the lifted field, once, for return_field and singularities
        if (request->return_field()) {
          const auto lift_start = Clock::now();
          response->mutable_field()->set_encoding(EncodingToProto(encoding));
          RETURN_IF_ERROR(LiftAllToValues(*basis, result.coefficients, encoding,
                                          response->mutable_field()->mutable_values(), &dofs));
          lift_ms = MsSince(lift_start);
        }
        if (request->singularities()) {
          if (dofs.size() == 0) {
            ASSIGN_OR_RETURN(dofs, fieldspace::Lift(*basis->system, result.coefficients));
          }
          RETURN_IF_ERROR(SingularitiesToProto(*basis, dofs, 0, response->mutable_singularities()));
        }
        v1::SolveTimings* t = response->mutable_timings();
        t->set_solve_ms(solve_ms);
        t->set_lift_ms(lift_ms);
        t->set_total_ms(MsSince(start));
        return absl::OkStatus();
      });
}

grpc::ServerWriteReactor<v1::FieldChunk>* FieldService::Lift(
    grpc::CallbackServerContext* /*context*/, const v1::LiftRequest* request) {
  return NewLiftWriter(this, *request);
}

grpc::ServerUnaryReactor* FieldService::Eigenfields(grpc::CallbackServerContext* /*context*/,
                                                    const v1::EigenfieldsRequest* request,
                                                    v1::EigenfieldsResponse* response) {
  return RunUnary(
      this, Where::kPool,
      [this, request, response](const std::atomic<bool>* cancel) -> absl::Status {
        const auto start = Clock::now();
        ASSIGN_OR_RETURN(std::shared_ptr<const ServedBasis> basis,
                         registry_->GetBasis(request->basis_id()));
        const int32_t d = basis->basis->dimension();
        if (request->count() < 1 || request->count() > d) {
          return absl::InvalidArgumentError(absl::StrCat(
              "count must be in [1, ", d, "] (the basis dimension), got ", request->count()));
        }
        if (int64_t{8} * (d + 1) * request->count() > options_.message_room()) {
          return absl::ResourceExhaustedError(
              "count x dimension coefficients exceed the message size limit");
        }
        ReducedEigenOptions options;
        options.count = request->count();
        options.cancel = cancel;
        ASSIGN_OR_RETURN(WorkGrant grant,
                         registry_->AdmitWork(ReducedEigenWorkingBytes(*basis->system, options),
                                              "this Eigenfields call"));
        ASSIGN_OR_RETURN(ReducedEigenResult result, ReducedEigenpairs(*basis->system, options));
        response->mutable_eigenvalues()->Add(result.values.data(),
                                             result.values.data() + result.values.size());
        for (Eigen::Index j = 0; j < result.coefficients.cols(); ++j) {
          const double* col = result.coefficients.col(j).data();
          response->mutable_coefficients()->Add(col, col + result.coefficients.rows());
        }
        response->set_dimension(d);
        response->set_seconds(std::chrono::duration<double>(Clock::now() - start).count());
        return absl::OkStatus();
      });
}

grpc::ServerBidiReactor<grpc::ByteBuffer, grpc::ByteBuffer>* FieldService::Design(
    grpc::CallbackServerContext* context) {
  return NewDesignReactor(this, context);
}

// --- applications ------------------------------------------------------------------------------

grpc::ServerWriteReactor<v1::CurvatureChunk>* FieldService::Curvature(
    grpc::CallbackServerContext* /*context*/, const v1::CurvatureRequest* request) {
  return NewCurvatureWriter(this, *request);
}

grpc::ServerUnaryReactor* FieldService::Singularities(grpc::CallbackServerContext* /*context*/,
                                                      const v1::SingularitiesRequest* request,
                                                      v1::SingularitiesResponse* response) {
  return RunUnary(
      this, Where::kPool, [this, request, response](const std::atomic<bool>*) -> absl::Status {
        ASSIGN_OR_RETURN(std::shared_ptr<const ServedBasis> basis,
                         registry_->GetBasis(request->basis_id()));
        if (basis->basis->type.kind == FieldKind::kTensor) {
          return absl::InvalidArgumentError(
              "singularities are defined for vector and n-field bases, not tensor bases");
        }
        // The field in double and the per-vertex indices.
        ASSIGN_OR_RETURN(WorkGrant grant, AdmitFieldWork(registry_, *basis, 8,
                                                         32 * int64_t{basis->mesh->num_faces()},
                                                         "this Singularities call"));
        const bool has_field = !request->field().values().empty();
        if (has_field == !request->coefficients().empty()) {
          return absl::InvalidArgumentError(
              "give the field either as coefficients or as values on all faces (field)");
        }
        Eigen::VectorXd dofs;
        if (has_field) {
          ASSIGN_OR_RETURN(dofs, FieldFromProto(request->field(), *basis));
        } else {
          ASSIGN_OR_RETURN(Eigen::VectorXd x,
                           CoefficientsFromProto(request->coefficients(), *basis));
          ASSIGN_OR_RETURN(dofs, fieldspace::Lift(*basis->system, x));
        }
        return SingularitiesToProto(*basis, dofs, request->zero_tolerance(), response);
      });
}

namespace {

// Smooths `X0` in `basis` (per-face `face_weights`, empty for 1) and fills `response`: the
// coefficients, the lifted field on request and the timings. Shared by Smooth and Align.
absl::Status SmoothInto(const ServedBasis& basis, const Eigen::VectorXd& X0,
                        const EnergyWeights& weights, absl::Span<const double> face_weights,
                        bool scale_free, bool return_field, int field_encoding, bool singularities,
                        const ServiceOptions& service, Registry* registry,
                        const std::atomic<bool>* cancel, Clock::time_point start,
                        v1::SmoothResponse* response) {
  RETURN_IF_ERROR(ValidateWeightsWithoutDataTerm(weights));
  ASSIGN_OR_RETURN(FieldEncoding encoding, EncodingFromProto(field_encoding));
  if (return_field) {
    const int64_t bytes =
        int64_t{4} * ValuesPerFace(basis.basis->type, encoding) * basis.mesh->num_faces();
    if (bytes > service.message_room()) {
      return absl::ResourceExhaustedError(absl::StrCat(
          "the smoothed field (", bytes, " bytes) exceeds the message size limit; use Lift"));
    }
  }
  // The smoother, and the lifted field (double and float) on request.
  ASSIGN_OR_RETURN(
      WorkGrant grant,
      AdmitFieldWork(registry, basis, return_field || singularities ? 12 : 0,
                     SmoothWorkingBytes(*basis.system, HardwareThreads()), "this smoothing"));
  SmoothingOptions options;
  options.scale_free = scale_free;
  options.cancel = cancel;
  ASSIGN_OR_RETURN(SmoothingResult result,
                   SmoothReduced(*basis.system, X0, weights, face_weights, options));
  RETURN_IF_ERROR(CheckSolutionFinite(result.coefficients));
  response->mutable_coefficients()->Add(result.coefficients.data(),
                                        result.coefficients.data() + result.coefficients.size());
  double lift_ms = 0;
  Eigen::VectorXd dofs;  // the lifted field, once, for return_field and singularities
  if (return_field) {
    const auto lift_start = Clock::now();
    response->mutable_field()->set_encoding(EncodingToProto(encoding));
    RETURN_IF_ERROR(LiftAllToValues(basis, result.coefficients, encoding,
                                    response->mutable_field()->mutable_values(), &dofs));
    lift_ms = MsSince(lift_start);
  }
  if (singularities) {
    if (dofs.size() == 0) {
      ASSIGN_OR_RETURN(dofs, fieldspace::Lift(*basis.system, result.coefficients));
    }
    RETURN_IF_ERROR(SingularitiesToProto(basis, dofs, 0, response->mutable_singularities()));
  }
  v1::SmoothTimings* t = response->mutable_timings();
  t->set_rhs_ms(result.timings.rhs_ms);
  t->set_weighted_mass_ms(result.timings.weighted_mass_ms);
  t->set_factorize_ms(result.timings.factorize_ms);
  t->set_solve_ms(result.timings.solve_ms);
  t->set_lift_ms(lift_ms);
  t->set_total_ms(MsSince(start));
  response->set_backward_error(result.backward_error);
  return absl::OkStatus();
}

}  // namespace

grpc::ServerUnaryReactor* FieldService::Smooth(grpc::CallbackServerContext* /*context*/,
                                               const v1::SmoothRequest* request,
                                               v1::SmoothResponse* response) {
  return RunUnary(this, Where::kPool,
                  [this, request, response](const std::atomic<bool>* cancel) -> absl::Status {
                    const auto start = Clock::now();
                    ASSIGN_OR_RETURN(std::shared_ptr<const ServedBasis> basis,
                                     registry_->GetBasis(request->basis_id()));
                    ASSIGN_OR_RETURN(Eigen::VectorXd X0, FieldFromProto(request->field(), *basis));
                    return SmoothInto(
                        *basis, X0, WeightsFromProto(request->weights(), kDefaultSmoothingWeights),
                        request->face_weights(), request->scale_free(), request->return_field(),
                        request->field_encoding(), request->singularities(), options_, registry_,
                        cancel, start, response);
                  });
}

grpc::ServerUnaryReactor* FieldService::Align(grpc::CallbackServerContext* /*context*/,
                                              const v1::AlignRequest* request,
                                              v1::SmoothResponse* response) {
  return RunUnary(
      this, Where::kPool,
      [this, request, response](const std::atomic<bool>* cancel) -> absl::Status {
        const auto start = Clock::now();
        ASSIGN_OR_RETURN(std::shared_ptr<const ServedBasis> basis,
                         registry_->GetBasis(request->basis_id()));
        ASSIGN_OR_RETURN(CurvatureEstimator estimator, EstimatorFromProto(request->estimator()));
        // The curvature target while it is computed (the smoothing is admitted in SmoothInto).
        ASSIGN_OR_RETURN(
            WorkGrant grant,
            AdmitFieldWork(registry_, *basis, 8, CurvatureWorkingBytes(basis->mesh->num_faces()),
                           "this Align"));
        ASSIGN_OR_RETURN(AlignmentTarget target, CurvatureAlignmentTarget(*basis, estimator));
        return SmoothInto(
            *basis, target.dofs, WeightsFromProto(request->weights(), kDefaultSmoothingWeights),
            absl::MakeConstSpan(target.face_weights.data(), target.face_weights.size()),
            /*scale_free=*/true, request->return_field(), request->field_encoding(),
            request->singularities(), options_, registry_, cancel, start, response);
      });
}

}  // namespace fieldspace::server
