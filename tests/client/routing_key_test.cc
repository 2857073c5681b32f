// The routing key: FieldClient (and so the CLI, which calls through it) sends
// `x-fieldspace-key: <basis or mesh id>` on every call that names one, and nothing on calls that
// name none. Checked against a test server that records the metadata it receives.

#include <memory>
#include <mutex>
#include <sstream>
#include <string>
#include <vector>

#include "client/cli.h"
#include "client/field_client.h"
#include "gmock/gmock.h"
#include "grpcpp/grpcpp.h"
#include "gtest/gtest.h"

namespace fieldspace::client {
namespace {

namespace v1 = ::fieldspace::v1;
using ::testing::ElementsAre;
using ::testing::Pair;

// Answers a few methods with NOT_FOUND (Design: after reading the first message) and records
// (method, x-fieldspace-key or "<none>") for each call.
class RecordingService final : public v1::FieldSpace::Service {
 public:
  std::vector<std::pair<std::string, std::string>> calls() {
    std::lock_guard<std::mutex> lock(mu_);
    return calls_;
  }

  grpc::Status GetMesh(grpc::ServerContext* context, const v1::GetMeshRequest*,
                       v1::MeshInfo*) override {
    return Record("GetMesh", context);
  }
  grpc::Status ListMeshes(grpc::ServerContext* context, const v1::ListMeshesRequest*,
                          v1::ListMeshesResponse*) override {
    return Record("ListMeshes", context);
  }
  grpc::Status GetBasis(grpc::ServerContext* context, const v1::GetBasisRequest*,
                        v1::BasisInfo*) override {
    return Record("GetBasis", context);
  }
  grpc::Status Solve(grpc::ServerContext* context, const v1::SolveRequest*,
                     v1::SolveResponse*) override {
    return Record("Solve", context);
  }
  grpc::Status BuildBasis(grpc::ServerContext* context, const v1::BuildBasisRequest*,
                          grpc::ServerWriter<v1::BuildBasisProgress>*) override {
    return Record("BuildBasis", context);
  }
  grpc::Status Lift(grpc::ServerContext* context, const v1::LiftRequest*,
                    grpc::ServerWriter<v1::FieldChunk>*) override {
    return Record("Lift", context);
  }
  grpc::Status Design(
      grpc::ServerContext* context,
      grpc::ServerReaderWriter<v1::DesignUpdate, v1::DesignRequest>* stream) override {
    v1::DesignRequest first;
    stream->Read(&first);
    return Record("Design", context);
  }

 private:
  grpc::Status Record(const std::string& method, grpc::ServerContext* context) {
    std::string key = "<none>";
    const auto& metadata = context->client_metadata();
    if (auto it = metadata.find(kRoutingKeyHeader); it != metadata.end()) {
      key = std::string(it->second.data(), it->second.size());
    }
    std::lock_guard<std::mutex> lock(mu_);
    calls_.emplace_back(method, key);
    return grpc::Status(grpc::StatusCode::NOT_FOUND, "recorded");
  }

  std::mutex mu_;
  std::vector<std::pair<std::string, std::string>> calls_;
};

class RoutingKeyTest : public ::testing::Test {
 protected:
  void SetUp() override {
    grpc::ServerBuilder builder;
    builder.AddListeningPort("127.0.0.1:0", grpc::InsecureServerCredentials(), &port_);
    builder.RegisterService(&service_);
    server_ = builder.BuildAndStart();
    ASSERT_NE(server_, nullptr);
    ASSERT_GT(port_, 0);
    FieldClientOptions options;
    options.address = "127.0.0.1:" + std::to_string(port_);
    auto client = FieldClient::Create(options);
    ASSERT_TRUE(client.ok()) << client.status();
    client_ = *std::move(client);
  }
  void TearDown() override {
    if (server_ != nullptr) server_->Shutdown();
  }

  RecordingService service_;
  int port_ = 0;
  std::unique_ptr<grpc::Server> server_;
  std::unique_ptr<FieldClient> client_;
};

TEST_F(RoutingKeyTest, RoutingKeyIsTheBasisIdElseTheMeshId) {
  v1::SolveRequest solve;
  solve.set_basis_id("b-1");
  EXPECT_EQ(RoutingKey(solve), "b-1");
  v1::BuildBasisRequest build;
  build.set_mesh_id("m-2");
  EXPECT_EQ(RoutingKey(build), "m-2");
  EXPECT_EQ(RoutingKey(v1::ListMeshesRequest()), "");
}

TEST_F(RoutingKeyTest, EveryCallThatNamesAnIdSendsIt) {
  v1::GetMeshRequest get_mesh;
  get_mesh.set_mesh_id("m-0000000000000001");
  EXPECT_FALSE(client_->GetMesh(get_mesh).ok());
  EXPECT_FALSE(client_->ListMeshes().ok());
  v1::GetBasisRequest get_basis;
  get_basis.set_basis_id("b-0000000000000002");
  EXPECT_FALSE(client_->GetBasis(get_basis).ok());
  v1::SolveRequest solve;
  solve.set_basis_id("b-0000000000000003");
  EXPECT_FALSE(client_->Solve(solve).ok());
  v1::BuildBasisRequest build;
  build.set_mesh_id("m-0000000000000004");
  EXPECT_FALSE(client_->BuildBasis(build).ok());
  v1::LiftRequest lift;
  lift.set_basis_id("b-0000000000000005");
  EXPECT_FALSE(client_->Lift(lift).ok());
  std::unique_ptr<DesignStream> design = client_->Design("b-0000000000000006");
  v1::OpenDesign open;
  open.set_basis_id("b-0000000000000006");
  EXPECT_FALSE(design->Open(open).ok());
  EXPECT_THAT(
      service_.calls(),
      ElementsAre(Pair("GetMesh", "m-0000000000000001"), Pair("ListMeshes", "<none>"),
                  Pair("GetBasis", "b-0000000000000002"), Pair("Solve", "b-0000000000000003"),
                  Pair("BuildBasis", "m-0000000000000004"), Pair("Lift", "b-0000000000000005"),
                  Pair("Design", "b-0000000000000006")));
}

TEST_F(RoutingKeyTest, TheCliSendsIt) {
  const std::string server = "127.0.0.1:" + std::to_string(port_);
  std::ostringstream out, err;
  EXPECT_NE(RunCli({"fieldspace", "--server", server, "basis", "b-00000000000000aa"}, out, err), 0)
      << err.str();
  EXPECT_NE(RunCli({"fieldspace", "--server", server, "mesh", "m-00000000000000bb"}, out, err), 0);
  EXPECT_THAT(service_.calls(), ElementsAre(Pair("GetBasis", "b-00000000000000aa"),
                                            Pair("GetMesh", "m-00000000000000bb")))
      << err.str();
}

}  // namespace
}  // namespace fieldspace::client
