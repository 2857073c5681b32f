// FieldClient against an in-process FieldServer on 127.0.0.1:0: status translation, the token,
// chunked uploads, builds with progress, lifts, design sessions and deadlines.

#include "client/field_client.h"

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "absl/strings/str_format.h"
#include "core/mesh/mesh_io.h"
#include "core/mesh/shapes.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "server/field_server.h"

namespace fieldspace::client {
namespace {

namespace fs = std::filesystem;
namespace v1 = ::fieldspace::v1;
using ::testing::HasSubstr;

constexpr int32_t kFaces = 320;  // icosphere, 2 subdivisions

// A running server in a temporary store, stopped and removed at the end.
class Server {
 public:
  explicit Server(const std::string& name, server::FieldServerOptions options = {}) {
    root_ = fs::temp_directory_path() / absl::StrFormat("fs_client_%d_%s", ::getpid(), name);
    fs::remove_all(root_);
    fs::create_directories(root_);
    options.listen = "127.0.0.1:0";
    options.store_dir = (root_ / "store").string();
    options.threads = 2;
    auto started = server::FieldServer::Start(options);
    EXPECT_TRUE(started.ok()) << started.status();
    if (started.ok()) server_ = *std::move(started);
  }
  ~Server() {
    if (server_ != nullptr) server_->Shutdown(std::chrono::seconds(5));
    server_.reset();
    fs::remove_all(root_);
  }
  bool ok() const { return server_ != nullptr; }
  const fs::path& root() const { return root_; }

  std::unique_ptr<FieldClient> Client(FieldClientOptions options = {}) const {
    options.address = server_->address();
    auto client = FieldClient::Create(options);
    EXPECT_TRUE(client.ok()) << client.status();
    return client.ok() ? *std::move(client) : nullptr;
  }

 private:
  fs::path root_;
  std::unique_ptr<server::FieldServer> server_;
};

MeshArrays Icosphere() {
  absl::StatusOr<MeshArrays> m = MakeIcosphere(2, 1.0);
  EXPECT_TRUE(m.ok()) << m.status();
  return *m;
}

v1::BuildBasisRequest VectorBasis(const std::string& mesh_id, int32_t dimension) {
  v1::BuildBasisRequest request;
  request.set_mesh_id(mesh_id);
  request.mutable_field()->set_kind(v1::FIELD_KIND_VECTOR);
  request.set_dimension(dimension);
  return request;
}

// Uploads the icosphere and builds a vector basis of dimension 30.
v1::BasisInfo UploadAndBuild(const FieldClient& client) {
  absl::StatusOr<v1::MeshInfo> mesh = client.UploadMeshArrays(Icosphere(), "icosphere");
  EXPECT_TRUE(mesh.ok()) << mesh.status();
  if (!mesh.ok()) return {};
  absl::StatusOr<v1::BasisInfo> basis = client.BuildBasis(VectorBasis(mesh->id(), 30));
  EXPECT_TRUE(basis.ok()) << basis.status();
  return basis.ok() ? *basis : v1::BasisInfo();
}

v1::DesignRequest AddConstraint(uint64_t seq, int32_t id, int32_t face) {
  v1::DesignRequest request;
  request.set_seq(seq);
  request.mutable_add()->set_id(id);
  v1::Constraint* c = request.mutable_add()->mutable_constraint();
  c->set_face(face);
  c->add_value(1.0);
  c->add_value(0.0);
  c->add_value(0.0);
  c->set_encoding(v1::FIELD_ENCODING_AMBIENT);
  return request;
}

v1::OpenDesign OpenRequest(const std::string& basis_id) {
  v1::OpenDesign open;
  open.set_basis_id(basis_id);
  open.mutable_weights()->set_mu_s(1.0);
  open.mutable_weights()->set_mu_c(1.0);
  open.set_watch_encoding(v1::FIELD_ENCODING_AMBIENT);
  return open;
}

// A server with the icosphere's vector basis (d = 30), and a client without deadlines.
class FieldClientBasisTest : public ::testing::Test {
 protected:
  void SetUp() override {
    server_ =
        std::make_unique<Server>(::testing::UnitTest::GetInstance()->current_test_info()->name());
    ASSERT_TRUE(server_->ok());
    client_ = server_->Client();
    ASSERT_NE(client_, nullptr);
    basis_ = UploadAndBuild(*client_);
    ASSERT_EQ(basis_.state(), v1::BASIS_STATE_READY);
  }

  std::unique_ptr<Server> server_;
  std::unique_ptr<FieldClient> client_;
  v1::BasisInfo basis_;
};

TEST(FieldClientTest, CreateNeedsAnAddress) {
  EXPECT_EQ(FieldClient::Create({}).status().code(), absl::StatusCode::kInvalidArgument);
}

TEST(FieldClientTest, TranslatesStatusCodesAndMessages) {
  Server server("codes");
  ASSERT_TRUE(server.ok());
  auto client = server.Client();
  ASSERT_NE(client, nullptr);
  absl::StatusOr<grpc::health::v1::HealthCheckResponse> health = client->Health();
  ASSERT_TRUE(health.ok()) << health.status();
  EXPECT_EQ(health->status(), grpc::health::v1::HealthCheckResponse::SERVING);

  v1::GetBasisRequest basis;
  basis.set_basis_id("b-0123456789abcdef");
  absl::StatusOr<v1::BasisInfo> missing = client->GetBasis(basis);
  EXPECT_EQ(missing.status().code(), absl::StatusCode::kNotFound);
  EXPECT_THAT(missing.status().message(), HasSubstr("b-0123456789abcdef"));
  v1::GetMeshRequest mesh;
  mesh.set_mesh_id("m-0123456789abcdef");
  EXPECT_EQ(client->GetMesh(mesh).status().code(), absl::StatusCode::kNotFound);
  v1::LoadMeshRequest load;  // the server has no data root
  load.set_path("sphere.obj");
  EXPECT_EQ(client->LoadMesh(load).status().code(), absl::StatusCode::kFailedPrecondition);
  // Streams report the final status too.
  v1::LiftRequest lift;
  lift.set_basis_id("b-0123456789abcdef");
  EXPECT_EQ(client->Lift(lift).status().code(), absl::StatusCode::kNotFound);
  EXPECT_EQ(client->BuildBasis(VectorBasis("m-0123456789abcdef", 10)).status().code(),
            absl::StatusCode::kNotFound);
  // A local failure of a file upload.
  absl::StatusOr<v1::MeshInfo> no_file =
      client->UploadMeshFile((server.root() / "missing.obj").string());
  EXPECT_EQ(no_file.status().code(), absl::StatusCode::kNotFound);
  EXPECT_THAT(no_file.status().message(), HasSubstr("cannot open"));
}

TEST(FieldClientTest, SendsTheTokenAsBearerMetadata) {
  server::FieldServerOptions options;
  options.auth_token = "s3cret";
  Server server("auth", options);
  ASSERT_TRUE(server.ok());
  FieldClientOptions wrong;
  wrong.token = "s3cres";
  auto wrong_client = server.Client(wrong);
  ASSERT_NE(wrong_client, nullptr);
  EXPECT_EQ(wrong_client->ListMeshes().status().code(), absl::StatusCode::kUnauthenticated);
  auto no_token = server.Client();
  EXPECT_EQ(no_token->ListMeshes().status().code(), absl::StatusCode::kUnauthenticated);
  std::unique_ptr<DesignStream> stream = wrong_client->Design();
  EXPECT_EQ(stream->Open(OpenRequest("b-0123456789abcdef")).status().code(),
            absl::StatusCode::kUnauthenticated);
  EXPECT_EQ(stream->Close().code(), absl::StatusCode::kUnauthenticated);
  // Health stays open; the right token passes.
  EXPECT_TRUE(wrong_client->Health().ok());
  FieldClientOptions right;
  right.token = "s3cret";
  EXPECT_TRUE(server.Client(right)->ListMeshes().ok());
}

TEST(FieldClientTest, UploadsInChunksAndBuildsWithProgress) {
  Server server("build");
  ASSERT_TRUE(server.ok());
  FieldClientOptions options;
  options.upload_chunk_bytes = 1000;  // many chunks
  auto client = server.Client(options);
  ASSERT_NE(client, nullptr);
  const MeshArrays m = Icosphere();
  absl::StatusOr<v1::MeshInfo> raw = client->UploadMeshArrays(m, "icosphere");
  ASSERT_TRUE(raw.ok()) << raw.status();
  EXPECT_EQ(raw->num_faces(), kFaces);
  EXPECT_EQ(raw->name(), "icosphere");
  // The same mesh from a PLY file (streamed from disk): the same content-derived id.
  const fs::path ply = server.root() / "ico.ply";
  ASSERT_TRUE(WritePly(ply.string(), m.vertices, m.faces).ok());
  absl::StatusOr<v1::MeshInfo> from_file = client->UploadMeshFile(ply.string());
  ASSERT_TRUE(from_file.ok()) << from_file.status();
  EXPECT_EQ(from_file->name(), "ico.ply");
  EXPECT_EQ(from_file->num_faces(), kFaces);
  EXPECT_EQ(MeshFileHeader(ply.string()).total_bytes(), fs::file_size(ply));
  EXPECT_EQ(MeshFileHeader(ply.string()).format(), v1::MESH_FORMAT_PLY);
  EXPECT_EQ(MeshFileHeader(ply.string(), "other").name(), "other");

  std::vector<v1::BuildBasisProgress> progress;
  absl::StatusOr<v1::BasisInfo> basis =
      client->BuildBasis(VectorBasis(raw->id(), 30),
                         [&progress](const v1::BuildBasisProgress& p) { progress.push_back(p); });
  ASSERT_TRUE(basis.ok()) << basis.status();
  EXPECT_EQ(basis->state(), v1::BASIS_STATE_READY);
  EXPECT_GT(basis->columns(), 0);
  EXPECT_EQ(basis->mesh_id(), raw->id());
  ASSERT_GE(progress.size(), 2u);
  for (size_t i = 1; i < progress.size(); ++i) {
    EXPECT_GE(progress[i].phase(), progress[i - 1].phase());
    if (progress[i].phase() == progress[i - 1].phase()) {
      EXPECT_GE(progress[i].fraction(), progress[i - 1].fraction()) << "message " << i;
    }
    EXPECT_EQ(progress[i].basis_id(), basis->id());
  }
  EXPECT_EQ(progress.back().phase(), v1::BUILD_PHASE_DONE);
  EXPECT_EQ(progress.back().basis().id(), basis->id());
  // Built already: one message, the stored basis.
  progress.clear();
  absl::StatusOr<v1::BasisInfo> again =
      client->BuildBasis(VectorBasis(raw->id(), 30),
                         [&progress](const v1::BuildBasisProgress& p) { progress.push_back(p); });
  ASSERT_TRUE(again.ok());
  EXPECT_EQ(again->id(), basis->id());
  EXPECT_EQ(progress.size(), 1u);
}

TEST_F(FieldClientBasisTest, LiftCollectsAllChunksAndGeometryRoundTrips) {
  FieldClient* client = client_.get();
  const v1::BasisInfo& basis = basis_;
  v1::LiftRequest request;
  request.set_basis_id(basis.id());
  for (int c = 0; c < basis.columns(); ++c) request.add_coefficients(c % 3 == 0 ? 1.0 : -0.5);
  request.set_encoding(v1::FIELD_ENCODING_AMBIENT);
  request.set_chunk_faces(100);
  absl::StatusOr<std::vector<v1::FieldChunk>> chunks = client->Lift(request);
  ASSERT_TRUE(chunks.ok()) << chunks.status();
  EXPECT_EQ(chunks->size(), 4u);  // 100 + 100 + 100 + 20 faces
  int32_t faces = 0;
  for (const v1::FieldChunk& chunk : *chunks) {
    EXPECT_EQ(chunk.start_face(), faces);
    EXPECT_EQ(chunk.total_faces(), kFaces);
    faces += chunk.field().values_size() / 3;
  }
  EXPECT_EQ(faces, kFaces);

  v1::GetMeshGeometryRequest geometry_request;
  geometry_request.set_mesh_id(basis.mesh_id());
  geometry_request.set_chunk_faces(50);
  absl::StatusOr<MeshGeometry> geometry = client->GetMeshGeometry(geometry_request);
  ASSERT_TRUE(geometry.ok()) << geometry.status();
  const MeshArrays m = Icosphere();
  EXPECT_EQ(geometry->vertices.size(), static_cast<size_t>(m.vertices.size()));
  EXPECT_EQ(geometry->faces.size(), static_cast<size_t>(3 * kFaces));
}

TEST_F(FieldClientBasisTest, DesignStreamRoundTrip) {
  FieldClient* client = client_.get();
  const v1::BasisInfo& basis = basis_;

  std::unique_ptr<DesignStream> stream = client->Design();
  v1::OpenDesign open = OpenRequest(basis.id());
  open.add_watch_faces(10);
  open.add_watch_faces(11);
  absl::StatusOr<v1::DesignUpdate> opened = stream->Open(open, 7);
  ASSERT_TRUE(opened.ok()) << opened.status();
  EXPECT_EQ(opened->seq(), 7u);
  EXPECT_EQ(opened->num_constraints(), 0);
  EXPECT_TRUE(opened->timings().refactorized());
  EXPECT_EQ(opened->coefficients_size(), basis.columns());

  absl::StatusOr<v1::DesignUpdate> added = stream->Edit(AddConstraint(8, 1, 10));
  ASSERT_TRUE(added.ok()) << added.status();
  EXPECT_EQ(added->seq(), 8u);
  EXPECT_EQ(added->num_constraints(), 1);
  EXPECT_FALSE(added->timings().refactorized());
  EXPECT_EQ(added->watched().faces_size(), 2);
  EXPECT_EQ(added->watched().values_size(), 6);
  // Pipelined: two sends, then two reads.
  v1::DesignRequest remove;
  remove.set_seq(9);
  remove.mutable_remove()->set_id(1);
  ASSERT_TRUE(stream->SendEdit(AddConstraint(10, 2, 12)).ok());
  ASSERT_TRUE(stream->SendEdit(remove).ok());
  absl::StatusOr<v1::DesignUpdate> second = stream->ReadUpdate();
  absl::StatusOr<v1::DesignUpdate> removed = stream->ReadUpdate();
  ASSERT_TRUE(second.ok() && removed.ok());
  EXPECT_EQ(second->num_constraints(), 2);
  EXPECT_EQ(removed->seq(), 9u);
  EXPECT_EQ(removed->num_constraints(), 1);
  EXPECT_TRUE(stream->Close().ok());
  EXPECT_TRUE(stream->Close().ok());  // the same status again
  EXPECT_EQ(stream->Edit(remove).status().code(), absl::StatusCode::kFailedPrecondition);

  // An edit the server refuses returns its code; the session goes on as it was, and Close is OK.
  std::unique_ptr<DesignStream> refused = client->Design();
  ASSERT_TRUE(refused->Open(open).ok());
  ASSERT_TRUE(refused->Edit(AddConstraint(1, 1, 10)).ok());
  EXPECT_EQ(refused->Edit(AddConstraint(2, 1, 20)).status().code(),
            absl::StatusCode::kAlreadyExists);
  EXPECT_FALSE(refused->is_closed());
  absl::StatusOr<v1::DesignUpdate> after = refused->Edit(AddConstraint(3, 2, 20));
  ASSERT_TRUE(after.ok()) << after.status();
  EXPECT_EQ(after->num_constraints(), 2);
  EXPECT_TRUE(refused->Close().ok());

  // Dropping an open stream cancels it; the client goes on working.
  {
    std::unique_ptr<DesignStream> dropped = client->Design();
    ASSERT_TRUE(dropped->Open(open).ok());
  }
  EXPECT_TRUE(client->ListBases().ok());
}

TEST(FieldClientTest, DeadlinesApplyToUnaryCallsAndHealth) {
  // A listener that never answers: every call waits until its deadline. (Against a live server
  // an expired deadline races with a fast answer on an already connected channel.)
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  ASSERT_GE(fd, 0);
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  socklen_t len = sizeof(addr);
  ASSERT_EQ(::bind(fd, reinterpret_cast<sockaddr*>(&addr), sizeof(addr)), 0);
  ASSERT_EQ(::listen(fd, 8), 0);
  ASSERT_EQ(::getsockname(fd, reinterpret_cast<sockaddr*>(&addr), &len), 0);
  FieldClientOptions options;
  options.address = absl::StrFormat("127.0.0.1:%d", ntohs(addr.sin_port));
  options.timeout = std::chrono::milliseconds(200);
  auto client = FieldClient::Create(options);
  ASSERT_TRUE(client.ok());
  const auto start = std::chrono::steady_clock::now();
  EXPECT_EQ((*client)->ListMeshes().status().code(), absl::StatusCode::kDeadlineExceeded);
  EXPECT_EQ((*client)->Health().status().code(), absl::StatusCode::kDeadlineExceeded);
  EXPECT_EQ((*client)->BuildBasis(VectorBasis("m-0123456789abcdef", 10)).status().code(),
            absl::StatusCode::kDeadlineExceeded);
  EXPECT_LT(std::chrono::steady_clock::now() - start, std::chrono::seconds(5));
  ::close(fd);
}

TEST_F(FieldClientBasisTest, DesignSessionDeadlineCoversTheWholeStream) {
  const v1::BasisInfo& basis = basis_;
  FieldClientOptions short_session;
  short_session.timeout = std::chrono::milliseconds(1000);
  auto timed = server_->Client(short_session);
  std::unique_ptr<DesignStream> stream = timed->Design();
  ASSERT_TRUE(stream->Open(OpenRequest(basis.id())).ok());
  std::this_thread::sleep_for(std::chrono::milliseconds(1500));
  EXPECT_EQ(stream->Edit(AddConstraint(1, 1, 10)).status().code(),
            absl::StatusCode::kDeadlineExceeded);
  EXPECT_EQ(stream->Close().code(), absl::StatusCode::kDeadlineExceeded);
}

// A server on a shared store (what a replica behind a router has), a client of its address and
// the icosphere's basis; Replace() stops the server and starts the next one on the same address
// and store, as a router finds the next replica.
class ResumableDesignTest : public ::testing::Test {
 protected:
  void SetUp() override {
    root_ = fs::temp_directory_path() /
            absl::StrFormat("fs_client_%d_%s", ::getpid(),
                            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(root_);
    options_.listen = "127.0.0.1:0";
    options_.store_dir = (root_ / "store").string();
    options_.threads = 2;
    options_.store_lock = server::StoreLockMode::kShared;
    auto first = server::FieldServer::Start(options_);
    ASSERT_TRUE(first.ok()) << first.status();
    server_ = *std::move(first);
    options_.listen = server_->address();
    FieldClientOptions client_options;
    client_options.address = server_->address();
    auto client = FieldClient::Create(client_options);
    ASSERT_TRUE(client.ok()) << client.status();
    client_ = *std::move(client);
    basis_ = UploadAndBuild(*client_);
    ASSERT_FALSE(basis_.id().empty());
  }
  void TearDown() override {
    if (server_ != nullptr) server_->Shutdown(std::chrono::seconds(1));
    server_.reset();
    fs::remove_all(root_);
  }

  // Drains the server: its sessions end UNAVAILABLE, nothing answers at the address.
  void Stop() {
    server_->Shutdown(std::chrono::seconds(2));
    server_.reset();
  }
  void StartNext() {
    auto next = server::FieldServer::Start(options_);
    ASSERT_TRUE(next.ok()) << next.status();
    server_ = *std::move(next);
  }

  fs::path root_;
  server::FieldServerOptions options_;
  std::unique_ptr<server::FieldServer> server_;
  std::unique_ptr<FieldClient> client_;
  v1::BasisInfo basis_;
};

// ResumableDesign: a session whose server drains resumes on the next server on the same address
// and shared store (what a router gives), with the same solution, and says so once.
TEST_F(ResumableDesignTest, ADrainedSessionResumesOnTheNextServerWithTheSameSolution) {
  v1::OpenDesign open = OpenRequest(basis_.id());
  open.add_watch_faces(3);
  ResumableDesign session(client_.get(), open);
  ASSERT_TRUE(session.Open(0).ok());
  ASSERT_TRUE(session.Edit(AddConstraint(1, 1, 10)).ok());
  ASSERT_TRUE(session.Edit(AddConstraint(2, 2, 20)).ok());
  ASSERT_TRUE(session.Edit(AddConstraint(3, 3, 30)).ok());
  v1::DesignRequest move;
  move.set_seq(4);
  move.mutable_move()->set_id(2);
  move.mutable_move()->set_face(21);
  for (double v : {0.0, 1.0, 0.0}) move.mutable_move()->add_value(v);
  move.mutable_move()->set_encoding(v1::FIELD_ENCODING_AMBIENT);
  ASSERT_TRUE(session.Edit(move).ok());
  v1::DesignRequest remove;
  remove.set_seq(5);
  remove.mutable_remove()->set_id(1);
  ASSERT_TRUE(session.Edit(remove).ok());
  v1::DesignRequest weights;
  weights.set_seq(6);
  weights.mutable_set_weights()->set_mu_s(1.0);
  weights.mutable_set_weights()->set_mu_b(0.01);
  weights.mutable_set_weights()->set_mu_c(1.0);
  absl::StatusOr<ResumableDesign::Update> before = session.Edit(weights);
  ASSERT_TRUE(before.ok()) << before.status();
  EXPECT_FALSE(before->resumed);

  Stop();  // drains: the session ends UNAVAILABLE
  StartNext();

  v1::DesignRequest watch;  // changes nothing
  watch.set_seq(7);
  watch.mutable_watch()->add_faces(3);
  watch.mutable_watch()->set_encoding(v1::FIELD_ENCODING_AMBIENT);
  absl::StatusOr<ResumableDesign::Update> after = session.Edit(watch);
  ASSERT_TRUE(after.ok()) << after.status();
  EXPECT_TRUE(after->resumed);
  EXPECT_EQ(session.resumes(), 1);
  EXPECT_EQ(after->update.seq(), 7u);
  EXPECT_EQ(after->update.num_constraints(), 2);
  ASSERT_EQ(after->update.coefficients_size(), before->update.coefficients_size());
  for (int i = 0; i < after->update.coefficients_size(); ++i) {
    EXPECT_NEAR(after->update.coefficients(i), before->update.coefficients(i), 1e-10) << i;
  }
  absl::StatusOr<ResumableDesign::Update> next = session.Edit(AddConstraint(8, 4, 40));
  ASSERT_TRUE(next.ok()) << next.status();
  EXPECT_FALSE(next->resumed);
  EXPECT_EQ(next->update.num_constraints(), 3);
  // A refused edit returns its error, is neither retried nor remembered, and the session goes on.
  EXPECT_EQ(session.Edit(AddConstraint(9, 4, 50)).status().code(),
            absl::StatusCode::kAlreadyExists);
  EXPECT_TRUE(session.is_open());
  EXPECT_EQ(session.resumes(), 1);
  absl::StatusOr<ResumableDesign::Update> last = session.Edit(AddConstraint(10, 5, 50));
  ASSERT_TRUE(last.ok()) << last.status();
  EXPECT_EQ(last->update.num_constraints(), 4);
  EXPECT_TRUE(session.Close().ok());
  EXPECT_FALSE(session.is_open());
  // Other errors are not retried.
  EXPECT_TRUE(ReplicaLost(absl::UnavailableError("x")));
  EXPECT_TRUE(ReplicaLost(absl::InternalError("Received RST_STREAM with error code 2")));
  EXPECT_FALSE(ReplicaLost(absl::InternalError("basis build failed")));
  EXPECT_FALSE(ReplicaLost(absl::NotFoundError("no basis")));
}

// The replica is lost while the open itself is pending (nothing answers at the address: it died
// loading the basis): the open is sent again until a server answers, and its update is the one a
// plain open gives, marked resumed.
TEST_F(ResumableDesignTest, ALostOpenIsSentAgain) {
  absl::StatusOr<v1::DesignUpdate> plain =
      client_->Design(basis_.id())->Open(OpenRequest(basis_.id()), 0);
  ASSERT_TRUE(plain.ok()) << plain.status();
  Stop();
  std::thread restart([this] {
    std::this_thread::sleep_for(std::chrono::milliseconds(300));
    StartNext();
  });
  ResumableDesign session(client_.get(), OpenRequest(basis_.id()));
  absl::StatusOr<ResumableDesign::Update> opened = session.Open(0);
  restart.join();
  ASSERT_TRUE(opened.ok()) << opened.status();
  EXPECT_TRUE(opened->resumed);
  EXPECT_EQ(session.resumes(), 1);
  ASSERT_EQ(opened->update.coefficients_size(), plain->coefficients_size());
  for (int i = 0; i < plain->coefficients_size(); ++i) {
    EXPECT_NEAR(opened->update.coefficients(i), plain->coefficients(i), 1e-12) << i;
  }
  absl::StatusOr<ResumableDesign::Update> next = session.Edit(AddConstraint(1, 4, 40));
  ASSERT_TRUE(next.ok()) << next.status();
  EXPECT_FALSE(next->resumed);
  EXPECT_EQ(next->update.num_constraints(), 1);
  EXPECT_TRUE(session.Close().ok());
}

}  // namespace
}  // namespace fieldspace::client
