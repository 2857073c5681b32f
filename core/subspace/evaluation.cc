#include "core/subspace/evaluation.h"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <optional>
#include <random>
#include <utility>

#include "absl/strings/str_cat.h"
#include "core/common/status_macros.h"
#include "core/linalg/supernodal_cholesky.h"
#include "core/operators/reference_solvers.h"
#include "core/subspace/model_problem.h"
#include "core/subspace/projection.h"

namespace fieldspace {
namespace {

// Uniform double in [0, 1) from 53 random bits (platform-independent, unlike
// std::uniform_real_distribution).
double Uniform01(std::mt19937_64& rng) { return static_cast<double>(rng() >> 11) * 0x1.0p-53; }

// Standard normal by Box-Muller on Uniform01 (platform-independent).
double Normal(std::mt19937_64& rng) {
  const double u1 = 1.0 - Uniform01(rng);  // (0, 1]
  const double u2 = Uniform01(rng);
  return std::sqrt(-2.0 * std::log(u1)) * std::cos(2.0 * std::numbers::pi * u2);
}

// Uniform integer in [0, n) (n small relative to 2^64: the modulo bias is negligible).
int64_t UniformInt(std::mt19937_64& rng, int64_t n) {
  return static_cast<int64_t>(rng() % static_cast<uint64_t>(n));
}

}  // namespace

absl::StatusOr<TestFieldSet> GenerateTestFields(const FieldOperator& op,
                                                const TestFieldOptions& options) {
  const int64_t k = op.dofs();
  const int32_t p = op.type.dofs_per_face();
  if (k == 0 || op.stiffness.rows() != k || op.stiffness.cols() != k || k % p != 0) {
    return absl::InvalidArgumentError("GenerateTestFields: operator sizes do not match");
  }
  const int64_t num_faces = k / p;
  if (options.count < 1 || options.min_constraints < 1 ||
      options.max_constraints < options.min_constraints || options.max_constraints > num_faces) {
    return absl::InvalidArgumentError(absl::StrCat(
        "GenerateTestFields: need count >= 1 and 1 <= min_constraints <= max_constraints <= #F "
        "= ",
        num_faces, "; got count ", options.count, ", constraints [", options.min_constraints, ", ",
        options.max_constraints, "]"));
  }
  Eigen::SparseMatrix<double> B = BiharmonicMatrix(op);
  B.makeCompressed();
  const std::vector<double> original(B.valuePtr(), B.valuePtr() + B.nonZeros());

  TestFieldSet set;
  set.fields.resize(k, options.count);
  set.constraints.resize(options.count);
  std::mt19937_64 rng(options.seed);
  std::vector<char> constrained(k, 0);
  // The pattern of B never changes: analyze once, refactorize numerically per field.
  ASSIGN_OR_RETURN(std::shared_ptr<const SupernodalSymbolic> symbolic,
                   SupernodalSymbolic::Analyze(B));
  std::optional<SupernodalFactor> factor;
  for (int32_t f = 0; f < options.count; ++f) {
    // Random distinct faces and unit values.
    const int32_t n =
        options.min_constraints + static_cast<int32_t>(UniformInt(
                                      rng, options.max_constraints - options.min_constraints + 1));
    std::vector<int32_t> faces;
    std::vector<char> used(num_faces, 0);
    while (static_cast<int32_t>(faces.size()) < n) {
      const int32_t face = static_cast<int32_t>(UniformInt(rng, num_faces));
      if (!used[face]) {
        used[face] = 1;
        faces.push_back(face);
      }
    }
    std::sort(faces.begin(), faces.end());
    Eigen::VectorXd c = Eigen::VectorXd::Zero(k);
    std::vector<FieldConstraint>& hard = set.constraints[f];
    for (int32_t face : faces) {
      Eigen::VectorXd value(p);
      if (p == 2) {
        const double angle = 2.0 * std::numbers::pi * Uniform01(rng);
        value << std::cos(angle), std::sin(angle);
      } else {
        do {
          for (int32_t i = 0; i < p; ++i) value[i] = Normal(rng);
        } while (value.norm() < 1e-12);
        value.normalize();
      }
      hard.push_back({face, value, 1.0, ConstraintKind::kHard});
      for (int32_t i = 0; i < p; ++i) {
        constrained[static_cast<int64_t>(face) * p + i] = 1;
        c[static_cast<int64_t>(face) * p + i] = value[i];
      }
    }
    // Constrained rows and columns of B become identity rows/columns (pattern kept, so the
    // symbolic analysis is reused); the right-hand side moves the known values over.
    Eigen::VectorXd rhs = Eigen::VectorXd::Zero(k);
    double* v = B.valuePtr();
    for (int64_t j = 0; j < k; ++j) {
      for (int64_t q = B.outerIndexPtr()[j]; q < B.outerIndexPtr()[j + 1]; ++q) {
        const int64_t i = B.innerIndexPtr()[q];
        const double b = original[q];
        if (constrained[j]) {
          if (!constrained[i]) rhs[i] -= b * c[j];
          v[q] = i == j ? 1.0 : 0.0;
        } else {
          v[q] = constrained[i] ? 0.0 : b;
        }
      }
    }
    for (int64_t j = 0; j < k; ++j) {
      if (constrained[j]) rhs[j] = c[j];
    }
    const absl::Span<const double> values(B.valuePtr(), B.nonZeros());
    if (!factor.has_value()) {
      ASSIGN_OR_RETURN(SupernodalFactor f, SupernodalFactor::Factorize(symbolic, values));
      factor.emplace(std::move(f));
    } else {
      RETURN_IF_ERROR(factor->Refactorize(values));
    }
    Eigen::VectorXd X = factor->Solve(rhs);
    for (int64_t j = 0; j < k; ++j) {
      if (constrained[j]) X[j] = c[j];  // exact interpolation
    }
    set.fields.col(f) = X;
    for (int32_t face : faces) {
      for (int32_t i = 0; i < p; ++i) constrained[static_cast<int64_t>(face) * p + i] = 0;
    }
  }
  return set;
}

absl::StatusOr<std::vector<double>> SmoothingWeights(const FieldOperator& op, int32_t count) {
  if (count < 1) return absl::InvalidArgumentError("SmoothingWeights: count must be >= 1");
  const double ones_m = op.mass.sum();
  double ones_s = 0;
  for (int64_t q = 0; q < op.stiffness.nonZeros(); ++q) ones_s += op.stiffness.valuePtr()[q];
  if (!(ones_s > 0) || !std::isfinite(ones_s) || !(ones_m > 0)) {
    return absl::FailedPreconditionError(absl::StrCat("SmoothingWeights: 1^T S 1 = ", ones_s,
                                                      " and 1^T M 1 = ", ones_m, " must be > 0"));
  }
  std::vector<double> lambdas(count);
  for (int32_t j = 0; j < count; ++j) lambdas[j] = 25.0 * (j + 1) * ones_m / ones_s;
  return lambdas;
}

absl::StatusOr<Eigen::MatrixXd> SmoothingErrors(const FieldOperator& op,
                                                const ReducedSystem& system,
                                                const Eigen::Ref<const Eigen::MatrixXd>& fields,
                                                absl::Span<const double> lambdas) {
  if (fields.rows() != op.dofs() || op.dofs() != system.dofs()) {
    return absl::InvalidArgumentError(absl::StrCat("SmoothingErrors: fields have ", fields.rows(),
                                                   " rows, operator ", op.dofs(), " DOFs, basis ",
                                                   system.dofs(), " rows"));
  }
  for (double lambda : lambdas) {
    if (!(lambda > 0) || !std::isfinite(lambda)) {
      return absl::InvalidArgumentError("SmoothingErrors: each lambda must be finite and > 0");
    }
  }
  const int64_t m = fields.cols();
  Eigen::MatrixXd errors(m, static_cast<int64_t>(lambdas.size()));
  // M X_f and U^T M X_f once for all lambdas.
  const Eigen::MatrixXd mass_fields = op.mass.asDiagonal() * fields;
  ASSIGN_OR_RETURN(const Eigen::MatrixXd reduced_rhs, MassWeightedProducts(system, fields));
  const Eigen::SparseMatrix<double>& Sr = system.stiffness();
  const Eigen::SparseMatrix<double>& Mr = system.mass_matrix();
  // Full space: M + lambda S on the pattern of S (diagonal stored), analyzed once.
  Eigen::SparseMatrix<double> full = op.stiffness;
  full.makeCompressed();
  std::vector<int64_t> diagonal(full.rows(), -1);
  for (int64_t j = 0; j < full.outerSize(); ++j) {
    for (int64_t q = full.outerIndexPtr()[j]; q < full.outerIndexPtr()[j + 1]; ++q) {
      if (full.innerIndexPtr()[q] == j) diagonal[j] = q;
    }
  }
  if (std::find(diagonal.begin(), diagonal.end(), -1) != diagonal.end()) {
    // A structurally missing diagonal entry: store it explicitly.
    Eigen::SparseMatrix<double> with_diagonal =
        full + Eigen::SparseMatrix<double>(Eigen::VectorXd::Zero(full.rows()).asDiagonal());
    full = std::move(with_diagonal);
    full.makeCompressed();
    for (int64_t j = 0; j < full.outerSize(); ++j) {
      for (int64_t q = full.outerIndexPtr()[j]; q < full.outerIndexPtr()[j + 1]; ++q) {
        if (full.innerIndexPtr()[q] == j) diagonal[j] = q;
      }
    }
  }
  const std::vector<double> stiffness_values(full.valuePtr(), full.valuePtr() + full.nonZeros());
  ASSIGN_OR_RETURN(std::shared_ptr<const SupernodalSymbolic> full_symbolic,
                   SupernodalSymbolic::Analyze(full));
  for (size_t j = 0; j < lambdas.size(); ++j) {
    const double lambda = lambdas[j];
    // Full space: (M + lambda S) X = M X_f.
    std::vector<double> full_values(stiffness_values.size());
    for (size_t q = 0; q < full_values.size(); ++q) full_values[q] = lambda * stiffness_values[q];
    for (int64_t i = 0; i < full.rows(); ++i) full_values[diagonal[i]] += op.mass[i];
    ASSIGN_OR_RETURN(SupernodalFactor full_factor,
                     SupernodalFactor::Factorize(full_symbolic, full_values));
    Eigen::MatrixXd X = mass_fields;
    full_factor.SolveInPlace(X);
    // Subspace: (U^T M U + lambda U^T S U) x = U^T M X_f.
    std::vector<double> values(Sr.nonZeros());
    for (int64_t q = 0; q < Sr.nonZeros(); ++q) {
      values[q] = Mr.valuePtr()[q] + lambda * Sr.valuePtr()[q];
    }
    ASSIGN_OR_RETURN(SupernodalFactor reduced,
                     SupernodalFactor::Factorize(system.pattern_symbolic(), values));
    Eigen::MatrixXd x = reduced_rhs;
    reduced.SolveInPlace(x);
    ASSIGN_OR_RETURN(errors.col(j), RelativeResiduals(system, X, x));
  }
  return errors;
}

absl::StatusOr<Eigen::VectorXd> BiharmonicModelErrors(const ReducedSystem& system,
                                                      const TestFieldSet& tests) {
  const int64_t m = tests.fields.cols();
  if (static_cast<int64_t>(tests.constraints.size()) != m) {
    return absl::InvalidArgumentError("BiharmonicModelErrors: one constraint set per field");
  }
  Eigen::MatrixXd x(system.dimension(), m);
  for (int64_t j = 0; j < m; ++j) {
    ModelProblem problem;
    problem.weights = {/*mu_s=*/0.0, /*mu_b=*/1.0, /*mu_c=*/1.0};
    problem.biharmonic = BiharmonicForm::kExact;  // the paper's experiment (Table 3)
    problem.constraints = tests.constraints[j];
    ASSIGN_OR_RETURN(ReducedSolution solution, SolveReducedModelProblem(system, problem));
    x.col(j) = solution.coefficients;
  }
  return RelativeResiduals(system, tests.fields, x);
}

absl::StatusOr<Eigen::VectorXd> BiharmonicDesignErrors(const FieldOperator& op,
                                                       const ReducedSystem& system,
                                                       const TestFieldSet& tests,
                                                       const EnergyWeights& weights,
                                                       BiharmonicForm form) {
  const int64_t m = tests.fields.cols();
  if (static_cast<int64_t>(tests.constraints.size()) != m) {
    return absl::InvalidArgumentError("BiharmonicDesignErrors: one constraint set per field");
  }
  if (op.dofs() != system.dofs()) {
    return absl::InvalidArgumentError("BiharmonicDesignErrors: operator and subspace differ");
  }
  // Full space: (mu_s S + mu_b B + mu_c C^T C) X = mu_c C^T c (AssembleModelSystem's). The
  // energy's pattern (B's, which holds S's and the diagonal) never changes: one symbolic
  // analysis, a numeric factorization per field with the soft constraints' diagonal added.
  const int64_t k = system.dofs();
  ModelProblem energy_only;
  energy_only.weights = weights;
  ASSIGN_OR_RETURN(ModelSystem energy_system, AssembleModelSystem(op, energy_only));
  const Eigen::SparseMatrix<double>& energy = energy_system.A;
  std::vector<int64_t> diagonal(k, -1);
  for (int64_t col = 0; col < k; ++col) {
    for (int64_t q = energy.outerIndexPtr()[col]; q < energy.outerIndexPtr()[col + 1]; ++q) {
      if (energy.innerIndexPtr()[q] == col) diagonal[col] = q;
    }
    if (diagonal[col] < 0) {
      return absl::InternalError("BiharmonicDesignErrors: the energy has no diagonal entry");
    }
  }
  ASSIGN_OR_RETURN(std::shared_ptr<const SupernodalSymbolic> symbolic,
                   SupernodalSymbolic::Analyze(energy));
  std::optional<SupernodalFactor> factor;
  Eigen::MatrixXd full(k, m);
  Eigen::MatrixXd x(system.dimension(), m);
  std::vector<double> values(energy.valuePtr(), energy.valuePtr() + energy.nonZeros());
  for (int64_t j = 0; j < m; ++j) {
    ModelProblem problem;
    problem.weights = weights;
    problem.constraints = tests.constraints[j];
    for (FieldConstraint& c : problem.constraints) {
      c.kind = ConstraintKind::kSoft;
      c.weight = 1.0;
    }
    ASSIGN_OR_RETURN(SoftConstraintTerms soft, AssembleSoftConstraints(op, problem));
    std::copy(energy.valuePtr(), energy.valuePtr() + energy.nonZeros(), values.begin());
    for (int64_t i = 0; i < k; ++i) values[diagonal[i]] += soft.diagonal[i];
    if (!factor.has_value()) {
      ASSIGN_OR_RETURN(SupernodalFactor f, SupernodalFactor::Factorize(symbolic, values));
      factor.emplace(std::move(f));
    } else {
      RETURN_IF_ERROR(factor->Refactorize(values));
    }
    full.col(j) = factor->Solve(soft.b);
    problem.biharmonic = form;
    ASSIGN_OR_RETURN(ReducedSolution solution, SolveReducedModelProblem(system, problem));
    x.col(j) = solution.coefficients;
  }
  return RelativeResiduals(system, full, x);
}

ErrorSummary Summarize(const Eigen::Ref<const Eigen::MatrixXd>& errors) {
  ErrorSummary s;
  if (errors.size() == 0) return s;
  s.mean = errors.mean();
  s.max = errors.maxCoeff();
  return s;
}

}  // namespace fieldspace
