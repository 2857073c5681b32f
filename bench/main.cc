// fieldspace-bench: runs the core directly on a mesh and prints one JSON object on stdout.
// Exit status: 0 on success, 2 on bad input (a one-line error on stderr), 1 on internal failure.
#include <cstdio>
#include <cstring>
#include <string>

#include "bench/commands.h"

namespace {

struct Command {
  const char* name;
  int (*run)(int argc, char** argv);
  const char* usage;
};

constexpr Command kCommands[] = {
    {"mesh", fieldspace::bench::RunMesh, "mesh FILE"},
    {"shape", fieldspace::bench::RunShape,
     "shape torus-knot|icosphere|torus|genus2 --out FILE.ply [--level N]"},
    {"operator", fieldspace::bench::RunOperator,
     "operator MESH --field vector|nfield|tensor [--n N] [--out DIR] [--timing]"},
    {"spectrum", fieldspace::bench::RunSpectrum,
     "spectrum MESH --field vector|nfield|tensor [--n N] --count K [--timing]"},
    {"basis", fieldspace::bench::RunBasis,
     "basis MESH --field vector|nfield|tensor [--n N] --dim D [--sigma S] [--threads T] "
     "[--weights FILE] [--save FILE] [--export-mtx DIR] [--seed N] [--no-kernel-columns]"},
    {"serve-load", fieldspace::bench::RunServeLoad,
     "serve-load MESH --dim D [--field vector|nfield|tensor] [--n N] [--sessions S] [--edits E] "
     "[--watch W] [--threads T] [--rate HZ] [--lifts L] [--server HOST:PORT]"},
    {"approx", fieldspace::bench::RunApprox,
     "approx MESH --field vector|nfield|tensor [--n N] --dim D [--sigma S] --tests K --seed N "
     "[--basis local|eigen] [--min-constraints A] [--max-constraints B] [--coarse-dim C] "
     "[--quality paper|low-modes|smooth] [--design-mu-c X] [--no-kernel-columns]"},
    {"eigen", fieldspace::bench::RunEigen,
     "eigen MESH --field vector|nfield|tensor [--n N] --count K --dim D [--sigma S] [--seed N] "
     "[--method auto|dense|sparse] [--full] [--coarse-dim C] [--quality paper|low-modes|smooth] "
     "[--no-kernel-columns]"},
    {"design", fieldspace::bench::RunDesign,
     "design MESH --field vector|nfield|tensor [--n N] --dim D --edits N --seed S [--sigma S] "
     "[--max-constraints C] [--no-full] [--full-biharmonic] [--no-kernel-columns]"},
    {"curvature", fieldspace::bench::RunCurvature,
     "curvature MESH [--estimator jet|normal-differences]"},
    {"kernel", fieldspace::bench::RunKernel, "kernel MESH --field vector|nfield|tensor [--n N]"},
    {"smooth", fieldspace::bench::RunSmooth,
     "smooth MESH --field tensor|vector|nfield [--n N] --dim D [--sigma S] [--seed N] "
     "[--coarse-dim C] [--quality paper|low-modes|smooth] [--mu-s X] [--mu-b X] [--mu-c X] "
     "[--repeat R] "
     "[--scale-free] [--no-kernel-columns]"},
};

void PrintUsage() {
  std::fprintf(stderr, "usage: fieldspace-bench COMMAND ...\ncommands:\n");
  for (const Command& c : kCommands) std::fprintf(stderr, "  %s\n", c.usage);
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2 || std::strcmp(argv[1], "--help") == 0 || std::strcmp(argv[1], "-h") == 0) {
    PrintUsage();
    return argc < 2 ? 2 : 0;
  }
  for (const Command& c : kCommands) {
    if (std::strcmp(argv[1], c.name) == 0) return c.run(argc - 2, argv + 2);
  }
  std::fprintf(stderr, "fieldspace-bench: unknown command '%s'\n", argv[1]);
  PrintUsage();
  return 2;
}
