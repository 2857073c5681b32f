#ifndef FIELDSPACE_CORE_SUBSPACE_MODEL_PROBLEM_H_
#define FIELDSPACE_CORE_SUBSPACE_MODEL_PROBLEM_H_

#include <atomic>
#include <cstdint>
#include <vector>

#include "Eigen/Core"
#include "Eigen/SparseCore"
#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "core/subspace/problem.h"
#include "core/subspace/reduced_system.h"

namespace fieldspace {

// The model problem (problem.h: eq. 8 with soft constraints weighted per constraint and optional
// hard constraints) solved in a subspace; full_space_solver.h solves the same description in the
// full space, so that callers can compare.

// The energy weights a problem is factorized with: `weights`, with mu_b multiplied by the mesh's
// total area A when scale_free (X^T B X scales like 1 / L^2 and A like L^2, so mu_b becomes
// dimensionless like mu_s and mu_c; docs/conventions.md, "Scale-free weights").
EnergyWeights EffectiveEnergyWeights(const ReducedSystem& system, const EnergyWeights& weights,
                                     bool scale_free);

// How reduced systems are factorized and solved (DesignSession and SolveReducedModelProblem).
struct ReducedSolveOptions {
  // The energy matrix A = U^T (mu_S S + mu_B B) U is only positive semi-definite in general (its
  // kernel holds fields of zero energy in span(U), e.g. the harmonic fields of a surface of genus
  // g > 0 if the subspace contains them). It is factorized with each diagonal entry scaled by
  // (1 + regularization); if that still fails, the shift is raised 1000x at a time up to
  // max_regularization (then FailedPrecondition). The solve then runs iterative refinement
  // against the unregularized system, so that whenever the constraints make the problem well
  // posed the result is that of the exact (unregularized) problem; directions no constraint
  // controls get the minimum-norm-like solution of the regularized system.
  double regularization = 1e-13;
  double max_regularization = 1e-6;
  // Refinement stops when the normwise backward error of the constrained (KKT) system drops
  // below `tolerance` or after max_refinement_steps corrections.
  double tolerance = 1e-12;
  int32_t max_refinement_steps = 4;
  // With the mixed biharmonic (BiharmonicForm::kMixed, mu_b > 0) the solve is a conjugate
  // gradient iteration to the same `tolerance` instead of the refinement: at most this many
  // iterations (measured at d = 2000: ~15 with the smooth basis, 45-55 with low-modes, 125-150
  // with the paper's). It stops early, unconverged, once *cancel is true.
  int32_t max_iterations = 400;
  // Hard constraints are linearly dependent when, after scaling to unit diagonal, the Schur
  // complement G A^-1 G^T has a pivot below this (the sine squared of the angle between a
  // constraint row and the span of the others): FailedPrecondition.
  double dependence_tolerance = 1e-10;
  bool parallel = true;
  // SolveReducedModelProblem: checked between its phases and before every front of the
  // factorization; Cancelled once *cancel is true. Not owned; may be null.
  const std::atomic<bool>* cancel = nullptr;
};

// InvalidArgument unless 0 <= regularization <= max_regularization (finite), tolerance >= 0,
// max_refinement_steps >= 0, max_iterations >= 1 and 0 < dependence_tolerance < 1.
absl::Status ValidateSolveOptions(const ReducedSolveOptions& options);

struct ReducedSolution {
  Eigen::VectorXd coefficients;  // d: the minimizer x in the subspace
  // Of the final iterate (see ReducedSolveOptions::tolerance); NaN when the solve was not checked
  // against the true system (DesignSessionOptions::verify_interval).
  double backward_error = 0;
  // Refinement steps, or with the mixed biharmonic the conjugate gradient iterations.
  int32_t refinement_steps = 0;
  double regularization = 0;  // the diagonal shift the factorization needed
};

// The reduced energy matrix with the soft constraints' terms, and the right-hand side (eq. 10):
//   A = U^T (mu_s S + mu_b B) U + mu_c sum_soft (w_i / g_i) U_i^T U_i   (d x d, symmetric PSD,
//       on the system's shared pattern, both triangles stored),
//   b = mu_c sum_soft (w_i / g_i) U_i^T c_i   (d)
// (U_i: the rows of U at face f(i); g_i = 1, or with problem.scale_free the FaceStiffness of the
// face under the energy alone, and mu_b times the total area). Hard constraints are left out. The
// soft constraints are summed per face first, so the cost grows with the number of distinct
// faces, not of constraints. Errors as SolveReducedModelProblem's before its factorization.
struct ReducedAssembly {
  Eigen::SparseMatrix<double> A;
  Eigen::VectorXd b;
};
absl::StatusOr<ReducedAssembly> AssembleReducedModelProblem(
    const ReducedSystem& system, const ModelProblem& problem,
    const ReducedSolveOptions& options = {});

// Solves the reduced problem (eq. 10, 11) from scratch: factorizes
//   U^T (mu_s S + mu_b B) U + mu_c sum_soft w_i U_i^T U_i   (U_i: the rows of U at face f(i))
// (with problem.biharmonic = kMixed and mu_b > 0 that matrix preconditions conjugate gradients on
// the same matrix with U^T B U replaced by K Mr^-1 K, in the null space of the hard constraints)
// (with problem.scale_free: mu_b times the total area and w_i / g_i, g_i = FaceStiffness of the
// face from a factorization of the energy alone) and imposes the hard constraints U_h x = c_h with
// a Schur complement on that factorization (AssembleReducedModelProblem forms the matrix: its cost
// grows with the distinct soft-constrained faces, not with the constraints). Use DesignSession for
// repeated solves with changing constraints. Weights: see ValidateWeights (mu_c = 0 disables the
// soft constraints). Errors: InvalidArgument for invalid weights or constraints (bad face id, wrong
// value size, non-finite value, non-positive soft weight); FailedPrecondition when the hard
// constraints are linearly dependent in the subspace (e.g. the same face twice, or more constraint
// DOFs than d) or the system cannot be factorized; Cancelled (options.cancel).
absl::StatusOr<ReducedSolution> SolveReducedModelProblem(const ReducedSystem& system,
                                                         const ModelProblem& problem,
                                                         const ReducedSolveOptions& options = {});

// An upper estimate of the bytes SolveReducedModelProblem allocates for `soft` soft and `hard`
// hard constraints on `system` (with `threads` threads summing the soft terms): the copies of the
// reduced matrix, the per-thread sums on its pattern and batch scratch space, the per-face sums,
// one or two factorizations and the hard constraints' Schur complement; the constraints
// themselves as ModelProblem holds them. For
// admission against a memory budget before any of it is allocated.
int64_t SolveWorkingBytes(const ReducedSystem& system, int64_t soft, int64_t hard, bool scale_free,
                          int32_t threads);

}  // namespace fieldspace

#endif  // FIELDSPACE_CORE_SUBSPACE_MODEL_PROBLEM_H_
