// `fieldspace-bench curvature MESH [--estimator jet|normal-differences]`: per-face shape operator
// (core/operators/curvature.h), principal curvatures and the aligned 2-field targets; prints the
// timings and curvature statistics as JSON.
#include <algorithm>
#include <cstdio>
#include <ctime>
#include <string>

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"
#include "bench/bench_util.h"
#include "bench/cmd_operator.h"
#include "bench/commands.h"
#include "core/operators/curvature.h"

namespace fieldspace::bench {
namespace {

// Process CPU seconds (all threads): on a shared machine wall-clock times depend on the load.
double CpuSeconds() { return static_cast<double>(std::clock()) / CLOCKS_PER_SEC; }

}  // namespace

int RunCurvature(const Args& args) {
  ShapeOperatorOptions options;
  const std::string estimator = args.Get("estimator").value_or("jet");
  if (estimator == "jet") {
    options.estimator = CurvatureEstimator::kJetFit;
  } else if (estimator == "normal-differences") {
    options.estimator = CurvatureEstimator::kNormalDifferences;
  } else {
    return ReportError(absl::InvalidArgumentError(
        absl::StrCat("--estimator must be jet or normal-differences, got '", estimator, "'")));
  }
  Stopwatch load_clock;
  auto mesh = LoadBenchMesh(args.positional()[0]);
  if (!mesh.ok()) return ReportError(mesh.status());
  const double load_s = load_clock.Seconds();

  Stopwatch shape_clock;
  const double shape_cpu_start = CpuSeconds();
  auto dofs = ComputeShapeOperator(*mesh, options);
  if (!dofs.ok()) return ReportError(dofs.status());
  const double shape_s = shape_clock.Seconds();
  const double shape_cpu_s = CpuSeconds() - shape_cpu_start;
  Stopwatch principal_clock;
  auto pc = ComputePrincipalCurvatures(*mesh, *dofs);
  if (!pc.ok()) return ReportError(pc.status());
  const double principal_s = principal_clock.Seconds();
  Stopwatch targets_clock;
  auto targets = ComputeCurvatureAlignedTargets(*mesh, *dofs, 2);
  if (!targets.ok()) return ReportError(targets.status());
  const double targets_s = targets_clock.Seconds();

  // Statistics scaled by the mesh's size: curvature times sqrt(area) is scale invariant.
  const double area = mesh->total_area();
  auto stats = [&](JsonWriter& json, const std::string& key, const Eigen::VectorXd& k) {
    json.BeginObject(key)
        .Double("min", k.minCoeff())
        .Double("max", k.maxCoeff())
        .Double("mean", k.mean())
        .Double("area_weighted_mean", k.dot(mesh->face_areas()) / area)
        .EndObject();
  };
  JsonWriter json;
  json.BeginObject()
      .String("mesh", args.positional()[0])
      .Int("faces", mesh->num_faces())
      .Int("vertices", mesh->num_vertices())
      .String("estimator", estimator)
      .Double("total_area", area)
      .Double("load_s", load_s)
      .Double("shape_operator_s", shape_s)
      .Double("shape_operator_cpu_s", shape_cpu_s)
      .Double("principal_s", principal_s)
      .Double("targets_s", targets_s);
  stats(json, "k1", pc->k1);
  stats(json, "k2", pc->k2);
  stats(json, "anisotropy", targets->weights);
  json.EndObject();
  std::printf("%s\n", json.str().c_str());
  return 0;
}

}  // namespace fieldspace::bench
