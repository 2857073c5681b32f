// `fieldspace-bench basis MESH --field vector|nfield|tensor [--n N] --dim D [--sigma S]
//   [--threads T] [--weights FILE] [--save FILE] [--export-mtx DIR] [--seed N] [--stats]
//   [--tolerance T] [--no-kernel-columns] [--coarse-dim C] [--quality paper|low-modes|smooth]`:
// builds the locally supported basis (paper section 4) and prints one JSON object
//   {"dim","regions","kernel_columns","dofs","nnz_u","nnz_per_row",
//    "seconds":{"sampling","regions","eigensolve","kernel","total"},"peak_rss_mb",
//    "estimated_peak_mb"}.
// estimated_peak_mb: EstimateBuildPeakBytes, what the daemon admits against its memory budget.
// --coarse-dim C: a two-level basis (BuildTwoLevelBasis, the daemon's coarse_dimension).
// --quality low-modes|smooth: the three-level bases of BasisQuality::kLowModes and kSmooth
// (BuildMultiLevelBasis).
// "dim" counts all columns of U: the d local ones and the kernel columns (BasisOptions::
// kernel_columns; --no-kernel-columns builds the paper's basis without them).
// --weights FILE: one positive adaptivity weight per face, one per line.
// --save FILE: the basis file (core/basis/basis_io.h), mesh id "crc32c:<hex of the mesh file>".
// --export-mtx DIR: DIR/U.mtx (k x d), DIR/S.mtx, DIR/M.mtx (MatrixMarket coordinate real
// general, 1-based, DOF order of docs/conventions.md, the operator subcommand's writer) and
// DIR/samples.txt (the sample face of each region, 0-based, one per line).
// --tolerance T: residual tolerance of the local eigenproblems (BasisOptions::eigen_tolerance).
// --stats adds "stats":{...} (how the local problems were solved; core/basis/basis.h BasisStats).
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <optional>
#include <sstream>
#include <string>
#include <system_error>
#include <utility>
#include <vector>

#include "absl/status/status.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/strip.h"
#include "bench/bench_util.h"
#include "bench/cmd_operator.h"
#include "bench/cmd_subspace.h"
#include "bench/commands.h"
#include "core/basis/basis.h"
#include "core/basis/basis_io.h"
#include "core/basis/crc32c.h"
#include "core/linalg/matrix_market.h"
#include "core/operators/field_operator.h"

namespace fieldspace::bench {
namespace {

absl::StatusOr<std::string> ReadWholeFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return absl::NotFoundError(absl::StrCat("cannot open '", path, "'"));
  std::ostringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

// One finite positive number per line (blank lines ignored), exactly one per face.
absl::StatusOr<Eigen::VectorXd> ReadWeights(const std::string& path, int32_t num_faces) {
  std::ifstream in(path);
  if (!in) return absl::NotFoundError(absl::StrCat("cannot open weights file '", path, "'"));
  Eigen::VectorXd w(num_faces);
  std::string line;
  int64_t count = 0, line_no = 0;
  while (std::getline(in, line)) {
    ++line_no;
    absl::string_view s = absl::StripAsciiWhitespace(line);
    if (s.empty()) continue;
    double v;
    if (!absl::SimpleAtod(s, &v) || !std::isfinite(v) || !(v > 0)) {
      return absl::InvalidArgumentError(absl::StrFormat(
          "%s:%d: '%s' is not a finite positive weight", path, line_no, std::string(s)));
    }
    if (count >= num_faces) {
      return absl::InvalidArgumentError(absl::StrFormat(
          "%s: more than %d weights (the mesh has %d faces)", path, num_faces, num_faces));
    }
    w[count++] = v;
  }
  if (count != num_faces) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "%s: %d weights for %d faces (one weight per face)", path, count, num_faces));
  }
  return w;
}

absl::Status ExportMtx(const std::string& dir, const Basis& basis, const FieldOperator& op) {
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec) {
    return absl::InvalidArgumentError(
        absl::StrCat("cannot create output directory ", dir, ": ", ec.message()));
  }
  const std::filesystem::path d(dir);
  {
    // U's float values, widened exactly to double, column-major as the writer expects.
    Eigen::SparseMatrix<double> U = basis.U.cast<double>();
    U.makeCompressed();
    if (auto st = WriteMatrixMarket((d / "U.mtx").string(), U); !st.ok()) return st;
  }
  if (auto st = WriteMatrixMarket((d / "S.mtx").string(), op.stiffness); !st.ok()) return st;
  if (auto st = WriteMatrixMarketDiagonal((d / "M.mtx").string(), op.mass); !st.ok()) return st;
  const std::string samples_path = (d / "samples.txt").string();
  std::FILE* f = std::fopen(samples_path.c_str(), "w");
  if (f == nullptr) return absl::ErrnoToStatus(errno, absl::StrCat("cannot create ", samples_path));
  for (int32_t s : basis.sample_faces) std::fprintf(f, "%d\n", s);
  if (std::fclose(f) != 0)
    return absl::ErrnoToStatus(errno, absl::StrCat("writing ", samples_path));
  return absl::OkStatus();
}

}  // namespace

int RunBasis(const Args& args) {
  auto type = FieldTypeFromArgs(args);
  if (!type.ok()) return ReportError(type.status());
  auto dim = args.GetInt("dim", 0);
  if (!dim.ok()) return ReportError(dim.status());
  auto sigma = args.GetDouble("sigma", 40.0);
  if (!sigma.ok()) return ReportError(sigma.status());
  auto threads = args.GetInt("threads", 0);
  if (!threads.ok()) return ReportError(threads.status());
  auto seed = args.GetInt("seed", 0);
  if (!seed.ok()) return ReportError(seed.status());
  auto tolerance = args.GetDouble("tolerance", BasisOptions().eigen_tolerance);
  if (!tolerance.ok()) return ReportError(tolerance.status());
  auto coarse_dim = args.GetInt("coarse-dim", 0);
  if (!coarse_dim.ok()) return ReportError(coarse_dim.status());
  if (*dim < 1 || *dim > (int64_t{1} << 31) - 1) {
    return ReportError(absl::InvalidArgumentError(absl::StrCat("--dim ", *dim, " out of range")));
  }
  if (*coarse_dim < 0 || *coarse_dim >= *dim) {
    return ReportError(absl::InvalidArgumentError("--coarse-dim must be in [0, dim)"));
  }
  const int32_t coarse = static_cast<int32_t>(*coarse_dim);
  auto quality = QualityFromArgs(args);
  if (!quality.ok()) return ReportError(quality.status());
  // The levels' other rules (a coarse dimension only with --quality paper, d >= 40 for the
  // others), checked before the mesh loads.
  const absl::Status levels =
      QualityLevels(*quality, static_cast<int32_t>(*dim), *sigma, coarse).status();
  if (!levels.ok()) return ReportError(levels);
  if (*threads < 0 || *threads > 4096) {
    return ReportError(
        absl::InvalidArgumentError(absl::StrCat("--threads ", *threads, " out of range")));
  }

  const std::string mesh_path = args.positional()[0];
  auto mesh = LoadBenchMesh(mesh_path);
  if (!mesh.ok()) return ReportError(mesh.status());
  auto op = BuildFieldOperatorWithoutStiffness(*mesh, *type);
  if (!op.ok()) return ReportError(op.status());

  BasisOptions options;
  options.params.dimension = static_cast<int32_t>(*dim);
  options.params.sigma = *sigma;
  options.params.seed = static_cast<uint64_t>(*seed);
  options.threads = static_cast<int32_t>(*threads);
  options.eigen_tolerance = *tolerance;
  options.kernel_columns = !args.Has("no-kernel-columns");
  if (const auto weights = args.Get("weights"); weights.has_value()) {
    auto w = ReadWeights(*weights, mesh->num_faces());
    if (!w.ok()) return ReportError(w.status());
    options.params.face_weights = std::move(*w);
  }
  // S only if the build reads it, as the daemon builds (BuildBasisOfQuality).
  absl::StatusOr<Basis> basis = BuildBasisOfQuality(*mesh, &*op, options, *quality, coarse);
  if (!basis.ok()) return ReportError(basis.status());

  if (const auto save = args.Get("save"); save.has_value()) {
    auto bytes = ReadWholeFile(mesh_path);
    if (!bytes.ok()) return ReportError(bytes.status());
    const std::string mesh_id =
        absl::StrFormat("crc32c:%08x", Crc32c(bytes->data(), bytes->size()));
    if (auto st = SaveBasisFile(*save, *basis, mesh_id); !st.ok()) return ReportError(st);
  }
  if (const auto dir = args.Get("export-mtx"); dir.has_value()) {
    if (!op->has_stiffness()) {
      if (auto st = AssembleStiffness(*mesh, &*op); !st.ok()) return ReportError(st);
    }
    if (auto st = ExportMtx(*dir, *basis, *op); !st.ok()) return ReportError(st);
  }

  const int64_t k = basis->U.rows();
  JsonWriter json;
  json.BeginObject()
      .Int("dim", basis->dimension())
      .Int("regions", basis->num_regions())
      .Int("kernel_columns", basis->kernel_columns)
      .Int("dofs", k)
      .Int("nnz_u", basis->U.nonZeros())
      .Double("nnz_per_row", k > 0 ? static_cast<double>(basis->U.nonZeros()) / k : 0.0)
      .BeginObject("seconds")
      .Double("sampling", basis->timings.sampling_seconds)
      .Double("regions", basis->timings.regions_seconds)
      .Double("eigensolve", basis->timings.eigensolve_seconds)
      .Double("kernel", basis->timings.kernel_seconds)
      .Double("total", basis->timings.total_seconds)
      .EndObject()
      .Double("peak_rss_mb", PeakRssMb())
      .Double("estimated_peak_mb", static_cast<double>(EstimateBuildPeakBytes(
                                       mesh->num_faces(), *type, static_cast<int32_t>(*dim), *sigma,
                                       options.kernel_columns && basis->kernel_columns > 0,
                                       *quality, coarse, options.threads)) /
                                       (1 << 20));
  if (args.Has("stats")) {
    const BasisStats& st = basis->stats;
    json.BeginObject("stats")
        .Bool("hodge_factor_used", st.hodge_factor_used)
        .Int("dense_regions", st.dense_regions)
        .Int("lanczos_fallbacks", st.lanczos_fallbacks)
        .Double("mean_lobpcg_iterations",
                static_cast<double>(st.lobpcg_iterations) / basis->num_regions())
        .Int("max_region_faces", st.max_region_faces)
        .Double("mean_region_faces", st.mean_region_faces)
        .Double("radius", basis->radius)
        .Double("coverage_radius", basis->coverage_radius)
        .Int("uncovered_faces", basis->uncovered_faces)
        .EndObject();
  }
  json.EndObject();
  std::printf("%s\n", json.str().c_str());
  return 0;
}

}  // namespace fieldspace::bench
