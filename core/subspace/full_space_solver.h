#ifndef FIELDSPACE_CORE_SUBSPACE_FULL_SPACE_SOLVER_H_
#define FIELDSPACE_CORE_SUBSPACE_FULL_SPACE_SOLVER_H_

#include <utility>

#include "Eigen/Core"
#include "Eigen/SparseCore"
#include "absl/status/statusor.h"
#include "core/linalg/sparse_cholesky.h"
#include "core/operators/field_operator.h"
#include "core/subspace/problem.h"

namespace fieldspace {

// The model problem (problem.h) solved in the full space, k unknowns: the reference the reduced
// solvers (model_problem.h, design_session.h) approximate, for tests, error measurements and test
// fields (docs/conventions.md, Model problem). It factorizes a k x k system with CHOLMOD, so cost
// grows superlinearly with the mesh.

// Normal equations of eq. 9 before hard constraints are applied:
// A = mu_s S + mu_b B + mu_c C^T C (k x k, sparse, symmetric PSD), b = mu_c C^T c (k).
struct ModelSystem {
  Eigen::SparseMatrix<double> A;
  Eigen::VectorXd b;

  ModelSystem() = default;
  ModelSystem(const ModelSystem&) = default;
  ModelSystem& operator=(const ModelSystem&) = default;
  // Eigen 3.4's SparseMatrix has no move operations (a "move" deep-copies); swap instead.
  ModelSystem(ModelSystem&& other) noexcept : b(std::move(other.b)) { A.swap(other.A); }
  ModelSystem& operator=(ModelSystem&& other) noexcept {
    A.swap(other.A);
    b = std::move(other.b);
    return *this;
  }
};
absl::StatusOr<ModelSystem> AssembleModelSystem(const FieldOperator& op,
                                                const ModelProblem& problem);

// The soft constraints' share of those normal equations: C^T C is diagonal, mu_c times each soft
// constraint's weight on its face's DOFs (`diagonal`, k), and b = mu_c C^T c (k). For solvers that
// keep the energy's factorization pattern and add the constraints per problem. InvalidArgument for
// a bad face, value or weight of a soft constraint (hard ones are ignored).
struct SoftConstraintTerms {
  Eigen::VectorXd diagonal;
  Eigen::VectorXd b;
};
absl::StatusOr<SoftConstraintTerms> AssembleSoftConstraints(const FieldOperator& op,
                                                            const ModelProblem& problem);

// Solves the model problem in the full space: the free DOFs satisfy A_ff X_f = b_f - A_fh X_h
// (hard-constrained DOFs X_h eliminated), hard-constrained DOFs take their values exactly.
// Returns X (k, DOF order of op). InvalidArgument for bad weights, faces or values (including a
// face with two hard constraints); FailedPrecondition when the reduced system is singular (e.g.
// only mu_s > 0 with no constraints: the energy has a kernel).
absl::StatusOr<Eigen::VectorXd> SolveModelProblem(const FieldOperator& op,
                                                  const ModelProblem& problem,
                                                  const CholeskyOptions& cholesky = {});

}  // namespace fieldspace

#endif  // FIELDSPACE_CORE_SUBSPACE_FULL_SPACE_SOLVER_H_
