#ifndef FIELDSPACE_SERVER_FIELD_SERVICE_H_
#define FIELDSPACE_SERVER_FIELD_SERVICE_H_

// Includes generated code: keep this header out of widely included headers (only field_server.cc
// and tests include it).

#include <atomic>
#include <chrono>
#include <cstdint>
#include <mutex>
#include <set>
#include <string>

#include "fieldspace/v1/fieldspace.grpc.pb.h"
#include "server/compute_pool.h"
#include "server/handlers.h"
#include "server/registry.h"
#include "server/service_options.h"

namespace fieldspace::server {

// Reference counting for reactors that other threads may touch after gRPC is done with them:
// gRPC's own reference is dropped in OnDone.
class RefCounted {
 public:
  virtual ~RefCounted() = default;
  void AddRef() { refs_.fetch_add(1); }
  void DropRef() {
    if (refs_.fetch_sub(1) == 1) delete this;
  }

 private:
  std::atomic<int> refs_{1};
};

// A long-lived stream that must be ended when the server drains (design sessions).
class DrainableStream : public RefCounted {
 public:
  virtual void Drain() = 0;
};

// StackMixins<Base, M1, M2, ...>::type is M1<M2<...<Base>>>, as grpc_cpp_plugin composes services.
template <typename Base, template <typename> class... Mixins>
struct StackMixins {
  using type = Base;
};
template <typename Base, template <typename> class First, template <typename> class... Rest>
struct StackMixins<Base, First, Rest...> {
  using type = First<typename StackMixins<Base, Rest...>::type>;
};

// FieldSpace::CallbackService with UploadMesh and Design raw (grpc::ByteBuffer), so that their
// reactors can tell a message that does not parse from the end of the stream (ParseStreamMessage,
// rpc_util.h). A raw mixin cannot sit on top of CallbackService (the typed Design clashes with the
// raw one), hence the whole list (a method missing here could not be overridden below).
using FieldSpaceService = fieldspace::v1::FieldSpace;
using FieldServiceBase = StackMixins<
    FieldSpaceService::Service, FieldSpaceService::WithRawCallbackMethod_UploadMesh,
    FieldSpaceService::WithCallbackMethod_LoadMesh, FieldSpaceService::WithCallbackMethod_GetMesh,
    FieldSpaceService::WithCallbackMethod_ListMeshes,
    FieldSpaceService::WithCallbackMethod_DeleteMesh,
    FieldSpaceService::WithCallbackMethod_GetMeshGeometry,
    FieldSpaceService::WithCallbackMethod_BuildBasis,
    FieldSpaceService::WithCallbackMethod_CancelBuild,
    FieldSpaceService::WithCallbackMethod_GetBasis, FieldSpaceService::WithCallbackMethod_ListBases,
    FieldSpaceService::WithCallbackMethod_DeleteBasis,
    FieldSpaceService::WithCallbackMethod_Project, FieldSpaceService::WithCallbackMethod_Solve,
    FieldSpaceService::WithCallbackMethod_Lift, FieldSpaceService::WithCallbackMethod_Eigenfields,
    FieldSpaceService::WithRawCallbackMethod_Design,
    FieldSpaceService::WithCallbackMethod_Curvature,
    FieldSpaceService::WithCallbackMethod_Singularities,
    FieldSpaceService::WithCallbackMethod_Smooth,
    FieldSpaceService::WithCallbackMethod_Align>::type;

// fieldspace.v1.FieldSpace on the callback API. Stateless apart from the set of open streams: it
// admits a call, runs its handler (handlers.h: proto in, proto out) on the compute pool or inline,
// and finishes the call with the handler's status.
class FieldService final : public FieldServiceBase {
 public:
  FieldService(Registry* registry, ComputePool* pool, ServiceOptions options);

  // New RPCs fail with UNAVAILABLE; open design sessions end with UNAVAILABLE after the edit in
  // progress (if any) has been answered.
  void BeginDrain();

  // For DrainableStream implementations.
  // One of the max_design_sessions places for a Design stream; false when all are taken.
  bool AcquireDesignSession();
  void ReleaseDesignSession();

  void RegisterStream(DrainableStream* stream);
  void UnregisterStream(DrainableStream* stream);

  // The drain check for a new RPC: Unavailable once the server is shutting down. (Tokens are
  // checked before a call reaches the service: server/auth.h.)
  absl::Status Admit() const;

  // The context of a handler run for a call; `cancel`: the call's cancellation flag.
  HandlerContext Context(const std::atomic<bool>* cancel) const;

  Registry* registry() const { return registry_; }
  ComputePool* pool() const { return pool_; }
  const ServiceOptions& options() const { return options_; }

  // Reads fieldspace.v1.UploadMeshRequest messages, answers a fieldspace.v1.MeshInfo.
  grpc::ServerReadReactor<grpc::ByteBuffer>* UploadMesh(grpc::CallbackServerContext* context,
                                                        grpc::ByteBuffer* response) override;
  grpc::ServerUnaryReactor* LoadMesh(grpc::CallbackServerContext* context,
                                     const fieldspace::v1::LoadMeshRequest* request,
                                     fieldspace::v1::MeshInfo* response) override;
  grpc::ServerUnaryReactor* GetMesh(grpc::CallbackServerContext* context,
                                    const fieldspace::v1::GetMeshRequest* request,
                                    fieldspace::v1::MeshInfo* response) override;
  grpc::ServerUnaryReactor* ListMeshes(grpc::CallbackServerContext* context,
                                       const fieldspace::v1::ListMeshesRequest* request,
                                       fieldspace::v1::ListMeshesResponse* response) override;
  grpc::ServerUnaryReactor* DeleteMesh(grpc::CallbackServerContext* context,
                                       const fieldspace::v1::DeleteMeshRequest* request,
                                       fieldspace::v1::DeleteMeshResponse* response) override;
  grpc::ServerWriteReactor<fieldspace::v1::MeshGeometryChunk>* GetMeshGeometry(
      grpc::CallbackServerContext* context,
      const fieldspace::v1::GetMeshGeometryRequest* request) override;

  grpc::ServerWriteReactor<fieldspace::v1::BuildBasisProgress>* BuildBasis(
      grpc::CallbackServerContext* context,
      const fieldspace::v1::BuildBasisRequest* request) override;
  grpc::ServerUnaryReactor* CancelBuild(grpc::CallbackServerContext* context,
                                        const fieldspace::v1::CancelBuildRequest* request,
                                        fieldspace::v1::CancelBuildResponse* response) override;
  grpc::ServerUnaryReactor* GetBasis(grpc::CallbackServerContext* context,
                                     const fieldspace::v1::GetBasisRequest* request,
                                     fieldspace::v1::BasisInfo* response) override;
  grpc::ServerUnaryReactor* ListBases(grpc::CallbackServerContext* context,
                                      const fieldspace::v1::ListBasesRequest* request,
                                      fieldspace::v1::ListBasesResponse* response) override;
  grpc::ServerUnaryReactor* DeleteBasis(grpc::CallbackServerContext* context,
                                        const fieldspace::v1::DeleteBasisRequest* request,
                                        fieldspace::v1::DeleteBasisResponse* response) override;

  grpc::ServerUnaryReactor* Project(grpc::CallbackServerContext* context,
                                    const fieldspace::v1::ProjectRequest* request,
                                    fieldspace::v1::ProjectResponse* response) override;
  grpc::ServerUnaryReactor* Solve(grpc::CallbackServerContext* context,
                                  const fieldspace::v1::SolveRequest* request,
                                  fieldspace::v1::SolveResponse* response) override;
  grpc::ServerWriteReactor<fieldspace::v1::FieldChunk>* Lift(
      grpc::CallbackServerContext* context, const fieldspace::v1::LiftRequest* request) override;
  grpc::ServerUnaryReactor* Eigenfields(grpc::CallbackServerContext* context,
                                        const fieldspace::v1::EigenfieldsRequest* request,
                                        fieldspace::v1::EigenfieldsResponse* response) override;
  // Reads fieldspace.v1.DesignRequest messages, writes fieldspace.v1.DesignUpdate messages.
  grpc::ServerBidiReactor<grpc::ByteBuffer, grpc::ByteBuffer>* Design(
      grpc::CallbackServerContext* context) override;

  grpc::ServerWriteReactor<fieldspace::v1::CurvatureChunk>* Curvature(
      grpc::CallbackServerContext* context,
      const fieldspace::v1::CurvatureRequest* request) override;
  grpc::ServerUnaryReactor* Singularities(grpc::CallbackServerContext* context,
                                          const fieldspace::v1::SingularitiesRequest* request,
                                          fieldspace::v1::SingularitiesResponse* response) override;
  grpc::ServerUnaryReactor* Smooth(grpc::CallbackServerContext* context,
                                   const fieldspace::v1::SmoothRequest* request,
                                   fieldspace::v1::SmoothResponse* response) override;
  grpc::ServerUnaryReactor* Align(grpc::CallbackServerContext* context,
                                  const fieldspace::v1::AlignRequest* request,
                                  fieldspace::v1::SmoothResponse* response) override;

 private:
  Registry* const registry_;
  ComputePool* const pool_;
  const ServiceOptions options_;
  std::atomic<bool> draining_{false};
  std::mutex streams_mu_;
  std::set<DrainableStream*> streams_;
  std::atomic<int32_t> design_sessions_{0};
};

}  // namespace fieldspace::server

#endif  // FIELDSPACE_SERVER_FIELD_SERVICE_H_
