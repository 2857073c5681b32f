// fieldspace-bench: runs the core directly on a mesh and prints one JSON object on stdout.
// Exit status: 0 on success, 2 on bad input (a one-line error on stderr), 1 on internal failure.
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

#include "absl/strings/ascii.h"
#include "absl/strings/str_cat.h"
#include "bench/commands.h"
#include "core/common/command_line.h"
#include "core/common/huge_pages.h"

namespace fieldspace::bench {
namespace {

struct Command {
  CommandDoc doc;  // flags and usage, written once
  int (*run)(const Args& args);
};

// Flags several commands share.
FlagDoc Field(bool required = true) { return {"field", "vector|nfield|tensor", required}; }
const FlagDoc kN = {"n", "N"};
const FlagDoc kSigma = {"sigma", "S"};
const FlagDoc kSeed = {"seed", "N"};
const FlagDoc kCoarseDim = {"coarse-dim", "C"};
const FlagDoc kQuality = {"quality", "paper|low-modes|smooth"};
const FlagDoc kBiharmonic = {"biharmonic", "exact|mixed"};
const FlagDoc kNoKernelColumns = {"no-kernel-columns", ""};
FlagDoc Dim(bool required = true) { return {"dim", "D", required}; }

const std::vector<Command>& Commands() {
  static const std::vector<Command> commands = {
      {{"mesh", "FILE", {}}, RunMesh},
      {{"shape", "torus-knot|icosphere|torus|genus2", {{"out", "FILE.ply", true}, {"level", "N"}}},
       RunShape},
      {{"operator", "MESH", {Field(), kN, {"out", "DIR"}, {"timing", ""}}}, RunOperator},
      {{"spectrum", "MESH", {Field(), kN, {"count", "K", true}, {"timing", ""}}}, RunSpectrum},
      {{"basis",
        "MESH",
        {Field(),
         kN,
         Dim(),
         kSigma,
         {"threads", "T"},
         {"weights", "FILE"},
         {"save", "FILE"},
         {"export-mtx", "DIR"},
         kSeed,
         {"stats", ""},
         {"tolerance", "T"},
         kNoKernelColumns,
         kCoarseDim,
         kQuality}},
       RunBasis},
      {{"serve-load",
        "MESH",
        {Dim(),
         Field(false),
         kN,
         {"sessions", "S"},
         {"edits", "E"},
         {"watch", "W"},
         {"threads", "T"},
         {"rate", "HZ"},
         {"lifts", "L"},
         {"server", "HOST:PORT"}}},
       RunServeLoad},
      {{"approx",
        "MESH",
        {Field(),
         kN,
         Dim(),
         kSigma,
         {"tests", "K", true},
         kSeed,
         {"basis", "local|eigen"},
         {"min-constraints", "A"},
         {"max-constraints", "B"},
         kCoarseDim,
         kQuality,
         {"design-mu-c", "X"},
         kBiharmonic,
         kNoKernelColumns}},
       RunApprox},
      {{"eigen",
        "MESH",
        {Field(),
         kN,
         {"count", "K", true},
         Dim(),
         kSigma,
         kSeed,
         {"method", "auto|dense|sparse"},
         {"full", ""},
         kCoarseDim,
         kQuality,
         kNoKernelColumns}},
       RunEigen},
      {{"design",
        "MESH",
        {Field(),
         kN,
         Dim(),
         {"edits", "N", true},
         kSeed,
         kSigma,
         {"max-constraints", "C"},
         {"no-full", ""},
         {"full-biharmonic", ""},
         kNoKernelColumns,
         kCoarseDim,
         kQuality,
         kBiharmonic,
         {"strokes", "K"},
         {"stroke-faces", "F"},
         {"verify-every", "K"}}},
       RunDesign},
      {{"curvature", "MESH", {{"estimator", "jet|normal-differences"}}}, RunCurvature},
      {{"kernel", "MESH", {Field(), kN, {"poisson", "multigrid|cholesky"}}}, RunKernel},
      {{"smooth",
        "MESH",
        {Field(),
         kN,
         Dim(),
         kSigma,
         kSeed,
         kCoarseDim,
         kQuality,
         {"mu-s", "X"},
         {"mu-b", "X"},
         {"mu-c", "X"},
         {"repeat", "R"},
         {"scale-free", ""},
         kNoKernelColumns}},
       RunSmooth},
  };
  return commands;
}

constexpr int kWidth = 100;

void PrintUsage() {
  std::fprintf(stderr, "usage: fieldspace-bench COMMAND ...\ncommands:\n");
  for (const Command& c : Commands()) {
    std::fprintf(stderr, "%s", FormatCommandUsage(c.doc, 2, 6, kWidth).c_str());
  }
}

int Run(int argc, char** argv) {
  if (argc < 2 || std::strcmp(argv[1], "--help") == 0 || std::strcmp(argv[1], "-h") == 0) {
    PrintUsage();
    return argc < 2 ? 2 : 0;
  }
  for (const Command& c : Commands()) {
    if (c.doc.name != argv[1]) continue;
    const std::vector<std::string> rest(argv + 2, argv + argc);
    absl::StatusOr<CommandLine> args = ParseCommand(c.doc, rest);
    if (!args.ok()) {
      // The message, then the command's usage, on one line as every bench error.
      return ReportError(absl::Status(
          args.status().code(),
          absl::StrCat(args.status().message(), "; usage: fieldspace-bench ",
                       absl::StripAsciiWhitespace(FormatCommandUsage(c.doc, 0, 0, 1 << 20)))));
    }
    return c.run(*args);
  }
  std::fprintf(stderr, "fieldspace-bench: unknown command '%s'\n", argv[1]);
  PrintUsage();
  return 2;
}

}  // namespace
}  // namespace fieldspace::bench

int main(int argc, char** argv) {
  fieldspace::ReexecWithHugePageMalloc(argv);
  return fieldspace::bench::Run(argc, argv);
}
