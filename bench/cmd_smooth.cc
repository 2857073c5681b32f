// `fieldspace-bench smooth MESH --field tensor|vector|nfield [--n N] --dim D [--sigma S]
//  [--seed N] [--coarse-dim C] [--mu-s X] [--mu-b X] [--mu-c X] [--repeat R] [--scale-free]`:
// reduced smoothing of a field (paper section 8, "Tensor field smoothing";
// core/subspace/smoothing.h) on the mesh scaled to unit area. The input X0:
//   tensor: the mesh's shape operator (ComputeShapeOperator, jet fit);
//   nfield: the maximum principal curvature direction d1 scaled by the anisotropy |k1 - k2|, as an
//           n-field (for n = 2 the curvature-aligned targets of curvature.h times their weights);
//   vector: the constant ambient direction (1, 0.5, 0.25) / |.| projected to each face (smooth).
// Builds the basis and reduced system, then a ReducedSmoother (rhs pass), and R solves with mu_S
// changed each time (so each one factorizes), and R lifts of the solution to all faces through
// the system's LiftPlan. Prints one JSON object; times are p50 over the R repeats:
//   {"rhs_ms","weighted_mass_ms","factorize_ms","solve_ms","lift_ms",...,"seconds":{...}}
// weighted_mass_ms: U^T W M U for per-face weights (here all 1, timing only; one pass over U).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"
#include "bench/bench_util.h"
#include "bench/cmd_operator.h"
#include "bench/cmd_subspace.h"
#include "bench/commands.h"
#include "core/operators/conversions.h"
#include "core/operators/curvature.h"
#include "core/subspace/projection.h"
#include "core/subspace/smoothing.h"

namespace fieldspace::bench {
namespace {

double Median(std::vector<double> v) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  return v[(v.size() - 1) / 2];
}

// The documented input field X0 for `type` on `mesh` (see the file comment).
absl::StatusOr<Eigen::VectorXd> SmoothingInput(const TriangleMesh& mesh, const FieldType& type) {
  if (type.kind == FieldKind::kVector) {
    const Eigen::RowVector3d a = Eigen::RowVector3d(1.0, 0.5, 0.25).normalized();
    const AmbientVectors vectors = a.replicate(mesh.num_faces(), 1);
    return VectorDofsFromAmbient(mesh, vectors);
  }
  auto shape = ComputeShapeOperator(mesh);
  if (!shape.ok() || type.kind == FieldKind::kTensor) return shape;
  auto pc = ComputePrincipalCurvatures(mesh, *shape);
  if (!pc.ok()) return pc.status();
  AmbientVectors directions = pc->d1;
  for (int32_t f = 0; f < mesh.num_faces(); ++f) directions.row(f) *= pc->k1[f] - pc->k2[f];
  return NFieldDofsFromAmbient(mesh, type.n, directions);
}

}  // namespace

int RunSmooth(const Args& args) {
  auto type = FieldTypeFromArgs(args);
  if (!type.ok()) return ReportError(type.status());
  auto mu_s = args.GetDouble("mu-s", 1.0);
  auto mu_b = args.GetDouble("mu-b", 0.0);
  auto mu_c = args.GetDouble("mu-c", 1000.0);
  for (const auto* v : {&mu_s, &mu_b, &mu_c}) {
    if (!v->ok()) return ReportError(v->status());
  }
  auto repeat = args.GetInt32("repeat", 10);
  if (!repeat.ok()) return ReportError(repeat.status());
  if (*repeat < 1 || *repeat > 100000) {
    return ReportError(absl::InvalidArgumentError("--repeat must be in [1, 100000]"));
  }
  const EnergyWeights weights{*mu_s, *mu_b, *mu_c};
  if (auto st = ValidateWeights(weights); !st.ok()) return ReportError(st);

  auto sub = LoadBenchSubspace(args, *type);
  if (!sub.ok()) return ReportError(sub.status());
  const ReducedSystem& sys = *sub->system;

  Stopwatch input_watch;
  auto field = SmoothingInput(sub->mesh, *type);
  if (!field.ok()) return ReportError(field.status());
  const double input_seconds = input_watch.Seconds();

  SmoothingOptions options;
  options.scale_free = args.Has("scale-free");
  auto smoother = ReducedSmoother::Create(sub->system, *field, {}, options);
  if (!smoother.ok()) return ReportError(smoother.status());
  // The weighted variant's extra pass (U^T W M U), timed once with W = 1.
  const std::vector<double> ones(sys.num_faces(), 1.0);
  auto weighted = ReducedSmoother::Create(sub->system, *field, ones, options);
  if (!weighted.ok()) return ReportError(weighted.status());

  std::vector<double> factorize_ms, solve_ms, lift_ms;
  SmoothingResult result;
  for (int32_t r = 0; r < *repeat; ++r) {
    EnergyWeights w = weights;
    w.mu_s = weights.mu_s * (1.0 + 0.01 * r);  // new weights: every repeat refactorizes
    auto solved = smoother->Solve(w);
    if (!solved.ok()) return ReportError(solved.status());
    factorize_ms.push_back(solved->timings.factorize_ms);
    solve_ms.push_back(solved->timings.solve_ms);
    if (r == 0) result = *std::move(solved);
  }
  std::vector<double> lifted(sys.dofs());
  for (int32_t r = 0; r < *repeat; ++r) {
    Stopwatch lw;
    if (auto st = LiftInto(sys, result.coefficients, absl::MakeSpan(lifted)); !st.ok()) {
      return ReportError(st);
    }
    lift_ms.push_back(lw.Seconds() * 1e3);
  }
  // How far the smoothed field moved from the input, and how far the input is from span(U).
  auto residual = RelativeResiduals(sys, *field, result.coefficients);
  if (!residual.ok()) return ReportError(residual.status());
  auto projection = Project(sys, *field);
  if (!projection.ok()) return ReportError(projection.status());

  JsonWriter json;
  json.BeginObject()
      .String("mesh", args.positional()[0])
      .String("field", type->ToString())
      .Int("faces", sys.num_faces())
      .Int("dim", sys.dimension())
      .Int("nnz_u", sys.basis().U.nonZeros())
      .BeginObject("weights")
      .Double("mu_s", weights.mu_s)
      .Double("mu_b", weights.mu_b)
      .Double("mu_c", weights.mu_c)
      .Bool("scale_free", options.scale_free)
      .EndObject()
      .Int("repeat", *repeat)
      .Double("rhs_ms", smoother->setup_timings().rhs_ms)
      .Double("weighted_mass_ms", weighted->setup_timings().weighted_mass_ms)
      .Double("factorize_ms", Median(factorize_ms))
      .Double("solve_ms", Median(solve_ms))
      .Double("lift_ms", Median(lift_ms))
      .Double("backward_error", result.backward_error)
      .Int("refinement_steps", result.refinement_steps)
      .Double("regularization", result.regularization)
      .Double("relative_change", (*residual)[0])  // ||U x - X0||_M / ||X0||_M
      .Double("projection_error", projection->relative_error)
      .BeginObject("reduced")
      .Int("pattern_nonzeros", sys.stats().pattern_nonzeros)
      .Int("factor_nonzeros", sys.stats().factor_nonzeros)
      .Double("factor_mflops", sys.stats().factor_flops * 1e-6)
      .EndObject()
      .BeginObject("seconds")
      .Double("basis", sub->basis_seconds)
      .Double("reduced_system", sub->reduced_seconds)
      .Double("reduced_products", sys.stats().products_seconds)
      .Double("reduced_analysis", sys.stats().analysis_seconds)
      .Double("input_field", input_seconds)
      .EndObject()
      .EndObject();
  std::printf("%s\n", json.str().c_str());
  return 0;
}

}  // namespace fieldspace::bench
