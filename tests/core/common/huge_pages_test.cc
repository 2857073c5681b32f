#include "core/common/huge_pages.h"

#include <cstdlib>
#include <fstream>
#include <optional>
#include <string>

#include "gtest/gtest.h"

namespace fieldspace {
namespace {

HugePageEnvironment Madvise() {
  HugePageEnvironment env;
  env.thp_enabled = "always [madvise] never";
  env.glibc_version = "2.36";
  return env;
}

TEST(HugePagesTest, AsksForTheTunableWhereTheKernelAndGlibcCanGiveIt) {
  EXPECT_EQ(HugePageTunables(Madvise()), "glibc.malloc.hugetlb=1");
  HugePageEnvironment always = Madvise();
  always.thp_enabled = "[always] madvise never";
  EXPECT_EQ(HugePageTunables(always), "glibc.malloc.hugetlb=1");
  HugePageEnvironment newer = Madvise();
  newer.glibc_version = "3.0";
  EXPECT_EQ(HugePageTunables(newer), "glibc.malloc.hugetlb=1");
}

TEST(HugePagesTest, KeepsTheUsersOtherTunables) {
  HugePageEnvironment env = Madvise();
  env.glibc_tunables = "glibc.malloc.arena_max=2";
  EXPECT_EQ(HugePageTunables(env), "glibc.malloc.arena_max=2:glibc.malloc.hugetlb=1");
  env.glibc_tunables = "";
  EXPECT_EQ(HugePageTunables(env), "glibc.malloc.hugetlb=1");
}

TEST(HugePagesTest, LeavesTheProcessAloneWhenItShould) {
  HugePageEnvironment env = Madvise();
  env.glibc_tunables = "glibc.malloc.hugetlb=0";  // the user's own choice
  EXPECT_EQ(HugePageTunables(env), std::nullopt);
  env = Madvise();
  env.glibc_tunables = "glibc.malloc.arena_max=2:glibc.malloc.hugetlb=2";
  EXPECT_EQ(HugePageTunables(env), std::nullopt);
  env = Madvise();
  env.opt_out = "0";
  EXPECT_EQ(HugePageTunables(env), std::nullopt);
  env = Madvise();
  env.opt_out = "1";  // anything but "0" keeps the default
  EXPECT_EQ(HugePageTunables(env), "glibc.malloc.hugetlb=1");
  env = Madvise();
  env.reexecuted = "1";  // never a second exec, whatever glibc did to GLIBC_TUNABLES
  EXPECT_EQ(HugePageTunables(env), std::nullopt);
  env = Madvise();
  env.thp_enabled = "always madvise [never]";
  EXPECT_EQ(HugePageTunables(env), std::nullopt);
  env.thp_enabled = "";  // no THP in this kernel
  EXPECT_EQ(HugePageTunables(env), std::nullopt);
  env = Madvise();
  env.glibc_version = "2.34";  // before glibc.malloc.hugetlb
  EXPECT_EQ(HugePageTunables(env), std::nullopt);
  env.glibc_version = "";  // not glibc
  EXPECT_EQ(HugePageTunables(env), std::nullopt);
  env.glibc_version = "2";
  EXPECT_EQ(HugePageTunables(env), std::nullopt);
  // A tunable whose name only ends like ours is not ours.
  env = Madvise();
  env.glibc_tunables = "x.glibc.malloc.hugetlb=1";
  EXPECT_EQ(HugePageTunables(env), "x.glibc.malloc.hugetlb=1:glibc.malloc.hugetlb=1");
}

// Passes in a normal run. ReexecWithHugePageMalloc sets kHugePageMarker on the program it
// re-executes, and FailingArgv re-executes this binary with this test alone: an exec that should
// not have happened makes the test that called it fail.
TEST(HugePagesTest, NotStartedByAReexecution) {
  EXPECT_EQ(std::getenv(kHugePageMarker), nullptr)
      << "ReexecWithHugePageMalloc re-executed although it should not have";
}

char** FailingArgv() {
  static char program[] = "huge_pages_test";
  static char filter[] = "--gtest_filter=HugePagesTest.NotStartedByAReexecution";
  static char* argv[] = {program, filter, nullptr};
  return argv;
}

TEST(HugePagesTest, ReadsThisProcesssEnvironment) {
  ASSERT_EQ(setenv("FIELDSPACE_HUGE_PAGES", "0", 1), 0);
  const HugePageEnvironment env = CurrentHugePageEnvironment();
  ASSERT_NE(env.opt_out, nullptr);
  EXPECT_STREQ(env.opt_out, "0");
  std::ifstream thp("/sys/kernel/mm/transparent_hugepage/enabled");
  std::string line;
  if (thp && std::getline(thp, line)) EXPECT_EQ(env.thp_enabled, line);
#if defined(__GLIBC__)
  EXPECT_FALSE(env.glibc_version.empty());
#endif
  // Opted out: returns without an exec.
  ReexecWithHugePageMalloc(FailingArgv());
  unsetenv("FIELDSPACE_HUGE_PAGES");
}

TEST(HugePagesTest, TheReexecutedProcessDropsItsMarker) {
  // As in the re-executed process: the marker is set. No second exec (the marker says so), and
  // the marker is gone afterwards, so that programs this one starts decide for themselves.
  ASSERT_EQ(setenv(kHugePageMarker, "1", 1), 0);
  ReexecWithHugePageMalloc(FailingArgv());
  EXPECT_EQ(std::getenv(kHugePageMarker), nullptr);
}

}  // namespace
}  // namespace fieldspace
