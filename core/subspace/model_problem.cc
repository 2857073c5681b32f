#include "core/subspace/model_problem.h"

#include <algorithm>
#include <cmath>
#include <optional>
#include <tuple>
#include <utility>
#include <vector>

#include "Eigen/Eigenvalues"
#include "absl/strings/str_cat.h"
#include "absl/types/span.h"
#include "core/common/cancel.h"
#include "core/common/index_check.h"
#include "core/common/status_macros.h"
#include "core/subspace/kkt_solver.h"
#include "core/subspace/subspace_util.h"
#include "oneapi/tbb/blocked_range.h"
#include "oneapi/tbb/enumerable_thread_specific.h"
#include "oneapi/tbb/parallel_for.h"

namespace fieldspace {

EnergyWeights EffectiveEnergyWeights(const ReducedSystem& system, const EnergyWeights& weights,
                                     bool scale_free) {
  EnergyWeights w = weights;
  if (scale_free) w.mu_b *= system.mass().sum() / system.dofs_per_face();
  return w;
}

absl::Status ValidateSolveOptions(const ReducedSolveOptions& o) {
  if (!(o.regularization >= 0) || !(o.max_regularization >= o.regularization) ||
      !std::isfinite(o.max_regularization) || !(o.tolerance >= 0) || o.max_refinement_steps < 0 ||
      o.max_iterations < 1 || !(o.dependence_tolerance > 0) || !(o.dependence_tolerance < 1)) {
    return absl::InvalidArgumentError(
        "ReducedSolveOptions: need 0 <= regularization <= max_regularization < inf, "
        "tolerance >= 0, max_refinement_steps >= 0, max_iterations >= 1 and "
        "0 < dependence_tolerance < 1");
  }
  return absl::OkStatus();
}

namespace {

// Faces per BatchFaceStiffness call: p times as many columns substituted together.
constexpr size_t kStiffnessBatch = 32;

// The soft constraints added up per face. Constraints on one face share its rows U_f of the basis
// and its stiffness g_f, so their terms sum to one:
//   sum_i (mu_c w_i / g_f) U_f^T U_f = (mu_c / g_f) (sum_i w_i) U_f^T U_f,
//   sum_i (mu_c w_i / g_f) U_f^T c_i = (mu_c / g_f) U_f^T (sum_i w_i c_i),
// which costs one outer product and one stiffness per distinct face, however many constraints
// hit it (2^20 constraints on a mesh of F faces touch at most F faces).
struct SoftFaceSums {
  std::vector<int32_t> faces;  // the distinct soft-constrained faces, in locality order
  std::vector<double> weight;  // per face: sum_i w_i
  Eigen::MatrixXd value;       // p x faces.size(): column j is sum_i w_i c_i of face j
};

SoftFaceSums SumSoftConstraintsPerFace(const std::vector<FieldConstraint>& constraints,
                                       const ReducedSystem& system) {
  const int32_t p = system.dofs_per_face();
  const int32_t num_faces = system.num_faces();
  BasisRowScratch scratch;
  std::vector<int32_t> slot(num_faces, -1);
  for (const FieldConstraint& c : constraints) {
    if (!c.hard()) slot[c.face] = 0;
  }
  SoftFaceSums sums;
  for (int32_t f = 0; f < num_faces; ++f) {
    if (slot[f] >= 0) sums.faces.push_back(f);
  }
  // Faces whose first rows span the same basis columns (the local fields over them) lie in one
  // region and share most of their elimination-tree reach: sorted by the first and last such
  // column, neighbours in this order go into one BatchFaceStiffness call.
  struct Keyed {
    int64_t first, last;  // the first and last basis column stored in the face's first row
    int32_t face;
    bool operator<(const Keyed& o) const {
      return std::tie(first, last, face) < std::tie(o.first, o.last, o.face);
    }
  };
  std::vector<Keyed> keyed(sums.faces.size());
  for (size_t j = 0; j < keyed.size(); ++j) {
    const int32_t f = sums.faces[j];
    const BasisRow row = system.BasisRowOf(static_cast<int64_t>(f) * p, &scratch);
    keyed[j] = {system.dimension(), -1, f};
    for (int64_t q = 0; q < row.size; ++q) {
      keyed[j].first = std::min<int64_t>(keyed[j].first, row.cols[q]);
      keyed[j].last = std::max<int64_t>(keyed[j].last, row.cols[q]);
    }
  }
  std::sort(keyed.begin(), keyed.end());
  for (size_t j = 0; j < keyed.size(); ++j) {
    sums.faces[j] = keyed[j].face;
    slot[sums.faces[j]] = static_cast<int32_t>(j);
  }
  sums.weight.assign(sums.faces.size(), 0.0);
  sums.value = Eigen::MatrixXd::Zero(p, static_cast<int64_t>(sums.faces.size()));
  for (const FieldConstraint& c : constraints) {
    if (c.hard()) continue;
    const int32_t j = slot[c.face];
    sums.weight[j] += c.weight;
    sums.value.col(j) += c.weight * c.value;
  }
  return sums;
}

// The stiffnesses g_f of `faces` (FaceStiffness, kkt_solver.h, with the kernel columns left out)
// written to stiffness[0..faces.size()): the same quantity, computed for a batch of faces with
// one sparse forward substitution of all their rows at once (SupernodalFactor::
// ForwardSparseColumns). Faces that share basis columns share most of their elimination-tree
// reach, which is then traversed once, with matrix-matrix instead of matrix-vector kernels.
// `rows`: the faces' BasisRowsOfFace, p per face. Y: scratch space (d x p * faces.size()).
absl::Status BatchFaceStiffness(const ReducedSystem& system, const SupernodalFactor& factor,
                                absl::Span<const int32_t> faces,
                                const std::vector<std::vector<SparseRow>>& rows, Eigen::MatrixXd* Y,
                                double* stiffness) {
  const int64_t d = system.dimension();
  const int32_t p = system.dofs_per_face();
  const int64_t first_kernel = d - std::max<int32_t>(0, system.basis().kernel_columns);
  const int64_t k = static_cast<int64_t>(faces.size()) * p;
  std::vector<SparseRow> kept(k);
  std::vector<absl::Span<const int32_t>> col_spans(k);
  std::vector<absl::Span<const double>> val_spans(k);
  for (size_t f = 0; f < faces.size(); ++f) {
    for (int32_t c = 0; c < p; ++c) {
      const SparseRow& row = rows[f][c];
      SparseRow& out = kept[f * p + c];
      for (size_t q = 0; q < row.cols.size(); ++q) {
        if (row.cols[q] >= first_kernel) continue;
        out.cols.push_back(row.cols[q]);
        out.vals.push_back(row.vals[q]);
      }
      col_spans[f * p + c] = out.cols;
      val_spans[f * p + c] = out.vals;
    }
  }
  Y->resize(d, k);
  factor.ForwardSparseColumns(col_spans, val_spans, *Y);
  for (size_t f = 0; f < faces.size(); ++f) {
    absl::StatusOr<double> g =
        StiffnessOfSubstitutions(Y->middleCols(static_cast<int64_t>(f) * p, p));
    if (!g.ok()) {
      return absl::Status(g.status().code(), absl::StrCat("constraint on face ", faces[f], ": ",
                                                          g.status().message()));
    }
    stiffness[f] = *g;
  }
  return absl::OkStatus();
}

// Per thread: the soft terms' sums on A's pattern, and scratch space for one face.
struct SoftPartial {
  std::vector<double> values;  // nnz(A): sum of the faces' mu R^T R
  Eigen::VectorXd b;           // d: sum of the faces' mu R^T v
  // Entries outside A's pattern. The pattern holds U^T M U's nonzero values, and on symmetric
  // meshes (a box's faces at right angles, a 4-field's frames turned by multiples of pi/2) a
  // pair of columns that share a face can still sum to an exact 0 there, and so be missing.
  std::vector<Eigen::Triplet<double>> outside;
  absl::Status error;  // the first FaceStiffness failure of this thread
  // Scratch space for a batch of faces: their rows of U, their stiffnesses and matrix and
  // right-hand side scales, the forward substitutions of BatchFaceStiffness; the union of their
  // rows' columns (ascending), their rows R on those columns, scaled, and R^T diag(a) R.
  std::vector<std::vector<SparseRow>> rows;
  std::vector<double> stiffness;
  std::vector<double> scale;
  Eigen::MatrixXd rhs;
  Eigen::MatrixXd Y;
  std::vector<int32_t> cols;
  Eigen::MatrixXd R;
  Eigen::MatrixXd scaled;
  Eigen::MatrixXd outer;
};

// Adds sum_f a_f R_f^T R_f to part->values, on the pattern of A (outer, inner: A's compressed
// columns, sorted row indices), and sum_f R_f^T v_f to part->b, for a batch of faces: R_f =
// rows[f] (the face's p rows of U), a_f = a[f] > 0, v_f = column f of v (p x rows.size()). The
// batch's rows on the union of their columns form one dense matrix R: one matrix product
// R^T diag(a) R and one pass over those columns of A for the whole batch.
void AddBatchTerms(const std::vector<std::vector<SparseRow>>& rows, absl::Span<const double> a,
                   const Eigen::Ref<const Eigen::MatrixXd>& v, const int32_t* outer,
                   const int32_t* inner, SoftPartial* part) {
  const int64_t p = v.rows();
  const int64_t count = static_cast<int64_t>(a.size());
  std::vector<int32_t>& cols = part->cols;
  cols.clear();
  for (int64_t f = 0; f < count; ++f) {
    for (const SparseRow& row : rows[f]) cols.insert(cols.end(), row.cols.begin(), row.cols.end());
  }
  std::sort(cols.begin(), cols.end());
  cols.erase(std::unique(cols.begin(), cols.end()), cols.end());
  const int64_t m = static_cast<int64_t>(cols.size());
  part->R.setZero(count * p, m);
  for (int64_t f = 0; f < count; ++f) {
    for (int64_t comp = 0; comp < p; ++comp) {
      const SparseRow& row = rows[f][comp];
      for (size_t q = 0; q < row.cols.size(); ++q) {
        const int64_t at = std::lower_bound(cols.begin(), cols.end(), row.cols[q]) - cols.begin();
        part->R(f * p + comp, at) += row.vals[q];
      }
    }
  }
  const Eigen::Map<const Eigen::VectorXd> rhs(v.data(), count * p);  // v is contiguous
  const Eigen::VectorXd b = part->R.transpose() * rhs;
  part->scaled = part->R;
  for (int64_t r = 0; r < count * p; ++r) part->scaled.row(r) *= a[r / p];
  part->outer.noalias() = part->R.transpose() * part->scaled;
  for (int64_t j = 0; j < m; ++j) {
    part->b[cols[j]] += b[j];
    // Column cols[j] of A holds its rows in ascending order, as cols: each search starts where
    // the previous one ended.
    const int32_t* at = inner + outer[cols[j]];
    const int32_t* end = inner + outer[cols[j] + 1];
    for (int64_t i = 0; i < m; ++i) {
      // Exactly 0 where no face of the batch has both columns (a structural zero of R^T R,
      // which the pattern need not hold).
      if (part->outer(i, j) == 0) continue;
      at = std::lower_bound(at, end, cols[i]);
      if (at == end || *at != cols[i]) {
        part->outside.emplace_back(cols[i], cols[j], part->outer(i, j));
        continue;
      }
      part->values[at - inner] += part->outer(i, j);
    }
  }
}

}  // namespace

absl::StatusOr<ReducedAssembly> AssembleReducedModelProblem(const ReducedSystem& system,
                                                            const ModelProblem& problem,
                                                            const ReducedSolveOptions& options) {
  RETURN_IF_ERROR(ValidateSolveOptions(options));
  RETURN_IF_ERROR(ValidateWeightsWithoutDataTerm(problem.weights));
  const EnergyWeights w = EffectiveEnergyWeights(system, problem.weights, problem.scale_free);
  for (const FieldConstraint& c : problem.constraints) {
    RETURN_IF_ERROR(ValidateConstraint(c, system.num_faces(), system.type()));
  }
  const absl::Status cancelled_error = absl::CancelledError("reduced model solve cancelled");
  if (IsCancelled(options.cancel)) return cancelled_error;
  const int64_t d = system.dimension();
  // A_s = U^T (mu_S S + mu_B B) U + mu_C sum_soft w_i U_i^T U_i, b = mu_C sum_soft w_i U_i^T c_i.
  ReducedAssembly out{system.stiffness(), Eigen::VectorXd::Zero(d)};
  Eigen::SparseMatrix<double>& A = out.A;
  {
    double* a = A.valuePtr();
    const double* s = system.stiffness().valuePtr();
    const double* bl = system.bilaplacian().valuePtr();
    for (int64_t p = 0; p < A.nonZeros(); ++p) a[p] = w.mu_s * s[p] + w.mu_b * bl[p];
  }
  const bool any_soft = std::any_of(problem.constraints.begin(), problem.constraints.end(),
                                    [](const FieldConstraint& c) { return !c.hard(); });
  if (!any_soft || !(w.mu_c > 0)) return out;
  const SoftFaceSums sums = SumSoftConstraintsPerFace(problem.constraints, system);
  // Scale-free: each face's weight is divided by its stiffness under the energy alone.
  std::optional<SupernodalFactor> energy;
  if (problem.scale_free) {
    double tau0 = 0;
    ASSIGN_OR_RETURN(energy, FactorizeRegularized(system.pattern_symbolic(),
                                                  ShiftKernelColumns(system, A), options, &tau0));
    if (IsCancelled(options.cancel)) return cancelled_error;
  }
  // The face terms go straight into A's values: every pair of columns nonzero at a common face is
  // an entry of U^T M U, so of the shared pattern. Per thread one value array and one right-hand
  // side (O(nnz(A) + d) memory, whatever the number of constraints), summed at the end;
  // cancellation is checked per block of faces.
  const int64_t nnz = A.nonZeros();
  tbb::enumerable_thread_specific<SoftPartial> partials([&] {
    SoftPartial part;
    part.values.assign(nnz, 0.0);
    part.b = Eigen::VectorXd::Zero(d);
    return part;
  });
  const int32_t* outer = A.outerIndexPtr();
  const int32_t* inner = A.innerIndexPtr();
  const size_t n = sums.faces.size();
  const size_t batches = (n + kStiffnessBatch - 1) / kStiffnessBatch;
  tbb::parallel_for(
      tbb::blocked_range<size_t>(0, batches, 1), [&](const tbb::blocked_range<size_t>& range) {
        SoftPartial& part = partials.local();
        for (size_t batch = range.begin(); batch != range.end(); ++batch) {
          if (IsCancelled(options.cancel) || !part.error.ok()) return;
          const size_t begin = batch * kStiffnessBatch;
          const size_t count = std::min(kStiffnessBatch, n - begin);
          const absl::Span<const int32_t> faces(sums.faces.data() + begin, count);
          std::vector<std::vector<SparseRow>>& rows = part.rows;
          rows.resize(count);
          for (size_t f = 0; f < count; ++f) rows[f] = BasisRowsOfFace(system, faces[f]);
          part.stiffness.assign(count, 1.0);
          if (energy.has_value()) {
            part.error =
                BatchFaceStiffness(system, *energy, faces, rows, &part.Y, part.stiffness.data());
            if (!part.error.ok()) return;
          }
          part.scale.resize(count);
          part.rhs.resize(sums.value.rows(), static_cast<int64_t>(count));
          for (size_t f = 0; f < count; ++f) {
            const double mu = w.mu_c / part.stiffness[f];
            const int64_t j = static_cast<int64_t>(begin + f);
            part.scale[f] = mu * sums.weight[j];
            part.rhs.col(static_cast<int64_t>(f)) = mu * sums.value.col(j);
          }
          AddBatchTerms(rows, part.scale, part.rhs, outer, inner, &part);
        }
      });
  for (const SoftPartial& part : partials) RETURN_IF_ERROR(part.error);
  if (IsCancelled(options.cancel)) return cancelled_error;
  double* a = A.valuePtr();
  std::vector<Eigen::Triplet<double>> outside;
  for (const SoftPartial& part : partials) {
    for (int64_t q = 0; q < nnz; ++q) a[q] += part.values[q];
    out.b += part.b;
    outside.insert(outside.end(), part.outside.begin(), part.outside.end());
  }
  if (!outside.empty()) {
    // A wider pattern: SolveReducedModelProblem analyzes it anew (SamePattern fails).
    Eigen::SparseMatrix<double> extra(d, d);
    extra.setFromTriplets(outside.begin(), outside.end());
    A = A + extra;
  }
  return out;
}

absl::StatusOr<ReducedSolution> SolveReducedModelProblem(const ReducedSystem& system,
                                                         const ModelProblem& problem,
                                                         const ReducedSolveOptions& options) {
  ASSIGN_OR_RETURN(ReducedAssembly assembly, AssembleReducedModelProblem(system, problem, options));
  const absl::Status cancelled_error = absl::CancelledError("reduced model solve cancelled");
  const int64_t d = system.dimension();
  const double mu_b = EffectiveEnergyWeights(system, problem.weights, problem.scale_free).mu_b;
  const Eigen::SparseMatrix<double>& A = assembly.A;
  Eigen::VectorXd& b = assembly.b;
  std::shared_ptr<const SupernodalSymbolic> symbolic = system.pattern_symbolic();
  if (!symbolic->SamePattern(A)) {
    ASSIGN_OR_RETURN(symbolic, SupernodalSymbolic::Analyze(A));
  }
  double tau = 0;
  if (IsCancelled(options.cancel)) return cancelled_error;
  ASSIGN_OR_RETURN(SupernodalFactor factor,
                   FactorizeRegularized(symbolic, ShiftKernelColumns(system, A), options, &tau));
  ASSIGN_OR_RETURN(SupernodalMatrix A_panels, SupernodalMatrix::Create(symbolic, A));

  KktSolver kkt(d, system.dofs_per_face(), options);
  for (const FieldConstraint& c : problem.constraints) {
    if (!c.hard()) continue;
    kkt.Append(BasisRowsOfFace(system, c.face), c.value, 0.0, /*hard=*/true);
  }
  if (IsCancelled(options.cancel)) return cancelled_error;
  RETURN_IF_ERROR(kkt.SetMatrix(&A_panels, &factor));
  if (problem.biharmonic == BiharmonicForm::kMixed) kkt.SetMixedBiharmonic(&system, mu_b);
  if (IsCancelled(options.cancel)) return cancelled_error;
  RETURN_IF_ERROR(kkt.FactorizeSchur());
  if (IsCancelled(options.cancel)) return cancelled_error;
  ReducedSolution solution = kkt.Solve(&b);
  if (IsCancelled(options.cancel)) return cancelled_error;  // the mixed form's iterations stop
  solution.regularization = tau;
  return solution;
}

int64_t SolveWorkingBytes(const ReducedSystem& system, int64_t soft, int64_t hard, bool scale_free,
                          int32_t threads) {
  const int64_t d = system.dimension();
  const int64_t p = system.dofs_per_face();
  const int64_t nnz = system.stats().pattern_nonzeros;
  const int64_t factor = system.stats().factor_nonzeros;
  // A, its kernel-shifted copy and the supernodal panels of A; the factor (twice when scale-free:
  // the energy's own factorization for the stiffnesses).
  int64_t bytes = 2 * nnz * 12 + factor * 8 + factor * 8 * (scale_free ? 2 : 1);
  if (soft > 0) {
    // Per thread: the sums on the pattern, and a batch's forward substitutions (twice: the
    // factor's own copy) and dense rows (at most p * batch x d).
    const int64_t batch = static_cast<int64_t>(kStiffnessBatch) * p;
    bytes += std::max<int64_t>(threads, 1) * ((nnz + d) * 8 + 3 * batch * d * 8);
    // The per-face sums: a slot per face of the mesh, and per distinct face its sums and its
    // sort key.
    const int64_t faces = std::min<int64_t>(soft, system.num_faces());
    bytes += int64_t{4} * system.num_faces() + faces * (8 * p + 8 + 4 + 24);
  }
  // Hard constraint rows: A^-1 G^T (d x h) and the h x h Schur complement, with its factor.
  const int64_t h = hard * p;
  bytes += h * d * 8 + 2 * h * h * 8;
  // Each FieldConstraint: face, kind, weight and a heap vector of p doubles (with its header).
  bytes += (soft + hard) * (static_cast<int64_t>(sizeof(FieldConstraint)) + 8 * p + 16);
  // Working vectors (about 16 with the mixed biharmonic's conjugate gradients).
  return bytes + 16 * d * 8;
}

}  // namespace fieldspace
