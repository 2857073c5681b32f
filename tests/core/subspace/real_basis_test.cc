// The subspace methods on a basis from the real construction (core/basis): invariants that hold
// for any basis, checked against independent computations, plus loose quality bounds (the tight
// figures are measured by fieldspace-bench approx / eigen).
#include <algorithm>
#include <cmath>
#include <memory>
#include <random>
#include <utility>
#include <vector>

#include "Eigen/Dense"
#include "core/basis/basis.h"
#include "core/operators/reference_solvers.h"
#include "core/subspace/design_session.h"
#include "core/subspace/evaluation.h"
#include "core/subspace/model_problem.h"
#include "core/subspace/problem.h"
#include "core/subspace/projection.h"
#include "core/subspace/reduced_system.h"
#include "core/subspace/spectrum.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tests/testing/fixtures.h"
#include "tests/testing/matchers.h"
#include "tests/testing/test_meshes.h"

namespace fieldspace {
namespace {

using ::fieldspace::testing::Icosphere;
using ::fieldspace::testing::MustBuildOperator;
using ::fieldspace::testing::RelativeDifference;
using ::fieldspace::testing::StatusIs;

class RealBasisTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    mesh_ = new TriangleMesh(Icosphere(4));  // 5120 faces on the unit sphere
    op_ = new FieldOperator(MustBuildOperator(*mesh_, FieldType::Vector()));
    BasisOptions options;
    options.params.dimension = 300;
    options.params.seed = 1;
    auto basis = BuildBasis(*mesh_, *op_, options);
    ASSERT_TRUE(basis.ok()) << basis.status();
    basis_ = new std::shared_ptr<const Basis>(std::make_shared<Basis>(*std::move(basis)));
    auto sys = ReducedSystem::Build(*basis_, *op_);
    ASSERT_TRUE(sys.ok()) << sys.status();
    system_ = new std::shared_ptr<const ReducedSystem>(*sys);
  }
  static void TearDownTestSuite() {
    delete system_;
    delete basis_;
    delete op_;
    delete mesh_;
  }
  static TriangleMesh* mesh_;
  static FieldOperator* op_;
  static std::shared_ptr<const Basis>* basis_;
  static std::shared_ptr<const ReducedSystem>* system_;
};

TriangleMesh* RealBasisTest::mesh_ = nullptr;
FieldOperator* RealBasisTest::op_ = nullptr;
std::shared_ptr<const Basis>* RealBasisTest::basis_ = nullptr;
std::shared_ptr<const ReducedSystem>* RealBasisTest::system_ = nullptr;

TEST_F(RealBasisTest, ReducedMatricesMatchSparseProducts) {
  const Eigen::SparseMatrix<double> U = (*basis_)->U.cast<double>();
  const Eigen::SparseMatrix<double> SU = op_->stiffness * U;
  const Eigen::SparseMatrix<double> Sr = U.transpose() * SU;
  const Eigen::SparseMatrix<double> Br =
      SU.transpose() * op_->mass.cwiseInverse().asDiagonal() * SU;
  const Eigen::SparseMatrix<double> Mr = U.transpose() * op_->mass.asDiagonal() * U;
  const ReducedSystem& sys = **system_;
  EXPECT_LT((Eigen::MatrixXd(Sr) - Eigen::MatrixXd(sys.stiffness())).norm() / Sr.norm(), 1e-12);
  EXPECT_LT((Eigen::MatrixXd(Br) - Eigen::MatrixXd(sys.bilaplacian())).norm() / Br.norm(), 1e-12);
  EXPECT_LT((Eigen::MatrixXd(Mr) - Eigen::MatrixXd(sys.mass_matrix())).norm() / Mr.norm(), 1e-12);
}

TEST_F(RealBasisTest, SmoothFieldsProjectWellAndExactSpanFieldsExactly) {
  EigenOptions eig;
  eig.count = 6;  // the l = 1 eigenspace of the unit sphere (eigenvalue 2, multiplicity 6)
  auto low = ReferenceEigenpairs(*op_, eig);
  ASSERT_TRUE(low.ok()) << low.status();
  auto p = ProjectMany(**system_, low->vectors);
  ASSERT_TRUE(p.ok());
  EXPECT_LT(p->relative_errors.maxCoeff(), 0.1);
  // A field in the span: recovered to the accuracy of double arithmetic.
  const Eigen::VectorXd x0 = Eigen::VectorXd::Random((*system_)->dimension());
  auto X = Lift(**basis_, x0);
  ASSERT_TRUE(X.ok());
  auto q = Project(**system_, *X);
  ASSERT_TRUE(q.ok());
  EXPECT_LT(q->relative_error, 1e-8);
  EXPECT_LT((q->coefficients - x0).norm() / x0.norm(), 1e-6);
}

TEST_F(RealBasisTest, TestFieldsAndSmoothingAreApproximated) {
  TestFieldOptions options;
  options.count = 4;
  options.min_constraints = 5;
  options.max_constraints = 10;
  auto fields = GenerateTestFields(*op_, options);
  ASSERT_TRUE(fields.ok()) << fields.status();
  auto p = ProjectMany(**system_, fields->fields);
  ASSERT_TRUE(p.ok());
  EXPECT_LT(p->relative_errors.mean(), 0.25);
  auto lambdas = SmoothingWeights(*op_, 2);
  ASSERT_TRUE(lambdas.ok());
  auto errors = SmoothingErrors(*op_, **system_, fields->fields, *lambdas);
  ASSERT_TRUE(errors.ok()) << errors.status();
  EXPECT_LT(errors->mean(), 0.25);
  EXPECT_GT(errors->minCoeff(), 0.0);
}

TEST_F(RealBasisTest, ReducedSpectrumBoundsTheFullOne) {
  EigenOptions eig;
  eig.count = 20;
  eig.compute_vectors = false;
  auto full = ReferenceEigenpairs(*op_, eig);
  ASSERT_TRUE(full.ok());
  ReducedEigenOptions options;
  options.count = 20;
  auto reduced = ReducedEigenpairs(**system_, options);
  ASSERT_TRUE(reduced.ok()) << reduced.status();
  for (int i = 0; i < 20; ++i) {
    EXPECT_GE(reduced->values[i], full->values[i] * (1 - 1e-9)) << i;
    EXPECT_LT(reduced->values[i], 2.0 * full->values[i]) << i;
  }
}

TEST_F(RealBasisTest, DesignSessionWithBiharmonicEnergyMatchesFreshSolves) {
  auto session = DesignSession::Create(*system_, {1.0, 0.01, 20.0});
  ASSERT_TRUE(session.ok()) << session.status();
  std::mt19937_64 rng(4);
  double worst = 0;
  for (int64_t id = 0; id < 30; ++id) {
    FieldConstraint c;
    c.face = static_cast<int32_t>(rng() % mesh_->num_faces());
    const double a = 0.001 * static_cast<double>(rng() % 6283);
    c.value = Eigen::Vector2d(std::cos(a), std::sin(a));
    c.kind = id % 3 == 0 ? ConstraintKind::kHard : ConstraintKind::kSoft;
    const absl::Status st = (*session)->AddConstraint(id, c);
    if (!st.ok()) {
      EXPECT_THAT(st, StatusIs(absl::StatusCode::kFailedPrecondition));
      continue;
    }
    if (id % 4 == 3 && (*session)->HasConstraint(id - 1)) {
      ASSERT_TRUE((*session)->RemoveConstraint(id - 1).ok());
    }
    auto fresh = SolveReducedModelProblem(**system_, (*session)->problem());
    ASSERT_TRUE(fresh.ok()) << fresh.status();
    worst = std::max(worst, RelativeDifference((*session)->coefficients(), fresh->coefficients));
  }
  EXPECT_LT(worst, 1e-6);
  ASSERT_TRUE((*session)->SetWeights({0.2, 0.05, 5.0}).ok());
  auto fresh = SolveReducedModelProblem(**system_, (*session)->problem());
  ASSERT_TRUE(fresh.ok());
  EXPECT_LT(RelativeDifference((*session)->coefficients(), fresh->coefficients), 1e-6);
}

}  // namespace
}  // namespace fieldspace
