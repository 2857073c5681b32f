#include "core/subspace/full_space_solver.h"

#include <utility>
#include <vector>

#include "absl/strings/str_format.h"
#include "core/common/status_macros.h"
#include "core/operators/reference_solvers.h"

namespace fieldspace {
namespace {

using SpMat = Eigen::SparseMatrix<double>;

// Rows and columns `keep` (sorted ascending) of A, renumbered 0..keep.size().
SpMat Submatrix(const SpMat& A, const std::vector<int>& keep, const std::vector<int>& new_index) {
  std::vector<Eigen::Triplet<double>> triplets;
  triplets.reserve(static_cast<size_t>(A.nonZeros()));
  for (int j : keep) {
    for (SpMat::InnerIterator it(A, j); it; ++it) {
      const int i = new_index[it.row()];
      if (i >= 0) triplets.emplace_back(i, new_index[j], it.value());
    }
  }
  SpMat sub(static_cast<Eigen::Index>(keep.size()), static_cast<Eigen::Index>(keep.size()));
  sub.setFromTriplets(triplets.begin(), triplets.end());
  return sub;
}

}  // namespace

absl::StatusOr<SoftConstraintTerms> AssembleSoftConstraints(const FieldOperator& op,
                                                            const ModelProblem& problem) {
  const EnergyWeights& w = problem.weights;
  const int64_t k = op.dofs();
  const int32_t p = op.type.dofs_per_face();
  const int64_t num_faces = k / p;
  for (const FieldConstraint& c : problem.constraints) {
    if (!c.hard()) RETURN_IF_ERROR(ValidateConstraint(c, num_faces, op.type));
  }
  // C^T C is diagonal: each soft constraint adds its weight to its face's DOFs.
  SoftConstraintTerms terms;
  terms.diagonal = Eigen::VectorXd::Zero(k);
  terms.b = Eigen::VectorXd::Zero(k);
  if (w.mu_c > 0.0) {
    for (const FieldConstraint& c : problem.constraints) {
      if (c.hard()) continue;
      for (int32_t d = 0; d < p; ++d) {
        const int64_t i = static_cast<int64_t>(p) * c.face + d;
        terms.diagonal[i] += w.mu_c * c.weight;
        terms.b[i] += w.mu_c * c.weight * c.value[d];
      }
    }
  }
  return terms;
}

absl::StatusOr<ModelSystem> AssembleModelSystem(const FieldOperator& op,
                                                const ModelProblem& problem) {
  RETURN_IF_ERROR(ValidateOperatorShape(op));
  RETURN_IF_ERROR(ValidateWeightsWithoutDataTerm(problem.weights));
  if (problem.scale_free) {
    return absl::InvalidArgumentError(
        "scale-free weights are defined relative to a subspace (each soft constraint's face "
        "stiffness in span(U)); the full-space model problem takes raw weights");
  }
  const EnergyWeights& w = problem.weights;
  const int64_t k = op.dofs();
  ASSIGN_OR_RETURN(SoftConstraintTerms soft, AssembleSoftConstraints(op, problem));
  ModelSystem system;
  system.A.resize(k, k);
  if (w.mu_s > 0.0) system.A = w.mu_s * op.stiffness;
  if (w.mu_b > 0.0) system.A += w.mu_b * BiharmonicMatrix(op);
  system.b = std::move(soft.b);
  std::vector<Eigen::Triplet<double>> diagonal;
  for (int64_t i = 0; i < k; ++i) {
    if (soft.diagonal[i] != 0.0) diagonal.emplace_back(i, i, soft.diagonal[i]);
  }
  if (!diagonal.empty()) {
    SpMat D(k, k);
    D.setFromTriplets(diagonal.begin(), diagonal.end());
    system.A += D;
  }
  system.A.makeCompressed();
  return system;
}

absl::StatusOr<Eigen::VectorXd> SolveModelProblem(const FieldOperator& op,
                                                  const ModelProblem& problem,
                                                  const CholeskyOptions& cholesky) {
  ASSIGN_OR_RETURN(ModelSystem system, AssembleModelSystem(op, problem));
  const int64_t k = op.dofs();
  const int32_t p = op.type.dofs_per_face();
  Eigen::VectorXd X = Eigen::VectorXd::Zero(k);
  std::vector<bool> fixed(k, false);
  bool any_hard = false;
  for (const FieldConstraint& c : problem.constraints) {
    if (!c.hard()) continue;
    any_hard = true;
    RETURN_IF_ERROR(ValidateConstraint(c, k / p, op.type));
    if (fixed[static_cast<int64_t>(p) * c.face]) {
      return absl::InvalidArgumentError(
          absl::StrFormat("model problem: face %d has two hard constraints", c.face));
    }
    for (int32_t d = 0; d < p; ++d) {
      fixed[static_cast<int64_t>(p) * c.face + d] = true;
      X[static_cast<int64_t>(p) * c.face + d] = c.value[d];
    }
  }
  std::vector<int> free;
  std::vector<int> new_index(k, -1);
  for (int64_t i = 0; i < k; ++i) {
    if (!fixed[i]) {
      new_index[i] = static_cast<int>(free.size());
      free.push_back(static_cast<int>(i));
    }
  }
  if (free.empty()) return X;

  // Eliminate the hard-constrained DOFs: A_ff X_f = b_f - A_fh X_h.
  const Eigen::VectorXd coupling = system.A * X;
  Eigen::VectorXd rhs(free.size());
  for (size_t i = 0; i < free.size(); ++i) rhs[i] = system.b[free[i]] - coupling[free[i]];
  const SpMat reduced = any_hard ? Submatrix(system.A, free, new_index) : SpMat();
  const SpMat& A_ff = any_hard ? reduced : system.A;
  auto factor = SparseCholesky::Factorize(A_ff, cholesky);
  if (!factor.ok()) {
    if (absl::IsFailedPrecondition(factor.status())) {
      return absl::FailedPreconditionError(absl::StrFormat(
          "model problem: the system is singular (not positive definite); add constraints or "
          "energy weights (%s)",
          factor.status().message()));
    }
    return factor.status();
  }
  ASSIGN_OR_RETURN(Eigen::VectorXd x_free, factor->Solve(rhs));
  for (size_t i = 0; i < free.size(); ++i) X[free[i]] = x_free[i];
  return X;
}

}  // namespace fieldspace
