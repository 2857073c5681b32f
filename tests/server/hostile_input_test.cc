// Regression tests for defects an adversarial probe found (issue "reliability and security", part
// B): each failed on 68a2fdc.

#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <memory>
#include <string>

#include "absl/strings/str_cat.h"
#include "fieldspace/v1/fieldspace.grpc.pb.h"
#include "grpcpp/grpcpp.h"
#include "gtest/gtest.h"
#include "server/field_server.h"

namespace fieldspace::server {
namespace {

namespace fs = std::filesystem;
namespace v1 = ::fieldspace::v1;

class HostileInputTest : public ::testing::Test {
 protected:
  void SetUp() override {
    root_ = fs::temp_directory_path() /
            absl::StrCat("fs_hostile_", ::getpid(), "_",
                         ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(root_);
  }
  void TearDown() override {
    if (server_ != nullptr) server_->Shutdown(std::chrono::seconds(2));
    server_.reset();
    fs::remove_all(root_);
  }
  void Start(FieldServerOptions options) {
    options.listen = "127.0.0.1:0";
    options.store_dir = (root_ / "store").string();
    options.threads = 2;
    auto started = FieldServer::Start(options);
    ASSERT_TRUE(started.ok()) << started.status();
    server_ = std::move(*started);
    stub_ = v1::FieldSpace::NewStub(
        grpc::CreateChannel(server_->address(), grpc::InsecureChannelCredentials()));
  }

  fs::path root_;
  std::unique_ptr<FieldServer> server_;
  std::unique_ptr<v1::FieldSpace::Stub> stub_;
};

// B4: an upload header announcing a size that cannot be reserved threw out of the read callback:
// the call never finished and shutdown waited for it forever.
TEST_F(HostileInputTest, UnreservableUploadSizeEndsTheCallAndShutdownCompletes) {
  FieldServerOptions options;
  options.max_upload_mb = int64_t{1} << 30;  // a limit that does not catch the size first
  Start(options);
  v1::MeshInfo info;
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(20));
  auto writer = stub_->UploadMesh(&context, &info);
  v1::UploadMeshRequest header;
  header.mutable_header()->set_name("huge.obj");
  header.mutable_header()->set_total_bytes(uint64_t{1} << 49);
  writer->Write(header);
  writer->WritesDone();
  const grpc::Status status = writer->Finish();
  EXPECT_NE(status.error_code(), grpc::StatusCode::OK);
  EXPECT_NE(status.error_code(), grpc::StatusCode::DEADLINE_EXCEEDED) << status.error_message();
  const auto start = std::chrono::steady_clock::now();
  server_->Shutdown(std::chrono::seconds(2));
  EXPECT_LT(std::chrono::steady_clock::now() - start, std::chrono::seconds(5));
}

// B9: the authorization scheme is case-insensitive (RFC 7235); the token is not.
TEST_F(HostileInputTest, BearerSchemeIsCaseInsensitive) {
  FieldServerOptions options;
  options.auth_token = "s3cret";
  Start(options);
  const auto list = [&](const std::string& header) {
    grpc::ClientContext context;
    context.AddMetadata("authorization", header);
    v1::ListMeshesResponse response;
    return stub_->ListMeshes(&context, v1::ListMeshesRequest(), &response).error_code();
  };
  EXPECT_EQ(list("Bearer s3cret"), grpc::StatusCode::OK);
  EXPECT_EQ(list("bearer s3cret"), grpc::StatusCode::OK);
  EXPECT_EQ(list("BEARER s3cret"), grpc::StatusCode::OK);
  EXPECT_EQ(list("Bearer S3CRET"), grpc::StatusCode::UNAUTHENTICATED);
  EXPECT_EQ(list("Basic s3cret"), grpc::StatusCode::UNAUTHENTICATED);
  EXPECT_EQ(list("Bearer"), grpc::StatusCode::UNAUTHENTICATED);
  EXPECT_EQ(list("s3cret"), grpc::StatusCode::UNAUTHENTICATED);
}

}  // namespace
}  // namespace fieldspace::server
