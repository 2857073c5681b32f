#ifndef FIELDSPACE_CORE_OPERATORS_REFERENCE_SOLVERS_H_
#define FIELDSPACE_CORE_OPERATORS_REFERENCE_SOLVERS_H_

#include "Eigen/Core"
#include "Eigen/SparseCore"
#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "core/linalg/eigensolver.h"
#include "core/linalg/sparse_cholesky.h"
#include "core/operators/field_operator.h"

namespace fieldspace {

// Full-space solvers for the problems the subspace methods approximate (docs/conventions.md,
// Subspace methods): references for tests, for measuring subspace errors, and for generating test
// fields. They factorize k x k systems with CHOLMOD, so cost grows superlinearly with the mesh.
// The model problem's full-space solver is core/subspace/full_space_solver.h (its vocabulary lives
// in core/subspace/problem.h).

// The K lowest eigenpairs of S x = lambda M x for `op` (eigenvectors in the DOF order of op,
// M-orthonormal). Errors as LowestEigenpairs.
absl::StatusOr<EigenResult> ReferenceEigenpairs(const FieldOperator& op,
                                                const EigenOptions& options = {});

// B = S M^-1 S (k x k, sparse, symmetric PSD): the biharmonic energy matrix of eq. 8. Its rows
// couple faces up to two rings apart, so it holds several times the nonzeros of S.
Eigen::SparseMatrix<double> BiharmonicMatrix(const FieldOperator& op);

// Smoothing (the eq. 8 instance with a mass-weighted data term):
//   min ||X - field||_M^2 + lambda X^T S X  <=>  (M + lambda S) X = M field.
// field: k entries; lambda finite, >= 0.
absl::StatusOr<Eigen::VectorXd> SmoothField(const FieldOperator& op, const Eigen::VectorXd& field,
                                            double lambda, const CholeskyOptions& cholesky = {});

}  // namespace fieldspace

#endif  // FIELDSPACE_CORE_OPERATORS_REFERENCE_SOLVERS_H_
