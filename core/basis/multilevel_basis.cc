#include "core/basis/basis.h"

// Bases of several levels (basis.h: StackBases, AppendKernelColumns, QualityLevels,
// BuildMultiLevelBasis, BuildTwoLevelBasis): one-level bases joined column-wise.

#include <algorithm>
#include <chrono>
#include <cstring>
#include <limits>
#include <optional>
#include <vector>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/string_view.h"
#include "core/basis/local_problem.h"
#include "core/basis/progress.h"
#include "core/common/status_macros.h"
#include "core/common/timing.h"
#include "core/operators/kernel_fields.h"
#include "tbb/blocked_range.h"
#include "tbb/parallel_for.h"

namespace fieldspace {
namespace {

using basis_internal::ProgressTicker;
using RowMajorU = Eigen::SparseMatrix<float, Eigen::RowMajor>;

// [A, B]: the b_cols columns of a block B appended to those of A (k rows, row-major,
// compressed), B's column j becoming column A.cols() + j. B is read through two calls per row:
// `count(row)`, its entries in the row, and `write(row, columns, values)`, which stores them
// (columns relative to B, ascending). ResourceExhausted (naming `what`) past the 2^31 - 1
// nonzeros of U's 32-bit indices. A, B and the result are alive together: this is the peak of a
// stacking or of kernel columns, so B is best read in place rather than converted first.
template <typename Count, typename Write>
absl::StatusOr<RowMajorU> AppendColumns(const RowMajorU& a, int32_t b_cols, const Count& count,
                                        const Write& write, absl::string_view what) {
  const int64_t k = a.rows();
  const int32_t* a_outer = a.outerIndexPtr();
  std::vector<int32_t> b_count(k);
  int64_t nnz = a.nonZeros();
  for (int64_t row = 0; row < k; ++row) {
    b_count[row] = count(row);
    nnz += b_count[row];
  }
  if (nnz > std::numeric_limits<int32_t>::max()) {
    return absl::ResourceExhaustedError(
        absl::StrFormat("%s: %d nonzeros exceed the 2^31 - 1 of U's indices", what, nnz));
  }
  const int32_t d1 = static_cast<int32_t>(a.cols());
  RowMajorU U(k, d1 + b_cols);
  U.resizeNonZeros(static_cast<Eigen::Index>(nnz));
  int32_t* outer = U.outerIndexPtr();
  outer[0] = 0;
  for (int64_t row = 0; row < k; ++row) {
    outer[row + 1] = outer[row] + (a_outer[row + 1] - a_outer[row]) + b_count[row];
  }
  std::vector<int32_t>().swap(b_count);
  tbb::parallel_for(tbb::blocked_range<int64_t>(0, k, 4096),
                    [&](const tbb::blocked_range<int64_t>& range) {
                      for (int64_t row = range.begin(); row != range.end(); ++row) {
                        const int32_t na = a_outer[row + 1] - a_outer[row];
                        int32_t* columns = U.innerIndexPtr() + outer[row];
                        float* values = U.valuePtr() + outer[row];
                        std::copy_n(a.innerIndexPtr() + a_outer[row], na, columns);
                        std::copy_n(a.valuePtr() + a_outer[row], na, values);
                        const int32_t nb = outer[row + 1] - outer[row] - na;
                        write(row, columns + na, values + na);
                        for (int32_t i = na; i < na + nb; ++i) columns[i] += d1;
                      }
                    });
  return U;
}

// [U, B] into U itself: in place when U's arrays have the room for B's entries (their capacity,
// e.g. BasisOptions::reserve_entries), the rows moving up by B's entries of the rows before them,
// the last row first, so that no row is overwritten before it moved; otherwise through
// AppendColumns beside a copy. `count` and `write` as for AppendColumns.
template <typename Count, typename Write>
absl::Status AppendColumnsTo(RowMajorU& U, int32_t b_cols, const Count& count, const Write& write,
                             absl::string_view what) {
  if (!U.isCompressed()) U.makeCompressed();
  const int64_t k = U.rows();
  const int64_t old_nnz = U.nonZeros();
  std::vector<int32_t> added(k);
  int64_t new_nnz = old_nnz;
  for (int64_t row = 0; row < k; ++row) {
    added[row] = count(row);
    new_nnz += added[row];
  }
  if (new_nnz > std::numeric_limits<int32_t>::max() || U.data().allocatedSize() < new_nnz) {
    const auto counted = [&](int64_t row) { return added[row]; };
    ASSIGN_OR_RETURN(RowMajorU appended, AppendColumns(U, b_cols, counted, write, what));
    U.swap(appended);
    return absl::OkStatus();
  }
  const int32_t d1 = static_cast<int32_t>(U.cols());
  U.resizeNonZeros(static_cast<Eigen::Index>(new_nnz));  // within the capacity: no reallocation
  U.conservativeResize(k, d1 + b_cols);                  // only the column count changes
  int32_t* outer = U.outerIndexPtr();
  int32_t* columns = U.innerIndexPtr();
  float* values = U.valuePtr();
  int64_t shift = new_nnz - old_nnz;
  for (int64_t row = k - 1; row >= 0; --row) {
    shift -= added[row];
    const int32_t begin = outer[row], end = outer[row + 1];
    std::memmove(columns + begin + shift, columns + begin, sizeof(int32_t) * (end - begin));
    std::memmove(values + begin + shift, values + begin, sizeof(float) * (end - begin));
    write(row, columns + end + shift, values + end + shift);
    for (int32_t i = 0; i < added[row]; ++i) columns[end + shift + i] += d1;
    outer[row + 1] = static_cast<int32_t>(end + shift + added[row]);
  }
  return absl::OkStatus();
}

// QualityLevels of options.params; the paper's levels take options.clamped_local_fields.
absl::StatusOr<std::vector<BasisLevel>> LevelsOf(const BasisOptions& options, BasisQuality quality,
                                                 int32_t coarse_dimension) {
  ASSIGN_OR_RETURN(
      std::vector<BasisLevel> levels,
      QualityLevels(quality, options.params.dimension, options.params.sigma, coarse_dimension));
  if (quality == BasisQuality::kPaper) {
    for (BasisLevel& level : levels) level.clamped = options.clamped_local_fields;
  }
  return levels;
}

}  // namespace

absl::Status AppendKernelColumns(const Eigen::MatrixXd& K, Basis* basis) {
  const int64_t k = basis->U.rows();
  if (K.rows() != k) {
    return absl::InvalidArgumentError(
        absl::StrFormat("AppendKernelColumns: %d rows against U's %d", K.rows(), k));
  }
  const int32_t q = static_cast<int32_t>(K.cols());
  if (q == 0) return absl::OkStatus();
  // K is read in place (its float values without their exact zeros: kernel fields of one
  // component of a several-component mesh, the zero a12 of c I); a float or sparse copy of it
  // would add to the old and the new U, this step's peak and the build's (Session 22).
  auto count = [&](int64_t row) {
    int32_t n = 0;
    for (int32_t j = 0; j < q; ++j) n += static_cast<float>(K(row, j)) != 0.0f;
    return n;
  };
  auto write = [&](int64_t row, int32_t* columns, float* values) {
    for (int32_t j = 0; j < q; ++j) {
      const float v = static_cast<float>(K(row, j));
      if (v == 0.0f) continue;
      *columns++ = j;
      *values++ = v;
    }
  };
  // In place in the room the layout left (BuildBasis), else beside a copy.
  RETURN_IF_ERROR(AppendColumnsTo(basis->U, q, count, write, "AppendKernelColumns"));
  basis->params.dimension = static_cast<int32_t>(basis->U.cols());
  basis->local_eigenvalues.resize(basis->U.cols(), 0.0);
  basis->kernel_columns += q;
  return absl::OkStatus();
}

absl::StatusOr<Basis> StackBases(Basis fine, const Basis& coarse) {
  if (fine.U.rows() != coarse.U.rows()) {
    return absl::InvalidArgumentError(
        absl::StrFormat("StackBases: %d rows against %d", fine.U.rows(), coarse.U.rows()));
  }
  if (!(fine.type == coarse.type)) {
    return absl::InvalidArgumentError("StackBases: the bases are of different field types");
  }
  if (fine.kernel_columns != 0 || coarse.kernel_columns != 0) {
    return absl::InvalidArgumentError(
        "StackBases: the bases have kernel columns; append them after stacking");
  }
  const RowMajorU& b = coarse.U;
  auto count = [&](int64_t row) { return b.outerIndexPtr()[row + 1] - b.outerIndexPtr()[row]; };
  auto write = [&](int64_t row, int32_t* columns, float* values) {
    const int32_t begin = b.outerIndexPtr()[row];
    std::copy_n(b.innerIndexPtr() + begin, count(row), columns);
    std::copy_n(b.valuePtr() + begin, count(row), values);
  };
  RETURN_IF_ERROR(
      AppendColumnsTo(fine.U, static_cast<int32_t>(b.cols()), count, write, "StackBases"));
  fine.params.dimension = static_cast<int32_t>(fine.U.cols());
  fine.sample_faces.insert(fine.sample_faces.end(), coarse.sample_faces.begin(),
                           coarse.sample_faces.end());
  fine.local_eigenvalues.insert(fine.local_eigenvalues.end(), coarse.local_eigenvalues.begin(),
                                coarse.local_eigenvalues.end());
  // A face is uncovered when no column of either level touches its rows.
  const int32_t dpf = fine.type.dofs_per_face();
  const int32_t* outer = fine.U.outerIndexPtr();
  int64_t uncovered = 0;
  for (int64_t row = 0; row < fine.U.rows(); row += dpf) {
    uncovered += outer[row + dpf] == outer[row] ? 1 : 0;
  }
  fine.uncovered_faces = uncovered;
  return fine;
}

absl::StatusOr<std::vector<BasisLevel>> QualityLevels(BasisQuality quality, int32_t dimension,
                                                      double sigma, int32_t coarse_dimension) {
  if (quality != BasisQuality::kPaper && coarse_dimension != 0) {
    return absl::InvalidArgumentError(
        "a coarse dimension combines only with the paper's quality level (the others set the "
        "levels)");
  }
  switch (quality) {
    case BasisQuality::kPaper:
      if (coarse_dimension < 0 || coarse_dimension >= dimension) {
        return absl::InvalidArgumentError(absl::StrCat(
            "the coarse dimension must be in [0, d = ", dimension, "), got ", coarse_dimension));
      }
      if (coarse_dimension == 0) return std::vector<BasisLevel>{{dimension, sigma}};
      return std::vector<BasisLevel>{{dimension - coarse_dimension, sigma},
                                     {coarse_dimension, sigma}};
    case BasisQuality::kLowModes:
    case BasisQuality::kSmooth: {
      const bool clamped = quality == BasisQuality::kSmooth;
      if (dimension < 40) {
        return absl::InvalidArgumentError(absl::StrCat(
            "the ", clamped ? "smooth" : "low-modes",
            " quality level needs d >= 40 (its coarsest level has d / 40 fields), got ",
            dimension));
      }
      const double level_sigma = sigma * 5.0 / 8.0;
      const int32_t coarse = dimension / 10;
      const int32_t coarsest = dimension / 40;
      return std::vector<BasisLevel>{{dimension - coarse - coarsest, level_sigma, clamped},
                                     {coarse, level_sigma, clamped},
                                     {coarsest, level_sigma, clamped}};
    }
  }
  return absl::InvalidArgumentError(
      absl::StrCat("unknown basis quality level ", static_cast<int>(quality)));
}

absl::StatusOr<Basis> BuildMultiLevelBasis(const TriangleMesh& mesh, const FieldOperator& op,
                                           const BasisOptions& options,
                                           const std::vector<BasisLevel>& given_levels) {
  if (given_levels.empty()) return absl::InvalidArgumentError("a basis needs at least one level");
  // A level of fewer than sigma fields has regions of more than the mesh's area
  // (pi r^2 = sigma A / d, eq. 12): each is nearly its whole component. On a surface of genus
  // g > 0 their lowest eigenfields are 2 g nearly harmonic fields whose eigenvalues lie far below
  // the local solver's shift and too close together to separate (it failed there after
  // minutes). There such a level's fields go to the level before it.
  std::vector<BasisLevel> levels = given_levels;
  if (mesh.genus() > 0) {
    for (size_t i = levels.size() - 1; i > 0; --i) {
      if (levels[i].dimension >= 1 && levels[i].dimension < levels[i].sigma) {
        levels[i - 1].dimension += levels[i].dimension;
        levels.erase(levels.begin() + static_cast<std::ptrdiff_t>(i));
      }
    }
  }
  if (!op.has_stiffness() && BuildReadsStiffness(op.type, options, levels)) {
    return basis_internal::MissingStiffnessError(op.type);
  }
  int64_t total = 0;
  for (const BasisLevel& level : levels) {
    if (level.dimension < 1) {
      return absl::InvalidArgumentError(
          absl::StrCat("each basis level needs at least one field, got ", level.dimension));
    }
    total += level.dimension;
  }
  if (total > std::numeric_limits<int32_t>::max()) {
    return absl::InvalidArgumentError(absl::StrCat("levels total ", total, " fields"));
  }
  BasisOptions level_options = options;
  if (levels.size() == 1) {
    level_options.params.dimension = levels[0].dimension;
    level_options.params.sigma = levels[0].sigma;
    level_options.clamped_local_fields = levels[0].clamped;
    return BuildBasis(mesh, op, level_options);
  }
  level_options.kernel_columns = false;
  double start = 0;
  double share = 0;
  if (options.progress) {
    level_options.progress = [&](BasisPhase phase, double fraction) {
      options.progress(phase, start + share * fraction);
    };
  }
  const auto started = std::chrono::steady_clock::now();
  BasisTimings timings;  // of all levels
  // The levels are built coarsest (last) first and stacked in their order at the end: the coarse
  // levels factor local problems of up to half the mesh on every thread, the build's largest
  // scratch, and built first they run beside no other level's U and not beside the kernel step,
  // which runs beside the first level, built last (bench/RESULTS.md, Session 28). Each level is
  // built on its own, so the order does not change the result.
  std::vector<std::optional<Basis>> built(levels.size());
  const auto build_level = [&](size_t i) -> absl::Status {
    const BasisLevel& level = levels[i];
    share = static_cast<double>(level.dimension) / static_cast<double>(total);
    level_options.params.dimension = level.dimension;
    level_options.params.sigma = level.sigma;
    level_options.clamped_local_fields = level.clamped;
    // The first level, built last, lays out U with room for the other levels' entries and the
    // kernel columns' (and the caller's reserve): both are appended to it in place.
    level_options.reserve_entries = 0;
    if (i == 0) {
      level_options.reserve_entries =
          std::max<int64_t>(0, options.reserve_entries) +
          (options.kernel_columns ? KernelEntriesBound(mesh, op.type) : int64_t{0});
      for (size_t j = 1; j < built.size(); ++j) {
        level_options.reserve_entries += built[j]->U.nonZeros();
      }
    }
    ASSIGN_OR_RETURN(built[i], BuildBasis(mesh, op, level_options));
    timings.sampling_seconds += built[i]->timings.sampling_seconds;
    timings.regions_seconds += built[i]->timings.regions_seconds;
    timings.eigensolve_seconds += built[i]->timings.eigensolve_seconds;
    start += share;
    return absl::OkStatus();
  };
  for (size_t i = levels.size() - 1; i > 0; --i) RETURN_IF_ERROR(build_level(i));
  const auto build_first_and_stack = [&]() -> absl::StatusOr<Basis> {
    RETURN_IF_ERROR(build_level(0));
    Basis stacked = *std::move(built[0]);
    built[0].reset();
    for (size_t i = 1; i < built.size(); ++i) {
      ASSIGN_OR_RETURN(stacked, StackBases(std::move(stacked), *built[i]));
      built[i].reset();
    }
    stacked.timings = timings;
    return stacked;
  };
  absl::StatusOr<Basis> stacked =
      BuildBesideKernel(mesh, op, options, build_first_and_stack, [] {});
  if (!stacked.ok()) return stacked;
  stacked->timings.total_seconds = SecondsSince(started);
  if (options.kernel_columns && options.progress) options.progress(BasisPhase::kAssembly, 1.0);
  return stacked;
}

absl::StatusOr<Basis> BuildTwoLevelBasis(const TriangleMesh& mesh, const FieldOperator& op,
                                         const BasisOptions& options, int32_t coarse_dimension) {
  ASSIGN_OR_RETURN(std::vector<BasisLevel> levels,
                   LevelsOf(options, BasisQuality::kPaper, coarse_dimension));
  return BuildMultiLevelBasis(mesh, op, options, levels);
}

absl::StatusOr<Basis> BuildBasisOfQuality(const TriangleMesh& mesh, FieldOperator* op,
                                          const BasisOptions& options, BasisQuality quality,
                                          int32_t coarse_dimension) {
  ASSIGN_OR_RETURN(std::vector<BasisLevel> levels, LevelsOf(options, quality, coarse_dimension));
  if (!op->has_stiffness() && BuildReadsStiffness(op->type, options, levels)) {
    RETURN_IF_ERROR(AssembleStiffness(mesh, op));
  }
  return BuildMultiLevelBasis(mesh, *op, options, levels);
}

}  // namespace fieldspace
