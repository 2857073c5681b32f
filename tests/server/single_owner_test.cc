// One daemon per port and one daemon per store: a second FieldServer on a port or a store that is
// already in use must refuse to start, with a message that says why (issue: two daemons on one
// port split the traffic; two on one store both deleted the same files).

#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <memory>
#include <string>

#include "absl/strings/str_cat.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "server/field_server.h"
#include "server/store_lock.h"

namespace fieldspace::server {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;

class SingleOwnerTest : public ::testing::Test {
 protected:
  void SetUp() override {
    root_ = fs::temp_directory_path() /
            absl::StrCat("fs_single_owner_", ::getpid(), "_",
                         ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(root_);
    fs::create_directories(root_);
  }
  void TearDown() override { fs::remove_all(root_); }

  FieldServerOptions Options(const std::string& store, const std::string& listen) const {
    FieldServerOptions options;
    options.listen = listen;
    options.store_dir = (root_ / store).string();
    options.threads = 1;
    return options;
  }

  fs::path root_;
};

TEST_F(SingleOwnerTest, SecondServerOnTheSamePortFailsWithAddressInUse) {
  auto first = FieldServer::Start(Options("a", "127.0.0.1:0"));
  ASSERT_TRUE(first.ok()) << first.status();
  auto second = FieldServer::Start(Options("b", (*first)->address()));
  ASSERT_FALSE(second.ok());
  EXPECT_EQ(second.status().code(), absl::StatusCode::kUnavailable);
  EXPECT_THAT(second.status().message(), HasSubstr("address already in use"));
  // The refused server released its store: it can be used right away.
  auto third = FieldServer::Start(Options("b", "127.0.0.1:0"));
  EXPECT_TRUE(third.ok()) << third.status();
}

TEST_F(SingleOwnerTest, SecondServerOnTheSameStoreFailsNamingTheFirstPid) {
  auto first = FieldServer::Start(Options("store", "127.0.0.1:0"));
  ASSERT_TRUE(first.ok()) << first.status();
  auto second = FieldServer::Start(Options("store", "127.0.0.1:0"));
  ASSERT_FALSE(second.ok());
  EXPECT_EQ(second.status().code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_THAT(second.status().message(), HasSubstr(absl::StrCat("pid ", ::getpid())));
  // Once the first is gone, the store is free again (the lock dies with its holder).
  (*first)->Shutdown(std::chrono::milliseconds(100));
  first->reset();
  auto third = FieldServer::Start(Options("store", "127.0.0.1:0"));
  EXPECT_TRUE(third.ok()) << third.status();
}

TEST_F(SingleOwnerTest, SharedLocksCoexistButExcludeAnExclusiveOne) {
  const std::string dir = (root_ / "shared").string();
  auto a = StoreLock::Acquire(dir, StoreLockMode::kShared);
  ASSERT_TRUE(a.ok()) << a.status();
  auto b = StoreLock::Acquire(dir, StoreLockMode::kShared);
  EXPECT_TRUE(b.ok()) << b.status();
  auto c = StoreLock::Acquire(dir, StoreLockMode::kExclusive);
  EXPECT_EQ(c.status().code(), absl::StatusCode::kFailedPrecondition);
}

TEST_F(SingleOwnerTest, LockFileRecordsThePid) {
  const std::string dir = (root_ / "pid").string();
  auto lock = StoreLock::Acquire(dir, StoreLockMode::kExclusive);
  ASSERT_TRUE(lock.ok()) << lock.status();
  std::ifstream in(fs::path(dir) / "LOCK");
  int pid = 0;
  in >> pid;
  EXPECT_EQ(pid, ::getpid());
}

}  // namespace
}  // namespace fieldspace::server
