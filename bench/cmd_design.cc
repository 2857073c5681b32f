// `fieldspace-bench design MESH --field vector|nfield|tensor [--n N] --dim D --edits N --seed S
//  [--sigma S] [--max-constraints C] [--no-full] [--full-biharmonic] [--no-kernel-columns]
//  [--coarse-dim C] [--quality paper|low-modes|smooth] [--biharmonic exact|mixed]
//  [--verify-every K]`:
// simulates an interactive design session (paper section 8, "Vector fields design") on the
// mesh scaled to unit area: random add / move / remove of soft and hard constraints (at most C
// live, default 40) and a few weight changes, timing each edit (the solve included), plus lifts
// of the solution to all faces and, for comparison, a CHOLMOD factorization and solve of the
// full-space system (mu_S S + mu_C C^T C with the final constraints as soft ones, + mu_B B with
// --full-biharmonic). Prints
//   {"factorize_ms","edit_ms":{"p50","p99","max"},"lift_ms":{"p50"},"full_factorize_ms",
//    "full_solve_ms","weight_change_ms":{"p50"},...}
// factorize_ms: median numeric factorization of U^T (mu_S S + mu_B B) U (shared analysis).
// --biharmonic: the session's BiharmonicForm (default mixed: the product of sparse solves
// N^-1 Mr K^-1, K's and N's factorizations made when the session opens, session_create_ms;
// exact: the paper's form).
// --verify-every K: the sessions' DesignSessionOptions::verify_interval (default 1: every solve
// checked against the true matrix; fieldspaced checks every 16th, --design-verify-every).
// --strokes K [--stroke-faces F]: afterwards, K soft strokes of about F faces (default 50; from a
// random face to one F dual-graph steps away, core/subspace/design_tools.h) each added, moved
// (to the strip one step over) and removed as one group edit, on top of the session's
// constraints: "strokes": {"faces", "geometry_ms", "add_ms", "move_ms", "remove_ms"} (p50, p99;
// geometry: the path and constraint values, not part of the edit).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>
#include <memory>
#include <numbers>
#include <random>
#include <string>
#include <unordered_set>
#include <vector>

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"
#include "bench/bench_util.h"
#include "bench/cmd_operator.h"
#include "bench/cmd_subspace.h"
#include "bench/commands.h"
#include "core/linalg/sparse_cholesky.h"
#include "core/linalg/supernodal_cholesky.h"
#include "core/operators/field_operator.h"
#include "core/subspace/design_session.h"
#include "core/subspace/design_tools.h"
#include "core/subspace/full_space_solver.h"
#include "core/subspace/projection.h"
#include "core/subspace/reduced_system.h"

namespace fieldspace::bench {
namespace {

double Percentile(std::vector<double> v, double q) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  const size_t rank = static_cast<size_t>(std::ceil(q * static_cast<double>(v.size())));
  return v[std::clamp<size_t>(rank, 1, v.size()) - 1];
}

// A face about `steps` dual-graph steps from `start` (the last face a breadth-first search
// reaches within that depth).
int32_t FaceStepsAway(const TriangleMesh& mesh, int32_t start, int32_t steps) {
  std::vector<int32_t> frontier = {start}, next;
  std::unordered_set<int32_t> seen = {start};
  int32_t last = start;
  for (int32_t d = 0; d < steps && !frontier.empty(); ++d) {
    next.clear();
    for (int32_t f : frontier) {
      for (int k = 0; k < 3; ++k) {
        const int32_t g = mesh.face_neighbors()(f, k);
        if (g != kNoFace && seen.insert(g).second) next.push_back(g);
      }
    }
    if (!next.empty()) last = next.back();
    frontier.swap(next);
  }
  return last;
}

double Uniform(std::mt19937_64& rng) { return static_cast<double>(rng() >> 11) * 0x1.0p-53; }

Eigen::VectorXd RandomUnit(std::mt19937_64& rng, int32_t p) {
  Eigen::VectorXd v(p);
  if (p == 2) {
    const double a = 2 * std::numbers::pi * Uniform(rng);
    v << std::cos(a), std::sin(a);
    return v;
  }
  for (int32_t i = 0; i < p; ++i) v[i] = Uniform(rng) - 0.5;
  return v.normalized();
}

}  // namespace

int RunDesign(const Args& args) {
  auto type = FieldTypeFromArgs(args);
  if (!type.ok()) return ReportError(type.status());
  auto edits = args.GetInt("edits", 0);
  auto seed = args.GetInt("seed", 0);
  auto max_constraints = args.GetInt("max-constraints", 40);
  auto strokes = args.GetInt("strokes", 0);
  auto stroke_faces = args.GetInt("stroke-faces", 50);
  auto verify_every = args.GetInt("verify-every", 1);
  for (const auto* v : {&edits, &seed, &max_constraints, &strokes, &stroke_faces, &verify_every}) {
    if (!v->ok()) return ReportError(v->status());
  }
  if (*edits < 1 || *edits > 10000000 || *max_constraints < 1 || *max_constraints > 100000) {
    return ReportError(absl::InvalidArgumentError("--edits and --max-constraints must be >= 1"));
  }
  if (*strokes < 0 || *strokes > 100000 || *stroke_faces < 1 || *stroke_faces > 100000) {
    return ReportError(
        absl::InvalidArgumentError("--strokes must be >= 0 and --stroke-faces >= 1"));
  }
  if (*verify_every < 1 || *verify_every > 1000000) {
    return ReportError(absl::InvalidArgumentError("--verify-every must be in [1, 1000000]"));
  }

  auto form = BiharmonicFormFromArgs(args);
  if (!form.ok()) return ReportError(form.status());
  auto sub = LoadBenchSubspace(args, *type);
  if (!sub.ok()) return ReportError(sub.status());
  const ReducedSystem& sys = *sub->system;

  const EnergyWeights initial{1.0, 0.01, 10.0};
  // The factorization alone (what a weight change costs before the constraints are re-solved).
  std::vector<double> factorize_ms;
  {
    const Eigen::SparseMatrix<double>& S = sys.stiffness();
    const Eigen::SparseMatrix<double>& B = sys.bilaplacian();
    std::vector<double> values(S.nonZeros());
    for (int64_t q = 0; q < S.nonZeros(); ++q) {
      values[q] = initial.mu_s * S.valuePtr()[q] + initial.mu_b * B.valuePtr()[q];
    }
    SupernodalFactorOptions fo;
    fo.diagonal_shift = 1e-13;
    for (int rep = 0; rep < 5; ++rep) {
      Stopwatch w;
      auto f = SupernodalFactor::Factorize(sys.pattern_symbolic(), values, fo);
      if (!f.ok()) return ReportError(f.status());
      factorize_ms.push_back(w.Seconds() * 1e3);
    }
  }
  Stopwatch create_watch;
  DesignSessionOptions session_options;
  session_options.biharmonic = *form;
  session_options.verify_interval = static_cast<int32_t>(*verify_every);
  auto session = DesignSession::Create(sub->system, initial, session_options);
  if (!session.ok()) return ReportError(session.status());
  const double create_ms = create_watch.Seconds() * 1e3;
  DesignSession& s = **session;

  std::mt19937_64 rng(static_cast<uint64_t>(*seed));
  const int32_t p = sys.dofs_per_face();
  const int32_t num_faces = sys.num_faces();
  std::vector<double> edit_ms, weight_ms, lift_ms, backward_errors;
  std::map<std::string, std::vector<double>> edit_ms_by_kind;
  std::vector<int64_t> live;
  int64_t next_id = 0, rejected = 0, refinement_steps = 0;
  std::vector<double> lift_buffer(sys.dofs());
  const int64_t lift_every = std::max<int64_t>(1, *edits / 10);
  for (int64_t e = 0; e < *edits; ++e) {
    const double r = Uniform(rng);
    if (r < 0.04 && !live.empty()) {
      EnergyWeights w{0.5 + 1.5 * Uniform(rng), 0.05 * Uniform(rng), 1.0 + 99.0 * Uniform(rng)};
      Stopwatch watch;
      if (auto st = s.SetWeights(w); !st.ok()) return ReportError(st);
      weight_ms.push_back(watch.Seconds() * 1e3);
      continue;
    }
    absl::Status st;
    std::string kind_name;
    Stopwatch watch;
    if (live.empty() || (r < 0.45 && static_cast<int64_t>(live.size()) < *max_constraints)) {
      FieldConstraint c;
      c.face = static_cast<int32_t>(rng() % num_faces);
      c.value = RandomUnit(rng, p);
      c.kind = Uniform(rng) < 0.3 ? ConstraintKind::kHard : ConstraintKind::kSoft;
      kind_name = c.hard() ? "add_hard" : "add_soft";
      st = s.AddConstraint(next_id, c);
      if (st.ok()) live.push_back(next_id);
      ++next_id;
    } else if (r < 0.8) {
      const int64_t id = live[rng() % live.size()];
      auto current = s.GetConstraint(id);
      if (!current.ok()) return ReportError(current.status());
      FieldConstraint c = *current;
      kind_name = "move_value";
      if (Uniform(rng) < 0.5) {
        c.face = static_cast<int32_t>(rng() % num_faces);
        kind_name = "move_face";
      }
      c.value = RandomUnit(rng, p);
      st = s.MoveConstraint(id, c);
    } else {
      kind_name = "remove";
      const size_t slot = rng() % live.size();
      st = s.RemoveConstraint(live[slot]);
      live[slot] = live.back();
      live.pop_back();
    }
    edit_ms.push_back(watch.Seconds() * 1e3);
    edit_ms_by_kind[kind_name].push_back(edit_ms.back());
    refinement_steps += s.last_refinement_steps();
    if (st.ok()) backward_errors.push_back(s.last_backward_error());
    if (!st.ok()) {
      // A hard constraint that duplicates another is rejected (FailedPrecondition) by design.
      if (!absl::IsFailedPrecondition(st)) return ReportError(st);
      ++rejected;
    }
    if ((e + 1) % lift_every == 0) {
      Stopwatch lw;
      if (auto ls = LiftInto(sys, s.coefficients(), absl::MakeSpan(lift_buffer)); !ls.ok()) {
        return ReportError(ls);
      }
      lift_ms.push_back(lw.Seconds() * 1e3);
    }
  }

  // Strokes as group edits (add, move, remove), with their geometry timed apart.
  std::vector<double> stroke_geometry_ms, stroke_add_ms, stroke_move_ms, stroke_remove_ms;
  int64_t stroke_faces_total = 0;
  const Eigen::Vector3d center = Eigen::Vector3d::Constant(1.0 / 3.0);
  const auto stroke = [&](int32_t from, int32_t to) {
    Stopwatch w;
    auto c = StrokeConstraints(sub->mesh, *type, {SurfacePoint{from, center}, {to, center}});
    stroke_geometry_ms.push_back(w.Seconds() * 1e3);
    return c;
  };
  for (int64_t k = 0; k < *strokes; ++k) {
    const int32_t from = static_cast<int32_t>(rng() % num_faces);
    const int32_t to = FaceStepsAway(sub->mesh, from, static_cast<int32_t>(*stroke_faces));
    const int32_t from2 = FaceStepsAway(sub->mesh, from, 1);
    const int32_t to2 = FaceStepsAway(sub->mesh, to, 1);
    auto first = stroke(from, to);
    auto second = stroke(from2, to2);
    if (!first.ok()) return ReportError(first.status());
    if (!second.ok()) return ReportError(second.status());
    stroke_faces_total += static_cast<int64_t>(first->size());
    const int64_t id = next_id++;
    Stopwatch add;
    if (auto st = s.AddConstraintGroup(id, *first); !st.ok()) return ReportError(st);
    stroke_add_ms.push_back(add.Seconds() * 1e3);
    Stopwatch move;
    if (auto st = s.MoveConstraintGroup(id, *second); !st.ok()) return ReportError(st);
    stroke_move_ms.push_back(move.Seconds() * 1e3);
    Stopwatch remove;
    if (auto st = s.RemoveConstraint(id); !st.ok()) return ReportError(st);
    stroke_remove_ms.push_back(remove.Seconds() * 1e3);
  }

  double full_factorize_ms = 0, full_solve_ms = 0;
  const bool full_biharmonic = args.Has("full-biharmonic");
  if (!args.Has("no-full")) {
    ModelProblem problem = s.problem();
    for (FieldConstraint& c : problem.constraints) {
      if (c.hard()) c = {c.face, c.value, 1.0, ConstraintKind::kSoft};
    }
    if (!full_biharmonic) problem.weights.mu_b = 0;
    auto full = AssembleModelSystem(sub->op, problem);
    if (!full.ok()) return ReportError(full.status());
    Stopwatch fw;
    auto factor = SparseCholesky::Factorize(full->A);
    if (!factor.ok()) return ReportError(factor.status());
    full_factorize_ms = fw.Seconds() * 1e3;
    Stopwatch sw;
    auto x = factor->Solve(full->b);
    if (!x.ok()) return ReportError(x.status());
    full_solve_ms = sw.Seconds() * 1e3;
  }

  JsonWriter json;
  json.BeginObject()
      .Double("factorize_ms", Percentile(factorize_ms, 0.5))
      .BeginObject("edit_ms")
      .Double("p50", Percentile(edit_ms, 0.5))
      .Double("p99", Percentile(edit_ms, 0.99))
      .Double("max", Percentile(edit_ms, 1.0))
      .EndObject()
      .BeginObject("edit_ms_by_kind");
  for (const auto& [name, times] : edit_ms_by_kind) {
    json.BeginObject(name)
        .Int("count", static_cast<int64_t>(times.size()))
        .Double("p50", Percentile(times, 0.5))
        .Double("p99", Percentile(times, 0.99))
        .EndObject();
  }
  json.EndObject()
      .BeginObject("lift_ms")
      .Double("p50", Percentile(lift_ms, 0.5))
      .EndObject()
      .Double("full_factorize_ms", full_factorize_ms)
      .Double("full_solve_ms", full_solve_ms)
      .String("full_system", full_biharmonic ? "harmonic+biharmonic" : "harmonic")
      .BeginObject("weight_change_ms")
      .Double("p50", Percentile(weight_ms, 0.5))
      .EndObject()
      .Double("session_create_ms", create_ms)
      .Int("edits", static_cast<int64_t>(edit_ms.size()))
      .Int("rejected_edits", rejected)
      .String("biharmonic", *form == BiharmonicForm::kMixed ? "mixed" : "exact")
      .Int("verify_every", *verify_every)
      .Int("final_constraints", s.num_constraints())
      .Double("mean_refinement_steps",
              edit_ms.empty() ? 0.0 : static_cast<double>(refinement_steps) / edit_ms.size())
      .BeginObject("backward_error")  // of each edit's solution against the true system
      .Double("p50", Percentile(backward_errors, 0.5))
      .Double("p99", Percentile(backward_errors, 0.99))
      .Double("max", Percentile(backward_errors, 1.0))
      .EndObject()
      .BeginObject("strokes")
      .Int("count", static_cast<int64_t>(stroke_add_ms.size()))
      .Double("faces", stroke_add_ms.empty() ? 0.0
                                             : static_cast<double>(stroke_faces_total) /
                                                   static_cast<double>(stroke_add_ms.size()));
  for (const auto& [name, times] :
       {std::pair<const char*, const std::vector<double>*>{"geometry_ms", &stroke_geometry_ms},
        {"add_ms", &stroke_add_ms},
        {"move_ms", &stroke_move_ms},
        {"remove_ms", &stroke_remove_ms}}) {
    json.BeginObject(name)
        .Double("p50", Percentile(*times, 0.5))
        .Double("p99", Percentile(*times, 0.99))
        .EndObject();
  }
  json.EndObject()
      .Int("dim", sys.dimension())
      .Int("faces", num_faces)
      .Int("nnz_u", sys.basis().U.nonZeros())
      .BeginObject("reduced")
      .Int("pattern_nonzeros", sys.stats().pattern_nonzeros)
      .Int("stiffness_nonzeros", sys.stats().stiffness_nonzeros)
      .Int("bilaplacian_nonzeros", sys.stats().bilaplacian_nonzeros)
      .Int("factor_nonzeros", sys.stats().factor_nonzeros)
      .Double("factor_mflops", sys.stats().factor_flops * 1e-6)
      .EndObject()
      .BeginObject("seconds")
      .Double("basis", sub->basis_seconds)
      .Double("reduced_system", sub->reduced_seconds)
      .Double("reduced_products", sys.stats().products_seconds)
      .Double("reduced_analysis", sys.stats().analysis_seconds)
      .EndObject()
      .EndObject();
  std::printf("%s\n", json.str().c_str());
  return 0;
}

}  // namespace fieldspace::bench
