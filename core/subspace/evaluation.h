#ifndef FIELDSPACE_CORE_SUBSPACE_EVALUATION_H_
#define FIELDSPACE_CORE_SUBSPACE_EVALUATION_H_

#include <cstdint>
#include <vector>

#include "Eigen/Core"
#include "absl/status/statusor.h"
#include "absl/types/span.h"
#include "core/operators/field_operator.h"
#include "core/subspace/full_space_solver.h"
#include "core/subspace/reduced_system.h"

namespace fieldspace {

// The evaluation protocol of paper section 6 ("Approximation"): random smooth test fields, their
// projection errors, and the error of the reduced model problem against the full-space one. The
// full-space systems are factorized with the supernodal Cholesky of supernodal_cholesky.h (the
// same numerics as CHOLMOD's supernodal method, with fast dense kernels: CHOLMOD on the reference
// BLAS of our platform takes ~10x longer on these k x k systems). Only the factorization code is
// shared with the reduced path; the systems are assembled independently.

struct TestFieldOptions {
  int32_t count = 50;            // number of fields, >= 1
  int32_t min_constraints = 10;  // per field, uniform in [min, max], 1 <= min <= max <= #F
  int32_t max_constraints = 50;
  uint64_t seed = 0;
};

struct TestFieldSet {
  Eigen::MatrixXd fields;  // k x count, DOF order of the operator
  std::vector<std::vector<FieldConstraint>>
      constraints;  // hard  // per field, the interpolated values
};

// Test fields (section 6): each is the minimizer of the biharmonic energy X^T B X (B = S M^-1 S)
// subject to hard interpolation constraints at min..max distinct random faces, solved in the full
// space. Constraint values are random unit vectors: a unit tangent vector (frame coordinates) for
// vector fields, a unit representation vector for n-fields, a unit Mandel-Voigt vector for
// tensors. Deterministic for a seed (own integer-to-real mapping, independent of the standard
// library's distributions). One symbolic analysis of B; per field the constrained rows and
// columns are replaced by the identity (same pattern) and only the numeric factorization reruns.
// InvalidArgument for bad options; FailedPrecondition if a constrained B is singular.
absl::StatusOr<TestFieldSet> GenerateTestFields(const FieldOperator& op,
                                                const TestFieldOptions& options);

// The smoothing weights of the minimization experiment: lambda_j = 25 j (1^T M 1) / (1^T S 1) for
// j = 1..count (1 the all-ones DOF vector), i.e. smoothing strengths relative to the operator's
// own scale. FailedPrecondition if 1^T S 1 <= 0.
absl::StatusOr<std::vector<double>> SmoothingWeights(const FieldOperator& op, int32_t count = 5);

// For each field X_f (columns of `fields`, k x m) and lambda: the smoothing instance of eq. 8
// (C = I with the data term weighted by M: min ||X - X_f||_M^2 + lambda X^T S X) solved in the
// full space, (M + lambda S) X = M X_f, and in the subspace, (U^T M U + lambda U^T S U) x =
// U^T M X_f; the error is ||X - U x||_M / ||X||_M. Returns m x lambdas.size() errors.
absl::StatusOr<Eigen::MatrixXd> SmoothingErrors(const FieldOperator& op,
                                                const ReducedSystem& system,
                                                const Eigen::Ref<const Eigen::MatrixXd>& fields,
                                                absl::Span<const double> lambdas);

// The model problem with a biharmonic energy (eq. 8 with mu_S = 0, mu_B = 1 and each test
// field's hard constraints, paper weights), whose full-space minimizer is the test field itself,
// solved in the subspace (SolveReducedModelProblem, the paper's exact form):
// ||X_f - U x||_M / ||X_f||_M per field.
// The paper's local fields kink at their region's edge, where the biharmonic energy is large, so
// this error is much larger than the projection error of the same fields.
absl::StatusOr<Eigen::VectorXd> BiharmonicModelErrors(const ReducedSystem& system,
                                                      const TestFieldSet& tests);

// The weights of the biharmonic design experiment (BiharmonicDesignErrors): mu_S = 0,
// mu_B = 1, mu_C = 1e4, raw (the paper's weights, for a mesh scaled to unit area as the
// benchmarks do). At these weights the full-space solution stays within ~20% of the constraint
// values (the soft constraints pull hard but do not interpolate).
inline constexpr EnergyWeights kBiharmonicDesignWeights = {/*mu_s=*/0.0, /*mu_b=*/1.0,
                                                           /*mu_c=*/1e4};

// The model problem of design with a biharmonic energy (eq. 8 with soft constraints, each of
// weight 1, at each test field's constrained faces and values): solved in the full space (the
// normal equations of AssembleModelSystem, one symbolic analysis for all fields) and in the
// subspace (SolveReducedModelProblem with the biharmonic term in `form`), raw weights;
// ||X - U x||_M / ||X||_M per field, X the full-space solution. `op` is the operator `system`
// was built for. InvalidArgument for invalid weights or a mismatch; errors of the solvers.
absl::StatusOr<Eigen::VectorXd> BiharmonicDesignErrors(
    const FieldOperator& op, const ReducedSystem& system, const TestFieldSet& tests,
    const EnergyWeights& weights = kBiharmonicDesignWeights,
    BiharmonicForm form = BiharmonicForm::kExact);

struct ErrorSummary {
  double mean = 0;
  double max = 0;
};
ErrorSummary Summarize(const Eigen::Ref<const Eigen::MatrixXd>& errors);

}  // namespace fieldspace

#endif  // FIELDSPACE_CORE_SUBSPACE_EVALUATION_H_
