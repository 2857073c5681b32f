#include "client/field_client.h"

#include <algorithm>
#include <bit>
#include <filesystem>
#include <fstream>
#include <thread>
#include <utility>

#include "absl/strings/ascii.h"
#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "core/common/file_util.h"
#include "core/common/status_macros.h"
#include "grpc/health/v1/health.grpc.pb.h"

namespace fieldspace::client {
namespace {

namespace v1 = ::fieldspace::v1;

// The one place where a grpc::Status becomes an absl::Status: the codes share their numbering.
absl::Status FromGrpc(const grpc::Status& status) {
  if (status.ok()) return absl::OkStatus();
  return absl::Status(static_cast<absl::StatusCode>(status.error_code()), status.error_message());
}

// Reads a server stream to its end; `on_message` sees every message.
template <typename Message, typename OnMessage>
absl::Status ReadAll(grpc::ClientReader<Message>& reader, OnMessage on_message) {
  Message message;
  while (reader.Read(&message)) on_message(message);
  return FromGrpc(reader.Finish());
}

constexpr std::chrono::seconds kHealthTimeout(10);

// The PEM file `path` (`what` names it in messages), read and checked for a PEM block.
absl::StatusOr<std::string> ReadPemFile(const std::string& what, const std::string& path) {
  absl::StatusOr<std::string> pem = ReadFileToString(path, int64_t{1} << 20);
  if (!pem.ok()) {
    return absl::InvalidArgumentError(
        absl::StrCat(what, " ", path, ": cannot read it: ", pem.status().message()));
  }
  if (!absl::StrContains(*pem, "-----BEGIN ")) {
    return absl::InvalidArgumentError(absl::StrCat(what, " ", path, ": not a PEM file"));
  }
  return pem;
}

// Plaintext without options.tls; otherwise TLS with its files.
absl::StatusOr<std::shared_ptr<grpc::ChannelCredentials>> ChannelCredentials(
    const FieldClientOptions& options) {
  if (!options.tls) return grpc::InsecureChannelCredentials();
  const ClientTlsOptions& tls = *options.tls;
  if (tls.cert_file.empty() != tls.key_file.empty()) {
    return absl::InvalidArgumentError(
        "a TLS client certificate needs its key and the other way round (--tls-cert and "
        "--tls-key)");
  }
  grpc::SslCredentialsOptions ssl;
  if (!tls.ca_file.empty()) {
    ASSIGN_OR_RETURN(ssl.pem_root_certs, ReadPemFile("TLS CA file", tls.ca_file));
  }
  if (!tls.cert_file.empty()) {
    ASSIGN_OR_RETURN(ssl.pem_cert_chain, ReadPemFile("TLS certificate", tls.cert_file));
    ASSIGN_OR_RETURN(ssl.pem_private_key, ReadPemFile("TLS key", tls.key_file));
  }
  return grpc::SslCredentials(ssl);
}

}  // namespace

v1::UploadMeshHeader MeshFileHeader(const std::string& path, const std::string& name) {
  const std::filesystem::path p(path);
  v1::UploadMeshHeader header;
  header.set_name(name.empty() ? p.filename().string() : name);
  const std::string ext = absl::AsciiStrToLower(p.extension().string());
  header.set_format(ext == ".obj"   ? v1::MESH_FORMAT_OBJ
                    : ext == ".off" ? v1::MESH_FORMAT_OFF
                    : ext == ".ply" ? v1::MESH_FORMAT_PLY
                                    : v1::MESH_FORMAT_UNSPECIFIED);
  std::error_code ec;
  const uintmax_t size = std::filesystem::file_size(p, ec);
  if (!ec) header.set_total_bytes(size);
  return header;
}

absl::StatusOr<std::unique_ptr<FieldClient>> FieldClient::Create(FieldClientOptions options) {
  if (options.address.empty()) {
    return absl::InvalidArgumentError("FieldClient needs a server address (HOST:PORT)");
  }
  if (options.upload_chunk_bytes == 0) {
    return absl::InvalidArgumentError("FieldClient upload_chunk_bytes must be positive");
  }
  ASSIGN_OR_RETURN(std::shared_ptr<grpc::ChannelCredentials> credentials,
                   ChannelCredentials(options));
  return std::unique_ptr<FieldClient>(new FieldClient(std::move(options), std::move(credentials)));
}

FieldClient::FieldClient(FieldClientOptions options,
                         std::shared_ptr<grpc::ChannelCredentials> credentials)
    : options_(std::move(options)) {
  grpc::ChannelArguments channel_args;
  channel_args.SetMaxReceiveMessageSize(-1);  // the server enforces its own limit
  channel_args.SetMaxSendMessageSize(-1);
  if (options_.tls && !options_.tls->server_name.empty()) {
    channel_args.SetSslTargetNameOverride(options_.tls->server_name);
  }
  channel_ = grpc::CreateCustomChannel(options_.address, credentials, channel_args);
  stub_ = v1::FieldSpace::NewStub(channel_);
}

std::string RoutingKey(const google::protobuf::Message& request) {
  const google::protobuf::Descriptor* descriptor = request.GetDescriptor();
  const google::protobuf::Reflection* reflection = request.GetReflection();
  for (const char* name : {"basis_id", "mesh_id"}) {
    const google::protobuf::FieldDescriptor* field = descriptor->FindFieldByName(name);
    if (field == nullptr || field->is_repeated() ||
        field->type() != google::protobuf::FieldDescriptor::TYPE_STRING) {
      continue;
    }
    std::string value = reflection->GetString(request, field);
    if (!value.empty()) return value;
  }
  return "";
}

std::unique_ptr<grpc::ClientContext> FieldClient::NewContext(const std::string& routing_key) const {
  auto context = std::make_unique<grpc::ClientContext>();
  if (!options_.token.empty()) context->AddMetadata("authorization", "Bearer " + options_.token);
  if (!routing_key.empty()) context->AddMetadata(kRoutingKeyHeader, routing_key);
  if (options_.timeout) context->set_deadline(std::chrono::system_clock::now() + *options_.timeout);
  return context;
}

template <typename Request, typename Response>
absl::StatusOr<Response> FieldClient::Unary(
    grpc::Status (v1::FieldSpace::Stub::*method)(grpc::ClientContext*, const Request&, Response*),
    const Request& request) const {
  std::unique_ptr<grpc::ClientContext> context = NewContext(RoutingKey(request));
  Response response;
  if (absl::Status status = FromGrpc((stub_.get()->*method)(context.get(), request, &response));
      !status.ok()) {
    return status;
  }
  return response;
}

absl::StatusOr<grpc::health::v1::HealthCheckResponse> FieldClient::Health(
    const std::string& service) const {
  auto stub = grpc::health::v1::Health::NewStub(channel_);
  grpc::health::v1::HealthCheckRequest request;
  request.set_service(service);
  grpc::health::v1::HealthCheckResponse response;
  std::unique_ptr<grpc::ClientContext> context = NewContext();
  if (!options_.timeout) context->set_deadline(std::chrono::system_clock::now() + kHealthTimeout);
  if (absl::Status status = FromGrpc(stub->Check(context.get(), request, &response));
      !status.ok()) {
    return status;
  }
  return response;
}

absl::StatusOr<v1::MeshInfo> FieldClient::Upload(
    const v1::UploadMeshHeader& header,
    const std::function<bool(std::string* chunk)>& next_chunk) const {
  std::unique_ptr<grpc::ClientContext> context = NewContext();
  v1::MeshInfo info;
  auto writer = stub_->UploadMesh(context.get(), &info);
  v1::UploadMeshRequest request;
  *request.mutable_header() = header;
  uint64_t offset = 0;
  bool more = true;
  // The last message is marked (it may be empty): the server stores nothing without the mark or
  // an announced size, so a stream cut short is never taken for a whole one.
  while (more) {
    std::string data;
    more = next_chunk(&data);
    request.set_offset(offset);
    offset += data.size();
    request.set_data(std::move(data));
    request.set_last(!more);
    if (!writer->Write(request)) break;  // the server ended the call: Finish tells why
    request.clear_header();
  }
  writer->WritesDone();
  if (absl::Status status = FromGrpc(writer->Finish()); !status.ok()) return status;
  return info;
}

absl::StatusOr<v1::MeshInfo> FieldClient::UploadMesh(const v1::UploadMeshHeader& header,
                                                     std::istream& in) const {
  const size_t chunk_bytes = options_.upload_chunk_bytes;
  return Upload(header, [&in, chunk_bytes](std::string* chunk) {
    chunk->resize(chunk_bytes);
    in.read(chunk->data(), static_cast<std::streamsize>(chunk_bytes));
    chunk->resize(static_cast<size_t>(std::max<std::streamsize>(in.gcount(), 0)));
    return chunk->size() == chunk_bytes;
  });
}

absl::StatusOr<v1::MeshInfo> FieldClient::UploadMesh(const v1::UploadMeshHeader& header,
                                                     absl::string_view bytes) const {
  const size_t chunk_bytes = options_.upload_chunk_bytes;
  size_t offset = 0;
  return Upload(header, [bytes, chunk_bytes, &offset](std::string* chunk) {
    const absl::string_view part = bytes.substr(offset, chunk_bytes);
    chunk->assign(part.data(), part.size());
    offset += part.size();
    return offset < bytes.size();
  });
}

absl::StatusOr<v1::MeshInfo> FieldClient::UploadMeshArrays(const MeshArrays& arrays,
                                                           const std::string& name) const {
  static_assert(std::endian::native == std::endian::little, "raw uploads are little-endian");
  // Row-major #V x 3 and #F x 3: the arrays' storage is the wire layout.
  std::string raw(reinterpret_cast<const char*>(arrays.vertices.data()),
                  sizeof(double) * arrays.vertices.size());
  raw.append(reinterpret_cast<const char*>(arrays.faces.data()),
             sizeof(int32_t) * arrays.faces.size());
  v1::UploadMeshHeader header;
  header.set_name(name);
  header.set_format(v1::MESH_FORMAT_RAW);
  header.set_num_vertices(arrays.vertices.rows());
  header.set_num_faces(arrays.faces.rows());
  header.set_total_bytes(raw.size());
  return UploadMesh(header, raw);
}

absl::StatusOr<v1::MeshInfo> FieldClient::UploadMeshFile(const std::string& path,
                                                         const std::string& name) const {
  std::ifstream in(path, std::ios::binary);
  if (!in) return absl::NotFoundError("cannot open " + path);
  return UploadMesh(MeshFileHeader(path, name), in);
}

absl::StatusOr<v1::MeshInfo> FieldClient::LoadMesh(const v1::LoadMeshRequest& request) const {
  return Unary(&v1::FieldSpace::Stub::LoadMesh, request);
}

absl::StatusOr<v1::MeshInfo> FieldClient::GetMesh(const v1::GetMeshRequest& request) const {
  return Unary(&v1::FieldSpace::Stub::GetMesh, request);
}

absl::StatusOr<v1::ListMeshesResponse> FieldClient::ListMeshes(
    const v1::ListMeshesRequest& request) const {
  return Unary(&v1::FieldSpace::Stub::ListMeshes, request);
}

absl::StatusOr<v1::DeleteMeshResponse> FieldClient::DeleteMesh(
    const v1::DeleteMeshRequest& request) const {
  return Unary(&v1::FieldSpace::Stub::DeleteMesh, request);
}

absl::StatusOr<MeshGeometry> FieldClient::GetMeshGeometry(
    const v1::GetMeshGeometryRequest& request) const {
  std::unique_ptr<grpc::ClientContext> context = NewContext(RoutingKey(request));
  auto reader = stub_->GetMeshGeometry(context.get(), request);
  MeshGeometry geometry;
  absl::Status status = ReadAll(*reader, [&geometry](const v1::MeshGeometryChunk& chunk) {
    geometry.vertices.insert(geometry.vertices.end(), chunk.vertices().begin(),
                             chunk.vertices().end());
    geometry.faces.insert(geometry.faces.end(), chunk.faces().begin(), chunk.faces().end());
  });
  if (!status.ok()) return status;
  return geometry;
}

absl::StatusOr<v1::BasisInfo> FieldClient::BuildBasis(
    const v1::BuildBasisRequest& request, const BuildProgressCallback& on_progress) const {
  std::unique_ptr<grpc::ClientContext> context = NewContext(RoutingKey(request));
  auto reader = stub_->BuildBasis(context.get(), request);
  std::optional<v1::BasisInfo> basis;
  absl::Status status = ReadAll(*reader, [&](const v1::BuildBasisProgress& progress) {
    if (on_progress) on_progress(progress);
    if (progress.has_basis()) basis = progress.basis();
  });
  if (!status.ok()) return status;
  if (!basis) return absl::InternalError("the build stream ended without a basis");
  return *std::move(basis);
}

absl::StatusOr<v1::CancelBuildResponse> FieldClient::CancelBuild(
    const v1::CancelBuildRequest& request) const {
  return Unary(&v1::FieldSpace::Stub::CancelBuild, request);
}

absl::StatusOr<v1::BasisInfo> FieldClient::GetBasis(const v1::GetBasisRequest& request) const {
  return Unary(&v1::FieldSpace::Stub::GetBasis, request);
}

absl::StatusOr<v1::ListBasesResponse> FieldClient::ListBases(
    const v1::ListBasesRequest& request) const {
  return Unary(&v1::FieldSpace::Stub::ListBases, request);
}

absl::StatusOr<v1::DeleteBasisResponse> FieldClient::DeleteBasis(
    const v1::DeleteBasisRequest& request) const {
  return Unary(&v1::FieldSpace::Stub::DeleteBasis, request);
}

absl::StatusOr<v1::ProjectResponse> FieldClient::Project(const v1::ProjectRequest& request) const {
  return Unary(&v1::FieldSpace::Stub::Project, request);
}

absl::StatusOr<v1::SolveResponse> FieldClient::Solve(const v1::SolveRequest& request) const {
  return Unary(&v1::FieldSpace::Stub::Solve, request);
}

template <typename Request, typename Chunk>
absl::StatusOr<std::vector<Chunk>> FieldClient::Collect(
    std::unique_ptr<grpc::ClientReader<Chunk>> (v1::FieldSpace::Stub::*method)(grpc::ClientContext*,
                                                                               const Request&),
    const Request& request) const {
  std::unique_ptr<grpc::ClientContext> context = NewContext(RoutingKey(request));
  auto reader = (stub_.get()->*method)(context.get(), request);
  std::vector<Chunk> chunks;
  absl::Status status =
      ReadAll(*reader, [&chunks](const Chunk& chunk) { chunks.push_back(chunk); });
  if (!status.ok()) return status;
  return chunks;
}

absl::StatusOr<std::vector<v1::FieldChunk>> FieldClient::Lift(
    const v1::LiftRequest& request) const {
  return Collect(&v1::FieldSpace::Stub::Lift, request);
}

absl::StatusOr<std::vector<v1::CurvatureChunk>> FieldClient::Curvature(
    const v1::CurvatureRequest& request) const {
  return Collect(&v1::FieldSpace::Stub::Curvature, request);
}

absl::StatusOr<v1::SingularitiesResponse> FieldClient::Singularities(
    const v1::SingularitiesRequest& request) const {
  return Unary(&v1::FieldSpace::Stub::Singularities, request);
}

absl::StatusOr<v1::SmoothResponse> FieldClient::Smooth(const v1::SmoothRequest& request) const {
  return Unary(&v1::FieldSpace::Stub::Smooth, request);
}

absl::StatusOr<v1::SmoothResponse> FieldClient::Align(const v1::AlignRequest& request) const {
  return Unary(&v1::FieldSpace::Stub::Align, request);
}

absl::StatusOr<v1::EigenfieldsResponse> FieldClient::Eigenfields(
    const v1::EigenfieldsRequest& request) const {
  return Unary(&v1::FieldSpace::Stub::Eigenfields, request);
}

std::unique_ptr<DesignStream> FieldClient::Design(const std::string& basis_id) const {
  return std::unique_ptr<DesignStream>(new DesignStream(NewContext(basis_id), stub_.get()));
}

DesignStream::DesignStream(std::unique_ptr<grpc::ClientContext> context, v1::FieldSpace::Stub* stub)
    : context_(std::move(context)), stream_(stub->Design(context_.get())) {}

DesignStream::~DesignStream() {
  if (final_status_) return;
  context_->TryCancel();
  stream_->Finish();
}

absl::StatusOr<v1::DesignUpdate> DesignStream::Open(const v1::OpenDesign& open, uint64_t seq) {
  v1::DesignRequest request;
  request.set_seq(seq);
  *request.mutable_open() = open;
  return Edit(request);
}

absl::StatusOr<v1::DesignUpdate> DesignStream::Edit(const v1::DesignRequest& request) {
  if (absl::Status status = SendEdit(request); !status.ok()) return status;
  return ReadUpdate();
}

absl::Status DesignStream::SendEdit(const v1::DesignRequest& request) {
  if (final_status_) return absl::FailedPreconditionError("the design stream is closed");
  if (!stream_->Write(request)) return Broken();
  return absl::OkStatus();
}

absl::StatusOr<v1::DesignUpdate> DesignStream::ReadUpdate() {
  if (final_status_) return absl::FailedPreconditionError("the design stream is closed");
  v1::DesignUpdate update;
  if (!stream_->Read(&update)) return Broken();
  // A refused edit: the session is as before and the stream stays open.
  if (update.has_error()) {
    return absl::Status(static_cast<absl::StatusCode>(update.error().code()),
                        update.error().message());
  }
  return update;
}

absl::Status DesignStream::Close() {
  if (!final_status_) {
    stream_->WritesDone();
    final_status_ = FromGrpc(stream_->Finish());
  }
  return *final_status_;
}

absl::Status DesignStream::Broken() {
  absl::Status status = Close();
  if (status.ok()) return absl::UnavailableError("the server ended the design session");
  return status;
}

bool ReplicaLost(const absl::Status& status) {
  if (absl::IsUnavailable(status)) return true;
  // gRPC's own UNKNOWN without a message: a call on a channel whose server went away (servers
  // always say what went wrong).
  if (absl::IsUnknown(status) && status.message().empty()) return true;
  return absl::IsInternal(status) && absl::StrContains(status.message(), "RST_STREAM");
}

absl::StatusOr<v1::DesignUpdate> ResumableDesign::Exchange(const v1::DesignRequest& r) {
  if (stream_ == nullptr) {
    stream_ = client_->Design(open_.basis_id());
  }
  return stream_->Edit(r);
}

absl::StatusOr<v1::DesignUpdate> ResumableDesign::Resume(const v1::DesignRequest& r,
                                                         const absl::Status& lost) {
  absl::Status error = lost;
  static constexpr int kPauseMs[kMaxReopens] = {0, 100, 300, 600, 1000, 2000};
  for (int attempt = 0; attempt < kMaxReopens; ++attempt) {
    std::this_thread::sleep_for(std::chrono::milliseconds(kPauseMs[attempt]));
    stream_.reset();  // cancels the broken call
    // A lost open is simply sent again; any other edit needs the session reopened and its
    // constraints replayed first.
    absl::StatusOr<v1::DesignUpdate> update = r.has_open() ? Exchange(r) : Replay(r.seq());
    if (update.ok() && !r.has_open()) update = Exchange(r);
    if (update.ok()) {
      ++resumes_;
      return update;
    }
    if (!ReplicaLost(update.status())) return update.status();
    error = update.status();
  }
  // Why the session was lost, and why it could not be reopened.
  return absl::Status(
      lost.code(),
      absl::StrCat(lost.message(), " (reopening the session failed ", kMaxReopens, " times, last: ",
                   error.message().empty() ? "no server answered" : error.ToString(), ")"));
}

absl::StatusOr<v1::DesignUpdate> ResumableDesign::Replay(uint64_t seq) {
  v1::DesignRequest open;
  open.set_seq(seq);
  *open.mutable_open() = open_;
  absl::StatusOr<v1::DesignUpdate> update = Exchange(open);
  for (size_t i = 0; update.ok() && i < constraints_.size(); ++i) {
    v1::DesignRequest add;
    add.set_seq(seq);
    add.mutable_add()->set_id(constraints_[i].first);
    *add.mutable_add()->mutable_constraint() = constraints_[i].second;
    update = Exchange(add);
  }
  return update;
}

void ResumableDesign::Remember(const v1::DesignRequest& r) {
  auto find = [this](int32_t id) {
    return std::find_if(constraints_.begin(), constraints_.end(),
                        [id](const auto& c) { return c.first == id; });
  };
  if (r.has_add()) {
    constraints_.emplace_back(r.add().id(), r.add().constraint());
  } else if (r.has_move()) {
    if (auto it = find(r.move().id()); it != constraints_.end()) {
      it->second.set_face(r.move().face());
      it->second.set_encoding(r.move().encoding());
      *it->second.mutable_value() = r.move().value();
    }
  } else if (r.has_remove()) {
    if (auto it = find(r.remove().id()); it != constraints_.end()) constraints_.erase(it);
  } else if (r.has_set_weights()) {
    // Weights an edit leaves out keep the session's values (where the proto tracks their
    // presence; otherwise every value is sent).
    const v1::Weights& w = r.set_weights();
    const google::protobuf::Descriptor* descriptor = w.GetDescriptor();
    v1::Weights* target = open_.mutable_weights();
    for (int i = 0; i < descriptor->field_count(); ++i) {
      const google::protobuf::FieldDescriptor* field = descriptor->field(i);
      if (field->cpp_type() != google::protobuf::FieldDescriptor::CPPTYPE_DOUBLE) continue;
      if (field->has_presence() && !w.GetReflection()->HasField(w, field)) continue;
      target->GetReflection()->SetDouble(target, field, w.GetReflection()->GetDouble(w, field));
    }
  } else if (r.has_watch()) {
    *open_.mutable_watch_faces() = r.watch().faces();
    open_.set_watch_encoding(r.watch().encoding());
  }
}

absl::StatusOr<ResumableDesign::Update> ResumableDesign::Open(uint64_t seq) {
  v1::DesignRequest request;
  request.set_seq(seq);
  *request.mutable_open() = open_;
  return Edit(request);
}

absl::StatusOr<ResumableDesign::Update> ResumableDesign::Edit(const v1::DesignRequest& request) {
  Update out;
  absl::StatusOr<v1::DesignUpdate> update = Exchange(request);
  if (!update.ok() && ReplicaLost(update.status())) {
    update = Resume(request, update.status());
    out.resumed = update.ok();
  }
  if (!update.ok()) return update.status();
  Remember(request);
  out.update = *std::move(update);
  return out;
}

absl::Status ResumableDesign::Close() {
  if (stream_ == nullptr) return absl::OkStatus();
  return stream_->Close();
}

}  // namespace fieldspace::client
