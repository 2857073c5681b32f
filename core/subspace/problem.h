#ifndef FIELDSPACE_CORE_SUBSPACE_PROBLEM_H_
#define FIELDSPACE_CORE_SUBSPACE_PROBLEM_H_

#include <cstdint>
#include <vector>

#include "Eigen/Core"
#include "absl/status/status.h"
#include "core/operators/field_type.h"

namespace fieldspace {

// The vocabulary of the model problem (paper eq. 8; docs/conventions.md, Model problem): its
// weights, its constraints and the problem itself, with one validator per concept. One
// description from core to the wire (fieldspace.v1.Weights and Constraint carry the same names):
// the full-space solver (full_space_solver.h), the reduced one (model_problem.h) and design
// sessions (design_session.h) all take these types.

// The weights of the model problem (eq. 8):
//   mu_s X^T S X + mu_b X^T B X + mu_c sum_soft w_i |X_f(i) - c_i|^2
// (the constraint term is the plain Euclidean norm of the face's DOFs, not weighted by area).
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
// The weights of a design session: ValidateWeights (with a data term) or
// ValidateWeightsWithoutDataTerm (without), and mu_c > 0: a session keeps each soft constraint as
// the diagonal term 1 / (mu_c weight) of its Woodbury update.
absl::Status ValidateSessionWeights(const EnergyWeights& weights, bool data_term);

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

// InvalidArgument unless `c` names a face in [0, num_faces), has type.dofs_per_face() finite
// values and (for a soft constraint) a finite positive weight.
absl::Status ValidateConstraint(const FieldConstraint& c, int64_t num_faces, const FieldType& type);

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
  // it through the partial fractions of its inverse, (K^-1 - mu_B N^-1) / mu_S with
  // N = mu_S Mr + mu_B K (core/subspace/mixed_energy.h); one-shot solves by conjugate gradients
  // preconditioned by the exact form's factorization. The default.
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

}  // namespace fieldspace

#endif  // FIELDSPACE_CORE_SUBSPACE_PROBLEM_H_
