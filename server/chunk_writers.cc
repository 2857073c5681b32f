// GetMeshGeometry, Lift and Curvature (server streaming): chunks produced on the compute pool.

#include <algorithm>
#include <memory>
#include <numeric>
#include <vector>

#include "core/common/status_macros.h"
#include "core/operators/curvature.h"
#include "core/subspace/projection.h"
#include "server/proto_convert.h"
#include "server/reactors.h"
#include "server/rpc_util.h"

namespace fieldspace::server {
namespace {

class GeometryWriter final : public ChunkWriter<v1::MeshGeometryChunk> {
 public:
  GeometryWriter(FieldService* service, const v1::GetMeshGeometryRequest& request)
      : ChunkWriter(service), request_(request) {
    Begin();
  }

 private:
  absl::Status Prepare(const std::atomic<bool>*) override {
    if (request_.chunk_faces() < 0) {
      return absl::InvalidArgumentError("chunk_faces must not be negative");
    }
    // A chunk carries up to chunk_ vertices (24 bytes) and chunk_ faces (12 bytes).
    chunk_ = service()->options().ChunkFaces(request_.chunk_faces(), 36);
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
  int32_t chunk_ = 0;
  int32_t next_vertex_ = 0;
  int32_t next_face_ = 0;
  bool sent_any_ = false;
};

class LiftWriter final : public ChunkWriter<v1::FieldChunk> {
 public:
  LiftWriter(FieldService* service, const v1::LiftRequest& request)
      : ChunkWriter(service), request_(request) {
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
    RETURN_IF_ERROR(CheckFaces(request_.faces(), basis_->mesh->num_faces(), "lift"));
    // Per face: its values (float) and, for subset lifts, its index.
    chunk_ = service()->options().ChunkFaces(
        request_.chunk_faces(),
        4 * ValuesPerFace(basis_->basis->type, encoding_) + (request_.faces().empty() ? 0 : 4));
    subset_ = !request_.faces().empty();
    total_ = subset_ ? request_.faces().size() : basis_->mesh->num_faces();
    if (!subset_) {
      // All faces: one parallel pass of the LiftPlan now; the chunks only encode slices of it.
      // The DOF encoding is the lift narrowed to float, done in the lift's own pass.
      ASSIGN_OR_RETURN(
          grant_,
          service()->registry()->AdmitWork(
              (encoding_ == FieldEncoding::kDof ? 4 : 8) * basis_->system->dofs(), "this Lift"));
      const auto start = Clock::now();
      if (encoding_ == FieldEncoding::kDof) {
        // Uninitialized: the lift writes every value (no zero-fill pass over 11 MB at 1.38M faces).
        all_values_.reset(new float[basis_->system->dofs()]);
        RETURN_IF_ERROR(LiftIntoFloat(*basis_->system, x_,
                                      absl::MakeSpan(all_values_.get(), basis_->system->dofs())));
      } else {
        ASSIGN_OR_RETURN(all_dofs_, fieldspace::Lift(*basis_->system, x_));
      }
      server_ms_ = MsSince(start);
    }
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
    if (subset_) {
      RETURN_IF_ERROR(
          LiftToValues(*basis_, x_, faces_, encoding_, out->mutable_field()->mutable_values()));
    } else if (encoding_ == FieldEncoding::kDof) {
      const int64_t dpf = basis_->basis->type.dofs_per_face();
      out->mutable_field()->mutable_values()->Add(all_values_.get() + dpf * next_,
                                                  all_values_.get() + dpf * (next_ + count));
    } else {
      const int64_t dpf = basis_->basis->type.dofs_per_face();
      RETURN_IF_ERROR(EncodeDofs(*basis_, faces_,
                                 absl::MakeConstSpan(all_dofs_.data() + dpf * next_, dpf * count),
                                 encoding_, out->mutable_field()->mutable_values()));
    }
    next_ += count;
    server_ms_ += MsSince(start);
    out->set_server_ms(server_ms_);
    return true;
  }

  const v1::LiftRequest request_;
  std::shared_ptr<const ServedBasis> basis_;
  Eigen::VectorXd x_;
  // All-faces lifts: the whole field, lifted in Prepare (as float for the DOF encoding).
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

// Curvature: the shape operator (and principal curvatures) computed once on the pool in
// Prepare, then sent in chunks of faces.
class CurvatureWriter final : public ChunkWriter<v1::CurvatureChunk> {
 public:
  CurvatureWriter(FieldService* service, const v1::CurvatureRequest& request)
      : ChunkWriter(service), request_(request) {
    Begin();
  }

 private:
  absl::Status Prepare(const std::atomic<bool>* cancel) override {
    const auto start = Clock::now();
    ASSIGN_OR_RETURN(encoding_, EncodingFromProto(request_.encoding()));
    if (request_.chunk_faces() < 0) {
      return absl::InvalidArgumentError("chunk_faces must not be negative");
    }
    // Per face: the tensor (6 or 3 floats) and, on request, k1, k2, d1, d2 (8 floats).
    chunk_ = service()->options().ChunkFaces(
        request_.chunk_faces(),
        4 * (ValuesPerFace(FieldType::Tensor(), encoding_) + (request_.principal() ? 8 : 0)));
    ShapeOperatorOptions options;
    options.cancel = cancel;
    ASSIGN_OR_RETURN(options.estimator, EstimatorFromProto(request_.estimator()));
    ASSIGN_OR_RETURN(mesh_, service()->registry()->GetMesh(request_.mesh_id()));
    ASSIGN_OR_RETURN(grant_, service()->registry()->AdmitWork(
                                 CurvatureWorkingBytes(mesh_->num_faces()), "this Curvature call"));
    ASSIGN_OR_RETURN(dofs_, ComputeShapeOperator(*mesh_, options));
    if (request_.principal()) {
      ASSIGN_OR_RETURN(principal_, ComputePrincipalCurvatures(*mesh_, dofs_));
    }
    server_ms_ = MsSince(start);
    return absl::OkStatus();
  }

  absl::StatusOr<bool> Next(v1::CurvatureChunk* out) override {
    const int32_t total = mesh_->num_faces();
    if (next_ >= total) return false;
    const auto start = Clock::now();
    const int32_t count = std::min(chunk_, total - next_);
    faces_.resize(count);
    std::iota(faces_.begin(), faces_.end(), next_);
    out->set_start_face(next_);
    out->set_total_faces(total);
    const FieldType type = FieldType::Tensor();
    const int32_t vpf = ValuesPerFace(type, encoding_);
    v1::FieldValues* tensor = out->mutable_tensor();
    tensor->set_encoding(EncodingToProto(encoding_));
    tensor->mutable_values()->Resize(count * vpf, 0.0f);
    RETURN_IF_ERROR(
        DofsToValues(*mesh_, type, encoding_, faces_,
                     absl::MakeConstSpan(dofs_.data() + int64_t{3} * next_, int64_t{3} * count),
                     absl::MakeSpan(tensor->mutable_values()->mutable_data(), count * vpf)));
    if (request_.principal()) {
      for (int32_t f = next_; f < next_ + count; ++f) {
        out->add_k1(static_cast<float>(principal_.k1[f]));
        out->add_k2(static_cast<float>(principal_.k2[f]));
        for (int c = 0; c < 3; ++c) {
          out->add_d1(static_cast<float>(principal_.d1(f, c)));
          out->add_d2(static_cast<float>(principal_.d2(f, c)));
        }
      }
    }
    next_ += count;
    server_ms_ += MsSince(start);
    out->set_server_ms(server_ms_);
    return true;
  }

  const v1::CurvatureRequest request_;
  std::shared_ptr<const TriangleMesh> mesh_;
  Eigen::VectorXd dofs_;
  PrincipalCurvatures principal_;
  WorkGrant grant_;  // the memory of the curvature computations
  FieldEncoding encoding_ = FieldEncoding::kDof;
  std::vector<int32_t> faces_;
  int32_t chunk_ = 0;
  int32_t next_ = 0;
  double server_ms_ = 0;
};

}  // namespace

grpc::ServerWriteReactor<v1::CurvatureChunk>* NewCurvatureWriter(
    FieldService* service, const v1::CurvatureRequest& request) {
  return new CurvatureWriter(service, request);
}

grpc::ServerWriteReactor<v1::MeshGeometryChunk>* NewGeometryWriter(
    FieldService* service, const v1::GetMeshGeometryRequest& request) {
  return new GeometryWriter(service, request);
}

grpc::ServerWriteReactor<v1::FieldChunk>* NewLiftWriter(FieldService* service,
                                                        const v1::LiftRequest& request) {
  return new LiftWriter(service, request);
}

}  // namespace fieldspace::server
