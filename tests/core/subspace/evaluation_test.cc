#include "core/subspace/evaluation.h"

#include <cmath>
#include <vector>

#include "Eigen/Dense"
#include "core/operators/reference_solvers.h"
#include "core/subspace/problem.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tests/testing/fixtures.h"
#include "tests/testing/matchers.h"
#include "tests/testing/test_meshes.h"

namespace fieldspace {
namespace {

using ::fieldspace::testing::DenseU;
using ::fieldspace::testing::Icosphere;
using ::fieldspace::testing::IdentityBasis;
using ::fieldspace::testing::MustBuildOperator;
using ::fieldspace::testing::RandomBasis;
using ::fieldspace::testing::StatusIs;

// Two test fields on `op` with 4-6 constraints each (the model-error tests' set).
absl::StatusOr<TestFieldSet> TwoConstrainedFields(const FieldOperator& op, uint64_t seed) {
  TestFieldOptions options;
  options.count = 2;
  options.min_constraints = 4;
  options.max_constraints = 6;
  options.seed = seed;
  return GenerateTestFields(op, options);
}

TEST(EvaluationTest, TestFieldsAreConstrainedBiharmonicMinimizers) {
  const TriangleMesh mesh = Icosphere(2);
  for (const FieldType& type : {FieldType::Vector(), FieldType::NField(2), FieldType::Tensor()}) {
    const FieldOperator op = MustBuildOperator(mesh, type);
    TestFieldOptions options;
    options.count = 3;
    options.min_constraints = 5;
    options.max_constraints = 12;
    options.seed = 42;
    auto set = GenerateTestFields(op, options);
    ASSERT_TRUE(set.ok()) << set.status();
    ASSERT_EQ(set->fields.cols(), 3);
    const Eigen::SparseMatrix<double> B = BiharmonicMatrix(op);
    const int p = type.dofs_per_face();
    for (int f = 0; f < 3; ++f) {
      const auto& constraints = set->constraints[f];
      ASSERT_GE(constraints.size(), 5u);
      ASSERT_LE(constraints.size(), 12u);
      const Eigen::VectorXd X = set->fields.col(f);
      Eigen::VectorXd BX = B * X;
      for (const FieldConstraint& c : constraints) {
        EXPECT_NEAR(c.value.norm(), 1.0, 1e-12);  // random unit values
        EXPECT_LT((X.segment(static_cast<int64_t>(c.face) * p, p) - c.value).norm(), 1e-12);
        BX.segment(static_cast<int64_t>(c.face) * p, p).setZero();
      }
      // Stationarity: the gradient B X vanishes on every unconstrained DOF.
      EXPECT_LT(BX.norm(), 1e-8 * (B * X).norm()) << type.ToString();
    }
    // Deterministic for a seed, different for another.
    auto again = GenerateTestFields(op, options);
    ASSERT_TRUE(again.ok());
    EXPECT_EQ(again->fields, set->fields);
    options.seed = 43;
    auto other = GenerateTestFields(op, options);
    ASSERT_TRUE(other.ok());
    EXPECT_GT((other->fields - set->fields).norm(), 0.1);
  }
}

TEST(EvaluationTest, SmoothingWeightsFollowTheOperatorScale) {
  const TriangleMesh mesh = Icosphere(2);
  const FieldOperator op = MustBuildOperator(mesh, FieldType::Vector());
  auto lambdas = SmoothingWeights(op, 5);
  ASSERT_TRUE(lambdas.ok());
  const Eigen::VectorXd ones = Eigen::VectorXd::Ones(op.dofs());
  const double ratio = ones.dot(op.mass.asDiagonal() * ones) / ones.dot(op.stiffness * ones);
  ASSERT_EQ(lambdas->size(), 5u);
  for (int j = 0; j < 5; ++j)
    EXPECT_NEAR((*lambdas)[j], 25.0 * (j + 1) * ratio, 1e-12 * (j + 1) * ratio);
  EXPECT_THAT(SmoothingWeights(op, 0), StatusIs(absl::StatusCode::kInvalidArgument));
}

TEST(EvaluationTest, SmoothingErrorsAgainstIndependentComputations) {
  const TriangleMesh mesh = Icosphere(2);
  const FieldOperator op = MustBuildOperator(mesh, FieldType::Vector());
  const Eigen::MatrixXd fields = Eigen::MatrixXd::Random(op.dofs(), 2);
  const std::vector<double> lambdas = {0.01, 0.3};
  // U = I: the subspace is the full space, no error.
  auto identity = ReducedSystem::Build(IdentityBasis(FieldType::Vector(), op.dofs()), op);
  ASSERT_TRUE(identity.ok());
  auto zero = SmoothingErrors(op, **identity, fields, lambdas);
  ASSERT_TRUE(zero.ok()) << zero.status();
  EXPECT_LT(zero->maxCoeff(), 1e-9);
  // A random subspace against a dense computation of the same two solves.
  auto basis = RandomBasis(FieldType::Vector(), op.dofs(), 100, 30, 6);
  auto sys = ReducedSystem::Build(basis, op);
  ASSERT_TRUE(sys.ok());
  auto errors = SmoothingErrors(op, **sys, fields, lambdas);
  ASSERT_TRUE(errors.ok());
  const Eigen::MatrixXd U = DenseU(*basis);
  const Eigen::MatrixXd S = Eigen::MatrixXd(op.stiffness);
  const Eigen::MatrixXd M = op.mass.asDiagonal();
  for (int j = 0; j < 2; ++j) {
    const Eigen::MatrixXd X = (M + lambdas[j] * S).ldlt().solve(M * fields);
    const Eigen::MatrixXd x =
        (U.transpose() * (M + lambdas[j] * S) * U).ldlt().solve(U.transpose() * M * fields);
    for (int f = 0; f < 2; ++f) {
      const Eigen::VectorXd r = X.col(f) - U * x.col(f);
      const double expected = std::sqrt(r.dot(M * r) / X.col(f).dot(M * X.col(f)));
      EXPECT_NEAR((*errors)(f, j), expected, 1e-9);
      EXPECT_GT(expected, 1e-3);
    }
  }
  const ErrorSummary summary = Summarize(*errors);
  EXPECT_NEAR(summary.mean, errors->mean(), 1e-15);
  EXPECT_EQ(summary.max, errors->maxCoeff());
  EXPECT_THAT(SmoothingErrors(op, **sys, fields, std::vector<double>{-1.0}),
              StatusIs(absl::StatusCode::kInvalidArgument));
}

TEST(EvaluationTest, BiharmonicModelErrorsAgainstADenseKktSolve) {
  const TriangleMesh mesh = Icosphere(2);
  const FieldOperator op = MustBuildOperator(mesh, FieldType::Vector());
  auto tests = TwoConstrainedFields(op, 5);
  ASSERT_TRUE(tests.ok()) << tests.status();
  // U = I: the reduced problem is the full one, whose minimizer is the test field.
  auto identity = ReducedSystem::Build(IdentityBasis(FieldType::Vector(), op.dofs()), op);
  ASSERT_TRUE(identity.ok());
  auto zero = BiharmonicModelErrors(**identity, *tests);
  ASSERT_TRUE(zero.ok()) << zero.status();
  EXPECT_LT(zero->maxCoeff(), 1e-7);
  // A random subspace: min x^T U^T B U x subject to the constraint rows C U x = c, by a dense
  // KKT solve, against the field in the mass norm.
  auto basis = RandomBasis(FieldType::Vector(), op.dofs(), 120, 30, 9);
  auto sys = ReducedSystem::Build(basis, op);
  ASSERT_TRUE(sys.ok());
  auto errors = BiharmonicModelErrors(**sys, *tests);
  ASSERT_TRUE(errors.ok()) << errors.status();
  const Eigen::MatrixXd U = DenseU(*basis);
  const Eigen::MatrixXd B = Eigen::MatrixXd(BiharmonicMatrix(op));
  const Eigen::MatrixXd M = op.mass.asDiagonal();
  const int64_t d = U.cols();
  for (int f = 0; f < 2; ++f) {
    const auto& constraints = tests->constraints[f];
    const int64_t r = 2 * static_cast<int64_t>(constraints.size());
    Eigen::MatrixXd K = Eigen::MatrixXd::Zero(d + r, d + r);
    Eigen::VectorXd rhs = Eigen::VectorXd::Zero(d + r);
    K.topLeftCorner(d, d) = U.transpose() * B * U;
    for (size_t i = 0; i < constraints.size(); ++i) {
      const Eigen::MatrixXd rows = U.middleRows(2 * int64_t{constraints[i].face}, 2);
      K.block(d + 2 * i, 0, 2, d) = rows;
      K.block(0, d + 2 * i, d, 2) = rows.transpose();
      rhs.segment(d + 2 * i, 2) = constraints[i].value;
    }
    const Eigen::VectorXd x = K.fullPivLu().solve(rhs).head(d);
    const Eigen::VectorXd res = tests->fields.col(f) - U * x;
    const double expected =
        std::sqrt(res.dot(M * res) / tests->fields.col(f).dot(M * tests->fields.col(f)));
    EXPECT_NEAR((*errors)[f], expected, 1e-6 * expected);
    EXPECT_GT(expected, 1e-3);
  }
}

TEST(EvaluationTest, BiharmonicDesignErrorsAgainstDenseSolves) {
  const TriangleMesh mesh = Icosphere(2);
  const FieldOperator op = MustBuildOperator(mesh, FieldType::Vector());
  auto tests = TwoConstrainedFields(op, 7);
  ASSERT_TRUE(tests.ok()) << tests.status();
  const EnergyWeights weights = {/*mu_s=*/0.5, /*mu_b=*/1.0, /*mu_c=*/30.0};
  // U = I: the subspace solution is the full-space one.
  auto identity = ReducedSystem::Build(IdentityBasis(FieldType::Vector(), op.dofs()), op);
  ASSERT_TRUE(identity.ok());
  auto zero = BiharmonicDesignErrors(op, **identity, *tests, weights);
  ASSERT_TRUE(zero.ok()) << zero.status();
  EXPECT_LT(zero->maxCoeff(), 1e-7);
  // A random subspace against dense normal equations in both spaces:
  // (mu_s S + mu_b B + mu_c C^T C) X = mu_c C^T c, and the same with X = U x.
  auto basis = RandomBasis(FieldType::Vector(), op.dofs(), 120, 30, 9);
  auto sys = ReducedSystem::Build(basis, op);
  ASSERT_TRUE(sys.ok());
  auto errors = BiharmonicDesignErrors(op, **sys, *tests, weights);
  ASSERT_TRUE(errors.ok()) << errors.status();
  const Eigen::MatrixXd U = DenseU(*basis);
  const Eigen::MatrixXd E = weights.mu_s * Eigen::MatrixXd(op.stiffness) +
                            weights.mu_b * Eigen::MatrixXd(BiharmonicMatrix(op));
  const Eigen::MatrixXd M = op.mass.asDiagonal();
  for (int f = 0; f < 2; ++f) {
    Eigen::MatrixXd A = E;
    Eigen::VectorXd b = Eigen::VectorXd::Zero(op.dofs());
    for (const FieldConstraint& c : tests->constraints[f]) {
      for (int i = 0; i < 2; ++i) {
        A(2 * c.face + i, 2 * c.face + i) += weights.mu_c;
        b[2 * c.face + i] += weights.mu_c * c.value[i];
      }
    }
    const Eigen::VectorXd full = A.ldlt().solve(b);
    const Eigen::VectorXd x = (U.transpose() * A * U).ldlt().solve(U.transpose() * b);
    const Eigen::VectorXd res = full - U * x;
    const double expected = std::sqrt(res.dot(M * res) / full.dot(M * full));
    EXPECT_NEAR((*errors)[f], expected, 1e-6 * expected);
    EXPECT_GT(expected, 1e-3);
  }
  // Weights the design needs: an energy.
  EXPECT_THAT(BiharmonicDesignErrors(op, **sys, *tests, {0.0, 0.0, 1.0}),
              StatusIs(absl::StatusCode::kInvalidArgument));
}

TEST(EvaluationTest, InvalidTestFieldOptions) {
  const TriangleMesh mesh = Icosphere(1);
  const FieldOperator op = MustBuildOperator(mesh, FieldType::Vector());
  TestFieldOptions options;
  options.count = 0;
  EXPECT_THAT(GenerateTestFields(op, options), StatusIs(absl::StatusCode::kInvalidArgument));
  options.count = 1;
  options.min_constraints = 10;
  options.max_constraints = 5;
  EXPECT_THAT(GenerateTestFields(op, options), StatusIs(absl::StatusCode::kInvalidArgument));
  options.min_constraints = 10;
  options.max_constraints = 81;  // more than #F = 80
  EXPECT_THAT(GenerateTestFields(op, options), StatusIs(absl::StatusCode::kInvalidArgument));
}

}  // namespace
}  // namespace fieldspace
