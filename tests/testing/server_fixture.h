#ifndef FIELDSPACE_TESTS_TESTING_SERVER_FIXTURE_H_
#define FIELDSPACE_TESTS_TESTING_SERVER_FIXTURE_H_

// The server tests' fixture: a temporary directory per test, and an in-process FieldServer on
// 127.0.0.1:0 with its store in one, a channel and a stub.

#include <chrono>
#include <filesystem>
#include <memory>
#include <string>

#include "fieldspace/v1/fieldspace.grpc.pb.h"
#include "grpcpp/grpcpp.h"
#include "server/field_server.h"

namespace fieldspace::testing {

// A fresh directory under the system's temporary directory, named after `name`, the process and
// the running test (so that tests and parallel test processes never share one); removed with
// everything in it on destruction.
class TempDir {
 public:
  explicit TempDir(const std::string& name);
  ~TempDir();
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;

  const std::filesystem::path& path() const { return path_; }
  // `name` inside the directory.
  std::filesystem::path operator/(const std::string& name) const { return path_ / name; }

 private:
  std::filesystem::path path_;
};

// A running FieldServer with a channel and a stub (messages of any size both ways).
struct TestServer {
  std::unique_ptr<TempDir> owned_root;  // when the server made its own directory
  std::filesystem::path root;  // the server's directory (the store is root/store unless given)
  std::unique_ptr<server::FieldServer> server;
  std::shared_ptr<grpc::Channel> channel;
  std::unique_ptr<fieldspace::v1::FieldSpace::Stub> stub;

  // Starts a server in `root` (created; emptied first when `fresh`): options.listen is
  // 127.0.0.1:0, options.store_dir root/store unless set, options.threads 2 unless set. Null
  // (and a test failure) when the server does not start.
  static std::unique_ptr<TestServer> StartIn(const std::filesystem::path& root,
                                             server::FieldServerOptions options, bool fresh = true);
  // The same in a TempDir(`name`) of its own, removed with the server.
  static std::unique_ptr<TestServer> Start(const std::string& name,
                                           server::FieldServerOptions options = {});
  // Shuts the server down (waiting up to `timeout` for calls to end); the directory stays.
  void Stop(std::chrono::milliseconds timeout = std::chrono::seconds(5));
  const std::string& address() const { return server->address(); }
  ~TestServer() { Stop(); }
};

}  // namespace fieldspace::testing

#endif  // FIELDSPACE_TESTS_TESTING_SERVER_FIXTURE_H_
