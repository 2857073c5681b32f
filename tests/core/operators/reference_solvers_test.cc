#include "core/operators/reference_solvers.h"

#include <algorithm>
#include <cmath>
#include <optional>
#include <ostream>
#include <random>
#include <utility>
#include <vector>

#include "core/mesh/shapes.h"
#include "core/subspace/full_space_solver.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tests/testing/fixtures.h"
#include "tests/testing/matchers.h"
#include "tests/testing/test_meshes.h"

namespace fieldspace {

// Readable parameter names in test listings.
void PrintTo(const FieldType& type, std::ostream* os) { *os << type.ToString(); }

namespace {

FieldConstraint Hard(int32_t face, Eigen::VectorXd value) {
  return {face, std::move(value), 1.0, ConstraintKind::kHard};
}

using ::fieldspace::testing::StatusIs;
using SpMat = Eigen::SparseMatrix<double>;
using ::fieldspace::testing::MaxAbs;
using ::fieldspace::testing::MaxAbsDiff;
using ::fieldspace::testing::MustCreate;
using ::testing::HasSubstr;

class ReferenceSolversTest : public ::testing::TestWithParam<FieldType> {
 protected:
  void SetUp() override {
    mesh_.emplace(MustCreate(MakeTorus(2.0, 0.7, 32, 16)));
    auto op = BuildFieldOperator(*mesh_, GetParam());
    ASSERT_TRUE(op.ok()) << op.status();
    op_ = *std::move(op);
  }

  Eigen::VectorXd RandomValue(std::mt19937& rng) const {
    std::normal_distribution<double> g;
    Eigen::VectorXd v(GetParam().dofs_per_face());
    for (int i = 0; i < v.size(); ++i) v[i] = g(rng);
    return v;
  }

  // Gradient / 2 of the model energy computed with matrix-vector products only (no B, no C):
  // mu_s S X + mu_b S M^-1 S X + mu_c sum_j w_j (X_fj - c_j) on the constrained faces.
  Eigen::VectorXd HalfGradient(const ModelProblem& p, const Eigen::VectorXd& X) const {
    const Eigen::VectorXd SX = op_.stiffness * X;
    const EnergyWeights& w = p.weights;
    Eigen::VectorXd g = w.mu_s * SX + w.mu_b * (op_.stiffness * SX.cwiseQuotient(op_.mass));
    const int d = GetParam().dofs_per_face();
    for (const FieldConstraint& c : p.constraints) {
      if (c.hard()) continue;
      g.segment(d * c.face, d) += w.mu_c * c.weight * (X.segment(d * c.face, d) - c.value);
    }
    return g;
  }

  std::optional<TriangleMesh> mesh_;
  FieldOperator op_;
};

TEST_P(ReferenceSolversTest, SoftConstraintsGiveZeroGradient) {
  std::mt19937 rng(7);
  ModelProblem p;
  p.weights.mu_s = 0.5;
  p.weights.mu_b = 0.02;
  p.weights.mu_c = 10.0;
  std::uniform_int_distribution<int> face(0, mesh_->num_faces() - 1);
  for (int i = 0; i < 30; ++i)
    p.constraints.push_back({face(rng), RandomValue(rng), 0.5 + i * 0.1});
  auto X = SolveModelProblem(op_, p);
  ASSERT_TRUE(X.ok()) << X.status();
  const Eigen::VectorXd g = HalfGradient(p, *X);
  const Eigen::VectorXd rhs = HalfGradient(p, Eigen::VectorXd::Zero(op_.dofs()));
  EXPECT_LT(g.norm(), 1e-9 * rhs.norm());
  // The system assembled for eq. 9 agrees with the matrix-free gradient.
  auto system = AssembleModelSystem(op_, p);
  ASSERT_TRUE(system.ok());
  EXPECT_LT((system->A * *X - system->b - g).norm(), 1e-9 * rhs.norm());
}

TEST_P(ReferenceSolversTest, BiharmonicInterpolationHitsHardConstraintsExactly) {
  // The test-field recipe (section 6): minimize X^T B X with 20 random faces fixed.
  std::mt19937 rng(11);
  ModelProblem p;
  p.weights = {.mu_s = 0.0, .mu_b = 1.0, .mu_c = 0.0};
  std::vector<int> faces(mesh_->num_faces());
  for (int i = 0; i < mesh_->num_faces(); ++i) faces[i] = i;
  std::shuffle(faces.begin(), faces.end(), rng);
  for (int i = 0; i < 20; ++i) p.constraints.push_back(Hard(faces[i], RandomValue(rng)));
  auto X = SolveModelProblem(op_, p);
  ASSERT_TRUE(X.ok()) << X.status();
  const int d = GetParam().dofs_per_face();
  std::vector<bool> fixed(op_.dofs(), false);
  for (const FieldConstraint& c : p.constraints) {
    EXPECT_EQ(X->segment(d * c.face, d), c.value);  // bitwise
    for (int i = 0; i < d; ++i) fixed[d * c.face + i] = true;
  }
  // Optimality: the gradient vanishes on the free DOFs (it is a Lagrange multiplier elsewhere).
  const Eigen::VectorXd g = HalfGradient(p, *X);
  double free_norm = 0, fixed_norm = 0;
  for (int i = 0; i < op_.dofs(); ++i) (fixed[i] ? fixed_norm : free_norm) += g[i] * g[i];
  EXPECT_LT(std::sqrt(free_norm), 1e-8 * std::sqrt(fixed_norm));
  EXPECT_GT(X->norm(), 0.0);
}

TEST_P(ReferenceSolversTest, MixedHardAndSoftConstraints) {
  std::mt19937 rng(13);
  ModelProblem p;
  p.weights.mu_s = 1.0;
  p.weights.mu_b = 0.1;
  p.weights.mu_c = 3.0;
  p.constraints.push_back(Hard(4, RandomValue(rng)));
  p.constraints.push_back(Hard(100, RandomValue(rng)));
  p.constraints.push_back({4, RandomValue(rng), 2.0});  // also hard: irrelevant but allowed
  p.constraints.push_back({300, RandomValue(rng), 1.0});
  auto X = SolveModelProblem(op_, p);
  ASSERT_TRUE(X.ok()) << X.status();
  const int d = GetParam().dofs_per_face();
  EXPECT_EQ(X->segment(d * 100, d), p.constraints[1].value);
  const Eigen::VectorXd g = HalfGradient(p, *X);
  for (int i = 0; i < op_.dofs(); ++i) {
    if (i / d == 4 || i / d == 100) continue;
    EXPECT_NEAR(g[i], 0.0, 1e-9 * g.cwiseAbs().maxCoeff()) << i;
  }
}

TEST_P(ReferenceSolversTest, SmoothingSolvesMassPlusLambdaS) {
  std::mt19937 rng(17);
  std::normal_distribution<double> n;
  Eigen::VectorXd field(op_.dofs());
  for (int i = 0; i < field.size(); ++i) field[i] = n(rng);
  auto X = SmoothField(op_, field, 0.3);
  ASSERT_TRUE(X.ok()) << X.status();
  const Eigen::VectorXd residual =
      op_.mass.cwiseProduct(*X) + 0.3 * (op_.stiffness * *X) - op_.mass.cwiseProduct(field);
  EXPECT_LT(residual.norm(), 1e-10 * op_.mass.cwiseProduct(field).norm());
  // Smoothing lowers the Dirichlet energy.
  EXPECT_LT(X->dot(op_.stiffness * *X), field.dot(op_.stiffness * field));
  auto same = SmoothField(op_, field, 0.0);
  ASSERT_TRUE(same.ok());
  EXPECT_EQ(*same, field);
}

TEST_P(ReferenceSolversTest, BiharmonicMatrixIsSMinvS) {
  const SpMat B = BiharmonicMatrix(op_);
  std::mt19937 rng(19);
  std::normal_distribution<double> n;
  Eigen::VectorXd x(op_.dofs());
  for (int i = 0; i < x.size(); ++i) x[i] = n(rng);
  const Eigen::VectorXd expected = op_.stiffness * (op_.stiffness * x).cwiseQuotient(op_.mass);
  EXPECT_LT((B * x - expected).norm(), 1e-12 * expected.norm());
  EXPECT_EQ(MaxAbsDiff(B, SpMat(B.transpose())), 0.0);
}

TEST_P(ReferenceSolversTest, ReferenceEigenpairsAreMOrthonormal) {
  EigenOptions options;
  options.count = 6;
  auto r = ReferenceEigenpairs(op_, options);
  ASSERT_TRUE(r.ok()) << r.status();
  const Eigen::MatrixXd gram = r->vectors.transpose() * op_.mass.asDiagonal() * r->vectors;
  EXPECT_LT((gram - Eigen::MatrixXd::Identity(6, 6)).cwiseAbs().maxCoeff(), 1e-8);
  for (int i = 0; i < 6; ++i) {
    const Eigen::VectorXd res =
        op_.stiffness * r->vectors.col(i) - r->values[i] * op_.mass.cwiseProduct(r->vectors.col(i));
    EXPECT_LT(res.norm(),
              1e-7 * (1 + r->values[i]) * op_.mass.cwiseProduct(r->vectors.col(i)).norm());
  }
}

TEST_P(ReferenceSolversTest, ErrorsHaveExactCodes) {
  const int d = GetParam().dofs_per_face();
  const Eigen::VectorXd v = Eigen::VectorXd::Ones(d);
  auto status_of = [&](const ModelProblem& p) { return SolveModelProblem(op_, p).status(); };
  ModelProblem p;
  p.weights.mu_s = -1;
  EXPECT_THAT(status_of(p), StatusIs(absl::StatusCode::kInvalidArgument));
  p = {};
  p.weights.mu_b = std::nan("");
  EXPECT_THAT(status_of(p), StatusIs(absl::StatusCode::kInvalidArgument));
  p = {};
  p.weights.mu_s = 1;
  p.constraints.push_back({mesh_->num_faces(), v, 1.0});
  EXPECT_THAT(status_of(p), StatusIs(absl::StatusCode::kInvalidArgument));
  p.constraints = {{0, Eigen::VectorXd::Ones(d + 1), 1.0}};
  EXPECT_THAT(status_of(p), StatusIs(absl::StatusCode::kInvalidArgument));
  p.constraints = {{0, v, 0.0}};
  EXPECT_THAT(status_of(p), StatusIs(absl::StatusCode::kInvalidArgument));
  p.constraints = {{0, v * std::nan(""), 1.0}};
  EXPECT_THAT(status_of(p), StatusIs(absl::StatusCode::kInvalidArgument));
  p.constraints = {Hard(3, v), Hard(3, v)};
  auto dup = SolveModelProblem(op_, p);
  EXPECT_THAT(dup, StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(dup.status().message(), HasSubstr("face 3"));
  p.constraints = {Hard(-1, v)};
  EXPECT_THAT(status_of(p), StatusIs(absl::StatusCode::kInvalidArgument));
  // No energy at all (A = 0 would be singular): refused by ValidateWeights, naming the weights.
  p = {};
  p.weights = {.mu_s = 0, .mu_b = 0, .mu_c = 0};
  EXPECT_THAT(status_of(p),
              StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr("mu_s and mu_b")));

  EXPECT_THAT(SmoothField(op_, Eigen::VectorXd::Zero(op_.dofs()), -1),
              StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(SmoothField(op_, Eigen::VectorXd::Zero(op_.dofs() - 1), 1),
              StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(SmoothField(op_, Eigen::VectorXd::Constant(op_.dofs(), std::nan("")), 1),
              StatusIs(absl::StatusCode::kInvalidArgument));
  FieldOperator broken = op_;
  broken.mass.resize(3);
  EXPECT_THAT(ReferenceEigenpairs(broken), StatusIs(absl::StatusCode::kInvalidArgument));
}

INSTANTIATE_TEST_SUITE_P(AllTypes, ReferenceSolversTest,
                         ::testing::Values(FieldType::Vector(), FieldType::NField(4),
                                           FieldType::Tensor()),
                         [](const ::testing::TestParamInfo<FieldType>& info) {
                           return info.param.ToString();
                         });

}  // namespace
}  // namespace fieldspace
