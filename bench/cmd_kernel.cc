// `fieldspace-bench kernel MESH --field vector|nfield|tensor [--n N]
//  [--poisson multigrid|cholesky]`: the kernel of the field's
// Laplacian (ComputeKernelFields, core/operators/kernel_fields.h: harmonic fields for vector
// fields, parallel fields otherwise), as the basis construction appends it by default. Prints
//   {"columns","candidates","expected_harmonic","max_rayleigh","min_rejected",
//    "kernel_residual","orthonormality_error","poisson_solver","poisson_iterations",
//    "poisson_fallback",
//    "seconds":{"operator","candidates","poisson","ritz","kernel"},"peak_rss_mb"}
// kernel_residual: max over columns of ||S x||_{M^-1} / (lambda_ref ||x||_M),
// lambda_ref = trace(S) / trace(M); orthonormality_error: max |X^T M X - I|.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>

#include "absl/status/status.h"
#include "bench/bench_util.h"
#include "bench/cmd_operator.h"
#include "bench/commands.h"
#include "core/operators/field_operator.h"
#include "core/operators/kernel_fields.h"

namespace fieldspace::bench {

int RunKernel(const Args& args) {
  const std::string poisson = args.Get("poisson").value_or("multigrid");
  KernelFieldOptions options;
  if (poisson == "cholesky") {
    options.poisson_solver = PoissonSolver::kCholesky;
  } else if (poisson != "multigrid") {
    return ReportError(absl::InvalidArgumentError("--poisson must be multigrid or cholesky"));
  }
  auto type = FieldTypeFromArgs(args);
  if (!type.ok()) return ReportError(type.status());
  auto mesh = LoadBenchMesh(args.positional()[0]);
  if (!mesh.ok()) return ReportError(mesh.status());
  Stopwatch op_watch;
  auto op = BuildFieldOperator(*mesh, *type);
  if (!op.ok()) return ReportError(op.status());
  const double op_seconds = op_watch.Seconds();
  KernelFieldStats stats;
  auto X = ComputeKernelFields(*mesh, *op, options, &stats);
  if (!X.ok()) return ReportError(X.status());
  double residual = 0, orthonormality = 0;
  if (X->cols() > 0) {
    const Eigen::MatrixXd SX = op->stiffness * *X;
    for (Eigen::Index j = 0; j < X->cols(); ++j) {
      const double num = std::sqrt(SX.col(j).cwiseAbs2().cwiseQuotient(op->mass).sum());
      const double den = stats.lambda_ref * std::sqrt(X->col(j).cwiseAbs2().dot(op->mass));
      residual = std::max(residual, num / den);
    }
    const Eigen::MatrixXd G = X->transpose() * op->mass.asDiagonal() * *X;
    orthonormality = (G - Eigen::MatrixXd::Identity(X->cols(), X->cols())).cwiseAbs().maxCoeff();
  }
  JsonWriter json;
  json.BeginObject()
      .Int("columns", X->cols())
      .Int("candidates", stats.candidates)
      .Int("expected_harmonic", stats.expected_harmonic)
      .Double("max_rayleigh", stats.max_rayleigh)
      .Double("min_rejected", stats.min_rejected)
      .Double("kernel_residual", residual)
      .Double("orthonormality_error", orthonormality)
      .String("poisson_solver", poisson)
      .Int("poisson_iterations", stats.poisson_iterations)
      .Bool("poisson_fallback", stats.poisson_fallback)
      .BeginObject("seconds")
      .Double("operator", op_seconds)
      .Double("candidates", stats.candidate_seconds)
      .Double("poisson", stats.poisson_seconds)
      .Double("ritz", stats.ritz_seconds)
      .Double("kernel", stats.seconds)
      .EndObject()
      .Double("peak_rss_mb", PeakRssMb())
      .EndObject();
  std::printf("%s\n", json.str().c_str());
  return 0;
}

}  // namespace fieldspace::bench
