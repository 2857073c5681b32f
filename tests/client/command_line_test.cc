// The command-line parser shared by fieldspaced, fieldspace and fieldspace-bench.

#include "core/common/command_line.h"

#include <string>
#include <vector>

#include "gmock/gmock.h"
#include "gtest/gtest.h"

namespace fieldspace {
namespace {

using ::testing::ElementsAre;

FlagSpec Spec() {
  FlagSpec spec;
  spec.value_flags = {"dim", "sigma", "out"};
  spec.switches = {"timing"};
  return spec;
}

absl::StatusOr<CommandLine> Parse(const std::vector<std::string>& args,
                                  const FlagSpec& spec = Spec()) {
  return CommandLine::Parse(args, spec);
}

TEST(CommandLineTest, ValuesSwitchesAndPositionalsInAnyOrder) {
  auto a = Parse({"mesh.obj", "--dim", "40", "--sigma=2.5", "--timing", "x", "--out", "-"});
  ASSERT_TRUE(a.ok()) << a.status();
  EXPECT_THAT(a->positional(), ElementsAre("mesh.obj", "x"));
  EXPECT_EQ(a->Get("dim"), "40");
  EXPECT_EQ(a->Get("sigma"), "2.5");
  EXPECT_EQ(a->Get("out"), "-");
  EXPECT_TRUE(a->Has("timing"));
  EXPECT_EQ(a->Get("timing"), "");
  EXPECT_FALSE(a->Has("missing"));
  EXPECT_EQ(a->Get("missing"), std::nullopt);
  EXPECT_EQ(*a->GetInt("dim", 0), 40);
  EXPECT_EQ(*a->GetDouble("sigma", 0), 2.5);
  EXPECT_EQ(*a->GetInt("missing", 7), 7);
  EXPECT_EQ(*a->GetDouble("missing", 0.5), 0.5);
}

TEST(CommandLineTest, ValuesAreTakenVerbatimAndTheLastOneWins) {
  auto a = Parse({"--sigma", "-1", "--dim", "3", "--dim=5", "--out="});
  ASSERT_TRUE(a.ok()) << a.status();
  EXPECT_EQ(*a->GetDouble("sigma", 0), -1.0);
  EXPECT_EQ(*a->GetInt("dim", 0), 5);
  EXPECT_EQ(a->Get("out"), "");
  EXPECT_TRUE(a->positional().empty());
}

TEST(CommandLineTest, UnknownFlagsAreRejected) {
  auto a = Parse({"mesh.obj", "--bogus", "1"});
  EXPECT_EQ(a.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(a.status().message(), "unknown flag --bogus");
  EXPECT_EQ(Parse({"--bogus=1"}).status().message(), "unknown flag --bogus");
  EXPECT_EQ(Parse({"--dim=3", "--"}).status().code(), absl::StatusCode::kOk);
}

TEST(CommandLineTest, MissingValueAndSwitchWithValue) {
  auto a = Parse({"mesh.obj", "--dim"});
  EXPECT_EQ(a.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(a.status().message(), "--dim needs a value");
  auto b = Parse({"--timing=yes"});
  EXPECT_EQ(b.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(b.status().message(), "--timing takes no value");
}

TEST(CommandLineTest, BadNumbersNameTheFlagAndTheValue) {
  auto a = Parse({"--dim", "4x", "--sigma", "nan", "--out", "99999999999"});
  ASSERT_TRUE(a.ok()) << a.status();
  EXPECT_EQ(a->GetInt("dim", 0).status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(a->GetInt("dim", 0).status().message(), "--dim: not an integer: '4x'");
  EXPECT_EQ(a->GetDouble("sigma", 0).status().message(), "--sigma: not a finite number: 'nan'");
  EXPECT_EQ(a->GetDouble("dim", 0).status().message(), "--dim: not a finite number: '4x'");
  EXPECT_EQ(*a->GetInt("out", 0), 99999999999);
  EXPECT_EQ(a->GetInt32("out", 0).status().message(), "--out: not an integer: '99999999999'");
  auto inf = Parse({"--sigma=inf"});
  EXPECT_EQ(inf->GetDouble("sigma", 0).status().code(), absl::StatusCode::kInvalidArgument);
}

TEST(CommandLineTest, DoubleDashEndsTheFlags) {
  auto a = Parse({"--dim", "2", "--", "--timing", "-h"});
  ASSERT_TRUE(a.ok()) << a.status();
  EXPECT_THAT(a->positional(), ElementsAre("--timing", "-h"));
  EXPECT_FALSE(a->Has("timing"));
}

TEST(CommandLineTest, StopAtPositionalLeavesASubcommandsArguments) {
  FlagSpec global;
  global.value_flags = {"server"};
  global.switches = {"help"};
  global.stop_at_positional = true;
  auto a = Parse({"--server=h:1", "build", "m-1", "--dim", "3", "--server", "x"}, global);
  ASSERT_TRUE(a.ok()) << a.status();
  EXPECT_EQ(a->Get("server"), "h:1");
  EXPECT_THAT(a->positional(), ElementsAre("build", "m-1", "--dim", "3", "--server", "x"));
  EXPECT_EQ(Parse({"--dim", "3", "build"}, global).status().message(), "unknown flag --dim");
}

TEST(CommandLineTest, BenchFormTakesAnyFlagWithAValueAndChecksLater) {
  const char* argv[] = {"mesh.obj", "--dim", "10", "--stats", "--seed=3"};
  auto a = CommandLine::Parse(5, argv, {"stats"});
  ASSERT_TRUE(a.ok()) << a.status();
  EXPECT_THAT(a->positional(), ElementsAre("mesh.obj"));
  EXPECT_EQ(*a->GetInt("seed", 0), 3);
  EXPECT_TRUE(a->CheckKnown({"dim", "stats", "seed"}).ok());
  absl::Status unknown = a->CheckKnown({"dim", "stats"});
  EXPECT_EQ(unknown.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(unknown.message(), "unknown flag --seed");
  const char* missing[] = {"--dim"};
  EXPECT_EQ(CommandLine::Parse(1, missing, {}).status().message(), "--dim needs a value");
}

}  // namespace
}  // namespace fieldspace
