#include "tests/testing/server_fixture.h"

#include <unistd.h>

#include <utility>

#include "absl/strings/str_cat.h"
#include "gtest/gtest.h"

namespace fieldspace::testing {

namespace fs = std::filesystem;

TempDir::TempDir(const std::string& name) {
  const ::testing::TestInfo* test = ::testing::UnitTest::GetInstance()->current_test_info();
  std::string dir = absl::StrCat("fs_", name, "_", ::getpid());
  if (test != nullptr) absl::StrAppend(&dir, "_", test->test_suite_name(), "_", test->name());
  for (char& c : dir) {
    if (c == '/') c = '_';  // parameterized test names
  }
  path_ = fs::temp_directory_path() / dir;
  fs::remove_all(path_);
  fs::create_directories(path_);
}

TempDir::~TempDir() {
  std::error_code ec;
  fs::remove_all(path_, ec);
}

std::unique_ptr<TestServer> TestServer::StartIn(const fs::path& root,
                                                server::FieldServerOptions options, bool fresh) {
  auto h = std::make_unique<TestServer>();
  h->root = root;
  if (fresh) fs::remove_all(h->root);
  fs::create_directories(h->root);
  options.listen = "127.0.0.1:0";
  if (options.store_dir.empty()) options.store_dir = (h->root / "store").string();
  if (options.threads == 0) options.threads = 2;
  auto started = server::FieldServer::Start(options);
  EXPECT_TRUE(started.ok()) << started.status();
  if (!started.ok()) return nullptr;
  h->server = *std::move(started);
  grpc::ChannelArguments args;
  args.SetMaxReceiveMessageSize(-1);
  args.SetMaxSendMessageSize(-1);
  h->channel =
      grpc::CreateCustomChannel(h->server->address(), grpc::InsecureChannelCredentials(), args);
  h->stub = fieldspace::v1::FieldSpace::NewStub(h->channel);
  return h;
}

std::unique_ptr<TestServer> TestServer::Start(const std::string& name,
                                              server::FieldServerOptions options) {
  auto dir = std::make_unique<TempDir>(name);
  std::unique_ptr<TestServer> h = StartIn(dir->path(), std::move(options), /*fresh=*/false);
  if (h != nullptr) h->owned_root = std::move(dir);
  return h;
}

void TestServer::Stop(std::chrono::milliseconds timeout) {
  if (server != nullptr) server->Shutdown(timeout);
  server.reset();
}

}  // namespace fieldspace::testing
