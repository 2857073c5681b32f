#include "server/field_service.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <map>
#include <numeric>
#include <optional>
#include <utility>
#include <vector>

#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "core/common/status_macros.h"
#include "core/mesh/mesh_io.h"
#include "server/status_util.h"

namespace fieldspace::server {
namespace {

namespace v1 = ::fieldspace::v1;
using Lane = ComputePool::Lane;
using Clock = std::chrono::steady_clock;

constexpr int32_t kDefaultChunkFaces = 65536;
constexpr int32_t kMaxChunkFaces = 1 << 19;
constexpr int32_t kMaxConstraints = 1 << 20;

double MsSince(Clock::time_point start) {
  return std::chrono::duration<double, std::milli>(Clock::now() - start).count();
}

// Runs `fn` (returning absl::Status) and turns exceptions escaping core code into statuses, so
// that no request can take the server down.
template <typename Fn>
absl::Status Guarded(Fn&& fn) {
  try {
    return fn();
  } catch (const std::bad_alloc&) {
    return absl::ResourceExhaustedError("out of memory");
  } catch (const std::exception& e) {
    return absl::InternalError(absl::StrCat("internal error: ", e.what()));
  }
}

// --- proto <-> core --------------------------------------------------------------------------

absl::StatusOr<FieldType> FieldTypeFromProto(const v1::FieldType& p) {
  switch (p.kind()) {
    case v1::FIELD_KIND_VECTOR:
      return FieldType::Vector();
    case v1::FIELD_KIND_NFIELD: {
      FieldType t = FieldType::NField(p.n());
      RETURN_IF_ERROR(t.Validate());
      return t;
    }
    case v1::FIELD_KIND_TENSOR:
      return FieldType::Tensor();
    default:
      return absl::InvalidArgumentError(
          "field.kind must be FIELD_KIND_VECTOR, FIELD_KIND_NFIELD or FIELD_KIND_TENSOR");
  }
}

void FieldTypeToProto(const FieldType& t, v1::FieldType* p) {
  switch (t.kind) {
    case FieldKind::kVector:
      p->set_kind(v1::FIELD_KIND_VECTOR);
      break;
    case FieldKind::kNField:
      p->set_kind(v1::FIELD_KIND_NFIELD);
      p->set_n(t.n);
      break;
    case FieldKind::kTensor:
      p->set_kind(v1::FIELD_KIND_TENSOR);
      break;
  }
}

absl::StatusOr<ValueEncoding> EncodingFromProto(int encoding) {
  switch (encoding) {
    case v1::FIELD_ENCODING_DOF:
      return ValueEncoding::kDof;
    case v1::FIELD_ENCODING_AMBIENT:
      return ValueEncoding::kAmbient;
    default:
      return absl::InvalidArgumentError(absl::StrCat("unknown field encoding ", encoding));
  }
}

v1::FieldEncoding EncodingToProto(ValueEncoding e) {
  return e == ValueEncoding::kAmbient ? v1::FIELD_ENCODING_AMBIENT : v1::FIELD_ENCODING_DOF;
}

v1::BuildPhase PhaseToProto(BuildStage stage) {
  switch (stage) {
    case BuildStage::kQueued:
      return v1::BUILD_PHASE_QUEUED;
    case BuildStage::kOperator:
      return v1::BUILD_PHASE_OPERATOR;
    case BuildStage::kSampling:
      return v1::BUILD_PHASE_SAMPLING;
    case BuildStage::kRegions:
      return v1::BUILD_PHASE_REGIONS;
    case BuildStage::kEigensolve:
      return v1::BUILD_PHASE_EIGENSOLVE;
    case BuildStage::kAssembly:
      return v1::BUILD_PHASE_ASSEMBLY;
    case BuildStage::kPrecompute:
      return v1::BUILD_PHASE_PRECOMPUTE;
    case BuildStage::kSaving:
      return v1::BUILD_PHASE_SAVING;
    case BuildStage::kDone:
      return v1::BUILD_PHASE_DONE;
  }
  return v1::BUILD_PHASE_UNSPECIFIED;
}

void MeshInfoFromRecord(const MeshRecord& r, bool loaded, v1::MeshInfo* p) {
  p->set_id(r.id);
  p->set_name(r.name);
  p->set_num_vertices(r.num_vertices);
  p->set_num_faces(r.num_faces);
  p->set_num_edges(r.num_edges);
  p->set_num_components(r.num_components);
  p->set_num_boundary_loops(r.num_boundary_loops);
  p->set_euler_characteristic(r.euler_characteristic);
  p->set_genus(r.genus);
  p->set_total_area(r.total_area);
  p->set_dropped_unreferenced_vertices(r.dropped_unreferenced_vertices);
  p->set_polygons_triangulated(r.polygons_triangulated);
  p->set_loaded(loaded);
  p->set_created_unix_ms(r.created_unix_ms);
}

void BasisInfoFromStatus(const BasisStatus& s, v1::BasisInfo* p) {
  const BasisRecord& r = s.record;
  p->set_id(r.id);
  p->set_mesh_id(r.key.mesh_id);
  FieldTypeToProto(r.key.field, p->mutable_field());
  p->set_dimension(r.key.dimension);
  p->set_sigma(r.key.sigma);
  p->set_fields_per_region(r.key.fields_per_region);
  p->set_seed(r.key.seed);
  p->set_coarse_dimension(r.key.coarse_dimension);
  p->set_adaptive(r.key.weights_hash != 0);
  p->set_dofs(r.dofs);
  if (s.ready) {
    p->set_state(v1::BASIS_STATE_READY);
    p->set_columns(r.columns);
    p->set_num_regions(r.num_regions);
    p->set_radius(r.radius);
    p->set_nnz(r.nnz);
    p->set_build_seconds(r.build_seconds);
    p->set_loaded(s.loaded);
    p->set_memory_bytes(s.memory_bytes);
    p->set_created_unix_ms(r.created_unix_ms);
    p->set_phase(v1::BUILD_PHASE_DONE);
    p->set_fraction(1.0);
  } else {
    p->set_state(v1::BASIS_STATE_BUILDING);
    p->set_phase(PhaseToProto(s.progress.stage));
    p->set_fraction(s.progress.fraction);
  }
}

void BasisInfoFromRecord(const BasisRecord& r, v1::BasisInfo* p) {
  BasisStatus s;
  s.record = r;
  s.ready = true;
  BasisInfoFromStatus(s, p);
}

absl::Status CheckFace(int64_t face, int32_t num_faces, absl::string_view what) {
  if (face < 0 || face >= num_faces) {
    return absl::InvalidArgumentError(
        absl::StrCat(what, ": face ", face, " is out of range [0, ", num_faces, ")"));
  }
  return absl::OkStatus();
}

absl::Status CheckFaces(const google::protobuf::RepeatedField<int32_t>& faces, int32_t num_faces,
                        absl::string_view what) {
  for (int32_t f : faces) RETURN_IF_ERROR(CheckFace(f, num_faces, what));
  return absl::OkStatus();
}

// One constraint value: `value` in `encoding` -> DOFs in the face frame.
absl::StatusOr<Eigen::Vector3d> ConstraintDofs(const TriangleMesh& mesh, const FieldType& type,
                                               int32_t face,
                                               const google::protobuf::RepeatedField<double>& value,
                                               int encoding, absl::string_view what) {
  RETURN_IF_ERROR(CheckFace(face, mesh.num_faces(), what));
  ASSIGN_OR_RETURN(ValueEncoding enc, EncodingFromProto(encoding));
  const int32_t vpf = ValuesPerFace(type, enc);
  if (value.size() != vpf) {
    return absl::InvalidArgumentError(absl::StrCat(
        what, ": value has ", value.size(), " numbers; a ", type.ToString(), " constraint in ",
        enc == ValueEncoding::kAmbient ? "ambient" : "DOF", " encoding needs ", vpf));
  }
  Eigen::Vector3d dofs = Eigen::Vector3d::Zero();
  const int32_t faces[1] = {face};
  RETURN_IF_ERROR(ValuesToDofs(mesh, type, enc, faces,
                               absl::MakeConstSpan(value.data(), value.size()),
                               absl::MakeSpan(dofs.data(), type.dofs_per_face())));
  return dofs;
}

absl::StatusOr<ConstraintSpec> ConstraintFromProto(const TriangleMesh& mesh, const FieldType& type,
                                                   const v1::Constraint& c,
                                                   absl::string_view what) {
  ConstraintSpec spec;
  spec.face = c.face();
  ASSIGN_OR_RETURN(spec.dofs, ConstraintDofs(mesh, type, c.face(), c.value(), c.encoding(), what));
  if (c.has_weight()) {
    if (!std::isfinite(c.weight()) || c.weight() <= 0) {
      return absl::InvalidArgumentError(
          absl::StrCat(what, ": weight must be finite and > 0, got ", c.weight()));
    }
    spec.weight = c.weight();
  }
  spec.hard = c.hard();
  return spec;
}

ModelWeights WeightsFromProto(const v1::Weights& w) { return {w.mu_s(), w.mu_b(), w.mu_c()}; }

absl::Status CheckCoefficients(const google::protobuf::RepeatedField<double>& c,
                               const ServedBasis& basis) {
  if (c.size() != basis.basis->dimension()) {
    return absl::InvalidArgumentError(absl::StrCat("expected ", basis.basis->dimension(),
                                                   " coefficients (the basis dimension), got ",
                                                   c.size()));
  }
  for (int i = 0; i < c.size(); ++i) {
    if (!std::isfinite(c[i])) {
      return absl::InvalidArgumentError(absl::StrCat("coefficient ", i, " is not finite"));
    }
  }
  return absl::OkStatus();
}

// Lifts `x` at `faces` and writes them in `encoding` into `out` (values appended).
absl::Status LiftToValues(const ServedBasis& basis, const Eigen::VectorXd& x,
                          absl::Span<const int32_t> faces, ValueEncoding encoding,
                          google::protobuf::RepeatedField<float>* out) {
  const FieldType& type = basis.basis->type;
  std::vector<double> dofs(faces.size() * type.dofs_per_face());
  RETURN_IF_ERROR(LiftFaces(basis, x, faces, absl::MakeSpan(dofs)));
  const int32_t vpf = ValuesPerFace(type, encoding);
  const int old = out->size();
  out->Resize(old + static_cast<int>(faces.size()) * vpf, 0.0f);
  return DofsToValues(*basis.mesh, type, encoding, faces, dofs,
                      absl::MakeSpan(out->mutable_data() + old, faces.size() * vpf));
}

// --- reactors ---------------------------------------------------------------------------------

// Unary calls: the work runs on the compute pool and finishes the call from there.
class UnaryCall final : public grpc::ServerUnaryReactor {
 public:
  void OnCancel() override { cancelled_.store(true); }
  void OnDone() override { delete this; }
  const std::atomic<bool>* cancelled() const { return &cancelled_; }

 private:
  std::atomic<bool> cancelled_{false};
};

// `work(const std::atomic<bool>* cancel) -> absl::Status` runs on the pool (heavy work) or inline
// on the gRPC thread (bookkeeping that only takes a lock and copies a little).
template <typename Work>
grpc::ServerUnaryReactor* RunUnary(FieldService* service, grpc::CallbackServerContext* context,
                                   bool inline_work, Work work) {
  auto* call = new UnaryCall();
  if (absl::Status admit = service->Admit(context); !admit.ok()) {
    call->Finish(ToGrpcStatus(admit));
    return call;
  }
  if (inline_work) {
    call->Finish(ToGrpcStatus(Guarded([&] { return work(call->cancelled()); })));
    return call;
  }
  const bool submitted =
      service->pool()->Submit(Lane::kInteractive, [call, work = std::move(work)]() mutable {
        absl::Status status = call->cancelled()->load()
                                  ? absl::CancelledError("the call was cancelled before it started")
                                  : Guarded([&] { return work(call->cancelled()); });
        call->Finish(ToGrpcStatus(status));
      });
  if (!submitted) call->Finish(ToGrpcStatus(absl::UnavailableError("server is shutting down")));
  return call;
}

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

// UploadMesh: accumulates in-order chunks, then parses and registers on the pool.
class UploadReactor final : public grpc::ServerReadReactor<v1::UploadMeshRequest> {
 public:
  UploadReactor(FieldService* service, grpc::CallbackServerContext* context, v1::MeshInfo* response)
      : service_(service), response_(response) {
    if (absl::Status admit = service->Admit(context); !admit.ok()) {
      Finish(ToGrpcStatus(admit));
      return;
    }
    StartRead(&request_);
  }

  void OnReadDone(bool ok) override {
    if (!ok) {
      End();
      return;
    }
    if (absl::Status st = Accept(); !st.ok()) {
      Finish(ToGrpcStatus(st));
      return;
    }
    StartRead(&request_);
  }
  void OnCancel() override { cancelled_.store(true); }
  void OnDone() override { delete this; }

 private:
  absl::Status Accept() {
    const int64_t limit = service_->options().max_upload_bytes;
    if (!have_header_) {
      if (!request_.has_header()) {
        return absl::InvalidArgumentError("the first UploadMeshRequest must carry the header");
      }
      header_ = request_.header();
      have_header_ = true;
      if (header_.format() == v1::MESH_FORMAT_UNSPECIFIED) {
        absl::StatusOr<MeshFormat> f = MeshFormatFromPath(header_.name());
        if (!f.ok()) {
          return absl::InvalidArgumentError(
              absl::StrCat("header.format is unspecified and the name '", header_.name(),
                           "' has no .obj, .off or .ply extension"));
        }
        header_.set_format(*f == MeshFormat::kObj   ? v1::MESH_FORMAT_OBJ
                           : *f == MeshFormat::kOff ? v1::MESH_FORMAT_OFF
                                                    : v1::MESH_FORMAT_PLY);
      }
      if (header_.format() < v1::MESH_FORMAT_OBJ || header_.format() > v1::MESH_FORMAT_RAW) {
        return absl::InvalidArgumentError(
            absl::StrCat("unknown mesh format ", static_cast<int>(header_.format())));
      }
      if (header_.format() == v1::MESH_FORMAT_RAW) {
        constexpr int64_t kMaxElements = int64_t{1} << 27;
        if (header_.num_vertices() <= 0 || header_.num_faces() <= 0 ||
            header_.num_vertices() > kMaxElements || header_.num_faces() > kMaxElements) {
          return absl::InvalidArgumentError(
              absl::StrCat("raw upload needs 0 < num_vertices, num_faces <= ", kMaxElements,
                           "; got ", header_.num_vertices(), " and ", header_.num_faces()));
        }
        const int64_t expected = 24 * header_.num_vertices() + 12 * header_.num_faces();
        if (expected > limit) {
          return absl::ResourceExhaustedError(absl::StrCat(
              "raw mesh of ", expected, " bytes exceeds the upload limit of ", limit, " bytes"));
        }
      }
      if (header_.total_bytes() > static_cast<uint64_t>(limit)) {
        return absl::ResourceExhaustedError(absl::StrCat(
            "upload of ", header_.total_bytes(), " bytes exceeds the limit of ", limit, " bytes"));
      }
      if (header_.total_bytes() > 0) data_.reserve(header_.total_bytes());
    } else if (request_.has_header()) {
      return absl::InvalidArgumentError("only the first UploadMeshRequest may carry a header");
    }
    if (request_.offset() != data_.size()) {
      return absl::InvalidArgumentError(
          absl::StrCat("out-of-order chunk: offset ", request_.offset(), ", expected ",
                       data_.size(), " (chunks must arrive in order, without gaps)"));
    }
    if (static_cast<int64_t>(data_.size() + request_.data().size()) > limit) {
      return absl::ResourceExhaustedError(
          absl::StrCat("upload exceeds the limit of ", limit, " bytes"));
    }
    data_.append(request_.data());
    request_.Clear();
    return absl::OkStatus();
  }

  void End() {
    if (!have_header_) {
      Finish(ToGrpcStatus(absl::InvalidArgumentError("empty upload: no header was sent")));
      return;
    }
    if (header_.total_bytes() > 0 && header_.total_bytes() != data_.size()) {
      Finish(ToGrpcStatus(absl::InvalidArgumentError(
          absl::StrCat("upload ended after ", data_.size(), " bytes; the header announced ",
                       header_.total_bytes()))));
      return;
    }
    const bool submitted = service_->pool()->Submit(Lane::kInteractive, [this] {
      absl::Status status = cancelled_.load() ? absl::CancelledError("upload cancelled")
                                              : Guarded([this] { return Register(); });
      Finish(ToGrpcStatus(status));
    });
    if (!submitted) Finish(ToGrpcStatus(absl::UnavailableError("server is shutting down")));
  }

  absl::Status Register() {
    MeshReadResult parsed;
    if (header_.format() == v1::MESH_FORMAT_RAW) {
      const int64_t nv = header_.num_vertices(), nf = header_.num_faces();
      if (static_cast<int64_t>(data_.size()) != 24 * nv + 12 * nf) {
        return absl::InvalidArgumentError(absl::StrCat("raw upload has ", data_.size(), " bytes; ",
                                                       nv, " vertices and ", nf, " faces need ",
                                                       24 * nv + 12 * nf));
      }
      parsed.arrays.vertices.resize(nv, 3);
      parsed.arrays.faces.resize(nf, 3);
      std::memcpy(parsed.arrays.vertices.data(), data_.data(), 24 * nv);
      std::memcpy(parsed.arrays.faces.data(), data_.data() + 24 * nv, 12 * nf);
    } else {
      const MeshFormat format = header_.format() == v1::MESH_FORMAT_OBJ   ? MeshFormat::kObj
                                : header_.format() == v1::MESH_FORMAT_OFF ? MeshFormat::kOff
                                                                          : MeshFormat::kPly;
      ASSIGN_OR_RETURN(parsed, ReadMesh(data_, format));
    }
    std::string().swap(data_);  // the parsed arrays replace the bytes
    ASSIGN_OR_RETURN(MeshRecord record, service_->registry()->AddMesh(
                                            std::move(parsed.arrays), header_.name(),
                                            static_cast<int32_t>(parsed.polygons_triangulated)));
    MeshInfoFromRecord(record, service_->registry()->IsMeshLoaded(record.id), response_);
    return absl::OkStatus();
  }

  FieldService* const service_;
  v1::MeshInfo* const response_;
  v1::UploadMeshRequest request_;
  v1::UploadMeshHeader header_;
  bool have_header_ = false;
  std::string data_;
  std::atomic<bool> cancelled_{false};
};

// Server-streaming calls that produce chunks on the pool, one write at a time.
template <typename Message>
class ChunkWriter : public grpc::ServerWriteReactor<Message> {
 public:
  ChunkWriter(FieldService* service, grpc::CallbackServerContext* context) : service_(service) {
    admitted_ = service->Admit(context);
  }

  // Call once from the subclass constructor.
  void Begin() {
    if (!admitted_.ok()) {
      this->Finish(ToGrpcStatus(admitted_));
      return;
    }
    Schedule(true);
  }

  void OnWriteDone(bool ok) override {
    if (!ok) {
      this->Finish(ToGrpcStatus(absl::CancelledError("the client went away")));
      return;
    }
    Schedule(false);
  }
  void OnCancel() override { cancelled_.store(true); }
  void OnDone() override { delete this; }

 protected:
  // On the pool: Prepare() once, then Next() for each chunk. Next() fills `chunk` and returns
  // true, or returns false when there is nothing more to send.
  virtual absl::Status Prepare(const std::atomic<bool>* cancel) = 0;
  virtual absl::StatusOr<bool> Next(Message* chunk) = 0;

  FieldService* service() const { return service_; }

 private:
  void Schedule(bool first) {
    const bool submitted = service_->pool()->Submit(Lane::kInteractive, [this, first] {
      bool has_chunk = false;
      absl::Status status = Guarded([&]() -> absl::Status {
        if (cancelled_.load()) return absl::CancelledError("cancelled");
        if (first) RETURN_IF_ERROR(Prepare(&cancelled_));
        chunk_.Clear();
        ASSIGN_OR_RETURN(has_chunk, Next(&chunk_));
        return absl::OkStatus();
      });
      if (!status.ok()) {
        this->Finish(ToGrpcStatus(status));
      } else if (has_chunk) {
        this->StartWrite(&chunk_);
      } else {
        this->Finish(grpc::Status::OK);
      }
    });
    if (!submitted) {
      this->Finish(ToGrpcStatus(absl::UnavailableError("server is shutting down")));
    }
  }

  FieldService* const service_;
  absl::Status admitted_;
  std::atomic<bool> cancelled_{false};
  Message chunk_;
};

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
    RETURN_IF_ERROR(CheckCoefficients(request_.coefficients(), *basis_));
    ASSIGN_OR_RETURN(encoding_, EncodingFromProto(request_.encoding()));
    if (request_.chunk_faces() < 0) {
      return absl::InvalidArgumentError("chunk_faces must not be negative");
    }
    chunk_ = request_.chunk_faces() == 0 ? kDefaultChunkFaces
                                         : std::min(request_.chunk_faces(), kMaxChunkFaces);
    RETURN_IF_ERROR(CheckFaces(request_.faces(), basis_->mesh->num_faces(), "lift"));
    x_ = Eigen::Map<const Eigen::VectorXd>(request_.coefficients().data(),
                                           request_.coefficients().size());
    subset_ = !request_.faces().empty();
    total_ = subset_ ? request_.faces().size() : basis_->mesh->num_faces();
    return absl::OkStatus();
  }

  absl::StatusOr<bool> Next(v1::FieldChunk* out) override {
    if (next_ >= total_ && sent_any_) return false;
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
    return true;
  }

  const v1::LiftRequest request_;
  std::shared_ptr<const ServedBasis> basis_;
  Eigen::VectorXd x_;
  ValueEncoding encoding_ = ValueEncoding::kDof;
  std::vector<int32_t> faces_;
  bool subset_ = false;
  int32_t chunk_ = kDefaultChunkFaces;
  int32_t total_ = 0;
  int32_t next_ = 0;
  bool sent_any_ = false;
};

// BuildBasis: watches a (possibly shared) build job and streams its progress. The job lives on
// if this stream goes away.
class BuildWatcher final : public grpc::ServerWriteReactor<v1::BuildBasisProgress>,
                           public RefCounted {
 public:
  BuildWatcher(FieldService* service, grpc::CallbackServerContext* context,
               const v1::BuildBasisRequest& request)
      : registry_(service->registry()) {
    absl::Status st = service->Admit(context);
    absl::StatusOr<Registry::StartedBuild> started = Registry::StartedBuild{};
    if (st.ok()) {
      started = Start(service, request);
    } else {
      started = st;
    }
    if (!started.ok()) {
      finished_ = true;
      Finish(ToGrpcStatus(started.status()));
      return;
    }
    if (started->existing.has_value()) {
      finished_ = true;
      msg_.set_basis_id(started->existing->id);
      msg_.set_phase(v1::BUILD_PHASE_DONE);
      msg_.set_fraction(1.0);
      BasisInfoFromRecord(*started->existing, msg_.mutable_basis());
      auto status = service->registry()->GetBasisStatus(started->existing->id);
      if (status.ok()) BasisInfoFromStatus(*status, msg_.mutable_basis());
      StartWriteAndFinish(&msg_, grpc::WriteOptions(), grpc::Status::OK);
      return;
    }
    job_ = started->job;
    joined_ = started->joined;
    // The job calls the listener from its own thread, possibly after this stream is done: the
    // gate tells it whether the watcher still exists, and a reference keeps it alive meanwhile.
    gate_ = std::make_shared<Gate>();
    gate_->watcher = this;
    token_ = job_->Subscribe([gate = gate_] {
      BuildWatcher* watcher;
      {
        std::lock_guard<std::mutex> lock(gate->mu);
        watcher = gate->watcher;
        if (watcher == nullptr) return;
        watcher->AddRef();
      }
      watcher->Pump();
      watcher->DropRef();
    });
    Pump();  // the current state (often QUEUED) right away, with the basis id
  }

  void OnWriteDone(bool ok) override {
    bool again = false, finish = false;
    {
      std::lock_guard<std::mutex> lock(mu_);
      writing_ = false;
      if (!ok || cancelled_) {
        finish = !finished_;
        finished_ = true;
      } else {
        again = pending_;
        pending_ = false;
      }
    }
    if (finish) Finish(ToGrpcStatus(absl::CancelledError("the client went away")));
    if (again) Pump();
  }

  void OnCancel() override {
    bool finish = false;
    {
      std::lock_guard<std::mutex> lock(mu_);
      cancelled_ = true;
      // With a write in flight, OnWriteDone finishes instead.
      if (!finished_ && !writing_) {
        finished_ = true;
        finish = true;
      }
    }
    if (finish) Finish(ToGrpcStatus(absl::CancelledError("cancelled by the client")));
  }

  void OnDone() override {
    if (job_ != nullptr) {
      job_->Unsubscribe(token_);
      std::lock_guard<std::mutex> lock(gate_->mu);
      gate_->watcher = nullptr;
    }
    DropRef();
  }

 private:
  struct Gate {
    std::mutex mu;
    BuildWatcher* watcher = nullptr;
  };

  static absl::StatusOr<Registry::StartedBuild> Start(FieldService* service,
                                                      const v1::BuildBasisRequest& request) {
    BuildRequest build;
    build.key.mesh_id = request.mesh_id();
    ASSIGN_OR_RETURN(build.key.field, FieldTypeFromProto(request.field()));
    build.key.dimension = request.dimension();
    build.key.sigma = request.has_sigma() ? request.sigma() : 40.0;
    build.key.fields_per_region = request.fields_per_region();
    build.key.seed = request.seed();
    build.key.coarse_dimension = request.coarse_dimension();
    build.face_weights = Eigen::Map<const Eigen::VectorXd>(request.face_weights().data(),
                                                           request.face_weights().size());
    return service->registry()->StartBuild(std::move(build));
  }

  // Sends the job's current state unless a write is in flight (then once it completes).
  void Pump() {
    BuildJob::Progress progress = job_->progress();
    bool final_ok = false, final_error = false;
    {
      std::lock_guard<std::mutex> lock(mu_);
      if (finished_ || cancelled_) return;
      if (writing_) {
        pending_ = true;
        return;
      }
      const v1::BuildPhase phase = PhaseToProto(progress.stage);
      if (!progress.finished && sent_any_ && phase == msg_.phase() &&
          std::abs(progress.fraction - msg_.fraction()) < 0.005) {
        return;
      }
      msg_.Clear();
      msg_.set_basis_id(job_->basis_id());
      msg_.set_phase(phase);
      msg_.set_fraction(progress.fraction);
      msg_.set_joined(joined_);
      sent_any_ = true;
      if (progress.finished) {
        finished_ = true;
        if (progress.status.ok()) {
          final_ok = true;
          absl::StatusOr<BasisStatus> s = registry_->GetBasisStatus(progress.record.id);
          if (s.ok()) {
            BasisInfoFromStatus(*s, msg_.mutable_basis());
          } else {  // deleted in the meantime: report what was built
            BasisInfoFromRecord(progress.record, msg_.mutable_basis());
          }
        } else {
          final_error = true;
        }
      }
      writing_ = !final_error;
    }
    if (final_ok) {
      StartWriteAndFinish(&msg_, grpc::WriteOptions(), grpc::Status::OK);
    } else if (final_error) {
      Finish(ToGrpcStatus(progress.status));
    } else {
      StartWrite(&msg_);
    }
  }

  Registry* const registry_;
  std::shared_ptr<BuildJob> job_;
  std::shared_ptr<Gate> gate_;
  uint64_t token_ = 0;
  bool joined_ = false;
  std::mutex mu_;
  bool writing_ = false;
  bool pending_ = false;
  bool finished_ = false;
  bool cancelled_ = false;
  bool sent_any_ = false;
  v1::BuildBasisProgress msg_;
};

// Design: one session per stream. Strictly sequential: read an edit, process it on the pool,
// write the answer, read the next one.
class DesignReactor final : public grpc::ServerBidiReactor<v1::DesignRequest, v1::DesignUpdate>,
                            public DrainableStream {
 public:
  DesignReactor(FieldService* service, grpc::CallbackServerContext* context) : service_(service) {
    if (absl::Status admit = service->Admit(context); !admit.ok()) {
      finish_sent_ = true;
      Finish(ToGrpcStatus(admit));
      return;
    }
    service_->RegisterStream(this);
    registered_ = true;
    reading_ = true;
    StartRead(&request_);
  }

  void OnReadDone(bool ok) override {
    received_ = Clock::now();
    bool finish = false;
    {
      std::lock_guard<std::mutex> lock(mu_);
      reading_ = false;
      if (!ok) {
        // The client closed its side (or went away): end the session.
        finish = !finish_sent_;
        finish_sent_ = true;
      } else if (finish_sent_) {
        // Drain() finished the stream while this read was in flight: the message is dropped
        // (the client gets UNAVAILABLE), and no work may be queued for a finishing reactor.
        return;
      } else {
        working_ = true;
      }
    }
    if (finish) {
      Finish(grpc::Status::OK);
      return;
    }
    // The queued task holds a reference: OnDone (and deletion) cannot overtake it.
    Ref();
    const bool submitted = service_->pool()->Submit(Lane::kInteractive, [this] {
      Work();
      Unref();
    });
    if (!submitted) {
      {
        std::lock_guard<std::mutex> lock(mu_);
        working_ = false;
        finish_sent_ = true;
      }
      Finish(ToGrpcStatus(absl::UnavailableError("server is shutting down")));
      Unref();
    }
  }

  void OnWriteDone(bool ok) override {
    enum { kRead, kFinishCancelled, kFinishDrain, kNothing } next = kNothing;
    {
      std::lock_guard<std::mutex> lock(mu_);
      writing_ = false;
      if (finish_sent_) {
        next = kNothing;
      } else if (!ok) {
        next = kFinishCancelled;
        finish_sent_ = true;
      } else if (drain_requested_) {
        next = kFinishDrain;
        finish_sent_ = true;
      } else {
        next = kRead;
        reading_ = true;
      }
    }
    switch (next) {
      case kRead:
        StartRead(&request_);
        break;
      case kFinishCancelled:
        Finish(ToGrpcStatus(absl::CancelledError("the client went away")));
        break;
      case kFinishDrain:
        Finish(ToGrpcStatus(absl::UnavailableError("server is shutting down")));
        break;
      case kNothing:
        break;
    }
  }

  void OnCancel() override { cancelled_.store(true); }

  void OnDone() override {
    if (registered_) service_->UnregisterStream(this);
    Unref();
  }

  void Drain() override {
    bool finish = false;
    {
      std::lock_guard<std::mutex> lock(mu_);
      drain_requested_ = true;
      if (!working_ && !writing_ && !finish_sent_) {
        finish = true;
        finish_sent_ = true;
      }
    }
    if (finish) Finish(ToGrpcStatus(absl::UnavailableError("server is shutting down")));
  }
  void Ref() override { refs_.fetch_add(1); }
  void Unref() override {
    if (refs_.fetch_sub(1) == 1) delete this;
  }

 private:
  void Work() {
    update_.Clear();
    absl::Status status = cancelled_.load() ? absl::CancelledError("cancelled")
                                            : Guarded([this] { return Process(); });
    bool finish = false;
    {
      std::lock_guard<std::mutex> lock(mu_);
      working_ = false;
      if (!status.ok()) {
        finish = !finish_sent_;
        finish_sent_ = true;
      } else {
        writing_ = true;
      }
    }
    if (!status.ok()) {
      if (finish) Finish(ToGrpcStatus(status));
      return;
    }
    update_.mutable_timings()->set_total_ms(MsSince(received_));
    StartWrite(&update_);
  }

  absl::Status Process() {
    const v1::DesignRequest& r = request_;
    update_.set_seq(r.seq());
    if (r.edit_case() == v1::DesignRequest::EDIT_NOT_SET) {
      return absl::InvalidArgumentError("a DesignRequest must carry one edit");
    }
    InteractiveSession::EditResult result;
    if (r.edit_case() == v1::DesignRequest::kOpen) {
      if (session_ != nullptr) {
        return absl::FailedPreconditionError("the session is already open");
      }
      ASSIGN_OR_RETURN(basis_, service_->registry()->GetBasis(r.open().basis_id()));
      const ModelWeights weights = WeightsFromProto(r.open().weights());
      RETURN_IF_ERROR(ValidateWeights(weights));
      RETURN_IF_ERROR(SetWatch(r.open().watch_faces(), r.open().watch_encoding()));
      ASSIGN_OR_RETURN(
          OpenSessionResult opened,
          OpenDesignSession(basis_, weights, service_->options().design_verify_interval));
      session_ = std::move(opened.session);
      result = opened.timings;
    } else {
      if (session_ == nullptr) {
        return absl::FailedPreconditionError("the first message of a session must be 'open'");
      }
      const TriangleMesh& mesh = *basis_->mesh;
      const FieldType& type = basis_->basis->type;
      switch (r.edit_case()) {
        case v1::DesignRequest::kAdd: {
          if (session_->num_constraints() >= kMaxConstraints) {
            return absl::ResourceExhaustedError("too many constraints in this session");
          }
          ASSIGN_OR_RETURN(ConstraintSpec spec,
                           ConstraintFromProto(mesh, type, r.add().constraint(),
                                               absl::StrCat("add id ", r.add().id())));
          ASSIGN_OR_RETURN(result, session_->Add(r.add().id(), spec));
          break;
        }
        case v1::DesignRequest::kMove: {
          ASSIGN_OR_RETURN(
              Eigen::Vector3d dofs,
              ConstraintDofs(mesh, type, r.move().face(), r.move().value(), r.move().encoding(),
                             absl::StrCat("move id ", r.move().id())));
          ASSIGN_OR_RETURN(result, session_->Move(r.move().id(), r.move().face(), dofs));
          break;
        }
        case v1::DesignRequest::kRemove: {
          ASSIGN_OR_RETURN(result, session_->Remove(r.remove().id()));
          break;
        }
        case v1::DesignRequest::kSetWeights: {
          const ModelWeights weights = WeightsFromProto(r.set_weights());
          RETURN_IF_ERROR(ValidateWeights(weights));
          ASSIGN_OR_RETURN(result, session_->SetWeights(weights));
          break;
        }
        case v1::DesignRequest::kWatch:
          RETURN_IF_ERROR(SetWatch(r.watch().faces(), r.watch().encoding()));
          break;
        case v1::DesignRequest::kOpen:
        case v1::DesignRequest::EDIT_NOT_SET:
          return absl::InternalError("unreachable: handled above");
      }
    }
    const Eigen::VectorXd& x = session_->coefficients();
    update_.mutable_coefficients()->Add(x.data(), x.data() + x.size());
    const auto lift_start = Clock::now();
    update_.mutable_watched()->set_encoding(EncodingToProto(watch_encoding_));
    update_.mutable_watched()->mutable_faces()->Add(watch_.begin(), watch_.end());
    RETURN_IF_ERROR(LiftToValues(*basis_, x, watch_, watch_encoding_,
                                 update_.mutable_watched()->mutable_values()));
    v1::DesignTimings* t = update_.mutable_timings();
    t->set_edit_ms(result.edit_ms);
    t->set_lift_ms(MsSince(lift_start));
    t->set_refactorized(result.refactorized);
    update_.set_num_constraints(session_->num_constraints());
    update_.set_num_hard_constraints(session_->num_hard_constraints());
    update_.set_basis_id(basis_->record.id);
    return absl::OkStatus();
  }

  absl::Status SetWatch(const google::protobuf::RepeatedField<int32_t>& faces, int encoding) {
    RETURN_IF_ERROR(CheckFaces(faces, basis_->mesh->num_faces(), "watch"));
    ASSIGN_OR_RETURN(watch_encoding_, EncodingFromProto(encoding));
    const int64_t bytes =
        int64_t{faces.size()} * ValuesPerFace(basis_->basis->type, watch_encoding_) * 4;
    if (bytes > service_->options().max_message_bytes / 2) {
      return absl::ResourceExhaustedError(
          absl::StrCat("watching ", faces.size(), " faces exceeds the message size limit"));
    }
    watch_.assign(faces.begin(), faces.end());
    return absl::OkStatus();
  }

  FieldService* const service_;
  bool registered_ = false;
  std::atomic<int> refs_{1};
  std::atomic<bool> cancelled_{false};
  std::mutex mu_;
  bool reading_ = false;
  bool working_ = false;
  bool writing_ = false;
  bool finish_sent_ = false;
  bool drain_requested_ = false;
  Clock::time_point received_;
  v1::DesignRequest request_;
  v1::DesignUpdate update_;
  std::shared_ptr<const ServedBasis> basis_;
  std::unique_ptr<InteractiveSession> session_;
  std::vector<int32_t> watch_;
  ValueEncoding watch_encoding_ = ValueEncoding::kDof;
};

// LoadMesh's path rule: relative, and inside the data root after resolving symlinks.
absl::StatusOr<std::string> ResolveDataPath(const std::string& root, const std::string& path) {
  namespace fs = std::filesystem;
  if (root.empty()) {
    return absl::FailedPreconditionError(
        "LoadMesh is disabled: the server was started without --data-root");
  }
  if (path.empty()) return absl::InvalidArgumentError("path must not be empty");
  if (path.find('\0') != std::string::npos) {
    return absl::InvalidArgumentError("path must not contain NUL bytes");
  }
  const fs::path rel(path);
  if (rel.is_absolute()) {
    return absl::InvalidArgumentError(
        absl::StrCat("path '", path, "' must be relative to the data root"));
  }
  for (const auto& part : rel) {
    if (part == "..") {
      return absl::InvalidArgumentError(
          absl::StrCat("path '", path, "' must not contain '..' components"));
    }
  }
  std::error_code ec;
  const fs::path canonical_root = fs::canonical(root, ec);
  if (ec)
    return absl::FailedPreconditionError(absl::StrCat("data root ", root, ": ", ec.message()));
  const fs::path full = fs::canonical(canonical_root / rel, ec);
  if (ec) return absl::NotFoundError(absl::StrCat("no file '", path, "' under the data root"));
  // Symlinks may still point outside: compare resolved paths component by component.
  auto r = canonical_root.begin();
  auto f = full.begin();
  for (; r != canonical_root.end(); ++r, ++f) {
    if (f == full.end() || *r != *f) {
      return absl::PermissionDeniedError(
          absl::StrCat("path '", path, "' resolves outside the data root"));
    }
  }
  if (!fs::is_regular_file(full, ec)) {
    return absl::InvalidArgumentError(absl::StrCat("'", path, "' is not a regular file"));
  }
  return full.string();
}

}  // namespace

FieldService::FieldService(Registry* registry, ComputePool* pool, ServiceOptions options)
    : registry_(registry), pool_(pool), options_(std::move(options)) {}

absl::Status FieldService::Admit(grpc::CallbackServerContext* context) const {
  if (draining_.load()) return absl::UnavailableError("server is shutting down");
  if (options_.auth_token.empty()) return absl::OkStatus();
  const auto& metadata = context->client_metadata();
  auto it = metadata.find("authorization");
  if (it == metadata.end()) {
    return absl::UnauthenticatedError("missing 'authorization: Bearer <token>' metadata");
  }
  const std::string_view value(it->second.data(), it->second.size());
  const std::string expected = "Bearer " + options_.auth_token;
  // Constant-time comparison: the time taken must not reveal how much of the token matched.
  unsigned char diff = value.size() == expected.size() ? 0 : 1;
  for (size_t i = 0; i < expected.size(); ++i) {
    diff |= static_cast<unsigned char>(expected[i] ^ (i < value.size() ? value[i] : 0));
  }
  if (diff != 0) return absl::UnauthenticatedError("invalid token");
  return absl::OkStatus();
}

void FieldService::BeginDrain() {
  draining_.store(true);
  std::vector<DrainableStream*> streams;
  {
    std::lock_guard<std::mutex> lock(streams_mu_);
    for (DrainableStream* s : streams_) {
      s->Ref();
      streams.push_back(s);
    }
  }
  for (DrainableStream* s : streams) {
    s->Drain();
    s->Unref();
  }
}

void FieldService::RegisterStream(DrainableStream* stream) {
  std::lock_guard<std::mutex> lock(streams_mu_);
  streams_.insert(stream);
}

void FieldService::UnregisterStream(DrainableStream* stream) {
  std::lock_guard<std::mutex> lock(streams_mu_);
  streams_.erase(stream);
}

// --- meshes ------------------------------------------------------------------------------------

grpc::ServerReadReactor<v1::UploadMeshRequest>* FieldService::UploadMesh(
    grpc::CallbackServerContext* context, v1::MeshInfo* response) {
  return new UploadReactor(this, context, response);
}

grpc::ServerUnaryReactor* FieldService::LoadMesh(grpc::CallbackServerContext* context,
                                                 const v1::LoadMeshRequest* request,
                                                 v1::MeshInfo* response) {
  return RunUnary(this, context, false, [this, request, response](const std::atomic<bool>*) {
    ASSIGN_OR_RETURN(std::string path, ResolveDataPath(options_.data_root, request->path()));
    ASSIGN_OR_RETURN(MeshReadResult parsed, ReadMeshFile(path));
    const std::string name = request->name().empty() ? request->path() : request->name();
    ASSIGN_OR_RETURN(MeshRecord record,
                     registry_->AddMesh(std::move(parsed.arrays), name,
                                        static_cast<int32_t>(parsed.polygons_triangulated)));
    MeshInfoFromRecord(record, registry_->IsMeshLoaded(record.id), response);
    return absl::OkStatus();
  });
}

grpc::ServerUnaryReactor* FieldService::GetMesh(grpc::CallbackServerContext* context,
                                                const v1::GetMeshRequest* request,
                                                v1::MeshInfo* response) {
  return RunUnary(this, context, true, [this, request, response](const std::atomic<bool>*) {
    ASSIGN_OR_RETURN(MeshRecord record, registry_->GetMeshRecord(request->mesh_id()));
    MeshInfoFromRecord(record, registry_->IsMeshLoaded(record.id), response);
    return absl::OkStatus();
  });
}

grpc::ServerUnaryReactor* FieldService::ListMeshes(grpc::CallbackServerContext* context,
                                                   const v1::ListMeshesRequest*,
                                                   v1::ListMeshesResponse* response) {
  return RunUnary(this, context, true, [this, response](const std::atomic<bool>*) {
    for (const MeshRecord& r : registry_->ListMeshes()) {
      MeshInfoFromRecord(r, registry_->IsMeshLoaded(r.id), response->add_meshes());
    }
    return absl::OkStatus();
  });
}

grpc::ServerUnaryReactor* FieldService::DeleteMesh(grpc::CallbackServerContext* context,
                                                   const v1::DeleteMeshRequest* request,
                                                   v1::DeleteMeshResponse* response) {
  return RunUnary(this, context, false, [this, request, response](const std::atomic<bool>*) {
    ASSIGN_OR_RETURN(std::vector<std::string> deleted,
                     registry_->DeleteMesh(request->mesh_id(), request->cascade()));
    for (std::string& id : deleted) response->add_deleted_basis_ids(std::move(id));
    return absl::OkStatus();
  });
}

grpc::ServerWriteReactor<v1::MeshGeometryChunk>* FieldService::GetMeshGeometry(
    grpc::CallbackServerContext* context, const v1::GetMeshGeometryRequest* request) {
  return new GeometryWriter(this, context, *request);
}

// --- bases -------------------------------------------------------------------------------------

grpc::ServerWriteReactor<v1::BuildBasisProgress>* FieldService::BuildBasis(
    grpc::CallbackServerContext* context, const v1::BuildBasisRequest* request) {
  return new BuildWatcher(this, context, *request);
}

grpc::ServerUnaryReactor* FieldService::CancelBuild(grpc::CallbackServerContext* context,
                                                    const v1::CancelBuildRequest* request,
                                                    v1::CancelBuildResponse*) {
  return RunUnary(this, context, true, [this, request](const std::atomic<bool>*) {
    return registry_->CancelBuild(request->basis_id());
  });
}

grpc::ServerUnaryReactor* FieldService::GetBasis(grpc::CallbackServerContext* context,
                                                 const v1::GetBasisRequest* request,
                                                 v1::BasisInfo* response) {
  return RunUnary(this, context, true, [this, request, response](const std::atomic<bool>*) {
    ASSIGN_OR_RETURN(BasisStatus status, registry_->GetBasisStatus(request->basis_id()));
    BasisInfoFromStatus(status, response);
    return absl::OkStatus();
  });
}

grpc::ServerUnaryReactor* FieldService::ListBases(grpc::CallbackServerContext* context,
                                                  const v1::ListBasesRequest* request,
                                                  v1::ListBasesResponse* response) {
  return RunUnary(this, context, true, [this, request, response](const std::atomic<bool>*) {
    for (const BasisStatus& s : registry_->ListBases(request->mesh_id())) {
      BasisInfoFromStatus(s, response->add_bases());
    }
    return absl::OkStatus();
  });
}

grpc::ServerUnaryReactor* FieldService::DeleteBasis(grpc::CallbackServerContext* context,
                                                    const v1::DeleteBasisRequest* request,
                                                    v1::DeleteBasisResponse*) {
  return RunUnary(this, context, false, [this, request](const std::atomic<bool>*) {
    return registry_->DeleteBasis(request->basis_id());
  });
}

// --- subspace methods ----------------------------------------------------------------------------

grpc::ServerUnaryReactor* FieldService::Project(grpc::CallbackServerContext* context,
                                                const v1::ProjectRequest* request,
                                                v1::ProjectResponse* response) {
  return RunUnary(
      this, context, false,
      [this, request, response](const std::atomic<bool>* cancel) -> absl::Status {
        const auto start = Clock::now();
        ASSIGN_OR_RETURN(std::shared_ptr<const ServedBasis> basis,
                         registry_->GetBasis(request->basis_id()));
        const TriangleMesh& mesh = *basis->mesh;
        const FieldType& type = basis->basis->type;
        const v1::FieldValues& field = request->field();
        if (!field.faces().empty()) {
          return absl::InvalidArgumentError(
              "Project takes a field on all faces: leave field.faces empty");
        }
        ASSIGN_OR_RETURN(ValueEncoding encoding, EncodingFromProto(field.encoding()));
        const int64_t vpf = ValuesPerFace(type, encoding);
        if (field.values().size() != vpf * mesh.num_faces()) {
          return absl::InvalidArgumentError(absl::StrCat(
              "field has ", field.values().size(), " values; ", mesh.num_faces(), " faces x ", vpf,
              " values per face = ", vpf * mesh.num_faces(), " expected"));
        }
        std::vector<double> values(field.values().begin(), field.values().end());
        std::vector<int32_t> faces(mesh.num_faces());
        std::iota(faces.begin(), faces.end(), 0);
        Eigen::VectorXd X(int64_t{type.dofs_per_face()} * mesh.num_faces());
        RETURN_IF_ERROR(
            ValuesToDofs(mesh, type, encoding, faces, values, absl::MakeSpan(X.data(), X.size())));
        ASSIGN_OR_RETURN(ProjectResult result, ProjectField(*basis, X, cancel));
        response->mutable_coefficients()->Add(
            result.coefficients.data(), result.coefficients.data() + result.coefficients.size());
        response->set_relative_error(result.relative_error);
        response->set_seconds(std::chrono::duration<double>(Clock::now() - start).count());
        return absl::OkStatus();
      });
}

grpc::ServerUnaryReactor* FieldService::Solve(grpc::CallbackServerContext* context,
                                              const v1::SolveRequest* request,
                                              v1::SolveResponse* response) {
  return RunUnary(
      this, context, false,
      [this, request, response](const std::atomic<bool>* cancel) -> absl::Status {
        const auto start = Clock::now();
        ASSIGN_OR_RETURN(std::shared_ptr<const ServedBasis> basis,
                         registry_->GetBasis(request->basis_id()));
        const ModelWeights weights = WeightsFromProto(request->weights());
        RETURN_IF_ERROR(ValidateWeights(weights));
        if (request->constraints_size() > kMaxConstraints) {
          return absl::ResourceExhaustedError(
              absl::StrCat("at most ", kMaxConstraints, " constraints per request"));
        }
        std::vector<ConstraintSpec> constraints;
        constraints.reserve(request->constraints_size());
        for (int i = 0; i < request->constraints_size(); ++i) {
          ASSIGN_OR_RETURN(
              ConstraintSpec spec,
              ConstraintFromProto(*basis->mesh, basis->basis->type, request->constraints(i),
                                  absl::StrCat("constraint ", i)));
          constraints.push_back(spec);
        }
        ASSIGN_OR_RETURN(ValueEncoding encoding, EncodingFromProto(request->field_encoding()));
        if (request->return_field()) {
          const int64_t bytes =
              int64_t{4} * ValuesPerFace(basis->basis->type, encoding) * basis->mesh->num_faces();
          if (bytes > options_.max_message_bytes - (int64_t{1} << 20)) {
            return absl::ResourceExhaustedError(absl::StrCat(
                "the lifted field (", bytes, " bytes) exceeds the message size limit; use Lift"));
          }
        }
        ASSIGN_OR_RETURN(SolveResult result, SolveModel(*basis, weights, constraints, cancel));
        response->mutable_coefficients()->Add(
            result.coefficients.data(), result.coefficients.data() + result.coefficients.size());
        double lift_ms = 0;
        if (request->return_field()) {
          const auto lift_start = Clock::now();
          std::vector<int32_t> faces(basis->mesh->num_faces());
          std::iota(faces.begin(), faces.end(), 0);
          response->mutable_field()->set_encoding(EncodingToProto(encoding));
          RETURN_IF_ERROR(LiftToValues(*basis, result.coefficients, faces, encoding,
                                       response->mutable_field()->mutable_values()));
          lift_ms = MsSince(lift_start);
        }
        v1::SolveTimings* t = response->mutable_timings();
        t->set_solve_ms(result.solve_ms);
        t->set_lift_ms(lift_ms);
        t->set_total_ms(MsSince(start));
        return absl::OkStatus();
      });
}

grpc::ServerWriteReactor<v1::FieldChunk>* FieldService::Lift(grpc::CallbackServerContext* context,
                                                             const v1::LiftRequest* request) {
  return new LiftWriter(this, context, *request);
}

grpc::ServerUnaryReactor* FieldService::Eigenfields(grpc::CallbackServerContext* context,
                                                    const v1::EigenfieldsRequest* request,
                                                    v1::EigenfieldsResponse* response) {
  return RunUnary(
      this, context, false,
      [this, request, response](const std::atomic<bool>* cancel) -> absl::Status {
        const auto start = Clock::now();
        ASSIGN_OR_RETURN(std::shared_ptr<const ServedBasis> basis,
                         registry_->GetBasis(request->basis_id()));
        const int32_t d = basis->basis->dimension();
        if (request->count() < 1 || request->count() > d) {
          return absl::InvalidArgumentError(absl::StrCat(
              "count must be in [1, ", d, "] (the basis dimension), got ", request->count()));
        }
        if (int64_t{8} * d * request->count() > options_.max_message_bytes - (int64_t{1} << 20)) {
          return absl::ResourceExhaustedError(
              "count x dimension coefficients exceed the message size limit");
        }
        ASSIGN_OR_RETURN(ReducedEigenfieldsResult result,
                         ReducedEigenfields(*basis, request->count(), cancel));
        response->mutable_eigenvalues()->Add(result.eigenvalues.data(),
                                             result.eigenvalues.data() + result.eigenvalues.size());
        for (Eigen::Index j = 0; j < result.coefficients.cols(); ++j) {
          const double* col = result.coefficients.col(j).data();
          response->mutable_coefficients()->Add(col, col + result.coefficients.rows());
        }
        response->set_dimension(d);
        response->set_seconds(std::chrono::duration<double>(Clock::now() - start).count());
        return absl::OkStatus();
      });
}

grpc::ServerBidiReactor<v1::DesignRequest, v1::DesignUpdate>* FieldService::Design(
    grpc::CallbackServerContext* context) {
  return new DesignReactor(this, context);
}

}  // namespace fieldspace::server
