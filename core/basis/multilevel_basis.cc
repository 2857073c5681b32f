#include "core/basis/basis.h"

// Bases of several levels (basis.h: StackBases, AppendKernelColumns, QualityLevels,
// BuildMultiLevelBasis, BuildTwoLevelBasis): one-level bases joined column-wise.

#include <algorithm>
#include <chrono>
#include <limits>
#include <optional>
#include <vector>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/string_view.h"
#include "core/basis/progress.h"
#include "core/common/status_macros.h"
#include "core/common/timing.h"
#include "tbb/blocked_range.h"
#include "tbb/parallel_for.h"

namespace fieldspace {
namespace {

using basis_internal::ProgressTicker;
using RowMajorU = Eigen::SparseMatrix<float, Eigen::RowMajor>;

// [A, B]: the columns of B appended to those of A (both k rows, row-major, compressed), B's
// column j becoming column A.cols() + j. ResourceExhausted (naming `what`) past the 2^31 - 1
// nonzeros of U's 32-bit indices.
absl::StatusOr<RowMajorU> AppendColumns(const RowMajorU& a, const RowMajorU& b,
                                        absl::string_view what) {
  const int64_t nnz = static_cast<int64_t>(a.nonZeros()) + b.nonZeros();
  if (nnz > std::numeric_limits<int32_t>::max()) {
    return absl::ResourceExhaustedError(
        absl::StrFormat("%s: %d nonzeros exceed the 2^31 - 1 of U's indices", what, nnz));
  }
  const int64_t k = a.rows();
  const int32_t d1 = static_cast<int32_t>(a.cols());
  RowMajorU U(k, d1 + b.cols());
  U.resizeNonZeros(static_cast<Eigen::Index>(nnz));
  int32_t* outer = U.outerIndexPtr();
  outer[0] = 0;
  for (int64_t row = 0; row < k; ++row) {
    const int32_t na = a.outerIndexPtr()[row + 1] - a.outerIndexPtr()[row];
    const int32_t nb = b.outerIndexPtr()[row + 1] - b.outerIndexPtr()[row];
    outer[row + 1] = outer[row] + na + nb;
  }
  tbb::parallel_for(
      tbb::blocked_range<int64_t>(0, k, 4096), [&](const tbb::blocked_range<int64_t>& range) {
        for (int64_t row = range.begin(); row != range.end(); ++row) {
          int32_t pos = outer[row];
          for (int32_t q = a.outerIndexPtr()[row]; q < a.outerIndexPtr()[row + 1]; ++q, ++pos) {
            U.innerIndexPtr()[pos] = a.innerIndexPtr()[q];
            U.valuePtr()[pos] = a.valuePtr()[q];
          }
          for (int32_t q = b.outerIndexPtr()[row]; q < b.outerIndexPtr()[row + 1]; ++q, ++pos) {
            U.innerIndexPtr()[pos] = b.innerIndexPtr()[q] + d1;
            U.valuePtr()[pos] = b.valuePtr()[q];
          }
        }
      });
  return U;
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
  // Row-major float copy of K without its exact zeros (kernel fields of one component of a
  // several-component mesh, the zero a12 of c I).
  const Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> Kf = K.cast<float>();
  RowMajorU kernel = Kf.sparseView();
  kernel.makeCompressed();
  if (!basis->U.isCompressed()) basis->U.makeCompressed();
  ASSIGN_OR_RETURN(RowMajorU U, AppendColumns(basis->U, kernel, "AppendKernelColumns"));
  basis->U.swap(U);
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
  ASSIGN_OR_RETURN(RowMajorU U, AppendColumns(fine.U, coarse.U, "StackBases"));
  fine.U.swap(U);
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
                                                      double sigma) {
  switch (quality) {
    case BasisQuality::kPaper:
      return std::vector<BasisLevel>{{dimension, sigma}};
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
  const auto build_levels = [&]() -> absl::StatusOr<Basis> {
    std::optional<Basis> stacked;
    for (const BasisLevel& level : levels) {
      share = static_cast<double>(level.dimension) / static_cast<double>(total);
      level_options.params.dimension = level.dimension;
      level_options.params.sigma = level.sigma;
      level_options.clamped_local_fields = level.clamped;
      ASSIGN_OR_RETURN(Basis built, BuildBasis(mesh, op, level_options));
      timings.sampling_seconds += built.timings.sampling_seconds;
      timings.regions_seconds += built.timings.regions_seconds;
      timings.eigensolve_seconds += built.timings.eigensolve_seconds;
      if (stacked.has_value()) {
        ASSIGN_OR_RETURN(Basis both, StackBases(*std::move(stacked), built));
        stacked = std::move(both);
      } else {
        stacked = std::move(built);
      }
      start += share;
    }
    stacked->timings = timings;
    return *std::move(stacked);
  };
  absl::StatusOr<Basis> stacked = BuildBesideKernel(mesh, op, options, build_levels, [] {});
  if (!stacked.ok()) return stacked;
  stacked->timings.total_seconds = SecondsSince(started);
  if (options.kernel_columns && options.progress) options.progress(BasisPhase::kAssembly, 1.0);
  return stacked;
}

absl::StatusOr<Basis> BuildTwoLevelBasis(const TriangleMesh& mesh, const FieldOperator& op,
                                         const BasisOptions& options, int32_t coarse_dimension) {
  const int32_t d = options.params.dimension;
  if (coarse_dimension < 0 || coarse_dimension >= d) {
    return absl::InvalidArgumentError(
        absl::StrCat("coarse dimension must be in [0, d = ", d, "), got ", coarse_dimension));
  }
  if (coarse_dimension == 0) return BuildBasis(mesh, op, options);
  const double sigma = options.params.sigma;
  return BuildMultiLevelBasis(mesh, op, options,
                              {{d - coarse_dimension, sigma, options.clamped_local_fields},
                               {coarse_dimension, sigma, options.clamped_local_fields}});
}

}  // namespace fieldspace
