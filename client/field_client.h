#ifndef FIELDSPACE_CLIENT_FIELD_CLIENT_H_
#define FIELDSPACE_CLIENT_FIELD_CLIENT_H_

// A small synchronous C++ client of fieldspace.v1.FieldSpace (and grpc.health.v1), the one piece
// of client/ and bench/ that touches gRPC stubs. Requests and responses are the wire protos;
// every grpc::Status becomes an absl::Status with the same code and message. A FieldClient is
// thread-safe (one channel, shared by all calls); a DesignStream belongs to one thread.

#include <chrono>
#include <cstdint>
#include <functional>
#include <istream>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"
#include "core/mesh/triangle_mesh.h"
#include "fieldspace/v1/fieldspace.grpc.pb.h"
#include "google/protobuf/message.h"
#include "grpc/health/v1/health.pb.h"
#include "grpcpp/grpcpp.h"

namespace fieldspace::client {

// TLS to a daemon started with --tls-cert (files are PEM).
struct ClientTlsOptions {
  // The CA that signed the server's certificate; empty: the system's trusted roots.
  std::string ca_file;
  // The client's certificate and key, for a server with --tls-client-ca (mutual TLS): both or
  // neither.
  std::string cert_file;
  std::string key_file;
  // The name the server's certificate must carry, instead of the host of the address (e.g. a
  // certificate issued to `fieldspaced` reached as 127.0.0.1); empty: the host.
  std::string server_name;
};

struct FieldClientOptions {
  std::string address;  // HOST:PORT of fieldspaced
  // Sent as `authorization: Bearer <token>` on every call when not empty.
  std::string token;
  // TLS when set, plaintext otherwise.
  std::optional<ClientTlsOptions> tls;
  // Deadline of every call (for a stream: of the whole stream, e.g. a build or a design
  // session); none when unset.
  std::optional<std::chrono::milliseconds> timeout;
  // Upload chunk size (the server's message limit is 64 MiB by default).
  size_t upload_chunk_bytes = size_t{1} << 20;
};

// A mesh's canonical arrays (GetMeshGeometry): #V x 3 coordinates and #F x 3 zero-based vertex
// indices, both row-major.
struct MeshGeometry {
  std::vector<double> vertices;
  std::vector<int32_t> faces;
};

// The header of an upload of the file `path`: `name` (default: the file name), the format from
// the extension (.obj, .off, .ply; otherwise left to the server) and the size when known.
fieldspace::v1::UploadMeshHeader MeshFileHeader(const std::string& path,
                                                const std::string& name = "");

class DesignStream;

// The routing key of a request: its `basis_id`, else its `mesh_id` (top-level string fields), else
// "". Sent as `x-fieldspace-key` metadata so that a router (nginx `hash $http_x_fieldspace_key
// consistent`, Envoy ring hash) sends the calls about one basis or mesh to the same replica
// (docs/scale-out.md); servers ignore it.
inline constexpr char kRoutingKeyHeader[] = "x-fieldspace-key";
std::string RoutingKey(const google::protobuf::Message& request);

class FieldClient {
 public:
  // InvalidArgument for an empty address, a TLS certificate without its key (or the other way
  // round) and a TLS file that cannot be read or holds no PEM block (the message names it).
  // Connecting is lazy: an unreachable server, or one whose certificate fails the check, shows as
  // UNAVAILABLE on the first call.
  static absl::StatusOr<std::unique_ptr<FieldClient>> Create(FieldClientOptions options);

  // grpc.health.v1 Check of `service` ("": the whole server). Without options.timeout it waits
  // at most 10 s, so that a probe never hangs.
  absl::StatusOr<grpc::health::v1::HealthCheckResponse> Health(
      const std::string& service = "") const;

  // UploadMesh from `in`, in chunks of options.upload_chunk_bytes (the header goes with the
  // first chunk; an empty input still sends it).
  absl::StatusOr<fieldspace::v1::MeshInfo> UploadMesh(
      const fieldspace::v1::UploadMeshHeader& header, std::istream& in) const;
  // The same from bytes in memory (e.g. MESH_FORMAT_RAW arrays).
  absl::StatusOr<fieldspace::v1::MeshInfo> UploadMesh(
      const fieldspace::v1::UploadMeshHeader& header, absl::string_view bytes) const;
  // A triangle soup as MESH_FORMAT_RAW: the little-endian float64 vertex and int32 face arrays.
  absl::StatusOr<fieldspace::v1::MeshInfo> UploadMeshArrays(const MeshArrays& arrays,
                                                            const std::string& name) const;
  // Opens `path` (NotFound "cannot open PATH") and uploads it with MeshFileHeader(path, name).
  absl::StatusOr<fieldspace::v1::MeshInfo> UploadMeshFile(const std::string& path,
                                                          const std::string& name = "") const;
  absl::StatusOr<fieldspace::v1::MeshInfo> LoadMesh(
      const fieldspace::v1::LoadMeshRequest& request) const;
  absl::StatusOr<fieldspace::v1::MeshInfo> GetMesh(
      const fieldspace::v1::GetMeshRequest& request) const;
  absl::StatusOr<fieldspace::v1::ListMeshesResponse> ListMeshes(
      const fieldspace::v1::ListMeshesRequest& request = {}) const;
  absl::StatusOr<fieldspace::v1::DeleteMeshResponse> DeleteMesh(
      const fieldspace::v1::DeleteMeshRequest& request) const;
  // All chunks of the mesh's arrays, concatenated.
  absl::StatusOr<MeshGeometry> GetMeshGeometry(
      const fieldspace::v1::GetMeshGeometryRequest& request) const;

  // Runs (or joins) the build and returns the final BasisInfo; `on_progress`, when given, sees
  // every progress message (the last one carries the basis). Internal if the stream ends
  // without a basis.
  using BuildProgressCallback = std::function<void(const fieldspace::v1::BuildBasisProgress&)>;
  absl::StatusOr<fieldspace::v1::BasisInfo> BuildBasis(
      const fieldspace::v1::BuildBasisRequest& request,
      const BuildProgressCallback& on_progress = nullptr) const;
  absl::StatusOr<fieldspace::v1::CancelBuildResponse> CancelBuild(
      const fieldspace::v1::CancelBuildRequest& request) const;
  absl::StatusOr<fieldspace::v1::BasisInfo> GetBasis(
      const fieldspace::v1::GetBasisRequest& request) const;
  absl::StatusOr<fieldspace::v1::ListBasesResponse> ListBases(
      const fieldspace::v1::ListBasesRequest& request = {}) const;
  absl::StatusOr<fieldspace::v1::DeleteBasisResponse> DeleteBasis(
      const fieldspace::v1::DeleteBasisRequest& request) const;

  absl::StatusOr<fieldspace::v1::ProjectResponse> Project(
      const fieldspace::v1::ProjectRequest& request) const;
  absl::StatusOr<fieldspace::v1::SolveResponse> Solve(
      const fieldspace::v1::SolveRequest& request) const;
  // All chunks of the lift, in the order the server sent them (all-faces lifts: by start_face).
  absl::StatusOr<std::vector<fieldspace::v1::FieldChunk>> Lift(
      const fieldspace::v1::LiftRequest& request) const;
  absl::StatusOr<fieldspace::v1::EigenfieldsResponse> Eigenfields(
      const fieldspace::v1::EigenfieldsRequest& request) const;

  // All chunks of the mesh's shape operator, in order.
  absl::StatusOr<std::vector<fieldspace::v1::CurvatureChunk>> Curvature(
      const fieldspace::v1::CurvatureRequest& request) const;
  absl::StatusOr<fieldspace::v1::SingularitiesResponse> Singularities(
      const fieldspace::v1::SingularitiesRequest& request) const;
  absl::StatusOr<fieldspace::v1::SmoothResponse> Smooth(
      const fieldspace::v1::SmoothRequest& request) const;
  absl::StatusOr<fieldspace::v1::SmoothResponse> Align(
      const fieldspace::v1::AlignRequest& request) const;

  // Starts a Design call; send `open` first (DesignStream::Open). `basis_id`, when given, is the
  // call's routing key (it must be sent before the first message names the basis).
  std::unique_ptr<DesignStream> Design(const std::string& basis_id = "") const;

 private:
  FieldClient(FieldClientOptions options, std::shared_ptr<grpc::ChannelCredentials> credentials);
  // A context with the token, the deadline of the options and the routing key (when not empty).
  std::unique_ptr<grpc::ClientContext> NewContext(const std::string& routing_key = "") const;
  // Unary calls of FieldSpace, one implementation for all.
  template <typename Request, typename Response>
  absl::StatusOr<Response> Unary(grpc::Status (fieldspace::v1::FieldSpace::Stub::*method)(
                                     grpc::ClientContext*, const Request&, Response*),
                                 const Request& request) const;
  // All messages of a server-streaming call of FieldSpace, in order.
  template <typename Request, typename Chunk>
  absl::StatusOr<std::vector<Chunk>> Collect(
      std::unique_ptr<grpc::ClientReader<Chunk>> (fieldspace::v1::FieldSpace::Stub::*method)(
          grpc::ClientContext*, const Request&),
      const Request& request) const;
  // UploadMesh of the chunks from `next_chunk`, which sets the next one and returns whether more
  // may follow; an empty chunk after the first ends the upload.
  absl::StatusOr<fieldspace::v1::MeshInfo> Upload(
      const fieldspace::v1::UploadMeshHeader& header,
      const std::function<bool(std::string* chunk)>& next_chunk) const;

  FieldClientOptions options_;
  std::shared_ptr<grpc::Channel> channel_;
  std::unique_ptr<fieldspace::v1::FieldSpace::Stub> stub_;
};

// One interactive session (the bidirectional Design stream): Open, then one Edit per change
// (or SendEdit / ReadUpdate to pipeline), then Close. An edit the server refuses (its update
// carries an EditError) returns that error, and the session goes on as it was before the edit.
// When the stream breaks, the failing call returns the call's final status and the stream is
// closed (is_closed). Destroying an unclosed stream cancels the call.
class DesignStream {
 public:
  ~DesignStream();
  DesignStream(const DesignStream&) = delete;
  DesignStream& operator=(const DesignStream&) = delete;

  // Sends {seq, open} and returns its update.
  absl::StatusOr<fieldspace::v1::DesignUpdate> Open(const fieldspace::v1::OpenDesign& open,
                                                    uint64_t seq = 0);
  // Sends one request and returns its update (SendEdit + ReadUpdate).
  absl::StatusOr<fieldspace::v1::DesignUpdate> Edit(const fieldspace::v1::DesignRequest& request);
  absl::Status SendEdit(const fieldspace::v1::DesignRequest& request);
  absl::StatusOr<fieldspace::v1::DesignUpdate> ReadUpdate();
  // Half-closes the stream and returns the call's final status (OK after a clean session); read
  // the updates of all sent edits first. The same status on every call; calls after it are
  // FailedPrecondition.
  absl::Status Close();
  // Whether the stream has ended (Close, or a broken stream); a refused edit does not end it.
  bool is_closed() const { return final_status_.has_value(); }

 private:
  friend class FieldClient;
  DesignStream(std::unique_ptr<grpc::ClientContext> context,
               fieldspace::v1::FieldSpace::Stub* stub);
  // Ends a broken stream and returns why (Unavailable when the server ended it with OK).
  absl::Status Broken();

  std::unique_ptr<grpc::ClientContext> context_;
  std::unique_ptr<
      grpc::ClientReaderWriter<fieldspace::v1::DesignRequest, fieldspace::v1::DesignUpdate>>
      stream_;
  std::optional<absl::Status> final_status_;
};

// Whether a failed design call lost its replica, so that reopening the session may help:
// UNAVAILABLE (the replica drained or is unreachable), a stream reset at the transport level,
// which is what a router does when the replica behind it dies (nginx: "Received RST_STREAM with
// error code 2", INTERNAL), or gRPC's UNKNOWN without a message (a call on a channel whose server
// went away). Statuses sent by a server (they have a message) are not such a loss.
bool ReplicaLost(const absl::Status& status);

// A design session that survives the loss of its replica (docs/scale-out.md). It keeps what the
// server confirmed (the open with its current weights and watch, the constraints by id in the
// order they were added); when an edit fails with ReplicaLost, it reopens the stream (through a
// router: on another replica), replays that state, sends the edit again and returns its update
// marked `resumed`, with the coefficients the lost session would have given (a lost open, e.g. a
// replica that died while loading the basis, is sent again the same way). A refused edit
// returns its error and the session goes on; other errors end the session as with DesignStream;
// when every reopen fails, the edit fails with the status that lost
// the session (its message says why reopening failed). Belongs to one thread.
class ResumableDesign {
 public:
  struct Update {
    fieldspace::v1::DesignUpdate update;
    bool resumed = false;
  };
  // Attempts and the pauses before them when reopening (a router may need a moment to mark the
  // dead replica down).
  static constexpr int kMaxReopens = 6;

  ResumableDesign(const FieldClient* client, fieldspace::v1::OpenDesign open)
      : client_(client), open_(std::move(open)) {}

  // Opens the session (the first call; `seq` is echoed).
  absl::StatusOr<Update> Open(uint64_t seq = 0);
  // One edit (not an open).
  absl::StatusOr<Update> Edit(const fieldspace::v1::DesignRequest& request);
  absl::Status Close();
  // Whether the session's stream is open: after a refused edit it is (the session goes on as it
  // was); after any other error it is not.
  bool is_open() const { return stream_ != nullptr && !stream_->is_closed(); }
  int resumes() const { return resumes_; }

 private:
  absl::StatusOr<fieldspace::v1::DesignUpdate> Exchange(const fieldspace::v1::DesignRequest& r);
  absl::StatusOr<fieldspace::v1::DesignUpdate> Resume(const fieldspace::v1::DesignRequest& r,
                                                      const absl::Status& lost);
  // Opens a new stream with the session's open and adds its constraints (every message with
  // `seq`); the last update.
  absl::StatusOr<fieldspace::v1::DesignUpdate> Replay(uint64_t seq);
  void Remember(const fieldspace::v1::DesignRequest& request);

  const FieldClient* const client_;
  fieldspace::v1::OpenDesign open_;
  std::vector<std::pair<int32_t, fieldspace::v1::Constraint>> constraints_;
  std::unique_ptr<DesignStream> stream_;
  int resumes_ = 0;
};

}  // namespace fieldspace::client

#endif  // FIELDSPACE_CLIENT_FIELD_CLIENT_H_
