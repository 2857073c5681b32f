// `fieldspace-bench eigen MESH --field vector|nfield|tensor [--n N] --count K --dim D
//  [--sigma S] [--seed N] [--method auto|dense|sparse] [--full] [--no-kernel-columns]`:
// the reduced eigenproblem of paper section 8 ("Laplace spectrum", Table 6): the K lowest
// eigenvalues of (U^T S U) y = lambda (U^T M U) y in a D-dimensional local basis, on the mesh
// scaled to unit total area. With --full also the full-space reference eigenvalues (CHOLMOD +
// Spectra) and their relative errors. Prints
//   {"reduced":[...],"full":[...],"relative_errors":[...],
//    "seconds":{"basis","basis_kernel","reduced_system","solve","full"},"method",
//    "full_kernel_dimension","kernel_ratio","dim","kernel_columns","nnz_u"}
// "dim" counts all columns (D local ones and the kernel columns, BasisOptions::kernel_columns);
// seconds.basis_kernel is the kernel columns' share of seconds.basis. kernel_ratio (with --full,
// when the full space has a kernel of dimension z): the largest of the z lowest reduced
// eigenvalues divided by the (z+1)-th full-space eigenvalue (0 when the kernel is reproduced
// exactly; the local basis alone gives O(1)).
// ("full" and "relative_errors" empty and seconds.full 0 without --full; relative_errors null
// where the full eigenvalue is numerically zero, i.e. for the 2g harmonic fields of genus g).
#include <cmath>
#include <cstdio>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "bench/bench_util.h"
#include "bench/cmd_operator.h"
#include "bench/cmd_subspace.h"
#include "bench/commands.h"
#include "core/operators/field_operator.h"
#include "core/operators/reference_solvers.h"
#include "core/subspace/reduced_system.h"
#include "core/subspace/spectrum.h"

namespace fieldspace::bench {

int RunEigen(const Args& args) {
  auto type = FieldTypeFromArgs(args);
  if (!type.ok()) return ReportError(type.status());
  auto count = args.GetInt("count", 0);
  if (!count.ok()) return ReportError(count.status());
  if (*count < 1 || *count > 100000) {
    return ReportError(absl::InvalidArgumentError("--count must be in [1, 100000]"));
  }
  ReducedEigenOptions options;
  options.count = static_cast<int32_t>(*count);
  options.compute_vectors = true;  // the eigenfields are part of the timed work
  const std::string method = args.Get("method").value_or("auto");
  if (method == "dense") {
    options.method = ReducedEigenMethod::kDense;
  } else if (method == "sparse") {
    options.method = ReducedEigenMethod::kSparse;
  } else if (method != "auto") {
    return ReportError(absl::InvalidArgumentError("--method must be auto, dense or sparse"));
  }

  auto sub = LoadBenchSubspace(args, *type);
  if (!sub.ok()) return ReportError(sub.status());

  Stopwatch solve_watch;
  auto reduced = ReducedEigenpairs(*sub->system, options);
  if (!reduced.ok()) return ReportError(reduced.status());
  const double solve_seconds = solve_watch.Seconds();

  std::vector<double> full_values, relative_errors;
  int64_t kernel_dimension = 0;
  double kernel_ratio = std::numeric_limits<double>::quiet_NaN();
  double full_seconds = 0;
  if (args.Has("full")) {
    Stopwatch full_watch;
    EigenOptions full_options;
    full_options.count = options.count;
    full_options.compute_vectors = false;
    auto full = ReferenceEigenpairs(sub->op, full_options);
    if (!full.ok()) return ReportError(full.status());
    full_seconds = full_watch.Seconds();
    // Eigenvalues of the kernel (harmonic fields on surfaces of genus > 0) are numerically zero:
    // a relative error means nothing there, so those entries are null and counted apart.
    const double scale = full->values.cwiseAbs().maxCoeff();
    for (int64_t i = 0; i < full->values.size(); ++i) {
      const double f = full->values[i];
      full_values.push_back(f);
      if (std::abs(f) <= 1e-9 * scale) {
        ++kernel_dimension;
        relative_errors.push_back(std::numeric_limits<double>::quiet_NaN());
      } else {
        relative_errors.push_back((reduced->values[i] - f) / std::abs(f));
      }
    }
    if (kernel_dimension > 0 && kernel_dimension < full->values.size()) {
      kernel_ratio =
          reduced->values.head(kernel_dimension).maxCoeff() / full->values[kernel_dimension];
    }
  }

  JsonWriter json;
  json.BeginObject()
      .DoubleArray("reduced", std::vector<double>(reduced->values.data(),
                                                  reduced->values.data() + reduced->values.size()))
      .DoubleArray("full", full_values)
      .DoubleArray("relative_errors", relative_errors)
      .BeginObject("seconds")
      .Double("basis", sub->basis_seconds)
      .Double("basis_kernel", sub->basis->timings.kernel_seconds)
      .Double("reduced_system", sub->reduced_seconds)
      .Double("solve", solve_seconds)
      .Double("full", full_seconds)
      .EndObject()
      .String("method", reduced->method == ReducedEigenMethod::kDense ? "dense" : "sparse")
      .Int("full_kernel_dimension", kernel_dimension)
      .Double("kernel_ratio", kernel_ratio)
      .Int("dim", sub->basis->dimension())
      .Int("kernel_columns", sub->basis->kernel_columns)
      .Int("nnz_u", sub->basis->U.nonZeros())
      .EndObject();
  std::printf("%s\n", json.str().c_str());
  return 0;
}

}  // namespace fieldspace::bench
