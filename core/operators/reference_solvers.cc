#include "core/operators/reference_solvers.h"

#include <cmath>
#include <utility>
#include <vector>

#include "absl/strings/str_format.h"
#include "core/common/status_macros.h"

namespace fieldspace {
namespace {

using SpMat = Eigen::SparseMatrix<double>;

absl::Status CheckConstraintValue(const FieldOperator& op, int32_t face,
                                  const Eigen::VectorXd& value, const char* kind) {
  const int64_t num_faces = op.dofs() / op.type.dofs_per_face();
  if (face < 0 || face >= num_faces) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "model problem: %s constraint on face %d, outside [0, %d)", kind, face, num_faces));
  }
  if (value.size() != op.type.dofs_per_face()) {
    return absl::InvalidArgumentError(
        absl::StrFormat("model problem: %s constraint on face %d has %d values, expected %d", kind,
                        face, value.size(), op.type.dofs_per_face()));
  }
  if (!value.allFinite()) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "model problem: %s constraint on face %d has a non-finite value", kind, face));
  }
  return absl::OkStatus();
}

absl::Status CheckOperator(const FieldOperator& op) {
  const int64_t k = op.dofs();
  if (k == 0 || op.stiffness.rows() != k || op.stiffness.cols() != k ||
      k % op.type.dofs_per_face() != 0) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "operator: stiffness %d x %d does not match mass of %d entries (%d per face)",
        op.stiffness.rows(), op.stiffness.cols(), k, op.type.dofs_per_face()));
  }
  return absl::OkStatus();
}

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

absl::Status ValidateWeights(const EnergyWeights& w) {
  const auto check = [](double v, const char* name) -> absl::Status {
    if (!std::isfinite(v) || v < 0.0) {
      return absl::InvalidArgumentError(
          absl::StrFormat("energy weight %s = %g is invalid: must be finite and >= 0", name, v));
    }
    return absl::OkStatus();
  };
  RETURN_IF_ERROR(check(w.mu_s, "mu_s"));
  RETURN_IF_ERROR(check(w.mu_b, "mu_b"));
  RETURN_IF_ERROR(check(w.mu_c, "mu_c"));
  RETURN_IF_ERROR(check(w.mu_a, "mu_a"));
  if (w.mu_s + w.mu_b <= 0.0) {
    return absl::InvalidArgumentError(
        "energy weights mu_s and mu_b are both 0; at least one must be > 0 (otherwise the energy "
        "does not determine the field away from the constraints)");
  }
  return absl::OkStatus();
}

absl::Status ValidateWeightsWithoutDataTerm(const EnergyWeights& w) {
  RETURN_IF_ERROR(ValidateWeights(w));
  if (w.mu_a != 0.0) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "energy weight mu_a = %g has no term to weigh: only a design session opened with a data "
        "(alignment) term has one",
        w.mu_a));
  }
  return absl::OkStatus();
}

absl::StatusOr<EigenResult> ReferenceEigenpairs(const FieldOperator& op,
                                                const EigenOptions& options) {
  RETURN_IF_ERROR(CheckOperator(op));
  return LowestEigenpairs(op.stiffness, op.mass, options);
}

SpMat BiharmonicMatrix(const FieldOperator& op) {
  const SpMat scaled = op.stiffness * op.mass.cwiseInverse().asDiagonal();
  SpMat B = scaled * op.stiffness;
  // The product sums in an order that depends on the side; mirror the upper triangle so B is
  // exactly symmetric (CHOLMOD reads one triangle; tests compare both).
  SpMat upper = B.triangularView<Eigen::Upper>();
  SpMat strict_upper = B.triangularView<Eigen::StrictlyUpper>();
  SpMat symmetric = upper + SpMat(strict_upper.transpose());
  return symmetric;
}

absl::StatusOr<SoftConstraintTerms> AssembleSoftConstraints(const FieldOperator& op,
                                                            const ModelProblem& problem) {
  const EnergyWeights& w = problem.weights;
  const int64_t k = op.dofs();
  const int32_t p = op.type.dofs_per_face();
  for (const FieldConstraint& c : problem.constraints) {
    if (c.hard()) continue;
    RETURN_IF_ERROR(CheckConstraintValue(op, c.face, c.value, "soft"));
    if (!std::isfinite(c.weight) || !(c.weight > 0.0)) {
      return absl::InvalidArgumentError(absl::StrFormat(
          "model problem: soft constraint on face %d has weight %g, must be finite and > 0", c.face,
          c.weight));
    }
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
  RETURN_IF_ERROR(CheckOperator(op));
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
    RETURN_IF_ERROR(CheckConstraintValue(op, c.face, c.value, "hard"));
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

absl::StatusOr<Eigen::VectorXd> SmoothField(const FieldOperator& op, const Eigen::VectorXd& field,
                                            double lambda, const CholeskyOptions& cholesky) {
  RETURN_IF_ERROR(CheckOperator(op));
  if (!std::isfinite(lambda) || lambda < 0.0) {
    return absl::InvalidArgumentError(
        absl::StrFormat("smoothing: lambda = %g must be finite and >= 0", lambda));
  }
  if (field.size() != op.dofs()) {
    return absl::InvalidArgumentError(
        absl::StrFormat("smoothing: field has %d entries, expected %d", field.size(), op.dofs()));
  }
  if (!field.allFinite()) return absl::InvalidArgumentError("smoothing: field is not finite");
  if (lambda == 0.0) return field;
  const SpMat scaled = lambda * op.stiffness;
  ASSIGN_OR_RETURN(SparseCholesky factor,
                   SparseCholesky::FactorizeShifted(scaled, 1.0, op.mass, cholesky));
  return factor.Solve(op.mass.cwiseProduct(field));
}

}  // namespace fieldspace
