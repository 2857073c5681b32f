#include "core/subspace/projection.h"

#include <atomic>
#include <cmath>
#include <limits>
#include <memory>
#include <vector>

#include "Eigen/Dense"
#include "core/subspace/lift_plan.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tests/testing/fixtures.h"
#include "tests/testing/matchers.h"
#include "tests/testing/test_meshes.h"

namespace fieldspace {
namespace {

using ::fieldspace::testing::DenseU;
using ::fieldspace::testing::Icosphere;
using ::fieldspace::testing::MustBuildOperator;
using ::fieldspace::testing::RandomBasis;
using ::fieldspace::testing::StatusIs;

class ProjectionTest : public ::testing::Test {
 protected:
  void SetUp() override {
    mesh_ = std::make_unique<TriangleMesh>(Icosphere(2));
    op_ = MustBuildOperator(*mesh_, FieldType::Vector());
    basis_ = RandomBasis(FieldType::Vector(), op_.dofs(), 80, 25, 21);
    auto sys = ReducedSystem::Build(basis_, op_);
    ASSERT_TRUE(sys.ok()) << sys.status();
    sys_ = *sys;
  }
  std::unique_ptr<TriangleMesh> mesh_;
  FieldOperator op_;
  std::shared_ptr<Basis> basis_;
  std::shared_ptr<const ReducedSystem> sys_;
};

TEST_F(ProjectionTest, FieldsInTheSpanAreRecoveredExactly) {
  const Eigen::VectorXd x0 = Eigen::VectorXd::Random(80);
  auto X = Lift(*basis_, x0);
  ASSERT_TRUE(X.ok());
  EXPECT_LT(((*X) - DenseU(*basis_) * x0).norm() / X->norm(), 1e-14);
  auto p = Project(*sys_, *X);
  ASSERT_TRUE(p.ok()) << p.status();
  EXPECT_LT((p->coefficients - x0).norm() / x0.norm(), 1e-9);
  EXPECT_LT(p->relative_error, 1e-9);
  // lift(project(U x)) == U x.
  auto X2 = Lift(*basis_, p->coefficients);
  ASSERT_TRUE(X2.ok());
  EXPECT_LT((*X2 - *X).norm() / X->norm(), 1e-9);
}

TEST_F(ProjectionTest, ProjectionIsTheMassOrthogonalProjection) {
  const Eigen::VectorXd X = Eigen::VectorXd::Random(op_.dofs());
  auto p = Project(*sys_, X);
  ASSERT_TRUE(p.ok());
  const Eigen::MatrixXd U = DenseU(*basis_);
  const Eigen::VectorXd residual = X - U * p->coefficients;
  // Residual M-orthogonal to span(U) (normal equations of eq. 13).
  const Eigen::VectorXd normal = U.transpose() * op_.mass.asDiagonal() * residual;
  const Eigen::VectorXd scale = U.transpose() * op_.mass.asDiagonal() * X;
  EXPECT_LT(normal.norm() / scale.norm(), 1e-10);
  // The reported error is ||X - U x||_M / ||X||_M.
  const double expected =
      std::sqrt(residual.dot(op_.mass.asDiagonal() * residual) / X.dot(op_.mass.asDiagonal() * X));
  EXPECT_NEAR(p->relative_error, expected, 1e-12);
  EXPECT_GT(p->relative_error, 0.1);  // a random field is far from an 80-dim subspace
  // Idempotent: projecting the projection changes nothing.
  auto lifted = Lift(*basis_, p->coefficients);
  ASSERT_TRUE(lifted.ok());
  auto again = Project(*sys_, *lifted);
  ASSERT_TRUE(again.ok());
  EXPECT_LT((again->coefficients - p->coefficients).norm() / p->coefficients.norm(), 1e-9);
  EXPECT_LT(again->relative_error, 1e-9);
}

TEST_F(ProjectionTest, BatchMatchesSingle) {
  const Eigen::MatrixXd X = Eigen::MatrixXd::Random(op_.dofs(), 3);
  auto batch = ProjectMany(*sys_, X);
  ASSERT_TRUE(batch.ok());
  for (int c = 0; c < 3; ++c) {
    auto single = Project(*sys_, X.col(c));
    ASSERT_TRUE(single.ok());
    EXPECT_LT((single->coefficients - batch->coefficients.col(c)).norm(), 1e-12);
    EXPECT_NEAR(single->relative_error, batch->relative_errors[c], 1e-14);
  }
  auto zero = Project(*sys_, Eigen::VectorXd::Zero(op_.dofs()));
  ASSERT_TRUE(zero.ok());
  EXPECT_EQ(zero->relative_error, 0.0);
  EXPECT_EQ(zero->coefficients.norm(), 0.0);
}

TEST_F(ProjectionTest, LiftFacesMatchesLiftAll) {
  const Eigen::VectorXd x = Eigen::VectorXd::Random(80);
  auto all = Lift(*basis_, x);
  ASSERT_TRUE(all.ok());
  const std::vector<int32_t> faces = {7, 0, 319, 7, 100};
  auto some = LiftFaces(*basis_, x, faces);
  ASSERT_TRUE(some.ok());
  ASSERT_EQ(some->size(), 10);
  for (size_t t = 0; t < faces.size(); ++t) {
    EXPECT_EQ((*some)[2 * t], (*all)[2 * faces[t]]);
    EXPECT_EQ((*some)[2 * t + 1], (*all)[2 * faces[t] + 1]);
  }
  std::vector<double> buffer(op_.dofs());
  ASSERT_TRUE(LiftInto(*basis_, x, absl::MakeSpan(buffer)).ok());
  EXPECT_EQ(Eigen::Map<Eigen::VectorXd>(buffer.data(), buffer.size()), *all);
  // The system's lift plan gives bit-identical values (same summation order; the entries a row
  // lacks are exact zeros).
  auto planned = Lift(*sys_, x);
  ASSERT_TRUE(planned.ok());
  EXPECT_EQ(*planned, *all);
  auto planned_some = LiftFaces(*sys_, x, faces);
  ASSERT_TRUE(planned_some.ok());
  EXPECT_EQ(*planned_some, *some);
  // Narrowed to float in the lift's pass: each value is the double lift rounded to float.
  std::vector<float> narrow(op_.dofs());
  ASSERT_TRUE(LiftIntoFloat(*sys_, x, absl::MakeSpan(narrow)).ok());
  for (int64_t i = 0; i < op_.dofs(); ++i) {
    ASSERT_EQ(narrow[i], static_cast<float>((*all)[i])) << i;
  }
  // Coefficients whose field overflows float are refused, not sent as infinities.
  const absl::Status overflow = LiftIntoFloat(*sys_, x * 1e300, absl::MakeSpan(narrow));
  EXPECT_EQ(overflow.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(overflow.message(), kFloatOverflowMessage);
  EXPECT_EQ(LiftIntoFloat(*sys_, x, absl::MakeSpan(narrow.data(), 3)).code(),
            absl::StatusCode::kInvalidArgument);
}

TEST(LiftPlanTest, TensorRowsWithDifferentSupportsAndWideIndices) {
  // 3 DOFs per face whose rows have different column sets, and d > 65536 (32-bit indices).
  const int64_t faces = 50, k = 3 * faces, d = 70000;
  std::vector<Eigen::Triplet<float>> t;
  for (int64_t i = 0; i < k; ++i) {
    t.emplace_back(i, (i * 7919) % d, 1.0f + i);
    if (i % 3 != 1) t.emplace_back(i, d - 1 - i, -0.5f * i);
  }
  Basis basis;
  basis.type = FieldType::Tensor();
  basis.U.resize(k, d);
  basis.U.setFromTriplets(t.begin(), t.end());
  const LiftPlan plan = LiftPlan::Build(basis.U, 3);
  EXPECT_EQ(plan.num_faces(), faces);
  const Eigen::VectorXd x = Eigen::VectorXd::Random(d);
  std::vector<double> out(k);
  plan.LiftAll(x.data(), out.data());
  auto expected = Lift(basis, x);
  ASSERT_TRUE(expected.ok());
  EXPECT_EQ(Eigen::Map<Eigen::VectorXd>(out.data(), k), *expected);
}

// LiftPlan::StreamBuilder fed U's CSR arrays in pieces of `piece` elements (0: whole), as a
// basis file streams them.
LiftPlan StreamedPlan(const BasisMatrix& U, int32_t p, int64_t piece) {
  LiftPlan::StreamBuilder builder;
  const int64_t nnz = U.nonZeros();
  builder.Begin(U.rows(), U.cols(), p,
                std::vector<int32_t>(U.outerIndexPtr(), U.outerIndexPtr() + U.rows() + 1));
  const int64_t step = piece > 0 ? piece : std::max<int64_t>(1, nnz);
  for (int64_t q = 0; q < nnz; q += step) {
    builder.AddColumns(U.innerIndexPtr() + q, std::min(step, nnz - q));
  }
  for (int64_t q = 0; q < nnz; q += step) {
    builder.AddValues(U.valuePtr() + q, std::min(step, nnz - q));
  }
  absl::StatusOr<LiftPlan> plan = std::move(builder).Finish();
  EXPECT_TRUE(plan.ok()) << plan.status();
  return plan.ok() ? *std::move(plan) : LiftPlan();
}

// The same layout, entry for entry, and bit-identical lifts.
void ExpectSamePlan(const LiftPlan& a, const LiftPlan& b, int64_t d) {
  ASSERT_EQ(a.num_faces(), b.num_faces());
  ASSERT_EQ(a.dofs_per_face(), b.dofs_per_face());
  EXPECT_EQ(a.memory_bytes(), b.memory_bytes());
  const int32_t p = a.dofs_per_face();
  for (int64_t f = 0; f < a.num_faces(); ++f) {
    std::vector<std::pair<int, std::vector<float>>> ea, eb;
    a.ForEachEntry(f,
                   [&](int col, const float* v) { ea.emplace_back(col, std::vector(v, v + p)); });
    b.ForEachEntry(f,
                   [&](int col, const float* v) { eb.emplace_back(col, std::vector(v, v + p)); });
    ASSERT_EQ(ea, eb) << "face " << f;
  }
  const Eigen::VectorXd x = Eigen::VectorXd::Random(d);
  std::vector<double> la(a.num_faces() * p), lb(b.num_faces() * p);
  a.LiftAll(x.data(), la.data());
  b.LiftAll(x.data(), lb.data());
  EXPECT_EQ(la, lb);
}

// A daemon reads a stored basis straight into its LiftPlan: the plan equals Build's from U, for
// faces whose rows share their columns or not, empty rows and faces, 16- and 32-bit column
// indices, in whatever pieces the file's chunks cut the arrays.
TEST(LiftPlanTest, StreamedPlanEqualsThePlanOfU) {
  {  // A built basis (2 DOFs per face) and a random one.
    const TriangleMesh mesh = Icosphere(2);
    const FieldOperator op = MustBuildOperator(mesh, FieldType::Vector());
    BasisOptions options;
    options.params.dimension = 40;
    absl::StatusOr<Basis> basis = BuildBasis(mesh, op, options);
    ASSERT_TRUE(basis.ok()) << basis.status();
    const auto random = RandomBasis(FieldType::Vector(), op.dofs(), 30, 9, 7);
    for (const BasisMatrix* U : {&basis->U, &random->U}) {
      const LiftPlan built = LiftPlan::Build(*U, 2);
      for (int64_t piece : {int64_t{0}, int64_t{1}, int64_t{7}, int64_t{4096}}) {
        SCOPED_TRACE(piece);
        ExpectSamePlan(built, StreamedPlan(*U, 2, piece), U->cols());
      }
    }
  }
  for (const auto& [p, d] : {std::pair{1, 90}, std::pair{2, 300}, std::pair{3, 70000}}) {
    SCOPED_TRACE(::testing::Message() << p << " DOFs per face, d " << d);
    // Faces 0-1 and 17-19 without entries, rows of a face sharing their columns (f % 4 == 0),
    // overlapping (f % 4 == 1), disjoint (f % 4 == 2), one row empty (f % 4 == 3).
    const int64_t faces = 40, k = p * faces;
    std::vector<Eigen::Triplet<float>> t;
    for (int64_t f = 0; f < faces; ++f) {
      if (f < 2 || (f >= 17 && f < 20)) continue;
      for (int64_t c = 0; c < p; ++c) {
        if (f % 4 == 3 && c == p - 1 && p > 1) continue;
        for (int64_t j = 0; j < 5; ++j) {
          const int64_t col = f % 4 == 0   ? (f * 13 + j * 17) % d
                              : f % 4 == 1 ? (f * 13 + (j + c) * 17) % d
                              : f % 4 == 2 ? (f * 13 + j * 17 + c * 5 * 17) % d
                                           : (f * 11 + j * 19) % d;
          t.emplace_back(f * p + c, col, static_cast<float>(1 + f + 0.25 * j - 0.5 * c));
        }
      }
    }
    BasisMatrix U(k, d);
    U.setFromTriplets(t.begin(), t.end());
    U.makeCompressed();
    const LiftPlan built = LiftPlan::Build(U, p);
    for (int64_t piece : {int64_t{0}, int64_t{1}, int64_t{3}, int64_t{11}}) {
      SCOPED_TRACE(piece);
      ExpectSamePlan(built, StreamedPlan(U, p, piece), d);
    }
  }
  // An empty U: every face without entries.
  BasisMatrix empty(8, 5);
  empty.makeCompressed();
  ExpectSamePlan(LiftPlan::Build(empty, 2), StreamedPlan(empty, 2, 0), 5);
  // Missing values: refused, not a plan of zeros.
  const std::shared_ptr<Basis> random = RandomBasis(FieldType::Vector(), 40, 10, 3, 5);
  const BasisMatrix& U = random->U;
  LiftPlan::StreamBuilder partial;
  partial.Begin(U.rows(), U.cols(), 2,
                std::vector<int32_t>(U.outerIndexPtr(), U.outerIndexPtr() + U.rows() + 1));
  partial.AddColumns(U.innerIndexPtr(), U.nonZeros());
  partial.AddValues(U.valuePtr(), U.nonZeros() - 1);
  EXPECT_THAT(std::move(partial).Finish(), StatusIs(absl::StatusCode::kFailedPrecondition));
}

TEST_F(ProjectionTest, InvalidInputs) {
  const Eigen::VectorXd x = Eigen::VectorXd::Random(80);
  EXPECT_THAT(Lift(*basis_, Eigen::VectorXd::Zero(79)),
              StatusIs(absl::StatusCode::kInvalidArgument));
  Eigen::VectorXd nan_x = x;
  nan_x[4] = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THAT(Lift(*basis_, nan_x), StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(LiftFaces(*basis_, x, std::vector<int32_t>{320}),
              StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(LiftFaces(*basis_, x, std::vector<int32_t>{-1}),
              StatusIs(absl::StatusCode::kInvalidArgument));
  std::vector<double> small(5);
  EXPECT_THAT(LiftInto(*basis_, x, absl::MakeSpan(small)),
              StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(LiftFacesInto(*basis_, x, std::vector<int32_t>{1, 2}, absl::MakeSpan(small)),
              StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(Lift(*sys_, Eigen::VectorXd::Zero(81)), StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(Lift(*sys_, nan_x), StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(LiftFaces(*sys_, x, std::vector<int32_t>{320}),
              StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(LiftInto(*sys_, x, absl::MakeSpan(small)),
              StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(LiftFacesInto(*sys_, x, std::vector<int32_t>{1}, absl::MakeSpan(small)),
              StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(Project(*sys_, Eigen::VectorXd::Zero(op_.dofs() + 1)),
              StatusIs(absl::StatusCode::kInvalidArgument));
  Eigen::VectorXd nan_field = Eigen::VectorXd::Zero(op_.dofs());
  nan_field[9] = std::numeric_limits<double>::infinity();
  EXPECT_THAT(Project(*sys_, nan_field), StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(
      RelativeResiduals(*sys_, Eigen::MatrixXd::Zero(op_.dofs(), 2), Eigen::MatrixXd::Zero(80, 3))
          .status(),
      StatusIs(absl::StatusCode::kInvalidArgument));
}

TEST_F(ProjectionTest, CancelledProjectionStopsWithCancelled) {
  const Eigen::VectorXd X = Eigen::VectorXd::Random(op_.dofs());
  std::atomic<bool> cancel{true};
  EXPECT_THAT(Project(*sys_, X, &cancel), StatusIs(absl::StatusCode::kCancelled));
  EXPECT_THAT(RelativeResiduals(*sys_, X, Eigen::VectorXd::Zero(80), &cancel),
              StatusIs(absl::StatusCode::kCancelled));
  cancel = false;
  auto p = Project(*sys_, X, &cancel);
  ASSERT_TRUE(p.ok());
  EXPECT_EQ(p->coefficients, Project(*sys_, X)->coefficients);
}

}  // namespace
}  // namespace fieldspace
