#include "core/subspace/design_session.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <memory>
#include <random>
#include <thread>
#include <utility>
#include <vector>

#include "Eigen/Dense"
#include "core/subspace/full_space_solver.h"
#include "core/subspace/projection.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tests/testing/fixtures.h"
#include "tests/testing/matchers.h"
#include "tests/testing/test_meshes.h"

namespace fieldspace {
namespace {

FieldConstraint As(ConstraintKind kind, FieldConstraint c) {
  c.kind = kind;
  return c;
}

using ::fieldspace::testing::Icosphere;
using ::fieldspace::testing::MustBuildOperator;
using ::fieldspace::testing::RandomBasis;
using ::fieldspace::testing::RelativeDifference;
using ::fieldspace::testing::StatusIs;
using ::fieldspace::testing::Torus;

class DesignSessionTest : public ::testing::TestWithParam<FieldType> {
 protected:
  void SetUp() override {
    mesh_ = std::make_unique<TriangleMesh>(Icosphere(2));
    op_ = MustBuildOperator(*mesh_, GetParam());
    basis_ = RandomBasis(GetParam(), op_.dofs(), 150, 30, 17);
    auto sys = ReducedSystem::Build(basis_, op_);
    ASSERT_TRUE(sys.ok()) << sys.status();
    sys_ = *sys;
  }
  FieldConstraint RandomConstraint(std::mt19937_64& rng) const {
    std::uniform_real_distribution<double> u(-1.0, 1.0);
    FieldConstraint c;
    c.face = static_cast<int32_t>(rng() % mesh_->num_faces());
    c.value.resize(GetParam().dofs_per_face());
    for (int i = 0; i < c.value.size(); ++i) c.value[i] = u(rng);
    c.weight = 0.2 + 2.0 * std::abs(u(rng));
    return c;
  }
  // The session's solution equals a fresh factorization of its current problem.
  void ExpectMatchesFreshSolve(const DesignSession& session) const {
    auto fresh = SolveReducedModelProblem(*sys_, session.problem());
    ASSERT_TRUE(fresh.ok()) << fresh.status();
    const double scale = std::max(fresh->coefficients.norm(), 1e-300);
    EXPECT_LT((session.coefficients() - fresh->coefficients).norm() / scale, 1e-6)
        << session.num_constraints() << " constraints";
    // Hard constraints hold in the lifted field.
    for (const FieldConstraint& c : session.problem().constraints) {
      if (!c.hard()) continue;
      auto v = session.LiftFaces(std::vector<int32_t>{c.face});
      ASSERT_TRUE(v.ok());
      EXPECT_LT((*v - c.value).norm(), 1e-9 * (1 + c.value.norm()));
    }
  }

  // Random adds, moves, removals and weight changes, each checked against a fresh solve.
  void RandomEdits(DesignSession& s, int steps) const {
    EXPECT_EQ(s.coefficients().norm(), 0.0);  // no constraints: the zero field
    std::mt19937_64 rng(GetParam().dofs_per_face() * 101 + GetParam().n);
    std::map<int64_t, ConstraintKind> live;
    int64_t next_id = 100;
    int hard_failures = 0;
    for (int step = 0; step < steps; ++step) {
      const uint64_t action = rng() % 10;
      if (live.empty() || action < 4) {
        const ConstraintKind kind = rng() % 3 == 0 ? ConstraintKind::kHard : ConstraintKind::kSoft;
        const absl::Status st = s.AddConstraint(next_id, As(kind, RandomConstraint(rng)));
        if (st.ok()) {
          live[next_id] = kind;
        } else {
          // Only a hard constraint landing on an already hard-constrained face may fail.
          EXPECT_THAT(st, StatusIs(absl::StatusCode::kFailedPrecondition)) << st;
          EXPECT_EQ(kind, ConstraintKind::kHard);
          ++hard_failures;
        }
        ++next_id;
      } else if (action < 6) {
        auto it = std::next(live.begin(), static_cast<int64_t>(rng() % live.size()));
        FieldConstraint c = RandomConstraint(rng);
        if (rng() % 2 == 0) {  // same face, new value and weight: no solve with A
          auto current = s.GetConstraint(it->first);
          ASSERT_TRUE(current.ok());
          c.face = current->face;
        }
        const absl::Status st = s.MoveConstraint(it->first, c);
        if (!st.ok()) {
          EXPECT_THAT(st, StatusIs(absl::StatusCode::kFailedPrecondition)) << st;
        }
      } else if (action < 8) {
        auto it = std::next(live.begin(), static_cast<int64_t>(rng() % live.size()));
        ASSERT_TRUE(s.RemoveConstraint(it->first).ok());
        live.erase(it);
      } else if (action == 8) {
        std::uniform_real_distribution<double> u(0.0, 1.0);
        ASSERT_TRUE(s.SetWeights({0.1 + u(rng), rng() % 2 ? 0.0 : u(rng), 0.5 + 5 * u(rng)}).ok());
      } else {
        EnergyWeights w = s.weights();
        w.mu_c *= 3.0;  // mu_C only: no refactorization of A
        ASSERT_TRUE(s.SetWeights(w).ok());
      }
      EXPECT_EQ(s.num_constraints(), static_cast<int32_t>(live.size()));
      int32_t hard = 0;
      for (const auto& [id, kind] : live) hard += kind == ConstraintKind::kHard;
      EXPECT_EQ(s.num_hard_constraints(), hard);
      ExpectMatchesFreshSolve(s);
    }
    EXPECT_GT(live.size(), 0u);
  }

  std::unique_ptr<TriangleMesh> mesh_;
  FieldOperator op_;
  std::shared_ptr<Basis> basis_;
  std::shared_ptr<const ReducedSystem> sys_;
};

TEST_P(DesignSessionTest, RandomEditSequencesMatchFreshFactorizations) {
  auto session = DesignSession::Create(sys_, {1.0, 0.05, 4.0});
  ASSERT_TRUE(session.ok()) << session.status();
  RandomEdits(**session, 60);
}

TEST_P(DesignSessionTest, MixedBiharmonicEditSequencesMatchFreshSolves) {
  for (const bool scale_free : {false, true}) {
    DesignSessionOptions options;
    options.biharmonic = BiharmonicForm::kMixed;
    options.scale_free = scale_free;
    auto session = DesignSession::Create(sys_, {1.0, 0.05, 4.0}, options);
    ASSERT_TRUE(session.ok()) << session.status();
    RandomEdits(**session, 40);
    DesignSession& s = **session;
    ASSERT_TRUE(s.SetWeights({0.2, 1.0, 4.0}).ok());
    ASSERT_GT(s.num_constraints(), 0);
    EXPECT_EQ(s.problem().biharmonic, BiharmonicForm::kMixed);
    // Solved in the spectrum of (K, Mr), refined against the true matrix: no conjugate gradients.
    EXPECT_LE(s.last_refinement_steps(), options.solve.max_refinement_steps);
    EXPECT_LE(s.last_backward_error(), 1e-12);
    ExpectMatchesFreshSolve(s);
    // Another minimizer than the exact form's.
    ModelProblem exact = s.problem();
    exact.biharmonic = BiharmonicForm::kExact;
    auto other = SolveReducedModelProblem(*sys_, exact);
    ASSERT_TRUE(other.ok());
    EXPECT_GT(RelativeDifference(s.coefficients(), other->coefficients), 1e-3);
  }
}

TEST_P(DesignSessionTest, MovingWithinAFaceAndAcrossFaces) {
  auto session = DesignSession::Create(sys_, {0.5, 0.1, 2.0});
  ASSERT_TRUE(session.ok());
  DesignSession& s = **session;
  std::mt19937_64 rng(5);
  FieldConstraint a = RandomConstraint(rng), b = RandomConstraint(rng);
  b.face = (a.face + 1) % mesh_->num_faces();
  ASSERT_TRUE(s.AddConstraint(1, As(ConstraintKind::kHard, a)).ok());
  ASSERT_TRUE(s.AddConstraint(2, As(ConstraintKind::kSoft, b)).ok());
  a.value *= -2.0;  // same face
  ASSERT_TRUE(s.MoveConstraint(1, a).ok());
  ExpectMatchesFreshSolve(s);
  b.weight = 7.5;  // same face, new weight
  ASSERT_TRUE(s.MoveConstraint(2, b).ok());
  ExpectMatchesFreshSolve(s);
  a.face = (a.face + 40) % mesh_->num_faces();  // another face
  ASSERT_TRUE(s.MoveConstraint(1, a).ok());
  ExpectMatchesFreshSolve(s);
  s.ClearConstraints();
  EXPECT_EQ(s.num_constraints(), 0);
  EXPECT_EQ(s.coefficients().norm(), 0.0);
}

TEST_P(DesignSessionTest, ErrorsLeaveTheSessionUnchanged) {
  auto session = DesignSession::Create(sys_, {1.0, 0.0, 1.0});
  ASSERT_TRUE(session.ok());
  DesignSession& s = **session;
  std::mt19937_64 rng(8);
  const FieldConstraint c = RandomConstraint(rng);
  ASSERT_TRUE(s.AddConstraint(7, As(ConstraintKind::kHard, c)).ok());
  FieldConstraint other = RandomConstraint(rng);
  other.face = (c.face + 3) % mesh_->num_faces();
  ASSERT_TRUE(s.AddConstraint(8, As(ConstraintKind::kSoft, other)).ok());
  const Eigen::VectorXd before = s.coefficients();
  const auto unchanged = [&] {
    EXPECT_EQ(s.num_constraints(), 2);
    EXPECT_EQ(s.coefficients(), before);
  };
  // Duplicate id.
  EXPECT_THAT(s.AddConstraint(7, As(ConstraintKind::kSoft, other)),
              StatusIs(absl::StatusCode::kAlreadyExists));
  unchanged();
  // Unknown ids.
  EXPECT_THAT(s.GetConstraint(99), StatusIs(absl::StatusCode::kNotFound));
  EXPECT_THAT(s.MoveConstraint(99, c), StatusIs(absl::StatusCode::kNotFound));
  EXPECT_THAT(s.RemoveConstraint(99), StatusIs(absl::StatusCode::kNotFound));
  unchanged();
  // Bad face ids, sizes, values, weights.
  FieldConstraint bad = c;
  bad.face = mesh_->num_faces();
  EXPECT_THAT(s.AddConstraint(9, As(ConstraintKind::kSoft, bad)),
              StatusIs(absl::StatusCode::kInvalidArgument));
  bad.face = -1;
  EXPECT_THAT(s.MoveConstraint(8, bad), StatusIs(absl::StatusCode::kInvalidArgument));
  bad = c;
  bad.value = Eigen::VectorXd::Zero(GetParam().dofs_per_face() + 1);
  EXPECT_THAT(s.AddConstraint(9, As(ConstraintKind::kHard, bad)),
              StatusIs(absl::StatusCode::kInvalidArgument));
  bad = c;
  bad.value[0] = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THAT(s.AddConstraint(9, As(ConstraintKind::kSoft, bad)),
              StatusIs(absl::StatusCode::kInvalidArgument));
  bad = other;
  bad.weight = 0;
  EXPECT_THAT(s.AddConstraint(9, As(ConstraintKind::kSoft, bad)),
              StatusIs(absl::StatusCode::kInvalidArgument));
  bad.weight = -1;
  EXPECT_THAT(s.MoveConstraint(8, bad), StatusIs(absl::StatusCode::kInvalidArgument));
  unchanged();
  // Non-positive or non-finite energy weights.
  EXPECT_THAT(s.SetWeights({-1.0, 0.0, 1.0}), StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(s.SetWeights({1.0, 0.0, 0.0}), StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(s.SetWeights({0.0, 0.0, 1.0}), StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(s.SetWeights({1.0, std::numeric_limits<double>::infinity(), 1.0}),
              StatusIs(absl::StatusCode::kInvalidArgument));
  unchanged();
  // A second hard constraint on the same face: dependent.
  FieldConstraint same = c;
  same.value *= 0.5;
  EXPECT_THAT(s.AddConstraint(9, As(ConstraintKind::kHard, same)),
              StatusIs(absl::StatusCode::kFailedPrecondition));
  unchanged();
  EXPECT_FALSE(s.HasConstraint(9));
  // Moving the soft constraint is fine; moving a second hard one onto the first's face is not.
  ASSERT_TRUE(s.AddConstraint(10, As(ConstraintKind::kHard, other)).ok());
  const Eigen::VectorXd with_three = s.coefficients();
  EXPECT_THAT(s.MoveConstraint(10, same), StatusIs(absl::StatusCode::kFailedPrecondition));
  EXPECT_EQ(s.coefficients(), with_three);
  ExpectMatchesFreshSolve(s);
  // Creation errors.
  EXPECT_THAT(DesignSession::Create(nullptr, {}), StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(DesignSession::Create(sys_, {1.0, -1.0, 1.0}),
              StatusIs(absl::StatusCode::kInvalidArgument));
  DesignSessionOptions bad_options;
  bad_options.solve.max_refinement_steps = -1;
  EXPECT_THAT(DesignSession::Create(sys_, {}, bad_options),
              StatusIs(absl::StatusCode::kInvalidArgument));
  bad_options = {};
  bad_options.solve.regularization = 1.0;  // above max_regularization
  EXPECT_THAT(DesignSession::Create(sys_, {}, bad_options),
              StatusIs(absl::StatusCode::kInvalidArgument));
}

// RestoreCoefficients takes back the solution from before an edit and its inverse, bit for bit,
// and refuses a vector that is not a solution of the current problem.
TEST_P(DesignSessionTest, RestoreCoefficientsAfterAnEditAndItsInverse) {
  auto session = DesignSession::Create(sys_, {1.0, 0.05, 2.0});
  ASSERT_TRUE(session.ok());
  DesignSession& s = **session;
  std::mt19937_64 rng(21);
  ASSERT_TRUE(s.AddConstraint(1, As(ConstraintKind::kHard, RandomConstraint(rng))).ok());
  ASSERT_TRUE(s.AddConstraint(2, As(ConstraintKind::kSoft, RandomConstraint(rng))).ok());
  const Eigen::VectorXd before = s.coefficients();
  ASSERT_TRUE(s.SetWeights({1.0, 0.5, 2.0}).ok());
  const Eigen::VectorXd other = s.coefficients();
  EXPECT_THAT(s.RestoreCoefficients(before), StatusIs(absl::StatusCode::kFailedPrecondition));
  EXPECT_EQ(s.coefficients(), other);
  ASSERT_TRUE(s.SetWeights({1.0, 0.05, 2.0}).ok());
  EXPECT_LT((s.coefficients() - before).norm(), 1e-9 * before.norm());
  ASSERT_TRUE(s.RestoreCoefficients(before).ok());
  EXPECT_EQ(s.coefficients(), before);
  EXPECT_THAT(s.RestoreCoefficients(before.head(3)),
              StatusIs(absl::StatusCode::kFailedPrecondition));
  ExpectMatchesFreshSolve(s);
}

TEST_P(DesignSessionTest, SessionsWithEqualEnergyWeightsShareOneFactorization) {
  auto cache = std::make_shared<EnergyFactorCache>();
  DesignSessionOptions options;
  options.energy_cache = cache;
  auto a = DesignSession::Create(sys_, {1.0, 0.05, 4.0}, options);
  auto b = DesignSession::Create(sys_, {1.0, 0.05, 0.5}, options);  // only mu_C differs
  auto plain = DesignSession::Create(sys_, {1.0, 0.05, 0.5});       // no cache
  ASSERT_TRUE(a.ok() && b.ok() && plain.ok());
  EXPECT_TRUE((*a)->last_factorized());
  EXPECT_FALSE((*b)->last_factorized());
  EXPECT_TRUE((*plain)->last_factorized());
  // The energy's entry and, for the mixed form (the default), K's (mu_S = 1, mu_B = 0), which
  // every mixed session of the system shares whatever its weights.
  EXPECT_EQ(cache->live_entries(), 2);
  // The shared factorization gives what a session's own gives.
  std::mt19937_64 rng(7);
  for (int64_t id = 0; id < 6; ++id) {
    const FieldConstraint c = RandomConstraint(rng);
    const ConstraintKind kind = id % 3 == 0 ? ConstraintKind::kHard : ConstraintKind::kSoft;
    const absl::Status st_b = (*b)->AddConstraint(id, As(kind, c));
    EXPECT_EQ(st_b, (*plain)->AddConstraint(id, As(kind, c)));
    EXPECT_TRUE((*a)->AddConstraint(id, As(kind, c)).ok() == st_b.ok());
  }
  EXPECT_LT(RelativeDifference((*b)->coefficients(), (*plain)->coefficients()), 1e-10);
  // A new mu_B factorizes once; the second session moving there shares it, and the old entry
  // goes when nobody holds it.
  ASSERT_TRUE((*b)->SetWeights({1.0, 0.2, 0.5}).ok());
  EXPECT_TRUE((*b)->last_factorized());
  EXPECT_EQ(cache->live_entries(), 3);
  ASSERT_TRUE((*a)->SetWeights({1.0, 0.2, 4.0}).ok());
  EXPECT_FALSE((*a)->last_factorized());
  EXPECT_EQ(cache->live_entries(), 2);
  ASSERT_TRUE((*a)->SetWeights({1.0, 0.2, 2.0}).ok());  // mu_C only: no factorization at all
  EXPECT_FALSE((*a)->last_factorized());
  ExpectMatchesFreshSolve(**a);
  ExpectMatchesFreshSolve(**b);
  a->reset();
  b->reset();
  EXPECT_EQ(cache->live_entries(), 0);
}

TEST_P(DesignSessionTest, VerifyIntervalChecksSomeSolvesAndKeepsThemExact) {
  DesignSessionOptions options;
  options.verify_interval = 4;
  auto session = DesignSession::Create(sys_, {1.0, 0.05, 4.0}, options);
  ASSERT_TRUE(session.ok()) << session.status();
  DesignSession& s = **session;
  // The first solve on a new factorization is always checked.
  EXPECT_FALSE(std::isnan(s.last_backward_error()));
  std::mt19937_64 rng(11);
  int checked = 0;
  constexpr int kEdits = 40;
  std::vector<int64_t> added;
  for (int64_t id = 0; id < kEdits; ++id) {
    if (id >= 8 && id % 2 == 0) {
      ASSERT_TRUE(s.MoveConstraint(added[rng() % added.size()], RandomConstraint(rng)).ok());
    } else {
      ASSERT_TRUE(s.AddConstraint(id, As(ConstraintKind::kSoft, RandomConstraint(rng))).ok());
      added.push_back(id);
    }
    if (!std::isnan(s.last_backward_error())) {
      ++checked;
      EXPECT_LE(s.last_backward_error(), 1e-12);
    }
    if (id % 5 == 0) ExpectMatchesFreshSolve(s);  // checked or not, the solution is exact
  }
  EXPECT_GE(checked, kEdits / 4);
  EXPECT_LT(checked, kEdits);
  // A new factorization: its first solve is checked again.
  ASSERT_TRUE(s.SetWeights({1.0, 0.3, 4.0}).ok());
  EXPECT_FALSE(std::isnan(s.last_backward_error()));
  ExpectMatchesFreshSolve(s);
  options.verify_interval = 0;
  EXPECT_THAT(DesignSession::Create(sys_, {1.0, 0.05, 4.0}, options),
              StatusIs(absl::StatusCode::kInvalidArgument));
}

TEST_P(DesignSessionTest, ConcurrentOpensWithEqualWeightsFactorizeOnce) {
  auto cache = std::make_shared<EnergyFactorCache>();
  DesignSessionOptions options;
  options.energy_cache = cache;
  constexpr int kThreads = 6;
  std::vector<std::unique_ptr<DesignSession>> sessions(kThreads);
  std::vector<std::thread> threads;
  for (int t = 0; t < kThreads; ++t) {
    threads.emplace_back([&, t] {
      auto s = DesignSession::Create(sys_, {1.0, 0.01, 1.0 + t}, options);
      if (s.ok()) sessions[t] = *std::move(s);
    });
  }
  for (auto& t : threads) t.join();
  int factorized = 0;
  for (const auto& s : sessions) {
    ASSERT_NE(s, nullptr);
    factorized += s->last_factorized() ? 1 : 0;
  }
  EXPECT_EQ(factorized, 1);
  EXPECT_EQ(cache->live_entries(), 2);  // the energy's and K's (the mixed form's)
}

TEST_P(DesignSessionTest, ConcurrentSessionsShareTheSystem) {
  // Four sessions on four threads replay the same edits; results equal the sequential ones.
  const auto run = [&](std::vector<Eigen::VectorXd>* out) {
    auto session = DesignSession::Create(sys_, {1.0, 0.2, 3.0});
    ASSERT_TRUE(session.ok());
    std::mt19937_64 rng(77);
    for (int64_t id = 0; id < 12; ++id) {
      FieldConstraint c = RandomConstraint(rng);
      c.face = static_cast<int32_t>((id * 23) % mesh_->num_faces());
      ASSERT_TRUE((*session)
                      ->AddConstraint(
                          id, As(id % 4 == 0 ? ConstraintKind::kHard : ConstraintKind::kSoft, c))
                      .ok());
      out->push_back((*session)->coefficients());
    }
  };
  std::vector<Eigen::VectorXd> reference;
  run(&reference);
  std::vector<std::vector<Eigen::VectorXd>> results(4);
  std::vector<std::thread> threads;
  for (int t = 0; t < 4; ++t) threads.emplace_back([&, t] { run(&results[t]); });
  for (std::thread& t : threads) t.join();
  for (const auto& r : results) {
    ASSERT_EQ(r.size(), reference.size());
    for (size_t i = 0; i < r.size(); ++i) EXPECT_LT(RelativeDifference(r[i], reference[i]), 1e-12);
  }
}

INSTANTIATE_TEST_SUITE_P(FieldTypes, DesignSessionTest,
                         ::testing::Values(FieldType::Vector(), FieldType::NField(4),
                                           FieldType::Tensor()),
                         [](const ::testing::TestParamInfo<FieldType>& info) {
                           return info.param.ToString();
                         });

TEST(DesignSessionTorusTest, SingularEnergyWithConstraints) {
  // U = I on a torus: the energy has the harmonic fields in its kernel (not marked as kernel
  // columns), so the factorizations are regularized; with constraints the session still matches
  // the fresh solve: the exact form with mu_B only, hard and soft constraints. The mixed form's
  // inverse K_s^-1 Mr N_s^-1 meets K's near-zero pivots (here of rounding size: no kernel columns
  // to shift) once more than the exact form's: with mu_S = 0 even soft constraints make H
  // numerically indefinite, and with mu_S > 0 hard constraints on the harmonic directions read as
  // dependent (docs/design-notes.md, "Mixed biharmonic edits"): mu_S > 0 and soft constraints.
  const TriangleMesh mesh = Torus(12, 6);
  const FieldOperator op = MustBuildOperator(mesh, FieldType::Vector());
  auto sys = ReducedSystem::Build(
      ::fieldspace::testing::IdentityBasis(FieldType::Vector(), op.dofs()), op);
  ASSERT_TRUE(sys.ok());
  for (const auto& [form, weights] :
       {std::pair{BiharmonicForm::kExact, EnergyWeights{0.0, 1.0, 1.0}},
        std::pair{BiharmonicForm::kMixed, EnergyWeights{0.05, 1.0, 1.0}}}) {
    DesignSessionOptions options;
    options.biharmonic = form;
    auto session = DesignSession::Create(*sys, weights, options);
    ASSERT_TRUE(session.ok()) << session.status();
    for (int64_t id = 0; id < 6; ++id) {
      FieldConstraint c;
      c.face = static_cast<int32_t>((id * 37 + 5) % mesh.num_faces());
      c.value = Eigen::Vector2d(std::cos(id), std::sin(id));
      const bool hard = id < 3 && form == BiharmonicForm::kExact;
      const absl::Status st = (*session)->AddConstraint(
          id, As(hard ? ConstraintKind::kHard : ConstraintKind::kSoft, c));
      ASSERT_TRUE(st.ok()) << st << (hard ? " hard" : " soft") << " constraint " << id
                           << (form == BiharmonicForm::kExact ? ", exact form" : ", mixed form");
    }
    auto fresh = SolveReducedModelProblem(**sys, (*session)->problem());
    ASSERT_TRUE(fresh.ok());
    EXPECT_LT(RelativeDifference((*session)->coefficients(), fresh->coefficients), 1e-6);
    // With U = I the two forms are one (K Mr^-1 K = S M^-1 S = B).
    auto full = SolveModelProblem(op, (*session)->problem());
    ASSERT_TRUE(full.ok()) << full.status();
    EXPECT_LT(RelativeDifference((*session)->coefficients(), *full), 1e-6);
  }
}

}  // namespace
}  // namespace fieldspace
