#ifndef FIELDSPACE_CORE_LINALG_SPARSE_CHECKS_H_
#define FIELDSPACE_CORE_LINALG_SPARSE_CHECKS_H_

#include <string_view>

#include "Eigen/Core"
#include "Eigen/SparseCore"
#include "absl/status/status.h"

namespace fieldspace {

// Input checks run before handing a matrix to a factorization or eigensolver: CHOLMOD reads only
// one triangle, so an asymmetric input would silently be solved as a different matrix.

// InvalidArgument naming `what` unless every stored value of `A` is finite.
absl::Status CheckFiniteValues(const Eigen::SparseMatrix<double>& A, std::string_view what);

// InvalidArgument naming `what` and the first offending entry unless `A` (any sparse matrix with
// sorted inner indices, as Eigen keeps them) is square and symmetric:
// |A_ij - A_ji| <= relative_tolerance * max_abs(A) for every stored entry (missing entries are 0).
// O(nnz log(nnz per column)) time, no extra memory, parallel over columns.
absl::Status CheckSymmetric(const Eigen::SparseMatrix<double>& A, double relative_tolerance,
                            std::string_view what);

// InvalidArgument naming `what` unless `v` has `size` entries, all finite and > 0.
absl::Status CheckPositiveVector(const Eigen::VectorXd& v, Eigen::Index size,
                                 std::string_view what);

// `A` itself when it is compressed (packed, as CHOLMOD and the Matrix Market writer read it), else
// a compressed copy stored in `*storage`, which must outlive the returned reference.
const Eigen::SparseMatrix<double>& CompressedOrCopy(const Eigen::SparseMatrix<double>& A,
                                                    Eigen::SparseMatrix<double>* storage);

}  // namespace fieldspace

#endif  // FIELDSPACE_CORE_LINALG_SPARSE_CHECKS_H_
