#include "core/basis/basis.h"

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <limits>
#include <memory>
#include <mutex>
#include <numeric>
#include <optional>
#include <thread>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "core/basis/dual_graph.h"
#include "core/basis/local_eigensolver.h"
#include "core/basis/local_problem.h"
#include "core/basis/progress.h"
#include "core/basis/regions.h"
#include "core/basis/sampling.h"
#include "core/common/random.h"
#include "core/common/status_macros.h"
#include "core/common/timing.h"
#include "core/operators/complex_power.h"
#include "core/operators/kernel_fields.h"
#include "tbb/blocked_range.h"
#include "tbb/enumerable_thread_specific.h"
#include "tbb/parallel_for.h"
#include "tbb/task_arena.h"
#include "tbb/task_group.h"

namespace fieldspace {

absl::Status ValidateBasisParams(const BasisParams& p, const FieldType& type, int64_t num_faces) {
  const int64_t k = static_cast<int64_t>(type.dofs_per_face()) * num_faces;
  if (p.dimension < 1) {
    return absl::InvalidArgumentError(
        absl::StrFormat("dimension must be >= 1 (got %d)", p.dimension));
  }
  if (p.dimension > k) {
    return absl::InvalidArgumentError(
        absl::StrFormat("dimension %d exceeds the number of DOFs (%d) of %s fields on this mesh",
                        p.dimension, k, type.ToString()));
  }
  if (!std::isfinite(p.sigma) || !(p.sigma > 0.0) || p.sigma > kMaxSigma) {
    return absl::InvalidArgumentError(
        absl::StrFormat("sigma must be finite and in (0, %g] (got %g)", kMaxSigma, p.sigma));
  }
  const int32_t m = p.fields_per_region.value_or(type.default_fields_per_region());
  if (m < 1 || m > kMaxFieldsPerRegion) {
    return absl::InvalidArgumentError(
        absl::StrFormat("fields_per_region must be in [1, %d] (got %d)", kMaxFieldsPerRegion, m));
  }
  if (p.face_weights.size() != 0 && p.face_weights.size() != num_faces) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "face_weights has %d entries; the mesh has %d faces (one weight per face, or none)",
        p.face_weights.size(), num_faces));
  }
  for (Eigen::Index f = 0; f < p.face_weights.size(); ++f) {
    const double w = p.face_weights[f];
    if (!std::isfinite(w) || !(w > 0.0)) {
      return absl::InvalidArgumentError(absl::StrFormat(
          "face_weights[%d] = %g; adaptivity weights must be finite and > 0", f, w));
    }
  }
  return absl::OkStatus();
}

namespace {

using basis_internal::DiskEigenvalueEstimate;
using basis_internal::HodgeFactorData;
using basis_internal::HodgeLocalOperator;
using basis_internal::kPrefetchFaces;
using basis_internal::LocalEigenOptions;
using basis_internal::LocalEigenResult;
using basis_internal::ProgressTicker;
using basis_internal::RegionWorkspace;
using basis_internal::RestrictedLocalOperator;

absl::Status ValidateInputs(const TriangleMesh& mesh, const FieldOperator& op,
                            const BasisOptions& options, int32_t* m_out) {
  const BasisParams& p = options.params;
  const int32_t dpf = op.type.dofs_per_face();
  const int64_t k = static_cast<int64_t>(dpf) * mesh.num_faces();
  if (op.dofs() != k ||
      (op.has_stiffness() && (op.stiffness.rows() != k || op.stiffness.cols() != k))) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "operator size (S %d x %d, mass %d) does not match the mesh: %d faces x %d DOFs = %d",
        op.stiffness.rows(), op.stiffness.cols(), op.dofs(), mesh.num_faces(), dpf, k));
  }
  if (!op.has_stiffness() && BuildReadsStiffness(op.type, options)) {
    return basis_internal::MissingStiffnessError(op.type);
  }
  RETURN_IF_ERROR(ValidateBasisParams(p, op.type, mesh.num_faces()));
  const int32_t m = p.fields_per_region.value_or(op.type.default_fields_per_region());
  if (!std::isfinite(options.eigen_tolerance) || !(options.eigen_tolerance > 0.0) ||
      options.eigen_tolerance >= 1.0) {
    return absl::InvalidArgumentError(
        absl::StrFormat("eigen_tolerance must be in (0, 1) (got %g)", options.eigen_tolerance));
  }
  if (options.threads < 0) {
    return absl::InvalidArgumentError(
        absl::StrFormat("threads must be >= 0 (got %d)", options.threads));
  }
  for (Eigen::Index i = 0; i < op.mass.size(); ++i) {
    if (!std::isfinite(op.mass[i]) || !(op.mass[i] > 0.0)) {
      return absl::InvalidArgumentError(
          absl::StrFormat("mass[%d] = %g; the mass must be finite and > 0", i, op.mass[i]));
    }
  }
  // Cheap memory guard before any work: the paper's rule of thumb, about sigma nonzeros per row.
  const double estimate_bytes = 8.0 * p.sigma * static_cast<double>(k);
  if (estimate_bytes > static_cast<double>(options.max_basis_bytes)) {
    return absl::ResourceExhaustedError(absl::StrFormat(
        "the basis would need about %.3g GiB (sigma %g x %d DOFs x 8 bytes), beyond the limit "
        "of %.3g GiB; lower sigma",
        estimate_bytes / (1 << 30), p.sigma, k,
        static_cast<double>(options.max_basis_bytes) / (1 << 30)));
  }
  *m_out = m;
  return absl::OkStatus();
}

// Smooth start vectors for a region's local problem (in the phi = M^1/2 Phi scaling of eq. 4):
// one fixed direction (the sample face's x axis) projected to every face, as the field type
// represents it, times a bump that vanishes at the region's rim. The lowest Dirichlet eigenfields
// of a disk look like that, so LOBPCG starts close to them (about 1.5 iterations fewer than from
// random vectors). Returns up to m columns.
Eigen::MatrixXd SmoothStartFields(const TriangleMesh& mesh, const FieldType& type,
                                  const std::vector<int32_t>& faces, int32_t sample, int32_t m) {
  const int32_t dpf = type.dofs_per_face();
  const int32_t nfr = static_cast<int32_t>(faces.size());
  const Eigen::Vector3d cs = mesh.face_barycenters().row(sample).transpose();
  const Eigen::Vector3d dir = mesh.frame_x().row(sample).transpose();
  // The region's faces are ascending but scattered over the mesh's rows (on a subdivided mesh
  // nearly one cache line per face): their rows are prefetched kPrefetchFaces ahead.
  const VertexMatrix& barycenters = mesh.face_barycenters();
  const VertexMatrix& normals = mesh.face_normals();
  const VertexMatrix& frame_x = mesh.frame_x();
  const VertexMatrix& frame_y = mesh.frame_y();
  const Eigen::VectorXd& areas = mesh.face_areas();
  double rmax = 0;
  for (int32_t i = 0; i < nfr; ++i) {
    if (i + kPrefetchFaces < nfr) __builtin_prefetch(&barycenters(faces[i + kPrefetchFaces], 0));
    rmax = std::max(rmax, (barycenters.row(faces[i]).transpose() - cs).norm());
  }
  const int32_t cols = std::min(m, type.kind == FieldKind::kTensor ? 3 : 2);
  Eigen::MatrixXd X(static_cast<Eigen::Index>(dpf) * nfr, cols);
  const int32_t turns = type.kind == FieldKind::kNField   ? type.n
                        : type.kind == FieldKind::kTensor ? 2
                                                          : 1;
  for (int32_t i = 0; i < nfr; ++i) {
    if (i + kPrefetchFaces < nfr) {
      const int32_t g = faces[i + kPrefetchFaces];
      __builtin_prefetch(&barycenters(g, 0));
      __builtin_prefetch(&normals(g, 0));
      __builtin_prefetch(&frame_x(g, 0));
      __builtin_prefetch(&frame_y(g, 0));
      __builtin_prefetch(&areas[g]);
    }
    const int32_t f = faces[i];
    const Eigen::Vector3d c = barycenters.row(f).transpose();
    const Eigen::Vector3d nf = normals.row(f).transpose();
    const double t = rmax > 0 ? (c - cs).norm() / rmax : 0.0;
    const double bump = std::cos(0.5 * M_PI * std::min(t, 1.0)) * std::sqrt(areas[f]);
    const Eigen::Vector3d d = dir - dir.dot(nf) * nf;
    // (cos, sin) of `turns` times the angle of d in the face's frame, without trigonometry.
    const double dx = d.dot(frame_x.row(f)), dy = d.dot(frame_y.row(f));
    const double norm = std::sqrt(dx * dx + dy * dy);
    const Eigen::Vector2d w =
        norm > 0.0 ? UnitComplexPower({dx / norm, dy / norm}, turns) : Eigen::Vector2d(1.0, 0.0);
    const double ca = w[0], sa = w[1];
    if (type.kind == FieldKind::kTensor) {
      // Mandel-Voigt (a11, a22, sqrt(2) a12): identity, and d d^T - I/2 at two angles.
      const double fields[3][3] = {{1.0, 1.0, 0.0},
                                   {0.5 * ca, -0.5 * ca, M_SQRT1_2 * sa},
                                   {-0.5 * sa, 0.5 * sa, M_SQRT1_2 * ca}};
      for (int32_t c2 = 0; c2 < cols; ++c2) {
        for (int32_t q = 0; q < 3; ++q) X(3 * i + q, c2) = bump * fields[c2][q];
      }
    } else {
      const double fields[2][2] = {{ca, sa}, {-sa, ca}};
      for (int32_t c2 = 0; c2 < cols; ++c2) {
        for (int32_t q = 0; q < 2; ++q) X(2 * i + q, c2) = bump * fields[c2][q];
      }
    }
  }
  return X;
}

// The body of BuildBasis, run inside the task arena.
absl::StatusOr<Basis> Build(const TriangleMesh& mesh, const FieldOperator& op,
                            const BasisOptions& options, int32_t m, ProgressTicker& ticker) {
  const auto t_start = std::chrono::steady_clock::now();
  const BasisParams& params = options.params;
  const int32_t d = params.dimension;
  const int32_t dpf = op.type.dofs_per_face();
  const int64_t k = op.dofs();
  const int32_t num_regions = static_cast<int32_t>((static_cast<int64_t>(d) + m - 1) / m);
  const CancelToken cancel = ticker.token();

  Basis basis;
  basis.type = op.type;
  basis.params = params;

  // 1. Sampling.
  ticker.SetPhase(BasisPhase::kSampling, 0.0);
  ticker.ReportNow();
  auto t0 = std::chrono::steady_clock::now();
  absl::StatusOr<DualGraph> graph = BuildDualGraph(mesh, params.face_weights);
  if (!graph.ok()) return graph.status();
  absl::StatusOr<std::vector<int32_t>> per_component =
      AllocateSamplesPerComponent(mesh, num_regions);
  if (!per_component.ok()) return per_component.status();
  absl::StatusOr<SamplingResult> sampling =
      FarthestPointSampling(mesh, *graph, *per_component, params.seed, cancel);
  if (!sampling.ok()) return sampling.status();
  basis.sample_faces = std::move(sampling->samples);
  basis.coverage_radius = sampling->coverage_radius;
  basis.timings.sampling_seconds = SecondsSince(t0);

  // 2. Regions and the sparsity of U.
  ticker.SetPhase(BasisPhase::kRegions, 0.0);
  ticker.ReportNow();
  t0 = std::chrono::steady_clock::now();
  // Eq. 12's area in the metric the regions grow in: with adaptivity weights a face's dual arcs
  // are w_f times longer, so its area counts w_f^2 times. Scaling all weights by c then scales the
  // distances and the radius alike and leaves the basis as it is.
  const double metric_area =
      params.face_weights.size() == 0
          ? mesh.total_area()
          : (mesh.face_areas().array() * params.face_weights.array().square()).sum();
  basis.radius = std::sqrt(params.sigma * metric_area / (d * M_PI));
  RegionOptions region_options;
  region_options.radius = basis.radius;
  region_options.min_faces = (m + dpf - 1) / dpf;
  absl::StatusOr<std::vector<std::vector<int32_t>>> regions =
      GrowRegions(*graph, basis.sample_faces, region_options, cancel);
  if (!regions.ok()) return regions.status();
  graph = DualGraph();  // free it
  auto fields_of = [&](int32_t r) { return r + 1 < num_regions ? m : d - m * (num_regions - 1); };
  // Position of each (region, face) pair's entries within the face's rows of U: regions in
  // column order, so every row's column indices come out ascending.
  const int32_t nf = mesh.num_faces();
  std::vector<std::vector<int32_t>> slot(num_regions);
  std::vector<int64_t> per_face(nf, 0);
  int64_t max_region = 0, sum_region = 0;
  for (int32_t r = 0; r < num_regions; ++r) {
    const std::vector<int32_t>& faces = (*regions)[r];
    if (static_cast<int64_t>(faces.size()) * dpf < fields_of(r)) {
      return absl::InvalidArgumentError(absl::StrFormat(
          "region %d (sample face %d) has only %d DOFs for %d fields: its component is too "
          "small; lower fields_per_region",
          r, basis.sample_faces[r], static_cast<int64_t>(faces.size()) * dpf, fields_of(r)));
    }
    slot[r].resize(faces.size());
    for (size_t i = 0; i < faces.size(); ++i) {
      const int64_t s = per_face[faces[i]];
      slot[r][i] = static_cast<int32_t>(std::min<int64_t>(s, std::numeric_limits<int32_t>::max()));
      per_face[faces[i]] = s + fields_of(r);
    }
    max_region = std::max<int64_t>(max_region, faces.size());
    sum_region += faces.size();
    if ((r & 63) == 0 && cancel.Check()) return ProgressTicker::CancelledError();
  }
  int64_t nnz = 0;
  for (int32_t f = 0; f < nf; ++f) {
    nnz += per_face[f] * dpf;
    basis.uncovered_faces += per_face[f] == 0;
  }
  if (nnz > std::numeric_limits<int32_t>::max()) {
    return absl::ResourceExhaustedError(absl::StrFormat(
        "U would have %d nonzeros, beyond the 2^31 - 1 of its 32-bit indices; lower sigma or "
        "the dimension",
        nnz));
  }
  if (8.0 * nnz > static_cast<double>(options.max_basis_bytes)) {
    return absl::ResourceExhaustedError(absl::StrFormat(
        "U would need %.3g GiB (%d nonzeros), beyond the limit of %.3g GiB; lower sigma",
        8.0 * nnz / (1 << 30), nnz, static_cast<double>(options.max_basis_bytes) / (1 << 30)));
  }
  basis.stats.max_region_faces = max_region;
  basis.stats.mean_region_faces = static_cast<double>(sum_region) / num_regions;
  Eigen::SparseMatrix<float, Eigen::RowMajor>& U = basis.U;
  U.resize(k, d);
  // Room for the kernel columns BuildBesideKernel appends and for options.reserve_entries, so
  // that AppendKernelColumns and StackBases can write them in place instead of beside a copy of U
  // (the build's peak on meshes with genus and of multilevel builds). Address space only: the
  // pages are not touched before those columns are written.
  const int64_t room = std::max<int64_t>(0, options.reserve_entries) +
                       (options.kernel_columns ? KernelEntriesBound(mesh, op.type) : int64_t{0});
  if (room > 0 && nnz + room <= std::numeric_limits<int32_t>::max()) U.reserve(nnz + room);
  U.resizeNonZeros(nnz);
  {
    int32_t* outer = U.outerIndexPtr();
    outer[0] = 0;
    for (int32_t f = 0; f < nf; ++f) {
      for (int32_t c = 0; c < dpf; ++c) {
        const int64_t row = static_cast<int64_t>(dpf) * f + c;
        outer[row + 1] = outer[row] + static_cast<int32_t>(per_face[f]);
      }
    }
  }
  std::vector<int64_t>().swap(per_face);
  basis.timings.regions_seconds = SecondsSince(t0);

  // 3. Local eigenproblems, written straight into U.
  ticker.SetPhase(BasisPhase::kEigensolve, 0.0);
  ticker.ReportNow();
  t0 = std::chrono::steady_clock::now();
  Eigen::VectorXd inv_sqrt_mass = op.mass.cwiseSqrt().cwiseInverse();
  HodgeFactorData hodge;
  // (Clamped local problems are always factored in the generic form.)
  if (op.type.kind == FieldKind::kVector && options.use_factored_vector_operator &&
      !options.clamped_local_fields) {
    hodge = basis_internal::BuildHodgeFactorData(mesh);
    // Without S the operator is the mesh's own, which is the factored form.
    absl::StatusOr<bool> matches = op.has_stiffness()
                                       ? basis_internal::HodgeFactorMatches(mesh, op, hodge, cancel)
                                       : absl::StatusOr<bool>(true);
    if (!matches.ok()) return matches.status();
    basis.stats.hodge_factor_used = *matches;
  }
  const bool use_hodge = basis.stats.hodge_factor_used;
  basis.local_eigenvalues.assign(d, 0.0);
  tbb::enumerable_thread_specific<std::unique_ptr<RegionWorkspace>> workspaces;
  std::atomic<int32_t> done{0};
  std::atomic<bool> failed{false};
  std::atomic<int32_t> dense_regions{0}, lanczos{0};
  std::atomic<int64_t> iterations{0};
  std::mutex error_mutex;
  absl::Status error;
  const Eigen::VectorXd& area = mesh.face_areas();
  float* values = U.valuePtr();
  int32_t* columns = U.innerIndexPtr();
  const int32_t* outer = U.outerIndexPtr();
  auto solve_region = [&](int32_t r, RegionWorkspace& ws) -> absl::Status {
    const std::vector<int32_t>& faces = (*regions)[r];
    const int32_t nfr = static_cast<int32_t>(faces.size());
    double region_area = 0.0;
    for (int32_t i = 0; i < nfr; ++i) {
      if (i + kPrefetchFaces < nfr) __builtin_prefetch(&area[faces[i + kPrefetchFaces]]);
      region_area += area[faces[i]];
    }
    const double lambda = DiskEigenvalueEstimate(region_area);
    const Eigen::MatrixXd start =
        SmoothStartFields(mesh, op.type, faces, basis.sample_faces[r], fields_of(r));
    LocalEigenOptions eo;
    eo.count = fields_of(r);
    // No guard vectors: measured ~12% cheaper overall than one guard (fewer solves per
    // iteration outweigh the slightly slower convergence); the Lanczos fallback covers the rare
    // region whose m-th and (m+1)-th eigenvalues nearly coincide.
    eo.guard = 0;
    eo.initial = &start;
    eo.tolerance = options.eigen_tolerance;
    eo.seed = SplitMix64::Combine(params.seed, static_cast<uint64_t>(r));
    // The shift tau only needs to keep the shifted matrix safely positive definite: a fraction
    // of the lowest eigenvalue (larger for the Woodbury form, whose rounding error grows like
    // lambda_max / tau). Should a factorization still fail, retry with a larger shift.
    absl::StatusOr<LocalEigenResult> res;
    for (double tau_scale : {1.0, 100.0, 1e4}) {
      std::unique_ptr<basis_internal::LocalOperator> local;
      if (options.clamped_local_fields) {
        local = std::make_unique<RestrictedLocalOperator>(
            op, inv_sqrt_mass, faces, 0.01 * tau_scale * lambda * lambda, ws, /*clamped=*/true);
      } else if (use_hodge) {
        local =
            std::make_unique<HodgeLocalOperator>(mesh, hodge, faces, 0.1 * tau_scale * lambda, ws);
      } else {
        local = std::make_unique<RestrictedLocalOperator>(op, inv_sqrt_mass, faces,
                                                          0.01 * tau_scale * lambda, ws);
      }
      res = SolveLocalEigenproblem(*local, eo, cancel);
      if (res.ok() || !absl::IsFailedPrecondition(res.status())) break;
    }
    if (!res.ok()) {
      if (absl::IsCancelled(res.status())) return res.status();
      return absl::Status(
          res.status().code(),
          absl::StrFormat("region %d (sample face %d, %d faces): %s", r, basis.sample_faces[r],
                          faces.size(), res.status().message()));
    }
    if (res->dense) dense_regions.fetch_add(1, std::memory_order_relaxed);
    if (res->lanczos_fallback) lanczos.fetch_add(1, std::memory_order_relaxed);
    iterations.fetch_add(res->iterations, std::memory_order_relaxed);
    const int32_t first_col = r * m;
    const int32_t count = eo.count;
    std::array<double, kMaxFieldsPerRegion> sign;
    for (int32_t c = 0; c < count; ++c) {
      Eigen::Index imax = 0;
      res->vectors.col(c).cwiseAbs().maxCoeff(&imax);
      sign[c] = res->vectors(imax, c) < 0 ? -1.0 : 1.0;
      basis.local_eigenvalues[first_col + c] = res->values[c];
    }
    // Row by row, all of the region's fields at once: the region's entries of a row are adjacent
    // (slot + c), so each row of U is fetched once, not once per field (U is hundreds of MB and the
    // region's rows are scattered through it).
    const double* phi = res->vectors.data();
    const int64_t ld = res->vectors.rows();
    // Each face's rows of U are a cache miss or two (U is hundreds of MB): their row offsets are
    // prefetched 2 kPrefetchFaces faces ahead, the entries themselves kPrefetchFaces ahead.
    for (int32_t i = 0; i < nfr; ++i) {
      if (i + 2 * kPrefetchFaces < nfr) {
        __builtin_prefetch(&outer[dpf * static_cast<int64_t>(faces[i + 2 * kPrefetchFaces])]);
      }
      if (i + kPrefetchFaces < nfr) {
        const int64_t g = faces[i + kPrefetchFaces];
        for (int32_t q = 0; q < dpf; ++q) {
          const int64_t pos = outer[dpf * g + q] + slot[r][i + kPrefetchFaces];
          __builtin_prefetch(values + pos, 1);
          __builtin_prefetch(columns + pos, 1);
        }
      }
      const int64_t f = faces[i];
      for (int32_t q = 0; q < dpf; ++q) {
        const int64_t row = dpf * f + q;
        const int64_t pos = outer[row] + slot[r][i];
        const double scale = inv_sqrt_mass[row];
        const double* x = phi + dpf * i + q;
        for (int32_t c = 0; c < count; ++c) {
          values[pos + c] = static_cast<float>(sign[c] * x[c * ld] * scale);
          columns[pos + c] = first_col + c;
        }
      }
    }
    return absl::OkStatus();
  };
  tbb::parallel_for(
      tbb::blocked_range<int32_t>(0, num_regions, 1),
      [&](const tbb::blocked_range<int32_t>& range) {
        std::unique_ptr<RegionWorkspace>& ws = workspaces.local();
        if (!ws) ws = std::make_unique<RegionWorkspace>();
        for (int32_t r = range.begin(); r != range.end(); ++r) {
          if (failed.load(std::memory_order_relaxed)) return;
          absl::Status s = solve_region(r, *ws);
          if (!s.ok()) {
            std::lock_guard<std::mutex> lock(error_mutex);
            if (error.ok()) error = s;
            failed.store(true, std::memory_order_relaxed);
            return;
          }
          ticker.SetFraction(static_cast<double>(done.fetch_add(1) + 1) / num_regions);
          if (cancel.Check()) {
            failed.store(true, std::memory_order_relaxed);
            return;
          }
        }
      },
      tbb::simple_partitioner());
  if (ticker.cancelled()) return ProgressTicker::CancelledError();
  if (!error.ok()) return error;
  basis.stats.dense_regions = dense_regions.load();
  basis.stats.lanczos_fallbacks = lanczos.load();
  basis.stats.lobpcg_iterations = iterations.load();
  basis.timings.eigensolve_seconds = SecondsSince(t0);
  basis.timings.total_seconds = SecondsSince(t_start);
  return basis;
}

}  // namespace

bool BuildReadsStiffness(const FieldType& type, const BasisOptions& options,
                         const std::vector<BasisLevel>& levels) {
  bool clamped = levels.empty() && options.clamped_local_fields;
  for (const BasisLevel& level : levels) clamped = clamped || level.clamped;
  return type.kind != FieldKind::kVector || !options.use_factored_vector_operator || clamped;
}

absl::StatusOr<Basis> BuildBasis(const TriangleMesh& mesh, const FieldOperator& op,
                                 const BasisOptions& options) {
  const auto t_start = std::chrono::steady_clock::now();
  int32_t m = 0;
  absl::Status valid = ValidateInputs(mesh, op, options, &m);
  if (!valid.ok()) return valid;
  ProgressTicker ticker(options.progress, options.cancel);
  if (ticker.cancelled()) return ProgressTicker::CancelledError();
  const int threads =
      options.threads > 0 ? options.threads : tbb::this_task_arena::max_concurrency();
  tbb::task_arena arena(threads);
  absl::StatusOr<Basis> result;
  arena.execute([&] {
    result = BuildBesideKernel(
        mesh, op, options, [&] { return Build(mesh, op, options, m, ticker); },
        [&] {
          if (!options.kernel_columns) return;
          ticker.SetPhase(BasisPhase::kAssembly, 0.0);
          ticker.ReportNow();
        });
  });
  if (ticker.cancelled()) return ProgressTicker::CancelledError();
  if (!result.ok()) return result;
  ticker.SetPhase(BasisPhase::kAssembly, 1.0);
  ticker.ReportNow();
  result->timings.total_seconds = SecondsSince(t_start);
  return result;
}

absl::StatusOr<Basis> BuildBesideKernel(const TriangleMesh& mesh, const FieldOperator& op,
                                        const BasisOptions& options,
                                        absl::FunctionRef<absl::StatusOr<Basis>()> build_local,
                                        absl::FunctionRef<void()> local_done) {
  absl::StatusOr<Eigen::MatrixXd> kernel = Eigen::MatrixXd();
  tbb::task_group kernel_task;
  if (options.kernel_columns) {
    kernel_task.run([&] {
      KernelFieldOptions kernel_options;
      kernel_options.cancel = options.cancel;
      kernel = ComputeKernelFields(mesh, op, kernel_options);
    });
  }
  absl::StatusOr<Basis> result = build_local();
  const auto local_end = std::chrono::steady_clock::now();
  local_done();
  kernel_task.wait();
  if (!result.ok() || !options.kernel_columns) return result;
  if (IsCancelled(options.cancel)) return ProgressTicker::CancelledError();
  if (!kernel.ok()) return kernel.status();
  RETURN_IF_ERROR(AppendKernelColumns(*kernel, &*result));
  result->timings.kernel_seconds = SecondsSince(local_end);
  return result;
}

int64_t Basis::MemoryBytes() const {
  const int64_t nnz = U.nonZeros();
  return nnz * static_cast<int64_t>(sizeof(float) + sizeof(int)) +
         (U.outerSize() + 1) * static_cast<int64_t>(sizeof(int)) +
         static_cast<int64_t>(local_eigenvalues.size() * sizeof(double) +
                              sample_faces.size() * sizeof(int32_t)) +
         params.face_weights.size() * static_cast<int64_t>(sizeof(double));
}

int64_t EstimateBuildPeakBytes(int64_t num_faces, const FieldType& type, int32_t dimension,
                               double sigma, bool kernel_columns, BasisQuality quality,
                               int32_t coarse_dimension, int32_t threads) {
  const double k = static_cast<double>(num_faces) * type.dofs_per_face();
  const bool vector = type.kind == FieldKind::kVector;
  const bool clamped = quality == BasisQuality::kSmooth;
  BasisOptions defaults;
  defaults.clamped_local_fields = clamped;
  const bool reads_stiffness = BuildReadsStiffness(type, defaults);
  // The levels' overlaps: sigma nonzeros per row of U each.
  double level_sigmas = sigma;
  int32_t num_levels = 1;
  const absl::StatusOr<std::vector<BasisLevel>> levels =
      QualityLevels(quality, dimension, sigma, coarse_dimension);
  if (levels.ok()) {
    level_sigmas = 0.0;
    for (const BasisLevel& level : *levels) level_sigmas += level.sigma;
    num_levels = static_cast<int32_t>(levels->size());
  }
  double local = 0.0;
  if (!reads_stiffness) {
    local = (num_levels > 1 ? 18.0 : 14.0) * level_sigmas * k;
  } else {
    local = (num_levels > 1 ? 2.5 : 1.0) * (vector ? 26.0 : 19.0) * sigma * k;
  }
  const double d = dimension;
  // The kernel step: the vertex Poisson solve's hierarchy and vectors and 2 g dense candidates
  // for vector fields; a few dense candidate columns otherwise.
  const double kernel =
      !kernel_columns ? 0.0 : (vector ? 400.0 * static_cast<double>(num_faces) : 32.0 * k);
  // As the build resolves BasisOptions::threads.
  const int32_t local_threads = threads > 0 ? threads : tbb::this_task_arena::max_concurrency();
  const double clamped_region = std::min(1.0, 25.0 * sigma / std::max(d, 1.0)) * k;
  const double clamped_factors = clamped ? local_threads * 8192.0 * clamped_region : 0.0;
  return static_cast<int64_t>(local + 8.0 * d * d + kernel + clamped_factors);
}

}  // namespace fieldspace
