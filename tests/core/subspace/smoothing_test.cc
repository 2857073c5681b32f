#include "core/subspace/smoothing.h"

#include <atomic>
#include <cmath>
#include <limits>
#include <memory>
#include <random>
#include <vector>

#include "Eigen/Dense"
#include "core/operators/reference_solvers.h"
#include "core/subspace/problem.h"
#include "core/subspace/projection.h"
#include "core/subspace/reduced_system.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tests/testing/fixtures.h"
#include "tests/testing/matchers.h"
#include "tests/testing/test_meshes.h"

namespace fieldspace {
namespace {

using ::fieldspace::testing::Arrays;
using ::fieldspace::testing::DenseU;
using ::fieldspace::testing::DisjointUnion;
using ::fieldspace::testing::Icosphere;
using ::fieldspace::testing::IdentityBasis;
using ::fieldspace::testing::MaxAbs;
using ::fieldspace::testing::MaxAbsDiff;
using ::fieldspace::testing::MustBuildOperator;
using ::fieldspace::testing::MustCreate;
using ::fieldspace::testing::RandomBasis;
using ::fieldspace::testing::RelativeDifference;
using ::fieldspace::testing::StatusIs;
using ::fieldspace::testing::Torus;

Eigen::VectorXd RandomVector(int64_t n, uint64_t seed, double lo = -1.0, double hi = 1.0) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(lo, hi);
  Eigen::VectorXd v(n);
  for (int64_t i = 0; i < n; ++i) v[i] = u(rng);
  return v;
}

// Per-face weights in [0, 2] with about every fifth face 0.
std::vector<double> RandomFaceWeights(int32_t faces, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0.0, 2.0);
  std::vector<double> w(faces);
  for (double& x : w) x = (rng() % 5 == 0) ? 0.0 : u(rng);
  return w;
}

// The reduced minimizer computed densely and independently from U, S and M:
// (U^T (mu_s S + mu_b S M^-1 S + mu_c W M) U) x = mu_c U^T W M X0.
Eigen::VectorXd DenseSmoothing(const FieldOperator& op, const Basis& basis,
                               const Eigen::VectorXd& field, const EnergyWeights& w,
                               const std::vector<double>& face_weights) {
  const Eigen::MatrixXd U = DenseU(basis);
  const Eigen::MatrixXd S = Eigen::MatrixXd(op.stiffness);
  const Eigen::MatrixXd B = S * op.mass.cwiseInverse().asDiagonal() * S;
  const int p = op.type.dofs_per_face();
  Eigen::VectorXd wm = op.mass;
  if (!face_weights.empty()) {
    for (int64_t i = 0; i < wm.size(); ++i) wm[i] *= face_weights[i / p];
  }
  const Eigen::MatrixXd A =
      U.transpose() * (w.mu_s * S + w.mu_b * B) * U + w.mu_c * U.transpose() * wm.asDiagonal() * U;
  const Eigen::VectorXd b = w.mu_c * U.transpose() * wm.asDiagonal() * field;
  return A.ldlt().solve(b);
}

struct Case {
  TriangleMesh mesh;
  FieldType type;
};

std::vector<Case> Cases() {
  std::vector<Case> cases;
  for (const FieldType& type : {FieldType::Vector(), FieldType::NField(4), FieldType::Tensor()}) {
    cases.push_back({Icosphere(2), type});
    cases.push_back({Torus(16, 8), type});
  }
  return cases;
}

// (a) Galerkin: the reduced result is the minimizer of the same energy over span(U).
TEST(SmoothingTest, MatchesDenseGalerkinSolution) {
  uint64_t seed = 1;
  for (const Case& c : Cases()) {
    const FieldOperator op = MustBuildOperator(c.mesh, c.type);
    auto basis = RandomBasis(c.type, op.dofs(), 60, 25, ++seed);
    auto sys = ReducedSystem::Build(basis, op);
    ASSERT_TRUE(sys.ok()) << sys.status();
    const Eigen::VectorXd field = RandomVector(op.dofs(), ++seed);
    for (const EnergyWeights& w : {EnergyWeights{1.0, 0.0, 5.0}, EnergyWeights{0.3, 0.02, 1.0},
                                   EnergyWeights{0.0, 0.1, 2.0}}) {
      for (const bool weighted : {false, true}) {
        const std::vector<double> face_weights =
            weighted ? RandomFaceWeights(c.mesh.num_faces(), ++seed) : std::vector<double>{};
        auto result = SmoothReduced(**sys, field, w, face_weights);
        ASSERT_TRUE(result.ok()) << result.status();
        const Eigen::VectorXd expected = DenseSmoothing(op, *basis, field, w, face_weights);
        EXPECT_LT(RelativeDifference(result->coefficients, expected), 1e-8)
            << c.type.ToString() << " faces " << c.mesh.num_faces() << " weighted " << weighted
            << " mu " << w.mu_s << " " << w.mu_b << " " << w.mu_c;
      }
    }
  }
}

// (b) A dominant data term gives the L2 projection (eq. 13).
TEST(SmoothingTest, LargeDataWeightGivesTheL2Projection) {
  uint64_t seed = 100;
  for (const Case& c : Cases()) {
    const FieldOperator op = MustBuildOperator(c.mesh, c.type);
    auto sys = ReducedSystem::Build(RandomBasis(c.type, op.dofs(), 60, 25, ++seed), op);
    ASSERT_TRUE(sys.ok()) << sys.status();
    const Eigen::VectorXd field = RandomVector(op.dofs(), ++seed);
    auto projection = Project(**sys, field);
    ASSERT_TRUE(projection.ok()) << projection.status();
    auto result = SmoothReduced(**sys, field, {1e-12, 1e-12, 1.0});
    ASSERT_TRUE(result.ok()) << result.status();
    EXPECT_LT(RelativeDifference(result->coefficients, projection->coefficients), 1e-6)
        << c.type.ToString();
    // Uniform weights of any positive value give the same result as none.
    const std::vector<double> ones(c.mesh.num_faces(), 1.0);
    auto weighted = SmoothReduced(**sys, field, {1e-12, 1e-12, 1.0}, ones);
    ASSERT_TRUE(weighted.ok()) << weighted.status();
    EXPECT_LT(RelativeDifference(weighted->coefficients, projection->coefficients), 1e-6);
  }
}

// (c) With U = I the reduced problem is the full-space one: SmoothField's
// (M + lambda S) X = M X0 is mu_S = lambda, mu_B = 0, mu_C = 1.
TEST(SmoothingTest, IdentityBasisMatchesFullSpaceSmoothField) {
  uint64_t seed = 200;
  for (const Case& c : Cases()) {
    const FieldOperator op = MustBuildOperator(c.mesh, c.type);
    auto sys = ReducedSystem::Build(IdentityBasis(c.type, op.dofs()), op);
    ASSERT_TRUE(sys.ok()) << sys.status();
    const Eigen::VectorXd field = RandomVector(op.dofs(), ++seed);
    for (const double lambda : {0.01, 0.5}) {
      auto full = SmoothField(op, field, lambda);
      ASSERT_TRUE(full.ok()) << full.status();
      auto reduced = SmoothReduced(**sys, field, {lambda, 0.0, 1.0});
      ASSERT_TRUE(reduced.ok()) << reduced.status();
      EXPECT_LT(RelativeDifference(reduced->coefficients, *full), 1e-8) << c.type.ToString();
    }
  }
}

// (d) scale_free: the same weights give the same field on a mesh scaled by 10; the raw weights
// do not.
TEST(SmoothingTest, ScaleFreeWeightsAreInvariantUnderUniformScaling) {
  uint64_t seed = 300;
  for (const FieldType& type : {FieldType::Vector(), FieldType::NField(2), FieldType::Tensor()}) {
    const FieldOperator op1 = MustBuildOperator(Icosphere(2, 1.0), type);
    const FieldOperator op10 = MustBuildOperator(Icosphere(2, 10.0), type);
    // The same basis values on both meshes: the lifted fields U x compare directly.
    const uint64_t basis_seed = ++seed;
    auto sys1 = ReducedSystem::Build(RandomBasis(type, op1.dofs(), 60, 25, basis_seed), op1);
    auto sys10 = ReducedSystem::Build(RandomBasis(type, op10.dofs(), 60, 25, basis_seed), op10);
    ASSERT_TRUE(sys1.ok() && sys10.ok());
    const Eigen::VectorXd field = RandomVector(op1.dofs(), ++seed);
    const std::vector<double> face_weights =
        RandomFaceWeights(static_cast<int32_t>(op1.dofs() / type.dofs_per_face()), ++seed);
    const EnergyWeights w{0.5, 0.05, 3.0};
    for (const bool weighted : {false, true}) {
      const absl::Span<const double> fw =
          weighted ? absl::MakeConstSpan(face_weights) : absl::Span<const double>();
      SmoothingOptions scale_free;
      scale_free.scale_free = true;
      auto a = SmoothReduced(**sys1, field, w, fw, scale_free);
      auto b = SmoothReduced(**sys10, field, w, fw, scale_free);
      ASSERT_TRUE(a.ok() && b.ok());
      EXPECT_LT(RelativeDifference(a->coefficients, b->coefficients), 1e-8) << type.ToString();
      auto raw1 = SmoothReduced(**sys1, field, w, fw);
      auto raw10 = SmoothReduced(**sys10, field, w, fw);
      ASSERT_TRUE(raw1.ok() && raw10.ok());
      EXPECT_GT(RelativeDifference(raw1->coefficients, raw10->coefficients), 1e-2);
      // scale_free is the raw problem with mu_B * A and mu_C / A.
      const double area = (*sys10)->mass().sum() / type.dofs_per_face();
      EXPECT_NEAR(area, 100 * (*sys1)->mass().sum() / type.dofs_per_face(), 1e-9 * area);
      auto explicit_scaling =
          SmoothReduced(**sys10, field, {w.mu_s, w.mu_b * area, w.mu_c / area}, fw);
      ASSERT_TRUE(explicit_scaling.ok());
      EXPECT_LT(RelativeDifference(explicit_scaling->coefficients, b->coefficients), 1e-10);
    }
  }
}

// (e) WeightedMassMatrix: W = 1 reproduces U^T M U on its pattern; general W matches a dense
// U^T W M U.
TEST(SmoothingTest, WeightedMassMatrix) {
  uint64_t seed = 400;
  for (const Case& c : Cases()) {
    const FieldOperator op = MustBuildOperator(c.mesh, c.type);
    auto basis = RandomBasis(c.type, op.dofs(), 60, 25, ++seed);
    auto sys = ReducedSystem::Build(basis, op);
    ASSERT_TRUE(sys.ok()) << sys.status();
    auto ones = WeightedMassMatrix(**sys, Eigen::VectorXd::Ones(op.dofs()));
    ASSERT_TRUE(ones.ok()) << ones.status();
    EXPECT_TRUE((*sys)->pattern_symbolic()->SamePattern(*ones));
    EXPECT_LE(MaxAbsDiff(*ones, (*sys)->mass_matrix()), 1e-12 * MaxAbs((*sys)->mass_matrix()));

    const Eigen::VectorXd w = RandomVector(op.dofs(), ++seed, 0.0, 3.0);
    // The budget matters only for the degenerate fallback: the result does not depend on it.
    for (const int64_t budget : {int64_t{768} << 20, int64_t{1}}) {
      WeightedMassOptions options;
      options.accumulator_budget_bytes = budget;
      auto C = WeightedMassMatrix(**sys, w, options);
      ASSERT_TRUE(C.ok()) << C.status();
      EXPECT_TRUE((*sys)->pattern_symbolic()->SamePattern(*C));
      const Eigen::MatrixXd U = DenseU(*basis);
      const Eigen::MatrixXd expected = U.transpose() * op.mass.cwiseProduct(w).asDiagonal() * U;
      EXPECT_LE((Eigen::MatrixXd(*C) - expected).cwiseAbs().maxCoeff(),
                1e-12 * expected.cwiseAbs().maxCoeff());
      EXPECT_EQ(Eigen::MatrixXd(*C), Eigen::MatrixXd(C->transpose()));
    }
  }
}

// Two columns whose U^T S U, U^T B U and U^T M U entries cancel exactly (two identical,
// disjoint triangles; columns e0 + e2 and e0 - e2), while U^T W M U does not: the weighted mass
// leaves the shared pattern, and the smoother analyzes the larger one itself.
TEST(SmoothingTest, WeightedMassOutsideTheSharedPattern) {
  const MeshArrays one = Arrays({{0, 0, 0}, {1, 0, 0}, {0, 1, 0}}, {Eigen::Vector3i(0, 1, 2)});
  const TriangleMesh mesh = MustCreate(DisjointUnion(one, one, {5, 0, 0}));
  const FieldType type = FieldType::Vector();
  const FieldOperator op = MustBuildOperator(mesh, type);
  auto basis = std::make_shared<Basis>();
  basis->type = type;
  basis->params.dimension = 2;
  basis->U.resize(4, 2);
  const std::vector<Eigen::Triplet<float>> entries = {
      {0, 0, 1.0f}, {2, 0, 1.0f}, {0, 1, 1.0f}, {2, 1, -1.0f}};
  basis->U.setFromTriplets(entries.begin(), entries.end());
  basis->U.makeCompressed();
  auto sys = ReducedSystem::Build(basis, op);
  ASSERT_TRUE(sys.ok()) << sys.status();
  ASSERT_EQ((*sys)->mass_matrix().nonZeros(), 2) << "the off-diagonal entries did not cancel";
  const std::vector<double> face_weights = {2.0, 1.0};
  Eigen::VectorXd dof_weights(4);
  dof_weights << 2.0, 2.0, 1.0, 1.0;
  auto C = WeightedMassMatrix(**sys, dof_weights);
  ASSERT_TRUE(C.ok()) << C.status();
  EXPECT_FALSE((*sys)->pattern_symbolic()->SamePattern(*C));
  const Eigen::MatrixXd U = DenseU(*basis);
  const Eigen::MatrixXd expected =
      U.transpose() * op.mass.cwiseProduct(dof_weights).asDiagonal() * U;
  EXPECT_LE((Eigen::MatrixXd(*C) - expected).cwiseAbs().maxCoeff(), 1e-14);
  const Eigen::VectorXd field = RandomVector(4, 31);
  const EnergyWeights w{0.5, 0.1, 2.0};
  auto result = SmoothReduced(**sys, field, w, face_weights);
  ASSERT_TRUE(result.ok()) << result.status();
  EXPECT_LT(
      RelativeDifference(result->coefficients, DenseSmoothing(op, *basis, field, w, face_weights)),
      1e-10);
}

TEST(SmoothingTest, WeightedMassMatrixErrors) {
  const FieldOperator op = MustBuildOperator(Icosphere(1), FieldType::Vector());
  auto sys = ReducedSystem::Build(RandomBasis(FieldType::Vector(), op.dofs(), 20, 10, 7), op);
  ASSERT_TRUE(sys.ok());
  EXPECT_THAT(WeightedMassMatrix(**sys, Eigen::VectorXd::Ones(op.dofs() - 1)),
              StatusIs(absl::StatusCode::kInvalidArgument));
  Eigen::VectorXd w = Eigen::VectorXd::Ones(op.dofs());
  w[3] = -1;
  EXPECT_THAT(WeightedMassMatrix(**sys, w), StatusIs(absl::StatusCode::kInvalidArgument));
  w[3] = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THAT(WeightedMassMatrix(**sys, w), StatusIs(absl::StatusCode::kInvalidArgument));
  CancelFlag cancel{true};
  WeightedMassOptions options;
  options.cancel = &cancel;
  EXPECT_THAT(WeightedMassMatrix(**sys, Eigen::VectorXd::Ones(op.dofs()), options),
              StatusIs(absl::StatusCode::kCancelled));
}

// (f) Errors, with their exact codes.
TEST(SmoothingTest, Errors) {
  const TriangleMesh mesh = Icosphere(1);
  const FieldOperator op = MustBuildOperator(mesh, FieldType::Vector());
  auto sys = ReducedSystem::Build(RandomBasis(FieldType::Vector(), op.dofs(), 20, 10, 9), op);
  ASSERT_TRUE(sys.ok());
  const Eigen::VectorXd field = RandomVector(op.dofs(), 3);
  const EnergyWeights w{1.0, 0.0, 1.0};
  const auto invalid = StatusIs(absl::StatusCode::kInvalidArgument);

  EXPECT_THAT(SmoothReduced(**sys, field.head(op.dofs() - 1), w), invalid);
  Eigen::VectorXd nan_field = field;
  nan_field[5] = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THAT(SmoothReduced(**sys, nan_field, w), invalid);
  nan_field[5] = std::numeric_limits<double>::infinity();
  EXPECT_THAT(SmoothReduced(**sys, nan_field, w), invalid);

  std::vector<double> fw(mesh.num_faces(), 1.0);
  EXPECT_THAT(SmoothReduced(**sys, field, w, absl::MakeConstSpan(fw).subspan(1)), invalid);
  fw[2] = -0.5;
  EXPECT_THAT(SmoothReduced(**sys, field, w, fw), invalid);
  fw[2] = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THAT(SmoothReduced(**sys, field, w, fw), invalid);
  std::fill(fw.begin(), fw.end(), 0.0);
  EXPECT_THAT(SmoothReduced(**sys, field, w, fw), invalid);

  EXPECT_THAT(SmoothReduced(**sys, field, {-1.0, 0.0, 1.0}), invalid);
  EXPECT_THAT(SmoothReduced(**sys, field, {1.0, -0.1, 1.0}), invalid);
  EXPECT_THAT(SmoothReduced(**sys, field, {1.0, 0.0, -1.0}), invalid);
  EXPECT_THAT(SmoothReduced(**sys, field, {0.0, 0.0, 1.0}), invalid);
  EXPECT_THAT(SmoothReduced(**sys, field, {std::nan(""), 0.0, 1.0}), invalid);
  EXPECT_THAT(SmoothReduced(**sys, field, {1.0, 0.0, std::numeric_limits<double>::infinity()}),
              invalid);
  SmoothingOptions bad_solve;
  bad_solve.solve.max_refinement_steps = -1;
  EXPECT_THAT(SmoothReduced(**sys, field, w, {}, bad_solve), invalid);
  EXPECT_THAT(ReducedSmoother::Create(nullptr, field), invalid);

  CancelFlag cancel{true};
  SmoothingOptions cancelled;
  cancelled.cancel = &cancel;
  EXPECT_THAT(SmoothReduced(**sys, field, w, {}, cancelled),
              StatusIs(absl::StatusCode::kCancelled));
  // A flag set after the smoother was created cancels its solves.
  CancelFlag later{false};
  SmoothingOptions cancel_later;
  cancel_later.cancel = &later;
  auto smoother = ReducedSmoother::Create(*sys, field, {}, cancel_later);
  ASSERT_TRUE(smoother.ok()) << smoother.status();
  ASSERT_TRUE(smoother->Solve(w).ok());
  later = true;
  EXPECT_THAT(smoother->Solve(w), StatusIs(absl::StatusCode::kCancelled));
}

TEST(SmoothingTest, ZeroDataWeightNeedsADefiniteEnergy) {
  // Hodge Laplacian of a sphere: no harmonic fields, the energy is definite and x = 0.
  {
    const FieldOperator op = MustBuildOperator(Icosphere(1), FieldType::Vector());
    auto sys = ReducedSystem::Build(IdentityBasis(FieldType::Vector(), op.dofs()), op);
    ASSERT_TRUE(sys.ok());
    auto result = SmoothReduced(**sys, RandomVector(op.dofs(), 5), {1.0, 0.0, 0.0});
    ASSERT_TRUE(result.ok()) << result.status();
    EXPECT_EQ(result->coefficients.norm(), 0.0);
  }
  // One triangle: no interior edge, the tensor Laplacian is 0: FailedPrecondition naming mu_C.
  {
    const TriangleMesh mesh =
        MustCreate(Arrays({{0, 0, 0}, {1, 0, 0}, {0, 1, 0}}, {Eigen::Vector3i(0, 1, 2)}));
    const FieldOperator op = MustBuildOperator(mesh, FieldType::Tensor());
    auto sys = ReducedSystem::Build(IdentityBasis(FieldType::Tensor(), op.dofs()), op);
    ASSERT_TRUE(sys.ok()) << sys.status();
    const Eigen::VectorXd field = RandomVector(op.dofs(), 6);
    EXPECT_THAT(SmoothReduced(**sys, field, {1.0, 1.0, 0.0}),
                StatusIs(absl::StatusCode::kFailedPrecondition, ::testing::HasSubstr("mu_C")));
    // With a data term it is the field itself.
    auto result = SmoothReduced(**sys, field, {1.0, 1.0, 1.0});
    ASSERT_TRUE(result.ok()) << result.status();
    EXPECT_LT(RelativeDifference(result->coefficients, field), 1e-12);
  }
}

// (g) A smoother re-solves for new weights without recomputing its passes over U, and agrees
// with fresh one-shot calls.
TEST(SmoothingTest, SmootherReusesItsPrecomputation) {
  const TriangleMesh mesh = Torus(16, 8);
  for (const FieldType& type : {FieldType::Vector(), FieldType::Tensor()}) {
    const FieldOperator op = MustBuildOperator(mesh, type);
    auto sys = ReducedSystem::Build(RandomBasis(type, op.dofs(), 60, 25, 11), op);
    ASSERT_TRUE(sys.ok());
    const Eigen::VectorXd field = RandomVector(op.dofs(), 12);
    const std::vector<double> fw = RandomFaceWeights(mesh.num_faces(), 13);
    for (const bool weighted : {false, true}) {
      const absl::Span<const double> face_weights =
          weighted ? absl::MakeConstSpan(fw) : absl::Span<const double>();
      auto smoother = ReducedSmoother::Create(*sys, field, face_weights);
      ASSERT_TRUE(smoother.ok()) << smoother.status();
      EXPECT_EQ(smoother->weighted(), weighted);
      EXPECT_GT(smoother->setup_timings().rhs_ms, 0.0);
      EXPECT_EQ(smoother->setup_timings().weighted_mass_ms > 0.0, weighted);
      const Eigen::VectorXd rhs = smoother->rhs();
      for (const EnergyWeights& w : {EnergyWeights{1.0, 0.0, 1.0}, EnergyWeights{0.2, 0.05, 4.0},
                                     EnergyWeights{3.0, 0.5, 0.5}}) {
        auto result = smoother->Solve(w);
        ASSERT_TRUE(result.ok()) << result.status();
        EXPECT_EQ(result->timings.rhs_ms, 0.0);
        EXPECT_EQ(result->timings.weighted_mass_ms, 0.0);
        EXPECT_GT(result->timings.factorize_ms, 0.0);
        EXPECT_GT(result->timings.solve_ms, 0.0);
        EXPECT_LE(result->backward_error, 1e-12);
        auto fresh = SmoothReduced(**sys, field, w, face_weights);
        ASSERT_TRUE(fresh.ok()) << fresh.status();
        EXPECT_LT(RelativeDifference(result->coefficients, fresh->coefficients), 1e-12);
        EXPECT_GT(fresh->timings.rhs_ms, 0.0);
        EXPECT_EQ(fresh->timings.weighted_mass_ms > 0.0, weighted);
      }
      EXPECT_EQ(smoother->rhs(), rhs);
    }
  }
}

// The smoothed field has lower energy than the input and stays close to it.
TEST(SmoothingTest, SmoothingLowersTheEnergy) {
  const TriangleMesh mesh = Icosphere(2);
  const FieldOperator op = MustBuildOperator(mesh, FieldType::Tensor());
  auto sys = ReducedSystem::Build(IdentityBasis(FieldType::Tensor(), op.dofs()), op);
  ASSERT_TRUE(sys.ok());
  const Eigen::VectorXd field = RandomVector(op.dofs(), 21);
  auto result = SmoothReduced(**sys, field, {0.01, 0.0, 1.0});
  ASSERT_TRUE(result.ok());
  const Eigen::VectorXd& x = result->coefficients;
  EXPECT_LT(x.dot(op.stiffness * x), 0.5 * field.dot(op.stiffness * field));
}

// A stronger data term moves the minimizer closer to the input (in the M norm) and raises its
// energy: both monotonically.
TEST(SmoothingTest, DataWeightTradesEnergyForFidelity) {
  const TriangleMesh mesh = Torus(16, 8);
  const FieldOperator op = MustBuildOperator(mesh, FieldType::NField(2));
  auto sys = ReducedSystem::Build(RandomBasis(FieldType::NField(2), op.dofs(), 80, 25, 41), op);
  ASSERT_TRUE(sys.ok());
  const Eigen::VectorXd field = RandomVector(op.dofs(), 42);
  auto smoother = ReducedSmoother::Create(*sys, field);
  ASSERT_TRUE(smoother.ok());
  double last_residual = std::numeric_limits<double>::infinity(), last_energy = 0;
  for (const double mu_c : {0.01, 0.1, 1.0, 10.0, 100.0}) {
    auto result = smoother->Solve({1.0, 0.01, mu_c});
    ASSERT_TRUE(result.ok()) << result.status();
    auto residual = RelativeResiduals(**sys, field, result->coefficients);
    ASSERT_TRUE(residual.ok());
    const Eigen::VectorXd& x = result->coefficients;
    const double energy = x.dot((*sys)->stiffness() * x) + 0.01 * x.dot((*sys)->bilaplacian() * x);
    EXPECT_LT((*residual)[0], last_residual) << mu_c;
    EXPECT_GT(energy, last_energy) << mu_c;
    last_residual = (*residual)[0];
    last_energy = energy;
  }
}

}  // namespace
}  // namespace fieldspace
