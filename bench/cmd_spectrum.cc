// `fieldspace-bench spectrum MESH --field vector|nfield|tensor [--n N] --count K [--timing]`:
// the K lowest eigenvalues of S x = lambda M x for the field operator (full space, CHOLMOD +
// Spectra shift-invert), ascending: {"eigenvalues":[...]}; --timing adds
// "seconds":{"load":..,"assemble":..,"eigensolve":..}.
#include <cstdio>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "bench/bench_util.h"
#include "bench/cmd_operator.h"
#include "bench/commands.h"
#include "core/linalg/eigensolver.h"
#include "core/operators/field_operator.h"
#include "core/operators/reference_solvers.h"

namespace fieldspace::bench {

int RunSpectrum(const Args& args) {
  auto type = FieldTypeFromArgs(args);
  if (!type.ok()) return ReportError(type.status());
  auto count = args.GetInt("count", 0);
  if (!count.ok()) return ReportError(count.status());
  if (*count < 1 || *count > (int64_t{1} << 20)) {
    return ReportError(absl::InvalidArgumentError("--count must be >= 1"));
  }

  Stopwatch load_watch;
  auto mesh = LoadBenchMesh(args.positional()[0]);
  if (!mesh.ok()) return ReportError(mesh.status());
  const double load_seconds = load_watch.Seconds();
  Stopwatch assemble_watch;
  auto op = BuildFieldOperator(*mesh, *type);
  if (!op.ok()) return ReportError(op.status());
  const double assemble_seconds = assemble_watch.Seconds();

  Stopwatch eigen_watch;
  EigenOptions options;
  options.count = static_cast<int32_t>(*count);
  options.compute_vectors = false;
  auto result = ReferenceEigenpairs(*op, options);
  if (!result.ok()) return ReportError(result.status());
  const double eigen_seconds = eigen_watch.Seconds();

  JsonWriter json;
  json.BeginObject().DoubleArray(
      "eigenvalues",
      std::vector<double>(result->values.data(), result->values.data() + result->values.size()));
  if (args.Has("timing")) {
    json.BeginObject("seconds")
        .Double("load", load_seconds)
        .Double("assemble", assemble_seconds)
        .Double("eigensolve", eigen_seconds)
        .EndObject();
  }
  json.EndObject();
  std::printf("%s\n", json.str().c_str());
  return 0;
}

}  // namespace fieldspace::bench
