#include "server/field_service.h"

#include <utility>
#include <vector>

#include "server/reactors.h"
#include "server/rpc_util.h"

namespace fieldspace::server {

FieldService::FieldService(Registry* registry, ComputePool* pool, ServiceOptions options)
    : registry_(registry), pool_(pool), options_(std::move(options)) {}

HandlerContext FieldService::Context(const std::atomic<bool>* cancel) const {
  HandlerContext context;
  context.registry = registry_;
  context.options = &options_;
  context.cancel = cancel;
  return context;
}

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
    grpc::CallbackServerContext* context, grpc::ByteBuffer* response) {
  return NewUploadReactor(this, context, response);
}

grpc::ServerUnaryReactor* FieldService::LoadMesh(grpc::CallbackServerContext* /*context*/,
                                                 const v1::LoadMeshRequest* request,
                                                 v1::MeshInfo* response) {
  return RunHandler(this, Where::kPool, &server::LoadMesh, request, response);
}

grpc::ServerUnaryReactor* FieldService::GetMesh(grpc::CallbackServerContext* /*context*/,
                                                const v1::GetMeshRequest* request,
                                                v1::MeshInfo* response) {
  return RunHandler(this, Where::kInline, &server::GetMesh, request, response);
}

grpc::ServerUnaryReactor* FieldService::ListMeshes(grpc::CallbackServerContext* /*context*/,
                                                   const v1::ListMeshesRequest* request,
                                                   v1::ListMeshesResponse* response) {
  return RunHandler(this, Where::kInline, &server::ListMeshes, request, response);
}

grpc::ServerUnaryReactor* FieldService::DeleteMesh(grpc::CallbackServerContext* /*context*/,
                                                   const v1::DeleteMeshRequest* request,
                                                   v1::DeleteMeshResponse* response) {
  return RunHandler(this, Where::kPool, &server::DeleteMesh, request, response);
}

grpc::ServerWriteReactor<v1::MeshGeometryChunk>* FieldService::GetMeshGeometry(
    grpc::CallbackServerContext* /*context*/, const v1::GetMeshGeometryRequest* request) {
  return new ChunkWriter<v1::MeshGeometryChunk, v1::GetMeshGeometryRequest>(this, *request,
                                                                            &OpenGeometry);
}

// --- bases -------------------------------------------------------------------------------------

grpc::ServerWriteReactor<v1::BuildBasisProgress>* FieldService::BuildBasis(
    grpc::CallbackServerContext* /*context*/, const v1::BuildBasisRequest* request) {
  return NewBuildWatcher(this, *request);
}

grpc::ServerUnaryReactor* FieldService::CancelBuild(grpc::CallbackServerContext* /*context*/,
                                                    const v1::CancelBuildRequest* request,
                                                    v1::CancelBuildResponse* response) {
  return RunHandler(this, Where::kInline, &server::CancelBuild, request, response);
}

grpc::ServerUnaryReactor* FieldService::GetBasis(grpc::CallbackServerContext* /*context*/,
                                                 const v1::GetBasisRequest* request,
                                                 v1::BasisInfo* response) {
  return RunHandler(this, Where::kInline, &server::GetBasis, request, response);
}

grpc::ServerUnaryReactor* FieldService::ListBases(grpc::CallbackServerContext* /*context*/,
                                                  const v1::ListBasesRequest* request,
                                                  v1::ListBasesResponse* response) {
  return RunHandler(this, Where::kInline, &server::ListBases, request, response);
}

grpc::ServerUnaryReactor* FieldService::DeleteBasis(grpc::CallbackServerContext* /*context*/,
                                                    const v1::DeleteBasisRequest* request,
                                                    v1::DeleteBasisResponse* response) {
  return RunHandler(this, Where::kPool, &server::DeleteBasis, request, response);
}

// --- subspace methods ----------------------------------------------------------------------------

grpc::ServerUnaryReactor* FieldService::Project(grpc::CallbackServerContext* /*context*/,
                                                const v1::ProjectRequest* request,
                                                v1::ProjectResponse* response) {
  return RunHandler(this, Where::kPool, &server::Project, request, response);
}

grpc::ServerUnaryReactor* FieldService::Solve(grpc::CallbackServerContext* /*context*/,
                                              const v1::SolveRequest* request,
                                              v1::SolveResponse* response) {
  return RunHandler(this, Where::kPool, &server::Solve, request, response);
}

grpc::ServerWriteReactor<v1::FieldChunk>* FieldService::Lift(
    grpc::CallbackServerContext* /*context*/, const v1::LiftRequest* request) {
  return new ChunkWriter<v1::FieldChunk, v1::LiftRequest>(this, *request, &OpenLift);
}

grpc::ServerUnaryReactor* FieldService::Eigenfields(grpc::CallbackServerContext* /*context*/,
                                                    const v1::EigenfieldsRequest* request,
                                                    v1::EigenfieldsResponse* response) {
  return RunHandler(this, Where::kPool, &server::Eigenfields, request, response);
}

grpc::ServerBidiReactor<grpc::ByteBuffer, grpc::ByteBuffer>* FieldService::Design(
    grpc::CallbackServerContext* context) {
  return NewDesignReactor(this, context);
}

// --- applications ------------------------------------------------------------------------------

grpc::ServerWriteReactor<v1::CurvatureChunk>* FieldService::Curvature(
    grpc::CallbackServerContext* /*context*/, const v1::CurvatureRequest* request) {
  return new ChunkWriter<v1::CurvatureChunk, v1::CurvatureRequest>(this, *request, &OpenCurvature);
}

grpc::ServerUnaryReactor* FieldService::Singularities(grpc::CallbackServerContext* /*context*/,
                                                      const v1::SingularitiesRequest* request,
                                                      v1::SingularitiesResponse* response) {
  return RunHandler(this, Where::kPool, &server::Singularities, request, response);
}

grpc::ServerUnaryReactor* FieldService::Smooth(grpc::CallbackServerContext* /*context*/,
                                               const v1::SmoothRequest* request,
                                               v1::SmoothResponse* response) {
  return RunHandler(this, Where::kPool, &server::Smooth, request, response);
}

grpc::ServerUnaryReactor* FieldService::Align(grpc::CallbackServerContext* /*context*/,
                                              const v1::AlignRequest* request,
                                              v1::SmoothResponse* response) {
  return RunHandler(this, Where::kPool, &server::Align, request, response);
}

}  // namespace fieldspace::server
