#ifndef FIELDSPACE_CORE_OPERATORS_REFERENCE_SOLVERS_H_
#define FIELDSPACE_CORE_OPERATORS_REFERENCE_SOLVERS_H_

#include <cstdint>
#include <utility>
#include <vector>

#include "Eigen/Core"
#include "Eigen/SparseCore"
#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "core/linalg/eigensolver.h"
#include "core/linalg/sparse_cholesky.h"
#include "core/operators/field_operator.h"

namespace fieldspace {

// Full-space solvers for the problems the subspace methods approximate (docs/conventions.md, Model
// problem and Subspace methods): references for tests, for measuring subspace errors, and for
// generating test fields. They factorize k x k systems with CHOLMOD, so cost grows superlinearly
// with the mesh.

// The K lowest eigenpairs of S x = lambda M x for `op` (eigenvectors in the DOF order of op,
// M-orthonormal). Errors as LowestEigenpairs.
absl::StatusOr<EigenResult> ReferenceEigenpairs(const FieldOperator& op,
                                                const EigenOptions& options = {});

// B = S M^-1 S (k x k, sparse, symmetric PSD): the biharmonic energy matrix of eq. 8. Its rows
// couple faces up to two rings apart, so it holds several times the nonzeros of S.
Eigen::SparseMatrix<double> BiharmonicMatrix(const FieldOperator& op);

// The weights of the model problem (eq. 8):
//   mu_s X^T S X + mu_b X^T B X + mu_c sum_soft w_i |X_f(i) - c_i|^2
// (the constraint term is the plain Euclidean norm of the face's DOFs, not weighted by area).
// The one weights type from core to the wire (fieldspace.v1.Weights carries the same names).
struct EnergyWeights {
  double mu_s = 1.0;  // harmonic (Dirichlet) energy, >= 0
  double mu_b = 0.0;  // biharmonic energy, >= 0
  double mu_c = 1.0;  // soft constraints (scales every soft constraint's weight), >= 0
  // A design session's data (alignment) term mu_a (X - X0)^T W M (X - X0), >= 0
  // (DesignSessionOptions::data_term); no other problem has that term, and they need it 0.
  double mu_a = 0.0;
};

// InvalidArgument (naming the weight) unless every weight is finite and >= 0 and
// mu_s + mu_b > 0 (otherwise the energy does not determine the field away from the
// constraints). mu_c = 0 is valid: the soft constraints then do nothing.
absl::Status ValidateWeights(const EnergyWeights& weights);
// ValidateWeights, and mu_a = 0: for every problem without a data term (all but design sessions
// opened with one), so that a data weight is never silently ignored.
absl::Status ValidateWeightsWithoutDataTerm(const EnergyWeights& weights);

enum class ConstraintKind : uint8_t {
  kSoft = 0,  // the term mu_c * weight * |X_face - value|^2
  kHard = 1,  // X_face = value exactly (weight ignored)
};

// A constraint on one face's DOFs (docs/conventions.md: 2 frame values for vector and n-fields,
// 3 Mandel-Voigt values for tensors). The one constraint type from core to the wire.
struct FieldConstraint {
  int32_t face = 0;
  Eigen::VectorXd value;  // dofs_per_face DOFs of the face
  double weight = 1.0;    // soft constraints: finite, > 0
  ConstraintKind kind = ConstraintKind::kSoft;

  bool hard() const { return kind == ConstraintKind::kHard; }
};

// How a reduced solver (SolveReducedModelProblem, DesignSession) discretizes the biharmonic energy
// X^T B X, B = S M^-1 S, in a subspace X = U x (docs/conventions.md, "Biharmonic form"). In the
// full space (U = I) both forms are B itself, so the full-space solvers accept either.
enum class BiharmonicForm : uint8_t {
  // x^T U^T S M^-1 S U x: the paper's (eq. 10), the energy of the lifted field exactly. It also
  // charges the kinks where local fields overlap or end, which a smooth minimizer never has.
  kExact = 0,
  // x^T K Mr^-1 K x with K = U^T S U and Mr = U^T M U: the biharmonic energy of the subspace's own
  // Laplacian (the M-projection of M^-1 S U x onto span(U)), never more than the exact form.
  // Closer to the full-space minimizer with local bases (bench/RESULTS.md). Design sessions solve
  // it in the simultaneous eigenbasis of K and Mr (core/subspace/spectral_mixed.h); one-shot
  // solves by conjugate gradients preconditioned by the exact form's factorization. The default.
  kMixed = 1,
};

// The model problem (eq. 8), optionally with hard constraints:
//   min mu_s X^T S X + mu_b X^T B X + mu_c sum_soft weight_j ||X_{face_j} - value_j||^2
//   subject to X_{face} = value for every hard constraint (at most one per face),
// i.e. C selects the soft-constrained faces' DOFs, scaled by sqrt(weight_j).
struct ModelProblem {
  EnergyWeights weights;
  std::vector<FieldConstraint> constraints;  // soft and hard, in any order
  // Scale-free weights (docs/conventions.md, "Scale-free weights"): mu_b is multiplied by the
  // mesh's total area and each soft constraint's weight divided by its face's stiffness in the
  // subspace (FaceStiffness, core/subspace/kkt_solver.h), so that the same weights give the same
  // field on a scaled or refined mesh and a soft constraint alone pulls its face at least
  // mu_c w / (1 + mu_c w) of the way to its value. Defined by a subspace: only the reduced
  // solvers (SolveReducedModelProblem, DesignSession) take it; the full-space ones answer
  // InvalidArgument. false: the paper's raw weights.
  bool scale_free = false;
  // The biharmonic term's form in a subspace (reduced solvers only; no effect when mu_b = 0).
  BiharmonicForm biharmonic = BiharmonicForm::kMixed;
};

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

// Smoothing (the eq. 8 instance with a mass-weighted data term):
//   min ||X - field||_M^2 + lambda X^T S X  <=>  (M + lambda S) X = M field.
// field: k entries; lambda finite, >= 0.
absl::StatusOr<Eigen::VectorXd> SmoothField(const FieldOperator& op, const Eigen::VectorXd& field,
                                            double lambda, const CholeskyOptions& cholesky = {});

}  // namespace fieldspace

#endif  // FIELDSPACE_CORE_OPERATORS_REFERENCE_SOLVERS_H_
