// Kernel columns in the subspace (BasisOptions::kernel_columns): the reduced eigenproblem has the
// 2 g zero eigenvalues of the full space, a design whose constraints a harmonic field meets keeps
// that field at zero energy, and the option off gives the paper's basis unchanged.

#include <cmath>
#include <cstdio>
#include <memory>
#include <optional>
#include <vector>

#include "Eigen/Dense"
#include "core/basis/basis.h"
#include "core/mesh/shapes.h"
#include "core/operators/field_operator.h"
#include "core/operators/kernel_fields.h"
#include "core/operators/reference_solvers.h"
#include "core/subspace/design_session.h"
#include "core/subspace/model_problem.h"
#include "core/subspace/problem.h"
#include "core/subspace/projection.h"
#include "core/subspace/reduced_system.h"
#include "core/subspace/spectrum.h"
#include "gtest/gtest.h"
#include "tests/testing/fixtures.h"
#include "tests/testing/test_meshes.h"

namespace fieldspace {
namespace {

using ::fieldspace::testing::ColumnMajor;
using ::fieldspace::testing::MaxAbsDiff;
using ::fieldspace::testing::MustBuildOperator;
using ::fieldspace::testing::MustCreate;

std::shared_ptr<const Basis> Build(const TriangleMesh& mesh, const FieldOperator& op, int32_t d,
                                   bool kernel_columns, int32_t coarse = 0) {
  BasisOptions options;
  options.params.dimension = d;
  options.kernel_columns = kernel_columns;
  absl::StatusOr<Basis> basis = BuildTwoLevelBasis(mesh, op, options, coarse);
  EXPECT_TRUE(basis.ok()) << basis.status();
  if (!basis.ok()) return nullptr;
  return std::make_shared<const Basis>(*std::move(basis));
}

double LambdaRef(const FieldOperator& op) { return op.stiffness.diagonal().sum() / op.mass.sum(); }

class KernelColumnsTest : public ::testing::Test {
 protected:
  void SetUp() override {
    mesh_.emplace(MustCreate(MakeTorus(1.0, 0.4, 48, 24)));
    op_ = MustBuildOperator(*mesh_, FieldType::Vector());
    with_ = Build(*mesh_, op_, kDim, true);
    without_ = Build(*mesh_, op_, kDim, false);
    ASSERT_NE(with_, nullptr);
    ASSERT_NE(without_, nullptr);
  }

  static constexpr int32_t kDim = 120;
  std::optional<TriangleMesh> mesh_;
  FieldOperator op_;
  std::shared_ptr<const Basis> with_, without_;
};

TEST_F(KernelColumnsTest, OptionOffIsThePaperBasisAndOnAppendsTheHarmonicFields) {
  EXPECT_EQ(without_->kernel_columns, 0);
  EXPECT_EQ(without_->dimension(), kDim);
  ASSERT_EQ(with_->kernel_columns, 2);
  ASSERT_EQ(with_->dimension(), kDim + 2);
  EXPECT_EQ(with_->params.dimension, kDim + 2);
  EXPECT_EQ(with_->sample_faces, without_->sample_faces);
  // The local columns are bit for bit those of the paper's construction.
  const Eigen::SparseMatrix<double> U = ColumnMajor(*with_);
  const Eigen::SparseMatrix<double> local = U.leftCols(kDim);
  EXPECT_EQ(MaxAbsDiff(local, ColumnMajor(*without_)), 0.0);
  // The kernel columns: M-orthonormal and harmonic to float precision (U is stored as float).
  const Eigen::MatrixXd K = Eigen::MatrixXd(U.rightCols(2));
  const Eigen::MatrixXd gram = K.transpose() * op_.mass.asDiagonal() * K;
  EXPECT_LT((gram - Eigen::Matrix2d::Identity()).cwiseAbs().maxCoeff(), 1e-6);
  const Eigen::MatrixXd SK = op_.stiffness * K;
  for (int j = 0; j < 2; ++j) {
    EXPECT_LT(K.col(j).dot(SK.col(j)), 1e-10 * LambdaRef(op_)) << j;
  }
  for (int j = kDim; j < kDim + 2; ++j) EXPECT_EQ(with_->local_eigenvalues[j], 0.0);
}

TEST_F(KernelColumnsTest, ReducedMassStaysWellConditioned) {
  // The kernel columns are not orthogonalized against the local ones. The local span
  // approximates the harmonic fields well in the M-norm (not in energy), so the smallest
  // eigenvalue of U^T M U drops (about 10x here), but the condition number stays far from
  // anything a double-precision factorization would notice.
  auto smallest = [&](const Basis& b) {
    const Eigen::MatrixXd U = Eigen::MatrixXd(ColumnMajor(b));
    const Eigen::MatrixXd G = U.transpose() * op_.mass.asDiagonal() * U;
    Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(G);
    return std::pair{es.eigenvalues()[0], es.eigenvalues()[G.rows() - 1]};
  };
  const auto [min_with, max_with] = smallest(*with_);
  const auto [min_without, max_without] = smallest(*without_);
  std::printf("U^T M U eigenvalues: with kernel columns [%.3g, %.3g], without [%.3g, %.3g]\n",
              min_with, max_with, min_without, max_without);
  EXPECT_GT(min_with, 0.02 * min_without);
  EXPECT_LT(max_with, 2 * max_without);
  EXPECT_LT(max_with / min_with, 1e6);
}

TEST_F(KernelColumnsTest, ReducedSpectrumHasTheHarmonicZeros) {
  auto full = ReferenceEigenpairs(op_, [] {
    EigenOptions o;
    o.count = 6;
    o.compute_vectors = false;
    return o;
  }());
  ASSERT_TRUE(full.ok()) << full.status();
  ASSERT_LT(full->values[1], 1e-9 * LambdaRef(op_));
  const double first_nonzero = full->values[2];
  for (bool kernel : {true, false}) {
    auto system = ReducedSystem::Build(kernel ? with_ : without_, op_);
    ASSERT_TRUE(system.ok()) << system.status();
    ReducedEigenOptions eo;
    eo.count = 6;
    auto reduced = ReducedEigenpairs(**system, eo);
    ASSERT_TRUE(reduced.ok()) << reduced.status();
    std::printf("kernel columns %s: reduced %.3g %.3g %.3g, full %.3g %.3g %.3g\n",
                kernel ? "on" : "off", reduced->values[0], reduced->values[1], reduced->values[2],
                full->values[0], full->values[1], full->values[2]);
    if (kernel) {
      EXPECT_LT(std::abs(reduced->values[0]), 1e-8 * first_nonzero);
      EXPECT_LT(std::abs(reduced->values[1]), 1e-8 * first_nonzero);
      EXPECT_GE(reduced->values[2], first_nonzero * (1 - 1e-9));
    } else {
      // The paper's local fields vanish at their rims: no combination is harmonic.
      EXPECT_GT(reduced->values[0], 0.01 * first_nonzero);
    }
  }
}

TEST_F(KernelColumnsTest, DesignKeepsAHarmonicFieldAtZeroEnergy) {
  absl::StatusOr<Eigen::MatrixXd> H = ComputeKernelFields(*mesh_, op_);
  ASSERT_TRUE(H.ok()) << H.status();
  const Eigen::VectorXd h = H->col(0) + 0.5 * H->col(1);
  // Soft constraints that the harmonic field h meets, at a few faces; mu_S > 0, no biharmonic.
  ModelProblem problem;
  problem.weights = {1.0, 0.0, 1.0};
  for (int32_t f : {0, 311, 977, 1500, 2203}) {
    FieldConstraint c;
    c.face = f;
    c.value = h.segment<2>(2 * f);
    problem.constraints.push_back(c);
  }
  for (bool kernel : {true, false}) {
    auto system = ReducedSystem::Build(kernel ? with_ : without_, op_);
    ASSERT_TRUE(system.ok()) << system.status();
    auto solution = SolveReducedModelProblem(**system, problem);
    ASSERT_TRUE(solution.ok()) << solution.status();
    auto x = Lift(**system, solution->coefficients);
    ASSERT_TRUE(x.ok()) << x.status();
    const double energy = x->dot(op_.stiffness * *x) / LambdaRef(op_);
    const double misfit =
        std::sqrt((*x - h).cwiseAbs2().dot(op_.mass) / h.cwiseAbs2().dot(op_.mass));
    std::printf("kernel columns %s: energy / lambda_ref %.3g, relative L2 distance to h %.3g\n",
                kernel ? "on" : "off", energy, misfit);
    if (kernel) {
      // The minimizer is h itself: zero energy, zero constraint residual.
      EXPECT_LT(energy, 1e-10);
      EXPECT_LT(misfit, 1e-5);
    } else {
      EXPECT_GT(misfit, 0.1);
    }
  }
  // Hard constraints (which a Schur complement through the singular energy matrix would call
  // dependent, see ShiftKernelColumns) and hard and soft ones together.
  for (int variant = 0; variant < 2; ++variant) {
    ModelProblem hard = problem;
    for (size_t i = 0; i < hard.constraints.size(); ++i) {
      if (variant == 0 || i % 2 == 0) hard.constraints[i].kind = ConstraintKind::kHard;
    }
    auto system = ReducedSystem::Build(with_, op_);
    ASSERT_TRUE(system.ok()) << system.status();
    auto solution = SolveReducedModelProblem(**system, hard);
    ASSERT_TRUE(solution.ok()) << solution.status();
    auto x = Lift(**system, solution->coefficients);
    ASSERT_TRUE(x.ok()) << x.status();
    const double energy = x->dot(op_.stiffness * *x) / LambdaRef(op_);
    const double misfit =
        std::sqrt((*x - h).cwiseAbs2().dot(op_.mass) / h.cwiseAbs2().dot(op_.mass));
    EXPECT_LT(energy, 1e-10) << "variant " << variant;
    EXPECT_LT(misfit, 1e-5) << "variant " << variant;
    EXPECT_LT(solution->backward_error, 1e-12) << "variant " << variant;
  }
  // Without constraints the minimizer is 0 (the kernel direction no constraint controls gets 0).
  ModelProblem none;
  none.weights = problem.weights;
  auto system = ReducedSystem::Build(with_, op_);
  ASSERT_TRUE(system.ok());
  auto zero = SolveReducedModelProblem(**system, none);
  ASSERT_TRUE(zero.ok()) << zero.status();
  EXPECT_EQ(zero->coefficients.cwiseAbs().maxCoeff(), 0.0);
}

// A harmonic field has zero biharmonic energy too (S h = 0), in both reduced forms (K x = 0 for
// its coefficients): a purely biharmonic design through constraints h meets is h, also with the
// mixed form's conjugate gradients on the kernel-shifted factorization.
TEST_F(KernelColumnsTest, BiharmonicDesignKeepsAHarmonicFieldInBothForms) {
  absl::StatusOr<Eigen::MatrixXd> H = ComputeKernelFields(*mesh_, op_);
  ASSERT_TRUE(H.ok()) << H.status();
  const Eigen::VectorXd h = 0.3 * H->col(0) - H->col(1);
  auto system = ReducedSystem::Build(with_, op_);
  ASSERT_TRUE(system.ok()) << system.status();
  for (const BiharmonicForm form : {BiharmonicForm::kExact, BiharmonicForm::kMixed}) {
    for (int variant = 0; variant < 3; ++variant) {  // soft, hard, both
      ModelProblem problem;
      problem.weights = {0.0, 1.0, 1.0};
      problem.biharmonic = form;
      int i = 0;
      for (int32_t f : {5, 400, 1111, 1900, 2300}) {
        FieldConstraint c;
        c.face = f;
        c.value = h.segment<2>(2 * f);
        if (variant == 1 || (variant == 2 && i++ % 2 == 0)) c.kind = ConstraintKind::kHard;
        problem.constraints.push_back(c);
      }
      auto solution = SolveReducedModelProblem(**system, problem);
      ASSERT_TRUE(solution.ok()) << solution.status();
      auto x = Lift(**system, solution->coefficients);
      ASSERT_TRUE(x.ok()) << x.status();
      const double misfit =
          std::sqrt((*x - h).cwiseAbs2().dot(op_.mass) / h.cwiseAbs2().dot(op_.mass));
      const bool mixed = form == BiharmonicForm::kMixed;
      EXPECT_LT(misfit, 1e-5) << "mixed " << mixed << " variant " << variant;
      EXPECT_LT(solution->backward_error, 1e-12) << "mixed " << mixed << " variant " << variant;
    }
  }
}

// A design session on a basis with kernel columns gives the one-shot solve's answer after every
// edit: the kernel shift of the factorization is refined away on each solve, also between the
// periodic checks (before the fix, the second soft constraint's answer was off by 8e-6).
TEST_F(KernelColumnsTest, DesignSessionEqualsTheOneShotSolveAfterEveryEdit) {
  auto system = ReducedSystem::Build(with_, op_);
  ASSERT_TRUE(system.ok()) << system.status();
  DesignSessionOptions options;
  options.verify_interval = 16;  // the server's default
  auto session = DesignSession::Create(*system, EnergyWeights{1.0, 0.0, 1.0}, options);
  ASSERT_TRUE(session.ok()) << session.status();
  ModelProblem problem;
  problem.weights = {1.0, 0.0, 1.0};
  int64_t id = 0;
  for (int32_t f : {10, 200, 977, 1500}) {
    FieldConstraint c;
    c.face = f;
    c.value = Eigen::Vector2d(1.0, 0.1 * f / 100.0);
    c.weight = 1.0 + f % 3;
    ASSERT_TRUE((*session)->AddConstraint(id++, c).ok());
    problem.constraints.push_back(c);
    auto fresh = SolveReducedModelProblem(**system, problem);
    ASSERT_TRUE(fresh.ok()) << fresh.status();
    const double scale = fresh->coefficients.norm();
    EXPECT_LT(((*session)->coefficients() - fresh->coefficients).norm(), 1e-10 * scale)
        << "after constraint " << id;
  }
}

TEST(KernelColumnsBasisTest, TensorAndTwoLevelBases) {
  const TriangleMesh torus = MustCreate(MakeTorus(1.0, 0.4, 32, 16));
  const FieldOperator tensor = MustBuildOperator(torus, FieldType::Tensor());
  std::shared_ptr<const Basis> t = Build(torus, tensor, 60, true);
  ASSERT_NE(t, nullptr);
  EXPECT_EQ(t->kernel_columns, 1);  // c I
  EXPECT_EQ(t->dimension(), 61);
  const FieldOperator vector = MustBuildOperator(torus, FieldType::Vector());
  std::shared_ptr<const Basis> two = Build(torus, vector, 60, true, /*coarse=*/12);
  ASSERT_NE(two, nullptr);
  EXPECT_EQ(two->kernel_columns, 2);
  EXPECT_EQ(two->dimension(), 62);
  std::shared_ptr<const Basis> two_off = Build(torus, vector, 60, false, /*coarse=*/12);
  ASSERT_NE(two_off, nullptr);
  EXPECT_EQ(MaxAbsDiff(Eigen::SparseMatrix<double>(ColumnMajor(*two).leftCols(60)),
                       ColumnMajor(*two_off)),
            0.0);
  auto system = ReducedSystem::Build(two, vector);
  EXPECT_TRUE(system.ok()) << system.status();
  // A sphere has no harmonic fields: the option changes nothing.
  const TriangleMesh sphere = MustCreate(MakeIcosphere(3));
  const FieldOperator sv = MustBuildOperator(sphere, FieldType::Vector());
  std::shared_ptr<const Basis> s = Build(sphere, sv, 40, true);
  ASSERT_NE(s, nullptr);
  EXPECT_EQ(s->kernel_columns, 0);
  EXPECT_EQ(s->dimension(), 40);
}

}  // namespace
}  // namespace fieldspace
