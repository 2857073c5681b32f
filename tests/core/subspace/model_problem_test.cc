#include "core/subspace/model_problem.h"

#include <atomic>
#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include "Eigen/Dense"
#include "core/subspace/full_space_solver.h"
#include "core/subspace/kkt_solver.h"
#include "core/subspace/projection.h"
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
using ::fieldspace::testing::RelativeDifference;
using ::fieldspace::testing::StatusIs;
using ::fieldspace::testing::Torus;

// Random constraints on distinct faces.
ModelProblem RandomProblem(int32_t num_faces, int32_t p, int soft, int hard, uint64_t seed,
                           double mu_s, double mu_b, double mu_c) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  ModelProblem problem;
  problem.weights = {.mu_s = mu_s, .mu_b = mu_b, .mu_c = mu_c};
  std::vector<char> used(num_faces, 0);
  auto face = [&] {
    int32_t f;
    do {
      f = static_cast<int32_t>(rng() % num_faces);
    } while (used[f]);
    used[f] = 1;
    return f;
  };
  for (int i = 0; i < soft; ++i) {
    Eigen::VectorXd v(p);
    for (int c = 0; c < p; ++c) v[c] = u(rng);
    problem.constraints.push_back({face(), v, 0.5 + std::abs(u(rng))});
  }
  for (int i = 0; i < hard; ++i) {
    Eigen::VectorXd v(p);
    for (int c = 0; c < p; ++c) v[c] = u(rng);
    problem.constraints.push_back({face(), v, 1.0, ConstraintKind::kHard});
  }
  return problem;
}

// The reduced minimizer computed densely and independently: the KKT system
// [A G^T; G 0] [x; l] = [b; c] with A = U^T (mu_s S + mu_b B + mu_c C^T W C) U.
// With problem.biharmonic = kMixed the biharmonic block is K Mr^-1 K (K = U^T S U,
// Mr = U^T M U) instead of U^T B U.
Eigen::VectorXd DenseReducedSolution(const FieldOperator& op, const Basis& basis,
                                     const ModelProblem& problem) {
  const Eigen::MatrixXd U = DenseU(basis);
  const Eigen::MatrixXd S = Eigen::MatrixXd(op.stiffness);
  const Eigen::MatrixXd B = S * op.mass.cwiseInverse().asDiagonal() * S;
  const int p = op.type.dofs_per_face();
  const int64_t d = U.cols();
  const EnergyWeights& w = problem.weights;
  Eigen::MatrixXd A = U.transpose() * (w.mu_s * S) * U;
  if (problem.biharmonic == BiharmonicForm::kMixed) {
    const Eigen::MatrixXd K = U.transpose() * S * U;
    const Eigen::MatrixXd Mr = U.transpose() * op.mass.asDiagonal() * U;
    A += w.mu_b * K * Mr.llt().solve(K);
  } else {
    A += w.mu_b * U.transpose() * B * U;
  }
  Eigen::VectorXd b = Eigen::VectorXd::Zero(d);
  std::vector<FieldConstraint> hard;
  for (const FieldConstraint& c : problem.constraints) {
    if (c.hard()) {
      hard.push_back(c);
      continue;
    }
    const Eigen::MatrixXd Uf = U.middleRows(static_cast<int64_t>(c.face) * p, p);
    A += w.mu_c * c.weight * Uf.transpose() * Uf;
    b += w.mu_c * c.weight * Uf.transpose() * c.value;
  }
  const int64_t h = static_cast<int64_t>(hard.size()) * p;
  Eigen::MatrixXd K = Eigen::MatrixXd::Zero(d + h, d + h);
  Eigen::VectorXd rhs = Eigen::VectorXd::Zero(d + h);
  K.topLeftCorner(d, d) = A;
  rhs.head(d) = b;
  for (size_t i = 0; i < hard.size(); ++i) {
    const Eigen::MatrixXd Uf = U.middleRows(static_cast<int64_t>(hard[i].face) * p, p);
    K.block(d + i * p, 0, p, d) = Uf;
    K.block(0, d + i * p, d, p) = Uf.transpose();
    rhs.segment(d + i * p, p) = hard[i].value;
  }
  return K.fullPivLu().solve(rhs).head(d);
}

// Hard constraints hold exactly in the lifted field U x.
void ExpectHardConstraintsHold(const Basis& basis, const ModelProblem& problem,
                               const Eigen::VectorXd& x) {
  for (const FieldConstraint& c : problem.constraints) {
    if (!c.hard()) continue;
    auto values = LiftFaces(basis, x, std::vector<int32_t>{c.face});
    ASSERT_TRUE(values.ok());
    EXPECT_LT((*values - c.value).norm(), 1e-9);
  }
}

// U = I: the reduced problem is the full-space one, in both biharmonic forms (K Mr^-1 K =
// S M^-1 S = B when U = I, so the mixed form's conjugate gradients must reach the same field).
TEST(ModelProblemTest, IdentityBasisReproducesTheFullSpaceSolve) {
  const TriangleMesh mesh = Icosphere(2);
  for (const FieldType& type : {FieldType::Vector(), FieldType::Tensor()}) {
    const FieldOperator op = MustBuildOperator(mesh, type);
    auto sys = ReducedSystem::Build(IdentityBasis(type, op.dofs()), op);
    ASSERT_TRUE(sys.ok()) << sys.status();
    const int p = type.dofs_per_face();
    const std::vector<ModelProblem> problems = {
        RandomProblem(mesh.num_faces(), p, 6, 0, 1, 1.0, 0.0, 10.0),
        RandomProblem(mesh.num_faces(), p, 0, 7, 2, 0.0, 1.0, 1.0),
        RandomProblem(mesh.num_faces(), p, 5, 4, 3, 0.5, 0.02, 3.0)};
    for (ModelProblem problem : problems) {
      for (const BiharmonicForm form : {BiharmonicForm::kExact, BiharmonicForm::kMixed}) {
        problem.biharmonic = form;
        auto full = SolveModelProblem(op, problem);
        ASSERT_TRUE(full.ok()) << full.status();
        auto reduced = SolveReducedModelProblem(**sys, problem);
        ASSERT_TRUE(reduced.ok()) << reduced.status();
        EXPECT_LT(RelativeDifference(reduced->coefficients, *full), 1e-8) << type.ToString();
        if (form == BiharmonicForm::kMixed) {
          EXPECT_LE(reduced->backward_error, 1e-12);
        }
      }
    }
  }
}

TEST(ModelProblemTest, SingularEnergyOnTorusIsRegularizedAndRefinedToTheExactSolution) {
  // Genus 1: S has a 2-dimensional kernel (harmonic fields). With U = I and only mu_s, the
  // energy matrix is singular; the soft constraints make the problem well posed.
  const TriangleMesh mesh = Torus(16, 8);
  const FieldOperator op = MustBuildOperator(mesh, FieldType::Vector());
  auto sys = ReducedSystem::Build(IdentityBasis(FieldType::Vector(), op.dofs()), op);
  ASSERT_TRUE(sys.ok());
  const ModelProblem problem = RandomProblem(mesh.num_faces(), 2, 5, 1, 9, 1.0, 0.0, 2.0);
  auto full = SolveModelProblem(op, problem);
  ASSERT_TRUE(full.ok()) << full.status();
  auto reduced = SolveReducedModelProblem(**sys, problem);
  ASSERT_TRUE(reduced.ok()) << reduced.status();
  EXPECT_LT(RelativeDifference(reduced->coefficients, *full), 1e-6);
  EXPECT_LE(reduced->backward_error, 1e-12);
}

TEST(ModelProblemTest, RandomBasisMatchesDenseKkt) {
  const TriangleMesh mesh = Icosphere(2);
  int seed = 0;
  for (const FieldType& type : {FieldType::Vector(), FieldType::NField(3), FieldType::Tensor()}) {
    const FieldOperator op = MustBuildOperator(mesh, type);
    auto basis = RandomBasis(type, op.dofs(), 90, 30, 5 + seed);
    auto sys = ReducedSystem::Build(basis, op);
    ASSERT_TRUE(sys.ok());
    const int p = type.dofs_per_face();
    for (const ModelProblem& problem :
         {RandomProblem(mesh.num_faces(), p, 8, 0, ++seed, 1.0, 0.1, 5.0),
          RandomProblem(mesh.num_faces(), p, 3, 5, ++seed, 0.3, 0.0, 1.0),
          RandomProblem(mesh.num_faces(), p, 0, 6, ++seed, 0.0, 2.0, 1.0)}) {
      auto reduced = SolveReducedModelProblem(**sys, problem);
      ASSERT_TRUE(reduced.ok()) << reduced.status();
      const Eigen::VectorXd expected = DenseReducedSolution(op, *basis, problem);
      EXPECT_LT(RelativeDifference(reduced->coefficients, expected), 1e-8) << type.ToString();
      ExpectHardConstraintsHold(*basis, problem, reduced->coefficients);
    }
  }
}

TEST(ModelProblemTest, MixedBiharmonicMatchesDenseKktAndNeverExceedsTheExactForm) {
  const TriangleMesh mesh = Icosphere(2);
  int seed = 20;
  for (const FieldType& type : {FieldType::Vector(), FieldType::NField(4), FieldType::Tensor()}) {
    const FieldOperator op = MustBuildOperator(mesh, type);
    auto basis = RandomBasis(type, op.dofs(), 90, 30, 5 + seed);
    auto sys = ReducedSystem::Build(basis, op);
    ASSERT_TRUE(sys.ok());
    // x^T K Mr^-1 K x <= x^T U^T B U x for every x (the mixed form is the biharmonic energy of
    // the M-projection of M^-1 S U x onto span(U)), strictly for a generic x.
    const Eigen::MatrixXd K((*sys)->stiffness());
    const Eigen::MatrixXd Mr((*sys)->mass_matrix());
    const Eigen::MatrixXd Bl((*sys)->bilaplacian());
    const Eigen::MatrixXd mixed = K * Mr.llt().solve(K);
    std::mt19937_64 rng(seed);
    std::normal_distribution<double> normal;
    for (int trial = 0; trial < 5; ++trial) {
      Eigen::VectorXd x(K.cols());
      for (int64_t i = 0; i < x.size(); ++i) x[i] = normal(rng);
      const double exact_energy = x.dot(Bl * x);
      EXPECT_LT(x.dot(mixed * x), (1 - 1e-3) * exact_energy) << type.ToString();
      EXPECT_GT(x.dot(mixed * x), 0.0);
    }
    const int p = type.dofs_per_face();
    for (ModelProblem problem : {RandomProblem(mesh.num_faces(), p, 8, 0, ++seed, 1.0, 0.1, 5.0),
                                 RandomProblem(mesh.num_faces(), p, 3, 5, ++seed, 0.3, 0.5, 1.0),
                                 RandomProblem(mesh.num_faces(), p, 0, 6, ++seed, 0.0, 2.0, 1.0)}) {
      problem.biharmonic = BiharmonicForm::kMixed;
      auto reduced = SolveReducedModelProblem(**sys, problem);
      ASSERT_TRUE(reduced.ok()) << reduced.status();
      EXPECT_LE(reduced->backward_error, 1e-12);
      EXPECT_GT(reduced->refinement_steps, 0);  // conjugate gradient iterations
      const Eigen::VectorXd expected = DenseReducedSolution(op, *basis, problem);
      EXPECT_LT(RelativeDifference(reduced->coefficients, expected), 1e-8) << type.ToString();
      // Not the exact form's solution.
      ModelProblem exact = problem;
      exact.biharmonic = BiharmonicForm::kExact;
      EXPECT_GT(RelativeDifference(DenseReducedSolution(op, *basis, exact), expected), 1e-3);
      ExpectHardConstraintsHold(*basis, problem, reduced->coefficients);
    }
  }
}

// Soft constraints piled onto a few faces (each face 1-9 times, random weights and values), hard
// constraints on other faces and on one of the soft-constrained faces.
ModelProblem RepeatedFacesProblem(int32_t num_faces, int32_t p, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  ModelProblem problem;
  problem.weights = {.mu_s = 0.7, .mu_b = 0.05, .mu_c = 4.0};
  const auto value = [&] {
    Eigen::VectorXd v(p);
    for (int c = 0; c < p; ++c) v[c] = u(rng);
    return v;
  };
  for (int i = 0; i < 60; ++i) {
    const int32_t face = static_cast<int32_t>(rng() % 12) * 7;  // faces 0, 7, ..., 77
    problem.constraints.push_back({face, value(), 0.1 + 2 * std::abs(u(rng))});
  }
  for (const int32_t face : {3, 50, 7}) {
    problem.constraints.push_back({face, value(), 1.0, ConstraintKind::kHard});
  }
  return problem;
}

// The assembly sums the soft constraints per face first; the reference adds one term per
// constraint, as the solver did before, each with its own FaceStiffness call.
TEST(ModelProblemTest, AssemblyPerFaceEqualsOneTermPerConstraint) {
  const TriangleMesh mesh = Icosphere(2);
  int seed = 40;
  for (const FieldType& type : {FieldType::Vector(), FieldType::NField(3), FieldType::Tensor()}) {
    const FieldOperator op = MustBuildOperator(mesh, type);
    auto sys = ReducedSystem::Build(RandomBasis(type, op.dofs(), 90, 30, ++seed), op);
    ASSERT_TRUE(sys.ok()) << sys.status();
    const ReducedSystem& system = **sys;
    const int p = type.dofs_per_face();
    const int64_t d = system.dimension();
    for (const bool scale_free : {false, true}) {
      ModelProblem problem = RepeatedFacesProblem(mesh.num_faces(), p, ++seed);
      problem.scale_free = scale_free;
      const EnergyWeights w = EffectiveEnergyWeights(system, problem.weights, scale_free);
      const Eigen::SparseMatrix<double> energy =
          w.mu_s * system.stiffness() + w.mu_b * system.bilaplacian();
      double tau = 0;
      auto factor = FactorizeRegularized(system.pattern_symbolic(),
                                         ShiftKernelColumns(system, energy), {}, &tau);
      ASSERT_TRUE(factor.ok()) << factor.status();
      Eigen::MatrixXd A_ref(energy);
      Eigen::VectorXd b_ref = Eigen::VectorXd::Zero(d);
      for (const FieldConstraint& c : problem.constraints) {
        if (c.hard()) continue;
        const std::vector<SparseRow> rows = BasisRowsOfFace(system, c.face);
        double g = 1;
        if (scale_free) {
          auto stiffness = FaceStiffness(system, *factor, rows);
          ASSERT_TRUE(stiffness.ok()) << stiffness.status();
          g = *stiffness;
        }
        Eigen::MatrixXd Uf = Eigen::MatrixXd::Zero(p, d);
        for (int comp = 0; comp < p; ++comp) {
          for (size_t q = 0; q < rows[comp].cols.size(); ++q) {
            Uf(comp, rows[comp].cols[q]) = rows[comp].vals[q];
          }
        }
        A_ref += w.mu_c * c.weight / g * Uf.transpose() * Uf;
        b_ref += w.mu_c * c.weight / g * Uf.transpose() * c.value;
      }
      auto assembly = AssembleReducedModelProblem(system, problem);
      ASSERT_TRUE(assembly.ok()) << assembly.status();
      EXPECT_TRUE(system.pattern_symbolic()->SamePattern(assembly->A));
      const Eigen::MatrixXd A(assembly->A);
      const std::string what = type.ToString() + (scale_free ? " scale-free" : " raw");
      EXPECT_LT((A - A_ref).norm(), 1e-12 * A_ref.norm()) << what;
      EXPECT_LT((assembly->b - b_ref).norm(), 1e-12 * b_ref.norm()) << what;
      // The soft terms are there: the hard constraints alone would leave b = 0.
      EXPECT_GT((A - Eigen::MatrixXd(energy)).norm(), 1e-3 * A_ref.norm()) << what;
      EXPECT_GT(b_ref.norm(), 0) << what;
      if (!scale_free) {
        // The whole solve against the dense KKT system, one term per constraint.
        auto reduced = SolveReducedModelProblem(system, problem);
        ASSERT_TRUE(reduced.ok()) << reduced.status();
        EXPECT_LT(RelativeDifference(reduced->coefficients,
                                     DenseReducedSolution(op, system.basis(), problem)),
                  1e-8)
            << what;
        ExpectHardConstraintsHold(system.basis(), problem, reduced->coefficients);
      }
    }
  }
}

// A face where no basis field is nonzero: scale-free weights cannot be normalized there
// (FailedPrecondition naming the face, whichever batch of faces it falls in); raw weights can.
TEST(ModelProblemTest, ScaleFreeConstraintOnAFaceWithoutSupportIsFailedPrecondition) {
  const TriangleMesh mesh = Icosphere(2);
  const FieldOperator op = MustBuildOperator(mesh, FieldType::Vector());
  std::shared_ptr<Basis> basis = RandomBasis(FieldType::Vector(), op.dofs(), 90, 30, 7);
  constexpr int32_t kBare = 123;
  for (int64_t row = 2 * kBare; row < 2 * kBare + 2; ++row) {
    for (Eigen::SparseMatrix<float, Eigen::RowMajor>::InnerIterator it(basis->U, row); it; ++it) {
      it.valueRef() = 0;
    }
  }
  auto sys = ReducedSystem::Build(basis, op);
  ASSERT_TRUE(sys.ok()) << sys.status();
  ModelProblem problem = RepeatedFacesProblem(mesh.num_faces(), 2, 3);
  problem.constraints.push_back({kBare, Eigen::Vector2d(1, 0), 2.0});
  problem.scale_free = false;
  EXPECT_TRUE(SolveReducedModelProblem(**sys, problem).ok());
  problem.scale_free = true;
  const absl::Status status = SolveReducedModelProblem(**sys, problem).status();
  EXPECT_THAT(status, StatusIs(absl::StatusCode::kFailedPrecondition));
  EXPECT_THAT(std::string(status.message()), ::testing::HasSubstr("face 123"));
  problem.constraints.pop_back();
  EXPECT_TRUE(SolveReducedModelProblem(**sys, problem).ok());
}

TEST(ModelProblemTest, MixedBiharmonicStopsAtTheIterationLimit) {
  const TriangleMesh mesh = Icosphere(2);
  const FieldOperator op = MustBuildOperator(mesh, FieldType::Vector());
  auto sys = ReducedSystem::Build(RandomBasis(FieldType::Vector(), op.dofs(), 90, 30, 3), op);
  ASSERT_TRUE(sys.ok());
  ModelProblem problem = RandomProblem(mesh.num_faces(), 2, 4, 3, 8, 0.0, 1.0, 1.0);
  problem.biharmonic = BiharmonicForm::kMixed;
  ReducedSolveOptions options;
  options.max_iterations = 1;
  auto one = SolveReducedModelProblem(**sys, problem, options);
  ASSERT_TRUE(one.ok()) << one.status();
  EXPECT_EQ(one->refinement_steps, 1);
  EXPECT_GT(one->backward_error, 1e-12);
  options.max_iterations = 0;
  EXPECT_THAT(SolveReducedModelProblem(**sys, problem, options),
              StatusIs(absl::StatusCode::kInvalidArgument));
}

TEST(ModelProblemTest, InvalidProblems) {
  const TriangleMesh mesh = Icosphere(1);  // 80 faces
  const FieldOperator op = MustBuildOperator(mesh, FieldType::Vector());
  auto sys = ReducedSystem::Build(RandomBasis(FieldType::Vector(), op.dofs(), 20, 10, 1), op);
  ASSERT_TRUE(sys.ok());
  const ModelProblem good = RandomProblem(mesh.num_faces(), 2, 2, 1, 4, 1.0, 0.0, 1.0);
  ASSERT_TRUE(SolveReducedModelProblem(**sys, good).ok());
  const auto solve = [&](const ModelProblem& p) {
    return SolveReducedModelProblem(**sys, p).status();
  };
  ModelProblem p = good;
  p.weights.mu_s = -1;
  EXPECT_THAT(solve(p), StatusIs(absl::StatusCode::kInvalidArgument));
  p = good;
  p.weights.mu_b = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THAT(solve(p), StatusIs(absl::StatusCode::kInvalidArgument));
  p = good;
  p.weights.mu_s = 0;
  p.weights.mu_b = 0;
  EXPECT_THAT(solve(p), StatusIs(absl::StatusCode::kInvalidArgument));
  p = good;
  p.weights.mu_c = -2;
  EXPECT_THAT(solve(p), StatusIs(absl::StatusCode::kInvalidArgument));
  p = good;
  p.constraints[0].face = 80;  // soft
  EXPECT_THAT(solve(p), StatusIs(absl::StatusCode::kInvalidArgument));
  p = good;
  p.constraints[2].face = -3;  // hard
  EXPECT_THAT(solve(p), StatusIs(absl::StatusCode::kInvalidArgument));
  p = good;
  p.constraints[1].value = Eigen::VectorXd::Zero(3);
  EXPECT_THAT(solve(p), StatusIs(absl::StatusCode::kInvalidArgument));
  p = good;
  p.constraints[2].value[1] = std::numeric_limits<double>::infinity();
  EXPECT_THAT(solve(p), StatusIs(absl::StatusCode::kInvalidArgument));
  p = good;
  p.constraints[0].weight = 0;
  EXPECT_THAT(solve(p), StatusIs(absl::StatusCode::kInvalidArgument));
  ReducedSolveOptions bad_options;
  bad_options.dependence_tolerance = 0;
  EXPECT_THAT(SolveReducedModelProblem(**sys, good, bad_options),
              StatusIs(absl::StatusCode::kInvalidArgument));
  // The same face hard-constrained twice: dependent rows.
  p = good;
  p.constraints.push_back(p.constraints[2]);
  EXPECT_THAT(solve(p), StatusIs(absl::StatusCode::kFailedPrecondition));
  // More hard DOFs (2 x 11 = 22) than the dimension (20).
  p = RandomProblem(mesh.num_faces(), 2, 0, 11, 5, 1.0, 0.0, 1.0);
  EXPECT_THAT(solve(p), StatusIs(absl::StatusCode::kFailedPrecondition));
}

TEST(ModelProblemTest, CancelledSolveStopsWithCancelled) {
  const TriangleMesh mesh = Icosphere(2);
  const FieldOperator op = MustBuildOperator(mesh, FieldType::Vector());
  auto sys = ReducedSystem::Build(IdentityBasis(FieldType::Vector(), op.dofs()), op);
  ASSERT_TRUE(sys.ok());
  const ModelProblem problem = RandomProblem(mesh.num_faces(), 2, 5, 4, 3, 0.5, 0.02, 3.0);
  std::atomic<bool> cancel{true};
  ReducedSolveOptions options;
  options.cancel = &cancel;
  EXPECT_THAT(SolveReducedModelProblem(**sys, problem, options),
              StatusIs(absl::StatusCode::kCancelled));
  cancel = false;
  EXPECT_TRUE(SolveReducedModelProblem(**sys, problem, options).ok());
}

}  // namespace
}  // namespace fieldspace
