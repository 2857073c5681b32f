// GetMeshGeometry and Lift (server streaming): chunks produced on the compute pool.

#include <algorithm>
#include <numeric>
#include <vector>

#include "core/common/status_macros.h"
#include "server/proto_convert.h"
#include "server/reactors.h"
#include "server/rpc_util.h"

namespace fieldspace::server {
namespace {

constexpr int32_t kDefaultChunkFaces = 65536;
constexpr int32_t kMaxChunkFaces = 1 << 19;

class GeometryWriter final : public ChunkWriter<v1::MeshGeometryChunk> {
 public:
  GeometryWriter(FieldService* service, grpc::CallbackServerContext* context,
                 const v1::GetMeshGeometryRequest& request)
      : ChunkWriter(service, context), request_(request) {
    Begin();
  }

 private:
  absl::Status Prepare(const std::atomic<bool>*) override {
    if (request_.chunk_faces() < 0) {
      return absl::InvalidArgumentError("chunk_faces must not be negative");
    }
    chunk_ = request_.chunk_faces() == 0 ? kDefaultChunkFaces
                                         : std::min(request_.chunk_faces(), kMaxChunkFaces);
    ASSIGN_OR_RETURN(mesh_, service()->registry()->GetMesh(request_.mesh_id()));
    return absl::OkStatus();
  }

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

  const v1::GetMeshGeometryRequest request_;
  std::shared_ptr<const TriangleMesh> mesh_;
  int32_t chunk_ = kDefaultChunkFaces;
  int32_t next_vertex_ = 0;
  int32_t next_face_ = 0;
  bool sent_any_ = false;
};

class LiftWriter final : public ChunkWriter<v1::FieldChunk> {
 public:
  LiftWriter(FieldService* service, grpc::CallbackServerContext* context,
             const v1::LiftRequest& request)
      : ChunkWriter(service, context), request_(request) {
    Begin();
  }

 private:
  absl::Status Prepare(const std::atomic<bool>*) override {
    ASSIGN_OR_RETURN(basis_, service()->registry()->GetBasis(request_.basis_id()));
    ASSIGN_OR_RETURN(x_, CoefficientsFromProto(request_.coefficients(), *basis_));
    ASSIGN_OR_RETURN(encoding_, EncodingFromProto(request_.encoding()));
    if (request_.chunk_faces() < 0) {
      return absl::InvalidArgumentError("chunk_faces must not be negative");
    }
    chunk_ = request_.chunk_faces() == 0 ? kDefaultChunkFaces
                                         : std::min(request_.chunk_faces(), kMaxChunkFaces);
    RETURN_IF_ERROR(CheckFaces(request_.faces(), basis_->mesh->num_faces(), "lift"));
    subset_ = !request_.faces().empty();
    total_ = subset_ ? request_.faces().size() : basis_->mesh->num_faces();
    return absl::OkStatus();
  }

  absl::StatusOr<bool> Next(v1::FieldChunk* out) override {
    if (next_ >= total_ && sent_any_) return false;
    const auto start = Clock::now();
    sent_any_ = true;
    const int32_t count = std::min(chunk_, total_ - next_);
    faces_.resize(count);
    if (subset_) {
      std::copy_n(request_.faces().data() + next_, count, faces_.begin());
      out->mutable_field()->mutable_faces()->Add(faces_.begin(), faces_.end());
    } else {
      std::iota(faces_.begin(), faces_.end(), next_);
    }
    out->set_start_face(subset_ ? 0 : next_);
    out->set_total_faces(total_);
    out->mutable_field()->set_encoding(EncodingToProto(encoding_));
    RETURN_IF_ERROR(
        LiftToValues(*basis_, x_, faces_, encoding_, out->mutable_field()->mutable_values()));
    next_ += count;
    server_ms_ += MsSince(start);
    out->set_server_ms(server_ms_);
    return true;
  }

  const v1::LiftRequest request_;
  std::shared_ptr<const ServedBasis> basis_;
  Eigen::VectorXd x_;
  FieldEncoding encoding_ = FieldEncoding::kDof;
  std::vector<int32_t> faces_;
  bool subset_ = false;
  int32_t chunk_ = kDefaultChunkFaces;
  int32_t total_ = 0;
  int32_t next_ = 0;
  bool sent_any_ = false;
  double server_ms_ = 0;
};

}  // namespace

grpc::ServerWriteReactor<v1::MeshGeometryChunk>* NewGeometryWriter(
    FieldService* service, grpc::CallbackServerContext* context,
    const v1::GetMeshGeometryRequest& request) {
  return new GeometryWriter(service, context, request);
}

grpc::ServerWriteReactor<v1::FieldChunk>* NewLiftWriter(FieldService* service,
                                                        grpc::CallbackServerContext* context,
                                                        const v1::LiftRequest& request) {
  return new LiftWriter(service, context, request);
}

}  // namespace fieldspace::server
