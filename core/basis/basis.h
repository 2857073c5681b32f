#ifndef FIELDSPACE_CORE_BASIS_BASIS_H_
#define FIELDSPACE_CORE_BASIS_BASIS_H_

#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "Eigen/Core"
#include "Eigen/SparseCore"
#include "absl/functional/function_ref.h"
#include "absl/status/statusor.h"
#include "core/common/cancel.h"
#include "core/mesh/triangle_mesh.h"
#include "core/operators/field_operator.h"

namespace fieldspace {

enum class BasisPhase : uint8_t { kSampling = 0, kRegions = 1, kEigensolve = 2, kAssembly = 3 };

// Parameters of the locally supported basis construction (paper section 4; docs/conventions.md,
// Basis construction).
struct BasisParams {
  int32_t dimension = 0;                     // d: target number of columns of U (>= 1)
  double sigma = 40.0;                       // overlap factor of eq. 12 (> 0)
  std::optional<int32_t> fields_per_region;  // m; default: FieldType::default_fields_per_region()
  uint64_t seed = 0;                         // picks the first farthest-point sample per component
  // Per-face adaptivity weights (#F, each finite and > 0); empty means uniform. A dual arc's
  // length is multiplied by the mean of its two faces' weights.
  Eigen::VectorXd face_weights;
};

// Bounds of the parameters (sigma up to kMaxSigma, m up to kMaxFieldsPerRegion: beyond them a
// build would only exhaust memory or time).
inline constexpr double kMaxSigma = 1e6;
inline constexpr int32_t kMaxFieldsPerRegion = 64;

// InvalidArgument unless `p` is valid for `type` fields on a mesh of `num_faces` faces:
// 1 <= d <= k, sigma finite in (0, kMaxSigma], m in [1, kMaxFieldsPerRegion] (after its default),
// face_weights empty or #F finite values > 0. The one check of a basis request (the builders and
// the server's registry call it).
absl::Status ValidateBasisParams(const BasisParams& p, const FieldType& type, int64_t num_faces);

struct BasisOptions {
  BasisParams params;
  int32_t threads = 0;  // 0: all available cores
  // Called from any thread, at least every 100 ms while building; fraction in [0, 1].
  std::function<void(BasisPhase phase, double fraction)> progress;
  // Checked at least every 100 ms; when it becomes true the build returns Cancelled.
  const CancelFlag* cancel = nullptr;
  // Refuse (ResourceExhausted) when U would need more than this many bytes: estimated as
  // sigma * k nonzeros before building, exact after the regions are known (8 bytes a nonzero).
  int64_t max_basis_bytes = int64_t{16} << 30;
  // Room for this many more entries of U beyond the basis's own and its kernel columns' (address
  // space only: the pages are not touched until written), for columns appended to it later in
  // place (StackBases, AppendKernelColumns). BuildMultiLevelBasis gives its first level the room
  // for the others' entries, so that stacking them does not copy U (the build's last peak).
  int64_t reserve_entries = 0;
  // Convergence of each local eigenproblem: ||S_bar x - theta x|| <= tolerance (theta + tau) for
  // unit x (eigenvector errors ~ tolerance, eigenvalue errors ~ tolerance^2, relative). The
  // default gives eigenvalues to about 1e-6 relative, which is plenty for a basis (its span, not
  // its individual fields, matters), and saves ~2 of ~7.5 LOBPCG iterations against 1e-5.
  double eigen_tolerance = 5e-4;
  // Vector fields: solve the local problems through the factored form S = B B^T when S matches it
  // (see BasisStats::hodge_factor_used); false forces the generic path (tests, comparisons).
  bool use_factored_vector_operator = true;
  // Append the kernel of S (ComputeKernelFields, core/operators/kernel_fields.h: the 2 g harmonic
  // fields of a vector basis on a closed genus-g surface, the isotropic fields c I of a tensor
  // basis, parallel fields where the connection allows them) as the last columns of U, so that
  // fields of zero energy are represented exactly. They are global (dense) columns, M-orthonormal
  // among themselves. false builds the paper's construction exactly (identical U).
  bool kernel_columns = true;
  // Clamped local fields: the m lowest eigenfields of the region's biharmonic energy
  // B_bar = (S~ V)^T (S~ V), S~ = M^-1/2 S M^-1/2, over fields that vanish outside the region
  // (its Laplacian's rows reach one ring of faces outside), instead of the paper's Dirichlet
  // eigenfields of V^T S~ V. A clamped field and its slope vanish at the region's edge, so it has
  // no kink there: its biharmonic energy in the full space, x^T S M^-1 S x, is exactly its local
  // eigenvalue (the paper's fields put most of theirs into that kink). Local eigenvalues are then
  // biharmonic (about the square of the Laplacian's). Same supports, so U has the same sparsity;
  // the local problems' stencil reaches two rings instead of one and is factored in the generic
  // form, so large regions cost far more time and memory (EstimateBuildPeakBytes). Used by
  // BasisQuality::kSmooth.
  bool clamped_local_fields = false;
};

// Wall-clock seconds per phase. sampling: dual graph + farthest point sampling; regions: growing
// the regions and laying out U's sparsity; eigensolve: local matrices, factorizations and
// eigenproblems, writing U's values; total: the whole BuildBasis call.
struct BasisTimings {
  double sampling_seconds = 0;
  double regions_seconds = 0;
  double eigensolve_seconds = 0;
  // What the kernel columns added to the build: BuildBasis and BuildTwoLevelBasis compute them
  // beside the local fields and count the wait for them after the local fields plus appending
  // them. Not stored.
  double kernel_seconds = 0;
  double total_seconds = 0;
};

// How the local eigenproblems were solved (diagnostics).
struct BasisStats {
  // Vector fields only: S matched its factored form B B^T, so the local shift-inverses used the
  // Woodbury form (see local_problem.h); false means the generic path (factoring S_bar).
  bool hodge_factor_used = false;
  int32_t dense_regions = 0;      // solved densely (tiny regions)
  int32_t lanczos_fallbacks = 0;  // LOBPCG did not converge; Spectra's Lanczos did
  int64_t lobpcg_iterations = 0;  // summed over regions
  int64_t max_region_faces = 0;
  double mean_region_faces = 0;
};

// A subspace basis U (k x d) of locally supported fields.
struct Basis {
  FieldType type;
  BasisParams params;
  double radius = 0;  // r of eq. 12 actually used (in dual-graph distance units)
  // k x d, DOF order of docs/conventions.md (DOF layout); column j = region j / m, field j % m,
  // M-orthonormal within a region. Row-major float storage: lifting (U x) walks rows in parallel.
  Eigen::SparseMatrix<float, Eigen::RowMajor> U;
  std::vector<int32_t> sample_faces;      // sample (center) face of each region
  std::vector<double> local_eigenvalues;  // d: eigenvalue of each column's local problem (eq. 7)
  // max over faces of the dual-graph distance to the nearest sample (FPS's rho): the regions
  // cover every face when radius >= coverage_radius.
  double coverage_radius = 0;
  int64_t uncovered_faces = 0;  // faces in no region (no local column touches their rows)
  // The last kernel_columns columns of U are the kernel of S (BasisOptions::kernel_columns), not
  // local fields; their local_eigenvalues are 0.
  int32_t kernel_columns = 0;
  BasisTimings timings;
  BasisStats stats;

  int32_t dimension() const { return static_cast<int32_t>(U.cols()); }
  int32_t num_regions() const { return static_cast<int32_t>(sample_faces.size()); }
  // Bytes held by U and the per-column and per-face arrays (for memory budgets).
  int64_t MemoryBytes() const;
};

// Builds the basis (section 4) for `op` on `mesh`:
// 1. dual graph (dual_graph.h) and farthest point sampling, samples per component in proportion
//    to its area (sampling.h): R = ceil(d / m) regions;
// 2. radius r = sqrt(sigma A / (d pi)) (eq. 12, A the total area, also with weights), region =
//    faces within dual distance r of the sample (regions.h);
// 3. per region the m lowest eigenpairs of S_bar = V^T S V (eqs. 5, 7), columns V phi_i of U.
// Column j belongs to region j / m, field j % m. When m does not divide d, the last region (the
// last sample of the last component) contributes only d - m (R - 1) fields, its lowest ones, so
// that U has exactly d local columns. With options.kernel_columns (the default) the q columns of
// ComputeKernelFields follow them: U has d + q columns, params.dimension = d + q,
// kernel_columns = q. Each column is normalized (unit M-norm) with its largest-magnitude
// entry positive. The result does not depend on the thread count (regions are independent and
// each is solved deterministically).
// `op` may be without S (BuildFieldOperatorWithoutStiffness) when the build does not read it
// (BuildReadsStiffness); it then stands for the mesh's own operator.
// Errors: InvalidArgument for bad parameters (d < 1 or > k, sigma <= 0 or non-finite, bad
// weights, fields_per_region < 1, more components than regions, operator/mesh size mismatch,
// an operator without S for a build that reads it),
// Cancelled when options.cancel fires, ResourceExhausted when U would exceed
// options.max_basis_bytes or 2^31 - 1 nonzeros.
absl::StatusOr<Basis> BuildBasis(const TriangleMesh& mesh, const FieldOperator& op,
                                 const BasisOptions& options);

// A two-level basis: the columns of `fine` followed by those of `coarse` (same mesh and field
// type; typically a basis of fewer, larger regions). The local Dirichlet fields of a dense basis
// form no partition of unity, so smooth large-scale fields (the lowest eigenfields, the smooth
// part of any field) are poorly represented; a coarse level of wider fields restores them. The
// result keeps fine's params (but params.dimension = the total column count) and radius; samples
// and local eigenvalues are concatenated, so the "column j belongs to region j / m" rule holds only
// for the fine columns. InvalidArgument when the row counts or field types differ,
// ResourceExhausted past 2^31 - 1 nonzeros.
// Neither may have kernel columns (InvalidArgument): append them to the stacked basis.
absl::StatusOr<Basis> StackBases(Basis fine, const Basis& coarse);

// Appends the columns of K (k x q, e.g. ComputeKernelFields) to U as kernel columns (stored as
// float; exact zeros are not stored), with local eigenvalue 0. InvalidArgument when the row
// counts differ, ResourceExhausted past 2^31 - 1 nonzeros.
absl::Status AppendKernelColumns(const Eigen::MatrixXd& K, Basis* basis);

// Runs `build_local` (the local fields) and, when options.kernel_columns, the kernel of S
// (ComputeKernelFields) beside it on another task: most of the kernel is one multigrid Poisson
// solve, mostly on one thread, and the local fields keep the other threads busy meanwhile. Then
// `local_done` runs (before the wait for the kernel), the kernel is appended as columns
// (AppendKernelColumns) and timings.kernel_seconds is the time after the local fields. The
// kernel does not stop early when the local fields fail; it does when the build is cancelled.
absl::StatusOr<Basis> BuildBesideKernel(const TriangleMesh& mesh, const FieldOperator& op,
                                        const BasisOptions& options,
                                        absl::FunctionRef<absl::StatusOr<Basis>()> build_local,
                                        absl::FunctionRef<void()> local_done);

// One level of a multilevel basis: `dimension` local fields of the paper's construction with
// overlap factor `sigma`, clamped (BasisOptions::clamped_local_fields) or not.
struct BasisLevel {
  int32_t dimension = 0;
  double sigma = 40.0;
  bool clamped = false;
};

// Whether a build reads S: BuildBasis and BuildTwoLevelBasis with `options`; BuildMultiLevelBasis
// with `options` and `levels` (each level's `clamped` in place of options.clamped_local_fields).
// Only vector fields whose local problems all take the factored Hodge form
// (use_factored_vector_operator, nothing clamped) do not: those builds take an operator without S
// (BuildFieldOperatorWithoutStiffness) and run without S's memory (867 MB of the 1.38M-face
// armadillo's vector build). Their reduced system needs no S either (ReducedSystem::Build from
// the mesh); AssembleStiffness adds it where a caller still wants it (e.g. to export it).
bool BuildReadsStiffness(const FieldType& type, const BasisOptions& options,
                         const std::vector<BasisLevel>& levels = {});

// Named basis quality levels (docs/conventions.md, Basis quality; measured in bench/RESULTS.md,
// "Session 10").
enum class BasisQuality : uint8_t {
  // One level: the paper's construction with params.dimension and params.sigma.
  kPaper = 0,
  // Three levels of d - d/10 - d/40, d/10 and d/40 fields, each with overlap sigma * 5/8 (fewer
  // on a surface of genus > 0 for small d: BuildMultiLevelBasis): the
  // coarse levels' wide fields represent smooth large-scale fields (the lowest eigenfields), which
  // the fine level's small Dirichlet fields cannot combine into. At d = 2000, sigma 40: the lowest
  // 50 non-zero reduced eigenvalues within 1.8-2.0% mean, 3.1-3.9% max (paper: 20-29%, 128-173%)
  // at 1.7-1.9x the paper's nonzeros of U.
  kLowModes = 1,
  // The levels of kLowModes with clamped local fields (BasisOptions::clamped_local_fields): no
  // kinks at the regions' edges, so biharmonic energies in the subspace are those of the lifted
  // fields and biharmonic design (mu_B > 0) follows the full space; projections are also closer.
  // Same nonzeros as kLowModes; builds take 7-9x as long and ~4x the memory (bench/RESULTS.md,
  // "Session 11").
  kSmooth = 2,
};

// The levels of `quality` for dimension d and overlap sigma, the finest first: for kPaper one
// level {d, sigma}, or with a coarse dimension 0 < C < d the two levels {d - C, sigma} and
// {C, sigma} (BuildTwoLevelBasis); for kLowModes and kSmooth the three levels above. The one
// place a basis's levels are laid out: the builds and EstimateBuildPeakBytes read them here.
// InvalidArgument for C outside [0, d), C != 0 with another quality than kPaper, and kLowModes
// and kSmooth with d < 40 (the coarsest level needs d / 40 >= 1 fields).
absl::StatusOr<std::vector<BasisLevel>> QualityLevels(BasisQuality quality, int32_t dimension,
                                                      double sigma, int32_t coarse_dimension = 0);

// The levels' bases (BuildBasis with options.params' dimension and sigma replaced by the level's)
// stacked in order (StackBases), then the kernel columns when options.kernel_columns, computed
// beside the first level as in BuildBasis. One level is BuildBasis with its dimension and sigma.
// params.dimension of the result is the total of the levels' dimensions. The levels are built
// last (coarsest) first, so that their large local problems meet neither the finer levels' U nor
// the kernel step; progress fractions cover each level in proportion to its dimension, in that
// order.
// InvalidArgument for no levels or a level's dimension < 1; otherwise errors as BuildBasis and
// StackBases.
// On a mesh of genus > 0 a level after the first with fewer fields than its sigma is built as part
// of the level before it (its dimension added to that level's): its regions would each exceed the
// mesh's area, nearly whole components whose nearly harmonic lowest fields the local eigensolver
// cannot separate (docs/conventions.md, Basis quality).
absl::StatusOr<Basis> BuildMultiLevelBasis(const TriangleMesh& mesh, const FieldOperator& op,
                                           const BasisOptions& options,
                                           const std::vector<BasisLevel>& levels);

// BuildBasis with a coarse second level of `coarse_dimension` = C columns: BuildMultiLevelBasis of
// QualityLevels(kPaper, d, sigma, C) of options.params (the basis of dimension d - C, then the
// basis of dimension C, both with the other options as given); d local columns in all, then the
// kernel columns when options.kernel_columns. C = 0 is BuildBasis. The coarse level is built
// first: progress fractions cover it in the first C / d of each phase and the fine level in the
// rest. InvalidArgument unless 0 <= C < d; otherwise errors as BuildBasis and StackBases.
absl::StatusOr<Basis> BuildTwoLevelBasis(const TriangleMesh& mesh, const FieldOperator& op,
                                         const BasisOptions& options, int32_t coarse_dimension);

// The build a caller names by quality: BuildMultiLevelBasis of QualityLevels(quality, d, sigma,
// coarse_dimension) of options.params (for kPaper, BuildTwoLevelBasis; with C = 0, BuildBasis).
// `op` may come without S (BuildFieldOperatorWithoutStiffness): S is assembled into it first
// (AssembleStiffness) exactly when the build reads it (BuildReadsStiffness), so a vector build
// never holds S. The daemon (BuildBasisForKey) and `fieldspace-bench basis` build through it.
// Errors as QualityLevels, the builds it calls and AssembleStiffness.
absl::StatusOr<Basis> BuildBasisOfQuality(const TriangleMesh& mesh, FieldOperator* op,
                                          const BasisOptions& options, BasisQuality quality,
                                          int32_t coarse_dimension = 0);

// An estimate of the peak bytes of BuildBasisOfQuality for a mesh of `num_faces` faces, built
// with `threads` threads (BasisOptions::threads: 0 is all available cores), for admission against
// a memory budget: the operator, U, the regions and the threads' local problems, plus the d x d
// reduced matrices, plus, with kernel columns, what computing them beside the local fields holds
// (for vector fields the P1 Poisson solve's multigrid hierarchy and vectors and the candidate
// fields: 560 MiB measured on 1.79M faces, counted as 400 bytes a face). The local part follows
// the rule of thumb of sigma nonzeros per row of U and level (QualityLevels), at bytes per such
// nonzero measured on built peaks:
// - vector builds without S (BuildReadsStiffness false): 14 for one level and 18 for several,
//   whose coarse levels factor local problems of up to half the mesh on every thread
//   (bench/RESULTS.md, "Session 28": 89-2346 MiB for one level, 160-4366 MiB for several, on
//   86k-1.79M faces at d = 2000);
// - builds that read S (n-fields, tensors, kSmooth): 26 (vector) or 19 bytes for one level and
//   2.5 times that for several (Session 22, when every build held S);
// - kSmooth adds, on each thread, the sparse Cholesky factor of a clamped local problem, whose
//   two-ring stencil fills in far more than the Dirichlet one: up to the coarsest level's
//   regions, min(1, 25 sigma / d) of the mesh, at 8 KiB per DOF (measured 6.2-7.2 KiB on
//   58k-173k DOFs; bench/RESULTS.md, "Session 11").
int64_t EstimateBuildPeakBytes(int64_t num_faces, const FieldType& type, int32_t dimension,
                               double sigma, bool kernel_columns, BasisQuality quality,
                               int32_t coarse_dimension, int32_t threads = 0);

}  // namespace fieldspace

#endif  // FIELDSPACE_CORE_BASIS_BASIS_H_
