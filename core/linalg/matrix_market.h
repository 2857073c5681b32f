#ifndef FIELDSPACE_CORE_LINALG_MATRIX_MARKET_H_
#define FIELDSPACE_CORE_LINALG_MATRIX_MARKET_H_

#include <string>

#include "Eigen/Core"
#include "Eigen/SparseCore"
#include "absl/status/status.h"
#include "absl/status/statusor.h"

namespace fieldspace {

// MatrixMarket exchange files, the format other implementations compare our operators in.
//
// Writing: "%%MatrixMarket matrix coordinate real general", every stored entry (symmetric
// matrices with both triangles), 1-based "row col value" lines with values printed as %.17g
// (round-trips doubles exactly), in column-major order (column ascending, row ascending).
// Entries are formatted in parallel and written in bounded batches (memory stays O(batch)).
// Errors: the errno of the failed open/write mapped to a status (NotFound for a missing
// directory, PermissionDenied, ResourceExhausted for a full disk, ...).
absl::Status WriteMatrixMarket(const std::string& path, const Eigen::SparseMatrix<double>& A);

// Writes diag(d) (n x n, n entries) in the same format.
absl::Status WriteMatrixMarketDiagonal(const std::string& path, const Eigen::VectorXd& d);

// Reads a coordinate file with field real or integer and symmetry general or symmetric (the
// other triangle is mirrored); duplicate entries are summed. NotFound for a missing file,
// InvalidArgument (with the line number) for anything malformed or out of range.
absl::StatusOr<Eigen::SparseMatrix<double>> ReadMatrixMarket(const std::string& path);

}  // namespace fieldspace

#endif  // FIELDSPACE_CORE_LINALG_MATRIX_MARKET_H_
