// The mixed biharmonic as a product of sparse solves (core/subspace/mixed_energy.h): the inverse
// itself against dense matrices, and design sessions with BiharmonicForm::kMixed (which use it
// unless a data term is on) against the one-shot solve's conjugate gradients and a dense KKT
// solve with K Mr^-1 K written here.

#include "core/subspace/mixed_energy.h"

#include <algorithm>
#include <cmath>
#include <memory>
#include <utility>
#include <vector>

#include "Eigen/Dense"
#include "core/basis/basis.h"
#include "core/operators/reference_solvers.h"
#include "core/subspace/design_session.h"
#include "core/subspace/design_tools.h"
#include "core/subspace/kkt_solver.h"
#include "core/subspace/model_problem.h"
#include "core/subspace/reduced_system.h"
#include "core/subspace/smoothing.h"
#include "gtest/gtest.h"
#include "tests/testing/fixtures.h"
#include "tests/testing/test_meshes.h"

namespace fieldspace {
namespace {

using ::fieldspace::testing::DenseU;
using ::fieldspace::testing::Icosphere;
using ::fieldspace::testing::MustBuildOperator;
using ::fieldspace::testing::RandomBasis;
using ::fieldspace::testing::RandomVector;
using ::fieldspace::testing::RelativeDifference;
using ::fieldspace::testing::Torus;

struct Fixture {
  FieldOperator op;
  std::shared_ptr<const Basis> basis;
  std::shared_ptr<const ReducedSystem> system;
  Eigen::MatrixXd U, K, Mr;  // dense copies: U k x d, K = U^T S U, Mr = U^T M U

  Fixture(const TriangleMesh& mesh, const FieldType& type, std::shared_ptr<const Basis> b,
          FieldOperator o)
      : op(std::move(o)), basis(std::move(b)) {
    auto sys = ReducedSystem::Build(basis, op);
    EXPECT_TRUE(sys.ok()) << sys.status();
    system = *std::move(sys);
    U = DenseU(*basis);
    const Eigen::MatrixXd S(op.stiffness);
    K = U.transpose() * S * U;
    Mr = U.transpose() * op.mass.asDiagonal() * U;
  }
  static Fixture Random(const TriangleMesh& mesh, const FieldType& type, int64_t d, uint64_t seed) {
    FieldOperator op = MustBuildOperator(mesh, type);
    auto basis = RandomBasis(type, op.dofs(), d, 30, seed);
    return Fixture(mesh, type, std::move(basis), std::move(op));
  }
  // A basis whose last columns are the harmonic fields of a torus (zero energy).
  static Fixture WithKernelColumns(const TriangleMesh& torus, int32_t d) {
    FieldOperator op = MustBuildOperator(torus, FieldType::Vector());
    BasisOptions options;
    options.params.dimension = d;
    options.kernel_columns = true;
    absl::StatusOr<Basis> basis = BuildTwoLevelBasis(torus, op, options, 0);
    EXPECT_TRUE(basis.ok()) << basis.status();
    EXPECT_EQ(basis->kernel_columns, 2);
    return Fixture(torus, FieldType::Vector(), std::make_shared<const Basis>(*std::move(basis)),
                   std::move(op));
  }
  int32_t p() const { return op.type.dofs_per_face(); }
  Eigen::MatrixXd Rows(int32_t face) const { return U.middleRows(int64_t{face} * p(), p()); }
  Eigen::MatrixXd MixedEnergy(double mu_s, double mu_b) const {
    return mu_s * K + mu_b * K * Mr.llt().solve(K);
  }
  // The minimizer of x^T (A + mu_a D) x - 2 b^T x + sum_soft mu_c w |U_f x - c|^2 subject to the
  // hard constraints, by a dense KKT solve (raw weights; D, b: a data term or empty).
  Eigen::VectorXd DenseSolution(const EnergyWeights& w, const std::vector<FieldConstraint>& cs,
                                const Eigen::MatrixXd& D = {},
                                const Eigen::VectorXd& data_b = {}) const {
    const int64_t d = K.cols();
    Eigen::MatrixXd A = MixedEnergy(w.mu_s, w.mu_b);
    Eigen::VectorXd b = Eigen::VectorXd::Zero(d);
    if (D.size() > 0) {
      A += w.mu_a * D;
      b += w.mu_a * data_b;
    }
    std::vector<const FieldConstraint*> hard;
    for (const FieldConstraint& c : cs) {
      if (c.hard()) {
        hard.push_back(&c);
        continue;
      }
      A += w.mu_c * c.weight * Rows(c.face).transpose() * Rows(c.face);
      b += w.mu_c * c.weight * Rows(c.face).transpose() * c.value;
    }
    const int64_t h = static_cast<int64_t>(hard.size()) * p();
    Eigen::MatrixXd kkt = Eigen::MatrixXd::Zero(d + h, d + h);
    Eigen::VectorXd rhs(d + h);
    kkt.topLeftCorner(d, d) = A;
    rhs.head(d) = b;
    for (size_t i = 0; i < hard.size(); ++i) {
      kkt.block(d + i * p(), 0, p(), d) = Rows(hard[i]->face);
      kkt.block(0, d + i * p(), d, p()) = Rows(hard[i]->face).transpose();
      rhs.segment(d + i * p(), p()) = hard[i]->value;
    }
    return kkt.fullPivLu().solve(rhs).head(d);
  }
};

// The mixed form is the default of every reduced solve (the exact one stays selectable).
TEST(BiharmonicFormTest, MixedIsTheDefault) {
  EXPECT_EQ(ModelProblem{}.biharmonic, BiharmonicForm::kMixed);
  EXPECT_EQ(DesignSessionOptions{}.biharmonic, BiharmonicForm::kMixed);
}

// The partial fractions invert the true mixed energy (up to rounding: no kernel columns here) and
// Multiply applies it, for mu_S > 0 and mu_S = 0 (pure biharmonic).
TEST(MixedEnergyInverseTest, InvertsAndAppliesTheMixedEnergy) {
  const TriangleMesh mesh = Icosphere(2);
  uint64_t seed = 3;
  for (const FieldType& type : {FieldType::Vector(), FieldType::NField(4), FieldType::Tensor()}) {
    const Fixture f = Fixture::Random(mesh, type, 90, ++seed);
    auto stiffness = FactorizeEnergy(*f.system, {.mu_s = 1.0, .mu_b = 0.0}, {});
    ASSERT_TRUE(stiffness.ok()) << stiffness.status();
    const int64_t d = f.K.cols();
    for (const auto& [mu_s, mu_b] : {std::pair{0.3, 2.0}, std::pair{0.0, 1.5}}) {
      auto inverse = MixedEnergyInverse::Create(f.system.get(), *stiffness, mu_s, mu_b, {});
      ASSERT_TRUE(inverse.ok()) << inverse.status();
      EXPECT_EQ((*inverse)->dimension(), d);
      const Eigen::MatrixXd A = f.MixedEnergy(mu_s, mu_b);
      const Eigen::VectorXd v = RandomVector(d, ++seed);
      EXPECT_LT(RelativeDifference((*inverse)->Multiply(v), A * v), 1e-12);
      // A block of three right-hand sides at once, the dense inverse as the reference.
      Eigen::MatrixXd B(d, 3);
      for (int j = 0; j < 3; ++j) B.col(j) = RandomVector(d, ++seed);
      const Eigen::MatrixXd expected = A.ldlt().solve(B);
      // A_s^-1 B from the partial fractions: sum_k c_k F_k^-1 B.
      Eigen::MatrixXd X = Eigen::MatrixXd::Zero(d, 3);
      for (const InverseTerm& term : (*inverse)->terms()) {
        Eigen::MatrixXd Y = B;
        term.factor->SolveInPlace(Y);
        X += term.weight * Y;
      }
      // With mu_S = 0, N_s's floor (kKernelColumnShift mu_B min_i K_ii / Mr_ii) perturbs A_s by
      // about kKernelColumnShift relative; refinement removes it in a session.
      EXPECT_LT((X - expected).norm() / expected.norm(), mu_s > 0 ? 1e-8 : 10 * kKernelColumnShift)
          << type.ToString() << " " << mu_s;
      // Symmetric: u^T A^-1 w = w^T A^-1 u, to the rounding of partial fractions whose terms
      // cancel (with mu_S = 0.3 the asymmetry reaches 1.03e-10 of the norms in ~5% of runs, as
      // the threads' summation order varies; a non-symmetric inverse is off by O(1)).
      EXPECT_NEAR(B.col(0).dot(X.col(1)), B.col(1).dot(X.col(0)),
                  1e-9 * B.col(0).norm() * X.col(1).norm());
    }
  }
}

// One session per variant: constraints added one at a time, each solution against the one-shot
// solve (conjugate gradients preconditioned by the exact form) and, with raw weights, the dense
// KKT solve.
// From the `first_checked`-th constraint on (a basis with kernel columns: once the constraints
// control the harmonic directions, before which neither solve is unique).
void ExpectSessionMatches(const Fixture& f, const std::vector<FieldConstraint>& all,
                          const EnergyWeights& w, bool scale_free, const std::string& what,
                          size_t first_checked = 1) {
  DesignSessionOptions options;
  options.biharmonic = BiharmonicForm::kMixed;
  options.scale_free = scale_free;
  // The conjugate gradients would stop after one iteration, unconverged: the session's 1e-12
  // below shows that it solved by the partial fractions (and refinement) instead.
  options.solve.max_iterations = 1;
  auto session = DesignSession::Create(f.system, w, options);
  ASSERT_TRUE(session.ok()) << session.status();
  DesignSession& s = **session;
  std::vector<FieldConstraint> added;
  for (size_t i = 0; i < all.size(); ++i) {
    ASSERT_TRUE(s.AddConstraint(static_cast<int64_t>(i), all[i]).ok()) << what;
    added.push_back(all[i]);
    if (added.size() < first_checked) continue;
    EXPECT_LE(s.last_backward_error(), 1e-12) << what << " after " << i + 1;
    EXPECT_LE(s.last_refinement_steps(), options.solve.max_refinement_steps);
    ModelProblem problem = s.problem();
    auto cg = SolveReducedModelProblem(*f.system, problem);  // max_iterations 400
    ASSERT_TRUE(cg.ok()) << cg.status();
    EXPECT_LE(cg->backward_error, 1e-10);  // its conjugate gradients stall near 1e-11 here
    EXPECT_LT(RelativeDifference(s.coefficients(), cg->coefficients), 1e-9)
        << what << " after " << i + 1;
    if (!scale_free) {
      EXPECT_LT(RelativeDifference(s.coefficients(), f.DenseSolution(w, added)), 1e-9)
          << what << " after " << i + 1;
    }
  }
}

std::vector<FieldConstraint> Constraints(const Fixture& f, const std::vector<int32_t>& faces,
                                         int variant, uint64_t seed) {
  std::vector<FieldConstraint> out;
  for (size_t i = 0; i < faces.size(); ++i) {
    FieldConstraint c;
    c.face = faces[i];
    c.value = RandomVector(f.p(), seed + i);
    c.weight = 0.5 + static_cast<double>(i % 3);
    // 0: soft, 1: hard, 2: both.
    if (variant == 1 || (variant == 2 && i % 2 == 0)) c.kind = ConstraintKind::kHard;
    out.push_back(c);
  }
  return out;
}

TEST(MixedSessionTest, EqualsConjugateGradientsAndDenseKkt) {
  const TriangleMesh mesh = Icosphere(2);  // 320 faces
  uint64_t seed = 60;
  for (const FieldType& type : {FieldType::Vector(), FieldType::NField(4), FieldType::Tensor()}) {
    const Fixture f = Fixture::Random(mesh, type, 100, ++seed);
    for (int variant = 0; variant < 3; ++variant) {
      for (const bool scale_free : {false, true}) {
        const std::vector<FieldConstraint> cs =
            Constraints(f, {4, 51, 130, 207, 299}, variant, ++seed);
        ExpectSessionMatches(f, cs, {0.5, 0.2, 3.0}, scale_free,
                             type.ToString() + " variant " + std::to_string(variant) +
                                 (scale_free ? " scale-free" : " raw"));
        // Purely biharmonic (mu_S = 0: D = mu_B Lambda^2).
        ExpectSessionMatches(f, cs, {0.0, 1.0, 3.0}, scale_free, "mu_s = 0");
      }
    }
  }
}

TEST(MixedSessionTest, KernelColumns) {
  const Fixture f = Fixture::WithKernelColumns(Torus(24, 12), 60);
  // The two harmonic fields: zero energy, to rounding (K is singular: only the shift of
  // ShiftKernelColumns makes K_s and N_s factorizable).
  const Eigen::VectorXd lambda =
      Eigen::GeneralizedSelfAdjointEigenSolver<Eigen::MatrixXd>(f.K, f.Mr).eigenvalues();
  EXPECT_LT(std::abs(lambda[1]), 1e-10 * lambda.maxCoeff());
  EXPECT_GT(lambda[2], 1e-6 * lambda.maxCoeff());
  uint64_t seed = 90;
  for (int variant = 0; variant < 3; ++variant) {
    for (const bool scale_free : {false, true}) {
      // Enough faces all around the torus that the constraints control the harmonic directions.
      const std::vector<FieldConstraint> cs =
          Constraints(f, {3, 100, 170, 260, 333, 420, 515}, variant, ++seed);
      ExpectSessionMatches(f, cs, {1.0, 0.5, 2.0}, scale_free,
                           "kernel columns, variant " + std::to_string(variant), 3);
      // Pure biharmonic: N_s = mu_B K_s plus its floor would put the kernel's shift into A_s^-1
      // twice (~1e12 times the other directions' energy), and a hard constraint on a face where
      // the harmonic fields are nonzero would read as dependent: such sessions solve by the
      // conjugate gradients (docs/design-notes.md, "Mixed biharmonic edits"), hard constraints
      // included, and still match the one-shot solve and the dense KKT system.
      DesignSessionOptions options;
      options.biharmonic = BiharmonicForm::kMixed;
      options.scale_free = scale_free;
      const EnergyWeights pure{0.0, 0.5, 2.0};
      auto session = DesignSession::Create(f.system, pure, options);
      ASSERT_TRUE(session.ok()) << session.status();
      std::vector<FieldConstraint> added;
      for (size_t i = 0; i < cs.size(); ++i) {
        const absl::Status st = (*session)->AddConstraint(static_cast<int64_t>(i), cs[i]);
        ASSERT_TRUE(st.ok()) << st << ", mu_s = 0, variant " << variant;
        added.push_back(cs[i]);
      }
      EXPECT_LE((*session)->last_backward_error(), 1e-10);
      auto fresh = SolveReducedModelProblem(*f.system, (*session)->problem());
      ASSERT_TRUE(fresh.ok()) << fresh.status();
      EXPECT_LT(RelativeDifference((*session)->coefficients(), fresh->coefficients), 1e-8)
          << "mu_s = 0, variant " << variant;
      if (!scale_free) {
        EXPECT_LT(RelativeDifference((*session)->coefficients(), f.DenseSolution(pure, added)),
                  1e-8)
            << "mu_s = 0, variant " << variant;
      }
    }
  }
}

// With a data term the energy has its mass: the session keeps the conjugate gradients.
TEST(MixedSessionTest, DataTermStillSolvesTheMixedForm) {
  const Fixture f = Fixture::Random(Torus(16, 8), FieldType::Vector(), 60, 7);
  const int32_t faces = f.system->num_faces();
  const Eigen::VectorXd X0 = RandomVector(f.op.dofs(), 1);
  const Eigen::VectorXd face_weights = RandomVector(faces, 2).cwiseAbs();
  auto smoother = ReducedSmoother::Create(
      f.system, X0, absl::MakeConstSpan(face_weights.data(), face_weights.size()));
  ASSERT_TRUE(smoother.ok()) << smoother.status();
  Eigen::VectorXd wm = f.op.mass;
  for (int64_t i = 0; i < wm.size(); ++i) wm[i] *= face_weights[i / f.p()];
  const Eigen::MatrixXd D = f.U.transpose() * wm.asDiagonal() * f.U;
  const Eigen::VectorXd data_b = f.U.transpose() * wm.asDiagonal() * X0;
  DesignSessionOptions options;
  options.biharmonic = BiharmonicForm::kMixed;
  options.data_term = std::make_shared<const ReducedSmoother>(*std::move(smoother));
  EnergyWeights w{.mu_s = 0.1, .mu_b = 0.5, .mu_c = 4.0, .mu_a = 2.0};
  auto session = DesignSession::Create(f.system, w, options);
  ASSERT_TRUE(session.ok()) << session.status();
  DesignSession& s = **session;
  std::vector<FieldConstraint> cs = Constraints(f, {5, 77, 140}, 2, 3);
  for (size_t i = 0; i < cs.size(); ++i) ASSERT_TRUE(s.AddConstraint(i, cs[i]).ok());
  EXPECT_LE(s.last_backward_error(), 1e-12);
  EXPECT_GT(s.last_refinement_steps(), 0);  // conjugate gradient iterations
  EXPECT_LT(RelativeDifference(s.coefficients(), f.DenseSolution(w, cs, D, data_b)), 1e-8);
  // mu_a = 0: the data term's mass is out of the energy, and the partial fractions take over.
  w.mu_a = 0.0;
  ASSERT_TRUE(s.SetWeights(w).ok());
  EXPECT_LE(s.last_backward_error(), 1e-12);
  EXPECT_LT(RelativeDifference(s.coefficients(), f.DenseSolution(w, cs)), 1e-9);
}

// The number of basis columns the rows of `constraints`' faces touch, and their rows.
std::pair<size_t, size_t> TouchedColumnsAndRows(const ReducedSystem& system,
                                                const std::vector<FieldConstraint>& constraints) {
  std::vector<int32_t> touched;
  size_t rows = 0;
  for (const FieldConstraint& c : constraints) {
    for (const SparseRow& row : BasisRowsOfFace(system, c.face)) {
      ++rows;
      touched.insert(touched.end(), row.cols.begin(), row.cols.end());
    }
  }
  std::sort(touched.begin(), touched.end());
  return {static_cast<size_t>(std::unique(touched.begin(), touched.end()) - touched.begin()), rows};
}

// A vector field's stroke from face `from`'s center to face `to`'s (StrokeConstraints).
std::vector<FieldConstraint> FaceCenterStroke(const TriangleMesh& mesh, int32_t from, int32_t to) {
  const Eigen::Vector3d center = Eigen::Vector3d::Constant(1.0 / 3.0);
  auto c = StrokeConstraints(mesh, FieldType::Vector(),
                             {SurfacePoint{from, center}, SurfacePoint{to, center}});
  EXPECT_TRUE(c.ok()) << c.status();
  return c.ok() ? *std::move(c) : std::vector<FieldConstraint>{};
}

// A stroke whose faces' rows touch fewer basis columns than it has rows takes KktSolver's
// combined substitutions (the touched columns' unit vectors, then the rows restricted to them)
// and the block of H over the rows' reach: added and moved as one group it must equal the same
// faces added one at a time (each substituted by its own rows), in both forms; the mixed session
// also equals the dense KKT solve. Removing the group leaves the session's other constraints.
TEST(GroupEditTest, AStrokeOfFewColumnsEqualsItsFacesOneByOne) {
  const TriangleMesh mesh = Torus(32, 16);
  const Fixture f = Fixture::WithKernelColumns(mesh, 40);
  const std::vector<FieldConstraint> first = FaceCenterStroke(mesh, 0, 300),
                                     second = FaceCenterStroke(mesh, 5, 333);
  for (const auto* s : {&first, &second}) {
    const auto [touched, rows] = TouchedColumnsAndRows(*f.system, *s);
    ASSERT_GE(s->size(), 8u);
    ASSERT_LT(touched, rows) << "the stroke must take the combined path";
  }
  // Other constraints around the torus, so that the harmonic directions are controlled.
  std::vector<FieldConstraint> others;
  for (const int32_t face : {100, 420, 610, 777, 900}) {
    others.push_back({face, RandomVector(2, 7 + face), 1.0, ConstraintKind::kSoft});
  }
  others[1].kind = ConstraintKind::kHard;
  const EnergyWeights w{0.7, 0.3, 5.0};
  for (const BiharmonicForm form : {BiharmonicForm::kExact, BiharmonicForm::kMixed}) {
    DesignSessionOptions options;
    options.biharmonic = form;
    options.scale_free = false;
    const auto one_by_one = [&](const std::vector<FieldConstraint>& stroke_faces) {
      auto s = DesignSession::Create(f.system, w, options);
      EXPECT_TRUE(s.ok()) << s.status();
      int64_t id = 0;
      for (const std::vector<FieldConstraint>* cs : {&std::as_const(others), &stroke_faces}) {
        for (const FieldConstraint& c : *cs) EXPECT_TRUE((*s)->AddConstraint(id++, c).ok());
      }
      return (*s)->coefficients();
    };
    auto session = DesignSession::Create(f.system, w, options);
    ASSERT_TRUE(session.ok()) << session.status();
    DesignSession& s = **session;
    for (size_t i = 0; i < others.size(); ++i) {
      ASSERT_TRUE(s.AddConstraint(static_cast<int64_t>(i), others[i]).ok());
    }
    const Eigen::VectorXd before = s.coefficients();
    ASSERT_TRUE(s.AddConstraintGroup(100, first).ok());
    EXPECT_LT(RelativeDifference(s.coefficients(), one_by_one(first)), 1e-10);
    ASSERT_TRUE(s.MoveConstraintGroup(100, second).ok());
    EXPECT_LT(RelativeDifference(s.coefficients(), one_by_one(second)), 1e-10);
    if (form == BiharmonicForm::kMixed) {
      std::vector<FieldConstraint> all = others;
      all.insert(all.end(), second.begin(), second.end());
      EXPECT_LT(RelativeDifference(s.coefficients(), f.DenseSolution(w, all)), 1e-8);
    }
    ASSERT_TRUE(s.RemoveConstraint(100).ok());
    EXPECT_LT(RelativeDifference(s.coefficients(), before), 1e-10);
  }
}

// The sources behind W (kkt_solver.h): strokes share one per edit, single constraints have their
// own, and removes swap groups between them and leave holes in V (moved out later). Through
// interleaved adds, removes from the middle, a move that keeps half a stroke's faces, a weight
// change (every source rebuilt) and a re-add, the session equals a fresh one with the same
// constraints added one by one.
TEST(GroupEditTest, StrokesAmongSingleConstraintsKeepTheirSourcesThroughEdits) {
  const TriangleMesh mesh = Torus(32, 16);
  const Fixture f = Fixture::WithKernelColumns(mesh, 40);
  const std::vector<FieldConstraint> a = FaceCenterStroke(mesh, 0, 300),
                                     b = FaceCenterStroke(mesh, 40, 380),
                                     c = FaceCenterStroke(mesh, 9, 200);
  for (const auto* s : {&a, &b, &c}) {
    const auto [touched, rows] = TouchedColumnsAndRows(*f.system, *s);
    ASSERT_LT(touched, rows) << "the stroke must take the combined path";
  }
  std::vector<FieldConstraint> others;
  for (const int32_t face : {100, 420, 610, 777, 900}) {
    others.push_back({face, RandomVector(2, 3 + face), 1.0, ConstraintKind::kSoft});
  }
  others[2].kind = ConstraintKind::kHard;
  for (const BiharmonicForm form : {BiharmonicForm::kExact, BiharmonicForm::kMixed}) {
    DesignSessionOptions options;
    options.biharmonic = form;
    options.scale_free = false;
    EnergyWeights w{0.7, 0.3, 5.0};
    auto session = DesignSession::Create(f.system, w, options);
    ASSERT_TRUE(session.ok()) << session.status();
    DesignSession& s = **session;
    const auto expect_one_by_one = [&](const char* step) {
      auto fresh = DesignSession::Create(f.system, w, options);
      ASSERT_TRUE(fresh.ok()) << fresh.status();
      int64_t id = 0;
      for (const FieldConstraint& k : s.problem().constraints) {
        ASSERT_TRUE((*fresh)->AddConstraint(id++, k).ok()) << step;
      }
      EXPECT_LT(RelativeDifference(s.coefficients(), (*fresh)->coefficients()), 1e-10) << step;
    };
    for (int i = 0; i < 3; ++i) ASSERT_TRUE(s.AddConstraint(i, others[i]).ok());
    ASSERT_TRUE(s.AddConstraintGroup(100, a).ok());
    ASSERT_TRUE(s.AddConstraint(3, others[3]).ok());
    ASSERT_TRUE(s.AddConstraintGroup(101, b).ok());
    ASSERT_TRUE(s.AddConstraint(4, others[4]).ok());
    expect_one_by_one("added");
    // Constraint 0's source leaves a hole in V.
    ASSERT_TRUE(s.RemoveConstraint(0).ok());
    expect_one_by_one("0 removed");
    ASSERT_TRUE(s.AddConstraint(0, others[0]).ok());
    // The last groups (constraint 4, then b's faces) move into a's slots; a's source's columns
    // make the holes a quarter of V, which moves the sources down.
    ASSERT_TRUE(s.RemoveConstraint(100).ok());
    expect_one_by_one("a removed");
    // Half of b's faces keep their face (new values), the rest become c's.
    std::vector<FieldConstraint> moved(b.begin(), b.begin() + b.size() / 2);
    for (FieldConstraint& k : moved) k.value = RandomVector(2, k.face);
    moved.insert(moved.end(), c.begin(), c.end());
    ASSERT_TRUE(s.MoveConstraintGroup(101, moved).ok());
    expect_one_by_one("b half moved");
    w = {1.3, 0.05, 20.0};
    ASSERT_TRUE(s.SetWeights(w).ok());
    expect_one_by_one("weights changed");
    ASSERT_TRUE(s.AddConstraintGroup(100, a).ok());
    expect_one_by_one("a added again");
    ASSERT_TRUE(s.RemoveConstraint(2).ok());
    ASSERT_TRUE(s.RemoveConstraint(101).ok());
    expect_one_by_one("b removed");
    if (form == BiharmonicForm::kMixed) {
      EXPECT_LT(RelativeDifference(s.coefficients(), f.DenseSolution(w, s.problem().constraints)),
                1e-8);
    }
  }
}

}  // namespace
}  // namespace fieldspace
