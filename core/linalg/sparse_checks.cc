#include "core/linalg/sparse_checks.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <limits>

#include "absl/strings/str_format.h"
#include "tbb/blocked_range.h"
#include "tbb/parallel_for.h"
#include "tbb/parallel_reduce.h"

namespace fieldspace {
namespace {

using SpMat = Eigen::SparseMatrix<double>;

// Range of stored entries of column j (works for compressed and uncompressed storage).
inline std::pair<int64_t, int64_t> ColumnRange(const SpMat& A, Eigen::Index j) {
  const int64_t begin = A.outerIndexPtr()[j];
  const int64_t end = A.isCompressed() ? A.outerIndexPtr()[j + 1] : begin + A.innerNonZeroPtr()[j];
  return {begin, end};
}

// Value of A(i, j) found by binary search in column j (0 if not stored).
inline double Lookup(const SpMat& A, Eigen::Index i, Eigen::Index j) {
  const auto [begin, end] = ColumnRange(A, j);
  const int* first = A.innerIndexPtr() + begin;
  const int* last = A.innerIndexPtr() + end;
  const int* it = std::lower_bound(first, last, static_cast<int>(i));
  if (it == last || *it != i) return 0.0;
  return A.valuePtr()[begin + (it - first)];
}

}  // namespace

absl::Status CheckFiniteValues(const SpMat& A, std::string_view what) {
  for (Eigen::Index j = 0; j < A.outerSize(); ++j) {
    for (SpMat::InnerIterator it(A, j); it; ++it) {
      if (!std::isfinite(it.value())) {
        return absl::InvalidArgumentError(
            absl::StrFormat("%s: entry (%d, %d) is not finite", what, it.row(), it.col()));
      }
    }
  }
  return absl::OkStatus();
}

absl::Status CheckSymmetric(const SpMat& A, double relative_tolerance, std::string_view what) {
  if (A.rows() != A.cols()) {
    return absl::InvalidArgumentError(
        absl::StrFormat("%s: not square (%d x %d)", what, A.rows(), A.cols()));
  }
  double max_abs = 0.0;
  for (Eigen::Index j = 0; j < A.outerSize(); ++j) {
    for (SpMat::InnerIterator it(A, j); it; ++it) max_abs = std::max(max_abs, std::abs(it.value()));
  }
  const double tolerance = relative_tolerance * max_abs;
  // Smallest column index holding an asymmetric entry, so the message is deterministic.
  std::atomic<int64_t> first_bad{std::numeric_limits<int64_t>::max()};
  tbb::parallel_for(tbb::blocked_range<Eigen::Index>(0, A.outerSize(), 4096),
                    [&](const tbb::blocked_range<Eigen::Index>& r) {
                      for (Eigen::Index j = r.begin(); j != r.end(); ++j) {
                        if (j >= first_bad.load(std::memory_order_relaxed)) return;
                        for (SpMat::InnerIterator it(A, j); it; ++it) {
                          const Eigen::Index i = it.row();
                          if (i == j) continue;
                          const double mirror = Lookup(A, j, i);
                          if (!(std::abs(it.value() - mirror) <= tolerance)) {
                            int64_t cur = first_bad.load();
                            while (j < cur && !first_bad.compare_exchange_weak(cur, j)) {
                            }
                            return;
                          }
                        }
                      }
                    });
  const int64_t j = first_bad.load();
  if (j == std::numeric_limits<int64_t>::max()) return absl::OkStatus();
  for (SpMat::InnerIterator it(A, j); it; ++it) {
    const double mirror = Lookup(A, j, it.row());
    if (it.row() != j && !(std::abs(it.value() - mirror) <= tolerance)) {
      return absl::InvalidArgumentError(
          absl::StrFormat("%s: not symmetric: entry (%d, %d) = %.17g but (%d, %d) = %.17g", what,
                          it.row(), j, it.value(), j, it.row(), mirror));
    }
  }
  return absl::InternalError("symmetry check lost track of the offending entry");
}

absl::Status CheckPositiveVector(const Eigen::VectorXd& v, Eigen::Index size,
                                 std::string_view what) {
  if (v.size() != size) {
    return absl::InvalidArgumentError(
        absl::StrFormat("%s: has %d entries, expected %d", what, v.size(), size));
  }
  for (Eigen::Index i = 0; i < v.size(); ++i) {
    if (!std::isfinite(v[i]) || !(v[i] > 0.0)) {
      return absl::InvalidArgumentError(
          absl::StrFormat("%s: entry %d is %g, must be finite and > 0", what, i, v[i]));
    }
  }
  return absl::OkStatus();
}

const Eigen::SparseMatrix<double>& CompressedOrCopy(const Eigen::SparseMatrix<double>& A,
                                                    Eigen::SparseMatrix<double>* storage) {
  if (A.isCompressed()) return A;
  *storage = A;
  storage->makeCompressed();
  return *storage;
}

}  // namespace fieldspace
