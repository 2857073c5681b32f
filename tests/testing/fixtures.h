#ifndef FIELDSPACE_TESTS_TESTING_FIXTURES_H_
#define FIELDSPACE_TESTS_TESTING_FIXTURES_H_

// Operators and bases built in the test (so that checks do not depend on the quality of the
// local basis construction), and small matrix helpers.

#include <cstdint>
#include <memory>

#include "Eigen/Core"
#include "Eigen/SparseCore"
#include "core/basis/basis.h"
#include "core/mesh/triangle_mesh.h"
#include "core/operators/field_operator.h"

namespace fieldspace::testing {

// BuildFieldOperator that must succeed: a failure fails the current test and then aborts.
FieldOperator MustBuildOperator(const TriangleMesh& mesh, const FieldType& type);

// A random sparse basis U (k x d): each column has support on `rows_per_column` random rows
// (values in [-1, 1]); every row gets at least one entry so that no face is unsupported.
std::shared_ptr<Basis> RandomBasis(const FieldType& type, int64_t k, int64_t d,
                                   int64_t rows_per_column, uint64_t seed);

// n values uniform in [-1, 1] from `seed` (the same vector for the same seed).
Eigen::VectorXd RandomVector(int64_t n, uint64_t seed);

// U = I (k x k).
std::shared_ptr<Basis> IdentityBasis(const FieldType& type, int64_t k);

// Dense double copy of the float basis U (k x d).
Eigen::MatrixXd DenseU(const Basis& basis);

// U in column-major double storage (k x d), for column access.
Eigen::SparseMatrix<double> ColumnMajor(const Basis& basis);

// Column j of a column-major U as a dense vector (k).
Eigen::VectorXd DenseColumn(const Eigen::SparseMatrix<double>& U, int32_t j);

// max |A_ij| over the pattern.
double MaxAbs(const Eigen::SparseMatrix<double>& A);

// max |A_ij - B_ij| over the union of both patterns.
double MaxAbsDiff(const Eigen::SparseMatrix<double>& A, const Eigen::SparseMatrix<double>& B);

// |a - b|_F / max(|a|_F, |b|_F), 0 when both are zero.
double RelativeDifference(const Eigen::MatrixXd& a, const Eigen::MatrixXd& b);

// 5-point Laplacian of an n x n grid (Neumann: degree on the diagonal) plus `diagonal` * I:
// n^2 x n^2, symmetric, positive definite for diagonal > 0, indefinite for diagonal < 0 (beyond
// -8).
Eigen::SparseMatrix<double> GridLaplacian(int n, double diagonal);

}  // namespace fieldspace::testing

#endif  // FIELDSPACE_TESTS_TESTING_FIXTURES_H_
