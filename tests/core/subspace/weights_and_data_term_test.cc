// Scale-free weights (ModelProblem::scale_free, DesignSessionOptions::scale_free) and design
// sessions with a data term (DesignSessionOptions::data_term), checked against dense solves
// written here from U, S and M (docs/conventions.md, "Scale-free weights" and "Design sessions
// with a data term").

#include <cmath>
#include <memory>
#include <vector>

#include "Eigen/Dense"
#include "core/subspace/design_session.h"
#include "core/subspace/full_space_solver.h"
#include "core/subspace/model_problem.h"
#include "core/subspace/reduced_system.h"
#include "core/subspace/smoothing.h"
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
using ::fieldspace::testing::RandomVector;
using ::fieldspace::testing::StatusIs;
using ::fieldspace::testing::Torus;

// A reduced system on a random sparse basis, with the dense matrices of the reference solves.
struct Fixture {
  FieldOperator op;
  std::shared_ptr<const ReducedSystem> system;
  Eigen::MatrixXd U, S, B;  // U: k x d; S, B: full space
  double area = 0;

  Fixture(const TriangleMesh& mesh, const FieldType& type, int64_t d, uint64_t seed) {
    op = MustBuildOperator(mesh, type);
    auto basis = RandomBasis(type, op.dofs(), d, 30, seed);
    auto sys = ReducedSystem::Build(basis, op);
    EXPECT_TRUE(sys.ok()) << sys.status();
    system = *std::move(sys);
    U = DenseU(*basis);
    S = Eigen::MatrixXd(op.stiffness);
    B = S * op.mass.cwiseInverse().asDiagonal() * S;
    area = mesh.face_areas().sum();
  }
  int32_t p() const { return op.type.dofs_per_face(); }
  Eigen::MatrixXd Rows(int32_t face) const { return U.middleRows(int64_t{face} * p(), p()); }
  Eigen::MatrixXd Energy(double mu_s, double mu_b) const {
    return U.transpose() * (mu_s * S + mu_b * B) * U;
  }
};

// One soft constraint alone, with scale-free weights: along the stiffest direction of its
// face (the eigenvector of the smallest eigenvalue of G = U_f A^-1 U_f^T, computed densely here)
// it pulls exactly mu / (1 + mu) of the way, and at least that much along any direction.
TEST(ScaleFreeWeightsTest, OneSoftConstraintPullsItsFaceAtLeastMuOverOnePlusMu) {
  uint64_t seed = 11;
  for (const FieldType& type : {FieldType::Vector(), FieldType::NField(4), FieldType::Tensor()}) {
    Fixture f(Icosphere(2), type, 80, ++seed);
    const double mu_b = 0.01;
    const Eigen::MatrixXd A = f.Energy(1.0, mu_b * f.area);  // mu_b scaled by the total area
    for (int32_t face : {3, 77, 250}) {
      const Eigen::MatrixXd Uf = f.Rows(face);
      const Eigen::MatrixXd G = Uf * A.ldlt().solve(Uf.transpose());
      Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(G);
      const Eigen::VectorXd least = eig.eigenvectors().col(0);
      for (double mu : {1.0, 9.0}) {
        ModelProblem problem;
        problem.weights = {.mu_s = 1.0, .mu_b = mu_b, .mu_c = mu};
        problem.scale_free = true;
        // Exactly mu / (1 + mu) in the form the stiffness is measured in; the mixed form's
        // energy is never larger, so it pulls at least as far (checked below).
        problem.biharmonic = BiharmonicForm::kExact;
        problem.constraints.push_back({.face = face, .value = least});
        auto x = SolveReducedModelProblem(*f.system, problem);
        ASSERT_TRUE(x.ok()) << x.status();
        EXPECT_NEAR(least.dot(Uf * x->coefficients), mu / (1 + mu), 1e-8)
            << type.ToString() << " face " << face;
        const Eigen::VectorXd c = RandomVector(f.p(), face + 7 * static_cast<uint64_t>(mu));
        problem.constraints[0].value = c;
        auto y = SolveReducedModelProblem(*f.system, problem);
        ASSERT_TRUE(y.ok()) << y.status();
        EXPECT_GE(c.dot(Uf * y->coefficients) / c.squaredNorm(), mu / (1 + mu) - 1e-9);
        problem.biharmonic = BiharmonicForm::kMixed;
        auto mixed = SolveReducedModelProblem(*f.system, problem);
        ASSERT_TRUE(mixed.ok()) << mixed.status();
        EXPECT_GE(c.dot(Uf * mixed->coefficients) / c.squaredNorm(), mu / (1 + mu) - 1e-9);
        problem.biharmonic = BiharmonicForm::kExact;
        // Raw weights on this basis pull by a different amount (the normalization is not 1).
        problem.scale_free = false;
        problem.weights.mu_b = mu_b * f.area;
        problem.constraints[0].value = least;
        auto raw = SolveReducedModelProblem(*f.system, problem);
        ASSERT_TRUE(raw.ok()) << raw.status();
        EXPECT_GT(std::abs(least.dot(Uf * raw->coefficients) - mu / (1 + mu)), 1e-3);
      }
    }
  }
}

// The same scale-free weights give the same field on the mesh scaled by 10 (with the basis
// scaled accordingly: U / 10 keeps it M-orthonormal, the field values per coefficient shrink,
// and the same field has 10x the coefficients); raw weights with mu_b > 0 do not.
TEST(ScaleFreeWeightsTest, SameWeightsSameFieldOnAScaledMesh) {
  const TriangleMesh small = Torus(16, 8);
  const TriangleMesh large = Torus(16, 8, 10.0, 4.0);  // radii 10 and 4: the default x 10
  for (const FieldType& type : {FieldType::Vector(), FieldType::Tensor()}) {
    const FieldOperator op_small = MustBuildOperator(small, type);
    const FieldOperator op_large = MustBuildOperator(large, type);
    auto basis_small = RandomBasis(type, op_small.dofs(), 60, 25, 5);
    auto basis_large = std::make_shared<Basis>(*basis_small);
    basis_large->U *= 0.1f;
    auto sys_small = ReducedSystem::Build(basis_small, op_small);
    auto sys_large = ReducedSystem::Build(basis_large, op_large);
    ASSERT_TRUE(sys_small.ok() && sys_large.ok());
    ModelProblem problem;
    problem.weights = {.mu_s = 1.0, .mu_b = 0.05, .mu_c = 2.0};
    const int32_t p = type.dofs_per_face();
    for (int32_t face : {5, 100, 200}) {
      problem.constraints.push_back({.face = face, .value = RandomVector(p, face), .weight = 1.5});
    }
    problem.constraints.push_back(
        {.face = 150, .value = RandomVector(p, 9), .kind = ConstraintKind::kHard});
    for (bool scale_free : {true, false}) {
      problem.scale_free = scale_free;
      auto a = SolveReducedModelProblem(**sys_small, problem);
      auto b = SolveReducedModelProblem(**sys_large, problem);
      ASSERT_TRUE(a.ok() && b.ok());
      const double diff =
          (a->coefficients * 10.0 - b->coefficients).norm() / (10.0 * a->coefficients.norm());
      if (scale_free) {
        EXPECT_LT(diff, 1e-6) << type.ToString();
      } else {
        EXPECT_GT(diff, 1e-3) << type.ToString();
      }
    }
  }
}

// A session with scale-free weights equals the one-shot scale-free solve of its problem() after
// adds, moves, weight changes (which renormalize every soft constraint) and removals.
TEST(ScaleFreeWeightsTest, DesignSessionEqualsOneShotSolve) {
  Fixture f(Torus(16, 8), FieldType::Vector(), 60, 3);
  DesignSessionOptions options;
  options.scale_free = true;
  auto session = DesignSession::Create(f.system, {.mu_s = 1.0, .mu_b = 0.0, .mu_c = 1.0}, options);
  ASSERT_TRUE(session.ok()) << session.status();
  DesignSession& s = **session;
  const auto check = [&](const char* what) {
    ModelProblem problem = s.problem();
    EXPECT_TRUE(problem.scale_free);
    auto fresh = SolveReducedModelProblem(*f.system, problem);
    ASSERT_TRUE(fresh.ok()) << fresh.status();
    EXPECT_LT((s.coefficients() - fresh->coefficients).norm(),
              1e-9 * fresh->coefficients.norm() + 1e-14)
        << what;
  };
  ASSERT_TRUE(s.AddConstraint(1, {.face = 10, .value = Eigen::Vector2d(1, 0)}).ok());
  check("add");
  ASSERT_TRUE(s.AddConstraint(2, {.face = 90, .value = Eigen::Vector2d(0, 2), .weight = 3}).ok());
  check("second add");
  ASSERT_TRUE(s.AddConstraint(
                   3, {.face = 40, .value = Eigen::Vector2d(1, 1), .kind = ConstraintKind::kHard})
                  .ok());
  check("hard");
  ASSERT_TRUE(s.MoveConstraint(1, 200, Eigen::Vector2d(0.5, 0.5)).ok());
  check("move to another face");
  ASSERT_TRUE(s.SetWeights({.mu_s = 0.5, .mu_b = 0.2, .mu_c = 4.0}).ok());
  check("new mu_s, mu_b, mu_c");
  ASSERT_TRUE(s.RemoveConstraint(2).ok());
  check("remove");
}

TEST(ScaleFreeWeightsTest, FullSpaceSolverRefusesScaleFreeWeights) {
  const FieldOperator op = MustBuildOperator(Icosphere(1), FieldType::Vector());
  ModelProblem problem;
  problem.scale_free = true;
  problem.constraints.push_back({.face = 0, .value = Eigen::Vector2d(1, 0)});
  EXPECT_THAT(SolveModelProblem(op, problem).status(),
              StatusIs(absl::StatusCode::kInvalidArgument, ::testing::HasSubstr("subspace")));
}

// The data-term session's minimizer computed densely: with D = U^T W M U and r = U^T W M X0,
// minimize x^T (mu_s S^ + mu_b B^ + mu_a' D) x - 2 mu_a' r^T x + sum_soft mu_c w |U_f x - c|^2
// subject to the hard constraints (KKT), mu_a' = mu_a / A (scale-free) or mu_a (raw).
Eigen::VectorXd DenseDataTermSolution(const Fixture& f, const Eigen::VectorXd& X0,
                                      const Eigen::VectorXd& face_weights, const EnergyWeights& w,
                                      double mu_a,
                                      const std::vector<FieldConstraint>& constraints) {
  const int64_t d = f.U.cols();
  Eigen::VectorXd wm = f.op.mass;
  for (int64_t i = 0; i < wm.size(); ++i) wm[i] *= face_weights[i / f.p()];
  Eigen::MatrixXd A = f.Energy(w.mu_s, w.mu_b) + mu_a * f.U.transpose() * wm.asDiagonal() * f.U;
  Eigen::VectorXd b = mu_a * f.U.transpose() * wm.asDiagonal() * X0;
  std::vector<const FieldConstraint*> hard;
  for (const FieldConstraint& c : constraints) {
    if (c.hard()) {
      hard.push_back(&c);
      continue;
    }
    const Eigen::MatrixXd Uf = f.Rows(c.face);
    A += w.mu_c * c.weight * Uf.transpose() * Uf;
    b += w.mu_c * c.weight * Uf.transpose() * c.value;
  }
  const int64_t h = static_cast<int64_t>(hard.size()) * f.p();
  Eigen::MatrixXd K = Eigen::MatrixXd::Zero(d + h, d + h);
  Eigen::VectorXd rhs(d + h);
  K.topLeftCorner(d, d) = A;
  rhs.head(d) = b;
  for (size_t i = 0; i < hard.size(); ++i) {
    const Eigen::MatrixXd Uf = f.Rows(hard[i]->face);
    K.block(d + i * f.p(), 0, f.p(), d) = Uf;
    K.block(0, d + i * f.p(), d, f.p()) = Uf.transpose();
    rhs.segment(d + i * f.p(), f.p()) = hard[i]->value;
  }
  return K.fullPivLu().solve(rhs).head(d);
}

TEST(DataTermSessionTest, EqualsDenseSolutionThroughEditsAndWeightChanges) {
  uint64_t seed = 40;
  for (const FieldType& type : {FieldType::Vector(), FieldType::NField(2), FieldType::Tensor()}) {
    Fixture f(Torus(16, 8), type, 60, ++seed);
    const int32_t faces = f.system->num_faces();
    const Eigen::VectorXd X0 = RandomVector(f.op.dofs(), ++seed);
    Eigen::VectorXd face_weights = RandomVector(faces, ++seed).cwiseAbs();
    auto smoother = ReducedSmoother::Create(
        f.system, X0, absl::MakeConstSpan(face_weights.data(), face_weights.size()));
    ASSERT_TRUE(smoother.ok()) << smoother.status();
    DesignSessionOptions options;
    options.data_term = std::make_shared<const ReducedSmoother>(*std::move(smoother));
    options.energy_cache = std::make_shared<EnergyFactorCache>();
    // The reference below is the exact form's (the mixed one: mixed_energy_test).
    options.biharmonic = BiharmonicForm::kExact;
    EnergyWeights w{.mu_s = 0.01, .mu_b = 0.001, .mu_c = 5.0, .mu_a = 2.0};
    auto session = DesignSession::Create(f.system, w, options);
    ASSERT_TRUE(session.ok()) << session.status();
    DesignSession& s = **session;
    std::vector<FieldConstraint> constraints;
    const auto check = [&](const char* what) {
      const Eigen::VectorXd expected =
          DenseDataTermSolution(f, X0, face_weights, s.weights(), s.weights().mu_a, constraints);
      EXPECT_LT((s.coefficients() - expected).norm(), 1e-8 * expected.norm())
          << type.ToString() << ": " << what;
    };
    check("open: the smoothed field");
    // Without constraints the session is Smooth with mu_c = mu_a.
    auto smoothed = options.data_term->Solve({.mu_s = 0.01, .mu_b = 0.001, .mu_c = 2.0});
    ASSERT_TRUE(smoothed.ok());
    EXPECT_LT((s.coefficients() - smoothed->coefficients).norm(),
              1e-9 * smoothed->coefficients.norm());
    const int32_t p = f.p();
    constraints.push_back({.face = 7, .value = RandomVector(p, 1), .weight = 2.0});
    ASSERT_TRUE(s.AddConstraint(0, constraints.back()).ok());
    check("soft add");
    constraints.push_back(
        {.face = 120, .value = RandomVector(p, 2), .kind = ConstraintKind::kHard});
    ASSERT_TRUE(s.AddConstraint(1, constraints.back()).ok());
    check("hard add");
    EXPECT_LT((f.Rows(120) * s.coefficients() - constraints.back().value).norm(), 1e-9);
    ASSERT_TRUE(s.SetWeights({.mu_s = 0.01, .mu_b = 0.001, .mu_c = 5.0, .mu_a = 0.5}).ok());
    EXPECT_TRUE(s.last_factorized());  // mu_a is in the energy matrix
    check("new mu_a");
    ASSERT_TRUE(s.SetWeights({.mu_s = 0.01, .mu_b = 0.001, .mu_c = 1.0, .mu_a = 0.5}).ok());
    EXPECT_FALSE(s.last_factorized());  // mu_c is not
    check("new mu_c");
    constraints[0].face = 33;
    ASSERT_TRUE(s.MoveConstraint(0, 33, constraints[0].value).ok());
    check("move");
    s.ClearConstraints();
    constraints.clear();
    check("cleared: the smoothed field again");
  }
}

TEST(DataTermSessionTest, ScaleFreeDataWeightIsDividedByTheArea) {
  Fixture f(Icosphere(2, 3.0), FieldType::Vector(), 50, 8);
  const Eigen::VectorXd X0 = RandomVector(f.op.dofs(), 4);
  auto smoother = ReducedSmoother::Create(f.system, X0);
  ASSERT_TRUE(smoother.ok());
  DesignSessionOptions options;
  options.scale_free = true;
  options.data_term = std::make_shared<const ReducedSmoother>(*std::move(smoother));
  const EnergyWeights w{.mu_s = 0.001, .mu_b = 0.0, .mu_c = 1.0, .mu_a = 1.0};
  auto session = DesignSession::Create(f.system, w, options);
  ASSERT_TRUE(session.ok()) << session.status();
  const Eigen::VectorXd expected = DenseDataTermSolution(
      f, X0, Eigen::VectorXd::Ones(f.system->num_faces()), w, 1.0 / f.area, {});
  EXPECT_LT(((*session)->coefficients() - expected).norm(), 1e-8 * expected.norm());
  // And equals the scale-free Smooth of the same field and weights.
  SmoothingOptions smoothing;
  smoothing.scale_free = true;
  auto smoothed =
      SmoothReduced(*f.system, X0, {.mu_s = 0.001, .mu_b = 0.0, .mu_c = 1.0}, {}, smoothing);
  ASSERT_TRUE(smoothed.ok());
  EXPECT_LT(((*session)->coefficients() - smoothed->coefficients).norm(),
            1e-9 * smoothed->coefficients.norm());
}

TEST(DataTermSessionTest, DataWeightWithoutADataTermIsRefused) {
  Fixture f(Icosphere(1), FieldType::Vector(), 20, 2);
  const EnergyWeights w{.mu_s = 1.0, .mu_b = 0.0, .mu_c = 1.0, .mu_a = 1.0};
  EXPECT_THAT(DesignSession::Create(f.system, w).status(),
              StatusIs(absl::StatusCode::kInvalidArgument, ::testing::HasSubstr("mu_a")));
  ModelProblem problem;
  problem.weights = w;
  EXPECT_THAT(SolveReducedModelProblem(*f.system, problem).status(),
              StatusIs(absl::StatusCode::kInvalidArgument, ::testing::HasSubstr("mu_a")));
  auto session = DesignSession::Create(f.system, {.mu_s = 1.0, .mu_b = 0.0, .mu_c = 1.0});
  ASSERT_TRUE(session.ok());
  EXPECT_THAT((*session)->SetWeights(w), StatusIs(absl::StatusCode::kInvalidArgument));
  // A data term of another system.
  Fixture other(Icosphere(1), FieldType::Vector(), 20, 3);
  auto smoother = ReducedSmoother::Create(other.system, Eigen::VectorXd::Ones(other.op.dofs()));
  ASSERT_TRUE(smoother.ok());
  DesignSessionOptions options;
  options.data_term = std::make_shared<const ReducedSmoother>(*std::move(smoother));
  EXPECT_THAT(DesignSession::Create(f.system, w, options).status(),
              StatusIs(absl::StatusCode::kInvalidArgument, ::testing::HasSubstr("another")));
}

}  // namespace
}  // namespace fieldspace
