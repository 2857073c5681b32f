#ifndef FIELDSPACE_BENCH_COMMANDS_H_
#define FIELDSPACE_BENCH_COMMANDS_H_

#include "absl/status/status.h"

namespace fieldspace::bench {

// Each subcommand gets the arguments after its name and returns the process exit status.
int RunMesh(int argc, char** argv);
int RunShape(int argc, char** argv);
int RunOperator(int argc, char** argv);
int RunSpectrum(int argc, char** argv);
int RunBasis(int argc, char** argv);
int RunServeLoad(int argc, char** argv);
int RunApprox(int argc, char** argv);
int RunEigen(int argc, char** argv);
int RunDesign(int argc, char** argv);
int RunCurvature(int argc, char** argv);
int RunSmooth(int argc, char** argv);
int RunKernel(int argc, char** argv);

// Prints `status` as one line on stderr and returns the exit code: 2 for caller errors
// (InvalidArgument, NotFound, OutOfRange, FailedPrecondition, ResourceExhausted, DataLoss), else 1.
int ReportError(const absl::Status& status);

}  // namespace fieldspace::bench

#endif  // FIELDSPACE_BENCH_COMMANDS_H_
