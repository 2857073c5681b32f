#ifndef FIELDSPACE_CORE_SUBSPACE_SUBSPACE_UTIL_H_
#define FIELDSPACE_CORE_SUBSPACE_SUBSPACE_UTIL_H_

// Small helpers shared by the subspace sources (not a public API).

#include <cstdint>
#include <string_view>
#include <vector>

#include "Eigen/SparseCore"
#include "absl/status/status.h"

namespace fieldspace {

// The storage of a basis U (core/basis/basis.h): k x d, row-major, float.
using BasisMatrix = Eigen::SparseMatrix<float, Eigen::RowMajor>;

// One row of U: `size` column indices (ascending) and values.
struct BasisRow {
  const int* cols;
  const float* vals;
  int64_t size;
};

// Row i of U, compressed or not.
inline BasisRow GetBasisRow(const BasisMatrix& U, int64_t i) {
  const int64_t begin = U.outerIndexPtr()[i];
  const int64_t end = U.isCompressed() ? U.outerIndexPtr()[i + 1] : begin + U.innerNonZeroPtr()[i];
  return {U.innerIndexPtr() + begin, U.valuePtr() + begin, end - begin};
}

// Where a row read from a basis's LiftPlan is copied (ReducedSystem::BasisRowOf): one per
// thread, reused row after row.
struct BasisRowScratch {
  std::vector<int> cols;
  std::vector<float> vals;
};

// InvalidArgument (prefixed with `what`) unless every stored value of U is finite. Parallel.
absl::Status CheckBasisMatrix(const BasisMatrix& U, std::string_view what);

}  // namespace fieldspace

#endif  // FIELDSPACE_CORE_SUBSPACE_SUBSPACE_UTIL_H_
