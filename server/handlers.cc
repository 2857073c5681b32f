// The handlers of the mesh and basis RPCs (bookkeeping on the registry) and the handler context.
// The subspace methods are in subspace_handlers.cc, the applications in application_handlers.cc.

#include "server/handlers.h"

#include <algorithm>
#include <utility>
#include <vector>

#include "core/common/status_macros.h"
#include "core/mesh/mesh_io.h"
#include "server/data_root.h"
#include "server/mesh_intake.h"
#include "server/record_convert.h"

namespace fieldspace::server {

absl::StatusOr<std::shared_ptr<const ServedBasis>> HandlerContext::GetBasis(
    const std::string& id) const {
  if (basis_lookup) return basis_lookup(id);
  if (registry == nullptr) return absl::InternalError("no registry to look up bases in");
  return registry->GetBasis(id);
}

absl::StatusOr<std::shared_ptr<const TriangleMesh>> HandlerContext::GetMesh(
    const std::string& id) const {
  if (mesh_lookup) return mesh_lookup(id);
  if (registry == nullptr) return absl::InternalError("no registry to look up meshes in");
  return registry->GetMesh(id);
}

absl::StatusOr<WorkGrant> HandlerContext::AdmitWork(int64_t bytes, absl::string_view what) const {
  if (registry == nullptr) return WorkGrant();
  return registry->AdmitWork(bytes, what);
}

namespace {

absl::Status NeedsRegistry(const HandlerContext& ctx) {
  if (ctx.registry == nullptr) return absl::InternalError("this request needs the registry");
  return absl::OkStatus();
}

}  // namespace

// --- meshes ------------------------------------------------------------------------------------

absl::Status LoadMesh(const HandlerContext& ctx, const v1::LoadMeshRequest& request,
                      v1::MeshInfo* response) {
  RETURN_IF_ERROR(NeedsRegistry(ctx));
  ASSIGN_OR_RETURN(ReadableFile file, OpenDataFile(ctx.options->data_root, request.path()));
  // The same size limit as an upload, and the same memory: the bytes, the parsed arrays and
  // their validation (MeshIntake).
  MeshReadOptions read;
  read.max_file_bytes = ctx.options->max_upload_bytes;
  const int64_t text_bytes = std::min(file.size, read.max_file_bytes);
  MeshIntake intake(ctx.registry, "this LoadMesh");
  RETURN_IF_ERROR(intake.HoldAtLeast(text_bytes));
  intake.AdmitArraysOf(&read, text_bytes);
  ASSIGN_OR_RETURN(MeshReadResult parsed, ReadMeshFile(std::move(file), request.path(), read));
  const std::string name = request.name().empty() ? request.path() : request.name();
  ASSIGN_OR_RETURN(MeshRecord record, intake.Add(std::move(parsed), name));
  MeshInfoFromRecord(record, ctx.registry->IsMeshLoaded(record.id), response);
  return absl::OkStatus();
}

absl::Status GetMesh(const HandlerContext& ctx, const v1::GetMeshRequest& request,
                     v1::MeshInfo* response) {
  RETURN_IF_ERROR(NeedsRegistry(ctx));
  ASSIGN_OR_RETURN(MeshRecord record, ctx.registry->GetMeshRecord(request.mesh_id()));
  MeshInfoFromRecord(record, ctx.registry->IsMeshLoaded(record.id), response);
  return absl::OkStatus();
}

absl::Status ListMeshes(const HandlerContext& ctx, const v1::ListMeshesRequest& /*request*/,
                        v1::ListMeshesResponse* response) {
  RETURN_IF_ERROR(NeedsRegistry(ctx));
  for (const MeshRecord& r : ctx.registry->ListMeshes()) {
    MeshInfoFromRecord(r, ctx.registry->IsMeshLoaded(r.id), response->add_meshes());
  }
  return absl::OkStatus();
}

absl::Status DeleteMesh(const HandlerContext& ctx, const v1::DeleteMeshRequest& request,
                        v1::DeleteMeshResponse* response) {
  RETURN_IF_ERROR(NeedsRegistry(ctx));
  ASSIGN_OR_RETURN(std::vector<std::string> deleted,
                   ctx.registry->DeleteMesh(request.mesh_id(), request.cascade()));
  for (std::string& id : deleted) response->add_deleted_basis_ids(std::move(id));
  return absl::OkStatus();
}

namespace {

class GeometryStream final : public ChunkStream<v1::MeshGeometryChunk> {
 public:
  GeometryStream(std::shared_ptr<const TriangleMesh> mesh, int32_t chunk)
      : mesh_(std::move(mesh)), chunk_(chunk) {}

  absl::StatusOr<bool> Next(v1::MeshGeometryChunk* out) override {
    const int32_t nv = mesh_->num_vertices(), nf = mesh_->num_faces();
    if (next_vertex_ >= nv && next_face_ >= nf && sent_any_) return false;
    sent_any_ = true;
    out->set_num_vertices(nv);
    out->set_num_faces(nf);
    const int32_t v_count = std::min(chunk_, nv - next_vertex_);
    const int32_t f_count = std::min(chunk_, nf - next_face_);
    out->set_start_vertex(next_vertex_);
    out->mutable_vertices()->Add(mesh_->vertices().data() + int64_t{3} * next_vertex_,
                                 mesh_->vertices().data() + int64_t{3} * (next_vertex_ + v_count));
    out->set_start_face(next_face_);
    out->mutable_faces()->Add(mesh_->faces().data() + int64_t{3} * next_face_,
                              mesh_->faces().data() + int64_t{3} * (next_face_ + f_count));
    next_vertex_ += v_count;
    next_face_ += f_count;
    return true;
  }

 private:
  const std::shared_ptr<const TriangleMesh> mesh_;
  const int32_t chunk_;
  int32_t next_vertex_ = 0;
  int32_t next_face_ = 0;
  bool sent_any_ = false;
};

}  // namespace

absl::StatusOr<std::unique_ptr<ChunkStream<v1::MeshGeometryChunk>>> OpenGeometry(
    const HandlerContext& ctx, const v1::GetMeshGeometryRequest& request) {
  if (request.chunk_faces() < 0) {
    return absl::InvalidArgumentError("chunk_faces must not be negative");
  }
  // A chunk carries up to `chunk` vertices (24 bytes) and `chunk` faces (12 bytes).
  const int32_t chunk = ctx.options->ChunkFaces(request.chunk_faces(), 36);
  ASSIGN_OR_RETURN(std::shared_ptr<const TriangleMesh> mesh, ctx.GetMesh(request.mesh_id()));
  return std::make_unique<GeometryStream>(std::move(mesh), chunk);
}

// --- bases -------------------------------------------------------------------------------------

absl::StatusOr<Registry::StartedBuild> StartBuild(const HandlerContext& ctx,
                                                  const v1::BuildBasisRequest& request) {
  RETURN_IF_ERROR(NeedsRegistry(ctx));
  ASSIGN_OR_RETURN(BuildRequest build, BuildRequestFromProto(request));
  return ctx.registry->StartBuild(std::move(build));
}

void BuiltBasisToProto(const HandlerContext& ctx, const BasisRecord& record,
                       v1::BuildBasisProgress* out) {
  out->set_basis_id(record.id);
  out->set_phase(v1::BUILD_PHASE_DONE);
  out->set_fraction(1.0);
  out->set_overall_fraction(1.0);
  // The status (loaded, memory) when the registry still has it; deleted meanwhile: the record.
  absl::StatusOr<BasisStatus> status = ctx.registry->GetBasisStatus(record.id);
  if (status.ok()) {
    BasisInfoFromStatus(*status, out->mutable_basis());
  } else {
    BasisInfoFromRecord(record, out->mutable_basis());
  }
}

void BuildProgressToProto(const HandlerContext& ctx, const BuildJob& job,
                          const BuildJob::Progress& progress, bool joined,
                          v1::BuildBasisProgress* out) {
  out->Clear();
  if (progress.finished && progress.status.ok()) {
    BuiltBasisToProto(ctx, progress.record, out);
  } else {
    out->set_basis_id(job.basis_id());
    out->set_phase(PhaseToProto(progress.stage));
    out->set_fraction(progress.fraction);
    out->set_overall_fraction(OverallFraction(progress.stage, progress.fraction));
  }
  out->set_joined(joined);
  out->set_waiting_for(progress.waiting_for);
}

absl::Status CancelBuild(const HandlerContext& ctx, const v1::CancelBuildRequest& request,
                         v1::CancelBuildResponse* /*response*/) {
  RETURN_IF_ERROR(NeedsRegistry(ctx));
  return ctx.registry->CancelBuild(request.basis_id());
}

absl::Status GetBasis(const HandlerContext& ctx, const v1::GetBasisRequest& request,
                      v1::BasisInfo* response) {
  RETURN_IF_ERROR(NeedsRegistry(ctx));
  ASSIGN_OR_RETURN(BasisStatus status, ctx.registry->GetBasisStatus(request.basis_id()));
  BasisInfoFromStatus(status, response);
  return absl::OkStatus();
}

absl::Status ListBases(const HandlerContext& ctx, const v1::ListBasesRequest& request,
                       v1::ListBasesResponse* response) {
  RETURN_IF_ERROR(NeedsRegistry(ctx));
  for (const BasisStatus& s : ctx.registry->ListBases(request.mesh_id())) {
    BasisInfoFromStatus(s, response->add_bases());
  }
  return absl::OkStatus();
}

absl::Status DeleteBasis(const HandlerContext& ctx, const v1::DeleteBasisRequest& request,
                         v1::DeleteBasisResponse* /*response*/) {
  RETURN_IF_ERROR(NeedsRegistry(ctx));
  return ctx.registry->DeleteBasis(request.basis_id());
}

}  // namespace fieldspace::server
