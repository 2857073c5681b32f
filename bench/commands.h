#ifndef FIELDSPACE_BENCH_COMMANDS_H_
#define FIELDSPACE_BENCH_COMMANDS_H_

#include "absl/status/status.h"
#include "bench/bench_util.h"

namespace fieldspace::bench {

// Each subcommand gets its arguments parsed and checked against the command table of main.cc
// (its flags, the required ones, the number of positional arguments) and returns the process
// exit status.
int RunMesh(const Args& args);
int RunShape(const Args& args);
int RunOperator(const Args& args);
int RunSpectrum(const Args& args);
int RunBasis(const Args& args);
int RunServeLoad(const Args& args);
int RunApprox(const Args& args);
int RunEigen(const Args& args);
int RunDesign(const Args& args);
int RunCurvature(const Args& args);
int RunSmooth(const Args& args);
int RunKernel(const Args& args);

// Prints `status` as one line on stderr and returns the exit code: 2 for caller errors
// (InvalidArgument, NotFound, OutOfRange, FailedPrecondition, ResourceExhausted, DataLoss), else 1.
int ReportError(const absl::Status& status);

}  // namespace fieldspace::bench

#endif  // FIELDSPACE_BENCH_COMMANDS_H_
