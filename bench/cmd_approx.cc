// `fieldspace-bench approx MESH --field vector|nfield|tensor [--n N] --dim D [--sigma S]
//  --tests K --seed N [--basis local|eigen] [--min-constraints A] [--max-constraints B]
//  [--coarse-dim C] [--quality paper|low-modes|smooth] [--design-mu-c X]
//  [--biharmonic exact|mixed]`:
// the approximation experiment of paper section 6 (Table 3) and, with --basis eigen, its
// comparison with the global eigenbasis of section 7 (Table 5). The mesh is scaled to unit total
// area first. Prints
//   {"projection_error":{"mean","max"},"minimization_error":{"mean","max"},
//    "biharmonic_model_error":{"mean","max"},
//    "biharmonic_design_error":{"mean","max","mu_s","mu_b","mu_c","form"},"dim","nnz_u","basis",
//    "seconds":{...}}
// projection_error: eq. 13 on K random test fields (biharmonic interpolants of A..B random unit
// constraints, default 10..50); minimization_error: the smoothing instance of eq. 8 for
// lambda_j = 25 j (1^T M 1)/(1^T S 1), j = 1..5, full space vs subspace, ||X - U x||_M / ||X||_M,
// averaged over j and the fields; biharmonic_model_error: the model problem with mu_S = 0,
// mu_B = 1 and the test fields' hard constraints solved in the subspace against its full-space
// solution, the test field (BiharmonicModelErrors); biharmonic_design_error: the same constraints
// as soft ones at kBiharmonicDesignWeights (mu_S = 0, mu_B = 1, mu_C = 1e4 or --design-mu-c,
// raw), subspace (biharmonic term in the --biharmonic form, default mixed: BiharmonicForm)
// against full-space solution (BiharmonicDesignErrors).
#include <cmath>
#include <cstdio>
#include <memory>
#include <string>
#include <utility>

#include "Eigen/Geometry"
#include "absl/status/status.h"
#include "absl/strings/str_cat.h"
#include "bench/bench_util.h"
#include "bench/cmd_operator.h"
#include "bench/cmd_subspace.h"
#include "bench/commands.h"
#include "core/basis/basis.h"
#include "core/mesh/mesh_io.h"
#include "core/operators/field_operator.h"
#include "core/subspace/evaluation.h"
#include "core/subspace/projection.h"
#include "core/subspace/reduced_system.h"
#include "core/subspace/spectrum.h"

namespace fieldspace::bench {

absl::StatusOr<TriangleMesh> LoadUnitAreaMesh(const std::string& path) {
  absl::StatusOr<MeshReadResult> read = ReadMeshFile(path);
  if (!read.ok()) return read.status();
  MeshArrays& arrays = read->arrays;
  // Area from the raw arrays (faces with bad indices are skipped here; Create rejects them).
  double area = 0;
  const int64_t nv = arrays.vertices.rows();
  for (int64_t f = 0; f < arrays.faces.rows(); ++f) {
    const auto& face = arrays.faces.row(f);
    if ((face.array() < 0).any() || (face.array() >= nv).any()) continue;
    const Eigen::Vector3d p0 = arrays.vertices.row(face[0]);
    const Eigen::Vector3d p1 = arrays.vertices.row(face[1]);
    const Eigen::Vector3d p2 = arrays.vertices.row(face[2]);
    area += 0.5 * (p1 - p0).cross(p2 - p0).norm();
  }
  if (area > 0 && std::isfinite(area)) arrays.vertices *= 1.0 / std::sqrt(area);
  return TriangleMesh::Create(std::move(arrays));
}

absl::StatusOr<BiharmonicForm> BiharmonicFormFromArgs(const Args& args) {
  const auto form = args.Get("biharmonic");
  if (!form.has_value() || *form == "mixed") return BiharmonicForm::kMixed;
  if (*form == "exact") return BiharmonicForm::kExact;
  return absl::InvalidArgumentError(
      absl::StrCat("--biharmonic must be exact or mixed, got '", *form, "'"));
}

absl::StatusOr<BasisQuality> QualityFromArgs(const Args& args) {
  const auto quality = args.Get("quality");
  if (!quality.has_value() || *quality == "paper") return BasisQuality::kPaper;
  if (*quality == "low-modes") return BasisQuality::kLowModes;
  if (*quality == "smooth") return BasisQuality::kSmooth;
  return absl::InvalidArgumentError(
      absl::StrCat("--quality must be paper, low-modes or smooth, got '", *quality, "'"));
}

absl::StatusOr<std::shared_ptr<const Basis>> BuildBenchBasis(const TriangleMesh& mesh,
                                                             FieldOperator* op, const Args& args) {
  auto dim = args.GetInt("dim", 0);
  if (!dim.ok()) return dim.status();
  auto sigma = args.GetDouble("sigma", 40.0);
  if (!sigma.ok()) return sigma.status();
  auto seed = args.GetInt("seed", 0);
  if (!seed.ok()) return seed.status();
  if (*dim < 1 || *dim > (int64_t{1} << 24)) {
    return absl::InvalidArgumentError("--dim must be a positive subspace dimension");
  }
  auto coarse_dim = args.GetInt("coarse-dim", 0);
  if (!coarse_dim.ok()) return coarse_dim.status();
  if (*coarse_dim < 0 || *coarse_dim >= *dim) {
    return absl::InvalidArgumentError("--coarse-dim must be in [0, dim)");
  }
  auto quality = QualityFromArgs(args);
  if (!quality.ok()) return quality.status();
  BasisOptions options;
  options.params.dimension = static_cast<int32_t>(*dim);
  options.params.sigma = *sigma;
  options.params.seed = static_cast<uint64_t>(*seed);
  options.kernel_columns = !args.Has("no-kernel-columns");
  absl::StatusOr<Basis> basis =
      BuildBasisOfQuality(mesh, op, options, *quality, static_cast<int32_t>(*coarse_dim));
  if (!basis.ok()) return basis.status();
  return std::shared_ptr<const Basis>(std::make_shared<Basis>(*std::move(basis)));
}

absl::StatusOr<BenchSubspace> LoadBenchSubspace(const Args& args, const FieldType& type) {
  auto mesh = LoadUnitAreaMesh(args.positional()[0]);
  if (!mesh.ok()) return mesh.status();
  auto op = BuildFieldOperator(*mesh, type);
  if (!op.ok()) return op.status();
  Stopwatch basis_watch;
  auto basis = BuildBenchBasis(*mesh, &*op, args);
  if (!basis.ok()) return basis.status();
  const double basis_seconds = basis_watch.Seconds();
  Stopwatch reduced_watch;
  auto system = ReducedSystem::Build(*basis, *op);
  if (!system.ok()) return system.status();
  return BenchSubspace{*std::move(mesh),   *std::move(op), *std::move(basis),
                       *std::move(system), basis_seconds,  reduced_watch.Seconds()};
}

int RunApprox(const Args& args) {
  auto type = FieldTypeFromArgs(args);
  if (!type.ok()) return ReportError(type.status());
  auto tests = args.GetInt("tests", 0);
  auto seed = args.GetInt("seed", 0);
  auto min_constraints = args.GetInt("min-constraints", 10);
  auto max_constraints = args.GetInt("max-constraints", 50);
  for (const auto* v : {&tests, &seed, &min_constraints, &max_constraints}) {
    if (!v->ok()) return ReportError(v->status());
  }
  auto design_mu_c = args.GetDouble("design-mu-c", kBiharmonicDesignWeights.mu_c);
  if (!design_mu_c.ok()) return ReportError(design_mu_c.status());
  if (!(*design_mu_c > 0) || !std::isfinite(*design_mu_c)) {
    return ReportError(absl::InvalidArgumentError("--design-mu-c must be finite and > 0"));
  }
  auto form = BiharmonicFormFromArgs(args);
  if (!form.ok()) return ReportError(form.status());
  if (*tests < 1 || *tests > 100000) {
    return ReportError(absl::InvalidArgumentError("--tests must be in [1, 100000]"));
  }
  const std::string basis_kind = args.Get("basis").value_or("local");
  if (basis_kind != "local" && basis_kind != "eigen") {
    return ReportError(absl::InvalidArgumentError("--basis must be local or eigen"));
  }

  Stopwatch setup_watch;
  auto mesh = LoadUnitAreaMesh(args.positional()[0]);
  if (!mesh.ok()) return ReportError(mesh.status());
  auto op = BuildFieldOperator(*mesh, *type);
  if (!op.ok()) return ReportError(op.status());
  const double setup_seconds = setup_watch.Seconds();

  Stopwatch basis_watch;
  std::shared_ptr<const Basis> basis;
  if (basis_kind == "local") {
    auto local = BuildBenchBasis(*mesh, &*op, args);
    if (!local.ok()) return ReportError(local.status());
    basis = *std::move(local);
  } else {
    auto dim = args.GetInt("dim", 0);
    if (!dim.ok()) return ReportError(dim.status());
    if (*dim < 1 || *dim > 100000) {
      return ReportError(absl::InvalidArgumentError("--dim must be in [1, 100000]"));
    }
    auto eigen = BuildEigenBasis(*op, static_cast<int32_t>(*dim));
    if (!eigen.ok()) return ReportError(eigen.status());
    basis = std::make_shared<Basis>(*std::move(eigen));
  }
  const double basis_seconds = basis_watch.Seconds();

  Stopwatch reduced_watch;
  auto system = ReducedSystem::Build(basis, *op);
  if (!system.ok()) return ReportError(system.status());
  const double reduced_seconds = reduced_watch.Seconds();

  Stopwatch fields_watch;
  TestFieldOptions field_options;
  field_options.count = static_cast<int32_t>(*tests);
  field_options.min_constraints = static_cast<int32_t>(*min_constraints);
  field_options.max_constraints = static_cast<int32_t>(*max_constraints);
  field_options.seed = static_cast<uint64_t>(*seed);
  auto fields = GenerateTestFields(*op, field_options);
  if (!fields.ok()) return ReportError(fields.status());
  const double fields_seconds = fields_watch.Seconds();

  Stopwatch projection_watch;
  auto projection = ProjectMany(**system, fields->fields);
  if (!projection.ok()) return ReportError(projection.status());
  const ErrorSummary projection_error = Summarize(projection->relative_errors);
  const double projection_seconds = projection_watch.Seconds();

  Stopwatch minimization_watch;
  auto lambdas = SmoothingWeights(*op, 5);
  if (!lambdas.ok()) return ReportError(lambdas.status());
  auto minimization = SmoothingErrors(*op, **system, fields->fields, *lambdas);
  if (!minimization.ok()) return ReportError(minimization.status());
  const ErrorSummary minimization_error = Summarize(*minimization);
  const double minimization_seconds = minimization_watch.Seconds();

  Stopwatch biharmonic_watch;
  auto biharmonic = BiharmonicModelErrors(**system, *fields);
  if (!biharmonic.ok()) return ReportError(biharmonic.status());
  const ErrorSummary biharmonic_error = Summarize(*biharmonic);
  const double biharmonic_seconds = biharmonic_watch.Seconds();

  Stopwatch design_watch;
  EnergyWeights design_weights = kBiharmonicDesignWeights;
  design_weights.mu_c = *design_mu_c;
  auto design = BiharmonicDesignErrors(*op, **system, *fields, design_weights, *form);
  if (!design.ok()) return ReportError(design.status());
  const ErrorSummary design_error = Summarize(*design);
  const double design_seconds = design_watch.Seconds();

  JsonWriter json;
  json.BeginObject()
      .BeginObject("projection_error")
      .Double("mean", projection_error.mean)
      .Double("max", projection_error.max)
      .EndObject()
      .BeginObject("minimization_error")
      .Double("mean", minimization_error.mean)
      .Double("max", minimization_error.max)
      .EndObject()
      .BeginObject("biharmonic_model_error")
      .Double("mean", biharmonic_error.mean)
      .Double("max", biharmonic_error.max)
      .EndObject()
      .BeginObject("biharmonic_design_error")
      .Double("mean", design_error.mean)
      .Double("max", design_error.max)
      .Double("mu_s", design_weights.mu_s)
      .Double("mu_b", design_weights.mu_b)
      .Double("mu_c", design_weights.mu_c)
      .String("form", *form == BiharmonicForm::kMixed ? "mixed" : "exact")
      .EndObject()
      .Int("dim", basis->dimension())
      .Int("nnz_u", basis->U.nonZeros())
      .String("basis", basis_kind)
      .BeginObject("seconds")
      .Double("setup", setup_seconds)
      .Double("basis", basis_seconds)
      .Double("reduced_system", reduced_seconds)
      .Double("test_fields", fields_seconds)
      .Double("projection", projection_seconds)
      .Double("minimization", minimization_seconds)
      .Double("biharmonic_model", biharmonic_seconds)
      .Double("biharmonic_design", design_seconds)
      .EndObject()
      .EndObject();
  std::printf("%s\n", json.str().c_str());
  return 0;
}

}  // namespace fieldspace::bench
