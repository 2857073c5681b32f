#ifndef FIELDSPACE_SERVER_HANDLERS_H_
#define FIELDSPACE_SERVER_HANDLERS_H_

// The bodies of the FieldSpace RPCs without the transport: proto in, proto out, absl::Status.
// The gRPC layer (field_service.cc and the reactors) admits a call, runs its handler (on the
// compute pool for heavy work) and finishes the call with the status; the fuzzers and tests call
// the same functions. Every handler validates its request (InvalidArgument naming the field),
// looks up what it names (NotFound), admits its working memory (ResourceExhausted) and calls core.
// Design sessions are DesignEditor (design_editor.h); uploads are the upload reactor's.

#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"
#include "core/mesh/triangle_mesh.h"
#include "fieldspace/v1/fieldspace.pb.h"
#include "server/registry.h"
#include "server/served_basis.h"
#include "server/service_options.h"
#include "server/work_grant.h"

namespace fieldspace::server {

namespace v1 = ::fieldspace::v1;

using MeshLookup =
    std::function<absl::StatusOr<std::shared_ptr<const TriangleMesh>>(const std::string& id)>;

// What a handler works with. The daemon sets registry and options; a fixture that serves its own
// basis without a registry (the fuzzers) sets the lookups.
struct HandlerContext {
  // Meshes, bases, builds and the memory budget. Required by the mesh and basis bookkeeping
  // handlers (LoadMesh, GetMesh, ..., StartBuild); without it no working memory is counted.
  Registry* registry = nullptr;
  const ServiceOptions* options = nullptr;    // required
  const std::atomic<bool>* cancel = nullptr;  // the client went away (may be null)
  // Where basis_id and mesh_id lead when set; otherwise the registry's GetBasis and GetMesh.
  BasisLookup basis_lookup;
  MeshLookup mesh_lookup;

  absl::StatusOr<std::shared_ptr<const ServedBasis>> GetBasis(const std::string& id) const;
  absl::StatusOr<std::shared_ptr<const TriangleMesh>> GetMesh(const std::string& id) const;
  // Registry::AdmitWork, or an empty grant without a registry.
  absl::StatusOr<WorkGrant> AdmitWork(int64_t bytes, absl::string_view what) const;
};

// Threads of oneTBB's default arena, which core's parallel loops use (for working memory
// estimates that grow with the threads).
int32_t HardwareThreads();

// --- Meshes (handlers.cc).
absl::Status LoadMesh(const HandlerContext& ctx, const v1::LoadMeshRequest& request,
                      v1::MeshInfo* response);
absl::Status GetMesh(const HandlerContext& ctx, const v1::GetMeshRequest& request,
                     v1::MeshInfo* response);
absl::Status ListMeshes(const HandlerContext& ctx, const v1::ListMeshesRequest& request,
                        v1::ListMeshesResponse* response);
absl::Status DeleteMesh(const HandlerContext& ctx, const v1::DeleteMeshRequest& request,
                        v1::DeleteMeshResponse* response);

// --- Bases (handlers.cc).
// Starts, joins or finds the build of the basis `request` names (Registry::StartBuild).
absl::StatusOr<Registry::StartedBuild> StartBuild(const HandlerContext& ctx,
                                                  const v1::BuildBasisRequest& request);
// The BuildBasis message for `progress` of `job`; once finished OK, with the basis's info.
void BuildProgressToProto(const HandlerContext& ctx, const BuildJob& job,
                          const BuildJob::Progress& progress, bool joined,
                          v1::BuildBasisProgress* out);
// The one BuildBasis message for a basis that exists.
void BuiltBasisToProto(const HandlerContext& ctx, const BasisRecord& record,
                       v1::BuildBasisProgress* out);
absl::Status CancelBuild(const HandlerContext& ctx, const v1::CancelBuildRequest& request,
                         v1::CancelBuildResponse* response);
absl::Status GetBasis(const HandlerContext& ctx, const v1::GetBasisRequest& request,
                      v1::BasisInfo* response);
absl::Status ListBases(const HandlerContext& ctx, const v1::ListBasesRequest& request,
                       v1::ListBasesResponse* response);
absl::Status DeleteBasis(const HandlerContext& ctx, const v1::DeleteBasisRequest& request,
                         v1::DeleteBasisResponse* response);

// --- Subspace methods (subspace_handlers.cc).
absl::Status Project(const HandlerContext& ctx, const v1::ProjectRequest& request,
                     v1::ProjectResponse* response);
absl::Status Solve(const HandlerContext& ctx, const v1::SolveRequest& request,
                   v1::SolveResponse* response);
absl::Status Eigenfields(const HandlerContext& ctx, const v1::EigenfieldsRequest& request,
                         v1::EigenfieldsResponse* response);

// --- Applications (application_handlers.cc).
absl::Status Singularities(const HandlerContext& ctx, const v1::SingularitiesRequest& request,
                           v1::SingularitiesResponse* response);
absl::Status Smooth(const HandlerContext& ctx, const v1::SmoothRequest& request,
                    v1::SmoothResponse* response);
absl::Status Align(const HandlerContext& ctx, const v1::AlignRequest& request,
                   v1::SmoothResponse* response);

// --- Server-streaming answers: opened once (the heavy work, e.g. a whole-field lift), then
// read chunk by chunk. Next fills `chunk` and returns true, or returns false when all is sent.
template <typename Message>
class ChunkStream {
 public:
  virtual ~ChunkStream() = default;
  virtual absl::StatusOr<bool> Next(Message* chunk) = 0;
};
absl::StatusOr<std::unique_ptr<ChunkStream<v1::MeshGeometryChunk>>> OpenGeometry(
    const HandlerContext& ctx, const v1::GetMeshGeometryRequest& request);  // handlers.cc
absl::StatusOr<std::unique_ptr<ChunkStream<v1::FieldChunk>>> OpenLift(
    const HandlerContext& ctx, const v1::LiftRequest& request);  // subspace_handlers.cc
absl::StatusOr<std::unique_ptr<ChunkStream<v1::CurvatureChunk>>> OpenCurvature(
    const HandlerContext& ctx, const v1::CurvatureRequest& request);  // application_handlers.cc

}  // namespace fieldspace::server

#endif  // FIELDSPACE_SERVER_HANDLERS_H_
