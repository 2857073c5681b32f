// The command-line parser shared by fieldspaced, fieldspace and fieldspace-bench, and the command
// table of fieldspace and fieldspace-bench.

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

// The command table: one CommandDoc gives the parser, the checks and the usage.
CommandDoc BuildDoc() {
  return {"build",
          "MESH_ID [EXTRA]",
          {{"field", "vector|nfield|tensor", true},
           {"dim", "D", true},
           {"sigma", "S"},
           {"no-kernel-columns", ""}},
          "build a basis of D columns"};
}

TEST(CommandTableTest, TheDocIsTheParser) {
  const FlagSpec spec = FlagSpecOf(BuildDoc(), {"help"});
  EXPECT_THAT(spec.value_flags, ElementsAre("field", "dim", "sigma"));
  EXPECT_THAT(spec.switches, ElementsAre("help", "no-kernel-columns"));
  auto a = ParseCommand(BuildDoc(), std::vector<std::string>{"m-1", "--field", "vector", "--dim",
                                                             "40", "--no-kernel-columns"});
  ASSERT_TRUE(a.ok()) << a.status();
  EXPECT_THAT(a->positional(), ElementsAre("m-1"));
  EXPECT_EQ(*a->GetInt("dim", 0), 40);
  EXPECT_TRUE(a->Has("no-kernel-columns"));
  // A flag the doc does not list is refused, as is a value given to a switch.
  EXPECT_EQ(ParseCommand(BuildDoc(), std::vector<std::string>{"m-1", "--field", "vector", "--dim",
                                                              "4", "--seed", "3"})
                .status()
                .message(),
            "unknown flag --seed");
  EXPECT_EQ(ParseCommand(BuildDoc(), std::vector<std::string>{"m-1", "--field", "vector", "--dim",
                                                              "4", "--no-kernel-columns=1"})
                .status()
                .message(),
            "--no-kernel-columns takes no value");
}

TEST(CommandTableTest, RequiredFlagsAndArgumentCountsAreChecked) {
  auto missing = ParseCommand(BuildDoc(), std::vector<std::string>{"m-1", "--dim", "4"});
  EXPECT_EQ(missing.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(missing.status().message(), "build needs --field vector|nfield|tensor");
  EXPECT_TRUE(ParseCommand(BuildDoc(),
                           std::vector<std::string>{"m-1", "x", "--field", "tensor", "--dim", "4"})
                  .ok());
  EXPECT_EQ(ParseCommand(BuildDoc(), std::vector<std::string>{"--field", "tensor", "--dim", "4"})
                .status()
                .message(),
            "build takes 1 to 2 argument(s), got 0");
  CommandDoc mesh = {"mesh", "FILE", {}, ""};
  EXPECT_EQ(ParseCommand(mesh, std::vector<std::string>{"a", "b"}).status().message(),
            "mesh takes 1 argument(s), got 2");
  CommandDoc align = {"align", "", {{"curvature", "", true}}, ""};
  EXPECT_EQ(ParseCommand(align, std::vector<std::string>{}).status().message(),
            "align needs --curvature");
}

TEST(CommandTableTest, UsageShowsEveryFlagAsParsed) {
  EXPECT_EQ(FormatCommandUsage(BuildDoc(), 2, 6, 100),
            "  build MESH_ID [EXTRA] --field vector|nfield|tensor --dim D [--sigma S] "
            "[--no-kernel-columns]\n"
            "      build a basis of D columns\n");
  // Wrapped: continued lines indented by 4 more, no flag split across lines.
  EXPECT_EQ(FormatCommandUsage(BuildDoc(), 0, 2, 40),
            "build MESH_ID [EXTRA]\n"
            "    --field vector|nfield|tensor --dim D\n"
            "    [--sigma S] [--no-kernel-columns]\n"
            "  build a basis of D columns\n");
  // A short synopsis: the help starts on its line, at its column.
  EXPECT_EQ(FormatCommandUsage({"mesh", "FILE", {}, "one mesh of the store, as JSON"}, 2, 20, 40),
            "  mesh FILE         one mesh of the\n"
            "                    store, as JSON\n");
}

}  // namespace
}  // namespace fieldspace
