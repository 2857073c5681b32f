// The Design stream's edit logic without gRPC: DesignEditor on a basis built in the test. Every
// answer must equal a fresh reduced solve of the session's current problem, failed requests must
// leave the session as it was, and each error has its exact code.

#include "server/design_editor.h"

#include <cstring>
#include <map>
#include <memory>
#include <string>

#include "absl/strings/str_cat.h"
#include "core/mesh/shapes.h"
#include "core/subspace/design_tools.h"
#include "core/subspace/model_problem.h"
#include "core/subspace/projection.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "server/field_answers.h"
#include "server/proto_convert.h"

namespace fieldspace::server {
namespace {

namespace v1 = ::fieldspace::v1;

class DesignEditorTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    auto arrays = MakeIcosphere(3, 1.0);  // 1280 faces
    ASSERT_TRUE(arrays.ok()) << arrays.status();
    auto mesh = TriangleMesh::Create(*arrays);
    ASSERT_TRUE(mesh.ok()) << mesh.status();
    auto shared_mesh = std::make_shared<const TriangleMesh>(std::move(*mesh));
    BasisKey key;
    key.mesh_id = "m-test";
    key.field = FieldType::Vector();
    key.dimension = 60;
    key.fields_per_region = 2;
    BuildContext context;
    context.threads = 2;
    auto built = BuildBasisForKey(*shared_mesh, key, Eigen::VectorXd(), context);
    ASSERT_TRUE(built.ok()) << built.status();
    BasisRecord record;
    record.id = "b-test";
    record.key = key;
    auto served = ServeBasis(record, shared_mesh, built->basis, built->op.get(), context);
    ASSERT_TRUE(served.ok()) << served.status();
    basis_ = new std::shared_ptr<const ServedBasis>(*served);
  }
  static void TearDownTestSuite() { delete basis_; }
  // A failed suite set-up must fail every test, not skip it.
  void SetUp() override { ASSERT_NE(basis_, nullptr) << "the test basis could not be built"; }

  static DesignEditor NewEditor() {
    return DesignEditor(
        [](const std::string& id) -> absl::StatusOr<std::shared_ptr<const ServedBasis>> {
          if (id != (*basis_)->record.id) return absl::NotFoundError(absl::StrCat("no ", id));
          return *basis_;
        },
        DesignEditorOptions());
  }

  static v1::DesignRequest Open(double mu_s, double mu_b, double mu_c) {
    v1::DesignRequest r;
    r.set_seq(1);
    r.mutable_open()->set_basis_id("b-test");
    r.mutable_open()->mutable_weights()->set_mu_s(mu_s);
    r.mutable_open()->mutable_weights()->set_mu_b(mu_b);
    r.mutable_open()->mutable_weights()->set_mu_c(mu_c);
    r.mutable_open()->add_watch_faces(10);
    r.mutable_open()->add_watch_faces(600);
    return r;
  }
  static v1::DesignRequest Add(int id, int face, double a, double b, bool hard) {
    v1::DesignRequest r;
    r.mutable_add()->set_id(id);
    v1::Constraint* c = r.mutable_add()->mutable_constraint();
    c->set_face(face);
    c->add_value(a);
    c->add_value(b);
    c->set_hard(hard);
    return r;
  }

  // The update's coefficients equal a fresh solve of the session's problem.
  static void ExpectFresh(const DesignEditor& editor, const v1::DesignUpdate& u) {
    ASSERT_NE(editor.session(), nullptr);
    auto fresh = SolveReducedModelProblem(*(*basis_)->system, editor.session()->problem());
    ASSERT_TRUE(fresh.ok()) << fresh.status();
    ASSERT_EQ(u.coefficients_size(), fresh->coefficients.size());
    const double scale = std::max(fresh->coefficients.norm(), 1e-300);
    double diff = 0;
    for (int i = 0; i < u.coefficients_size(); ++i) {
      diff += std::pow(u.coefficients(i) - fresh->coefficients[i], 2);
    }
    EXPECT_LT(std::sqrt(diff) / scale, 1e-8);
  }

  static std::shared_ptr<const ServedBasis>* basis_;
};

std::shared_ptr<const ServedBasis>* DesignEditorTest::basis_ = nullptr;

TEST_F(DesignEditorTest, EditsMatchFreshSolvesAndWatchedFacesAreLifted) {
  DesignEditor editor = NewEditor();
  v1::DesignUpdate u;
  ASSERT_TRUE(editor.Apply(Open(1, 0.01, 1), &u).ok());
  EXPECT_EQ(u.seq(), 1u);
  EXPECT_TRUE(u.timings().refactorized());
  EXPECT_EQ(u.coefficients_size(), 60);
  EXPECT_EQ(u.watched().values_size(), 4);  // two faces x 2 DOFs
  u.Clear();
  ASSERT_TRUE(editor.Apply(Add(1, 10, 1.0, 0.0, /*hard=*/true), &u).ok());
  ExpectFresh(editor, u);
  // A hard constraint holds in the lifted (watched) value of its face.
  EXPECT_NEAR(u.watched().values(0), 1.0, 1e-5);
  EXPECT_NEAR(u.watched().values(1), 0.0, 1e-5);
  EXPECT_EQ(u.num_hard_constraints(), 1);
  u.Clear();
  ASSERT_TRUE(editor.Apply(Add(2, 600, 0.0, 2.0, /*hard=*/false), &u).ok());
  ExpectFresh(editor, u);
  EXPECT_FALSE(u.timings().refactorized());
  // A move keeps the kind and the weight.
  v1::DesignRequest move;
  move.mutable_move()->set_id(2);
  move.mutable_move()->set_face(601);
  move.mutable_move()->add_value(0.5);
  move.mutable_move()->add_value(0.5);
  u.Clear();
  ASSERT_TRUE(editor.Apply(move, &u).ok());
  ExpectFresh(editor, u);
  auto moved = editor.session()->GetConstraint(2);
  ASSERT_TRUE(moved.ok());
  EXPECT_EQ(moved->face, 601);
  EXPECT_FALSE(moved->hard());
  // Weights: mu_b changes refactorize, mu_c alone does not.
  v1::DesignRequest weights;
  weights.mutable_set_weights()->set_mu_s(1);
  weights.mutable_set_weights()->set_mu_b(0.1);
  weights.mutable_set_weights()->set_mu_c(1);
  u.Clear();
  ASSERT_TRUE(editor.Apply(weights, &u).ok());
  EXPECT_TRUE(u.timings().refactorized());
  ExpectFresh(editor, u);
  weights.mutable_set_weights()->set_mu_c(5);
  u.Clear();
  ASSERT_TRUE(editor.Apply(weights, &u).ok());
  EXPECT_FALSE(u.timings().refactorized());
  ExpectFresh(editor, u);
  // A set_weights that gives only mu_c keeps the session's mu_s and mu_b.
  v1::DesignRequest only_c;
  only_c.mutable_set_weights()->set_mu_c(2);
  u.Clear();
  ASSERT_TRUE(editor.Apply(only_c, &u).ok());
  EXPECT_FALSE(u.timings().refactorized());
  EXPECT_EQ(editor.session()->weights().mu_s, 1);
  EXPECT_EQ(editor.session()->weights().mu_b, 0.1);
  EXPECT_EQ(editor.session()->weights().mu_c, 2);
  ExpectFresh(editor, u);
  v1::DesignRequest remove;
  remove.mutable_remove()->set_id(1);
  u.Clear();
  ASSERT_TRUE(editor.Apply(remove, &u).ok());
  EXPECT_EQ(u.num_constraints(), 1);
  ExpectFresh(editor, u);
}

TEST_F(DesignEditorTest, ErrorsHaveExactCodesAndLeaveTheSessionAsItWas) {
  DesignEditor editor = NewEditor();
  v1::DesignUpdate u;
  EXPECT_EQ(editor.Apply(Add(1, 10, 1, 0, false), &u).code(),
            absl::StatusCode::kFailedPrecondition);  // before open
  EXPECT_EQ(editor.Apply(v1::DesignRequest(), &u).code(), absl::StatusCode::kInvalidArgument);
  v1::DesignRequest unknown = Open(1, 0, 1);
  unknown.mutable_open()->set_basis_id("b-nope");
  EXPECT_EQ(editor.Apply(unknown, &u).code(), absl::StatusCode::kNotFound);
  EXPECT_EQ(editor.Apply(Open(0, 0, 1), &u).code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(editor.Apply(Open(1, 0, 0), &u).code(), absl::StatusCode::kInvalidArgument);
  EXPECT_FALSE(editor.is_open());
  ASSERT_TRUE(editor.Apply(Open(1, 0, 1), &u).ok());
  EXPECT_EQ(editor.Apply(Open(1, 0, 1), &u).code(), absl::StatusCode::kFailedPrecondition);
  u.Clear();
  ASSERT_TRUE(editor.Apply(Add(1, 10, 1, 0, true), &u).ok());
  const std::vector<double> before(u.coefficients().begin(), u.coefficients().end());
  // Each of these fails and changes nothing.
  EXPECT_EQ(editor.Apply(Add(1, 11, 1, 0, false), &u).code(), absl::StatusCode::kAlreadyExists);
  EXPECT_EQ(editor.Apply(Add(2, 10, 0, 1, true), &u).code(),
            absl::StatusCode::kFailedPrecondition);  // the same face hard twice
  EXPECT_EQ(editor.Apply(Add(3, 5000, 1, 0, false), &u).code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(editor.Apply(Add(3, 5, std::nan(""), 0, false), &u).code(),
            absl::StatusCode::kInvalidArgument);
  v1::DesignRequest move;
  move.mutable_move()->set_id(42);
  move.mutable_move()->set_face(3);
  move.mutable_move()->add_value(1);
  move.mutable_move()->add_value(0);
  EXPECT_EQ(editor.Apply(move, &u).code(), absl::StatusCode::kNotFound);
  v1::DesignRequest watch;
  watch.mutable_watch()->add_faces(-1);
  EXPECT_EQ(editor.Apply(watch, &u).code(), absl::StatusCode::kInvalidArgument);
  v1::DesignRequest bad_weights;
  bad_weights.mutable_set_weights()->set_mu_s(-1);
  EXPECT_EQ(editor.Apply(bad_weights, &u).code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(editor.session()->num_constraints(), 1);
  const Eigen::VectorXd& x = editor.session()->coefficients();
  ASSERT_EQ(static_cast<size_t>(x.size()), before.size());
  for (size_t i = 0; i < before.size(); ++i) EXPECT_EQ(x[i], before[i]) << i;
}

// An edit that the session accepts but whose answer cannot be made (a constraint of 1e39 is a
// finite double, but its lifted value overflows float) fails and is undone (found by
// fuzz/design_fuzzer.cc).
TEST_F(DesignEditorTest, EditsWhoseAnswerFailsAreUndone) {
  DesignEditor editor = NewEditor();
  v1::DesignUpdate u;
  ASSERT_TRUE(editor.Apply(Open(1, 0, 1), &u).ok());
  u.Clear();
  ASSERT_TRUE(editor.Apply(Add(1, 10, 1, 0, /*hard=*/true), &u).ok());
  const std::vector<double> before(u.coefficients().begin(), u.coefficients().end());
  const auto expect_unchanged = [&] {
    EXPECT_EQ(editor.session()->num_constraints(), 1);
    EXPECT_EQ(editor.session()->num_hard_constraints(), 1);
    auto kept = editor.session()->GetConstraint(1);
    ASSERT_TRUE(kept.ok()) << kept.status();
    EXPECT_EQ(kept->face, 10);
    EXPECT_EQ(kept->value[0], 1);
    const Eigen::VectorXd& x = editor.session()->coefficients();
    ASSERT_EQ(static_cast<size_t>(x.size()), before.size());
    for (size_t i = 0; i < before.size(); ++i) EXPECT_NEAR(x[i], before[i], 1e-12) << i;
  };
  EXPECT_EQ(editor.Apply(Add(2, 600, 1e39, 0, /*hard=*/true), &u).code(),
            absl::StatusCode::kInvalidArgument);
  expect_unchanged();
  v1::DesignRequest move;
  move.mutable_move()->set_id(1);
  move.mutable_move()->set_face(600);
  move.mutable_move()->add_value(1e39);
  move.mutable_move()->add_value(0);
  EXPECT_EQ(editor.Apply(move, &u).code(), absl::StatusCode::kInvalidArgument);
  expect_unchanged();
  // The session still answers, and equals a fresh solve.
  u.Clear();
  ASSERT_TRUE(editor.Apply(Add(3, 600, 0, 1, /*hard=*/false), &u).ok());
  ExpectFresh(editor, u);
}

// Found by the design fuzzer: a failed weight change (its field overflowed float) was undone by
// setting the old weights again, whose re-solve agreed with the old coefficients only to rounding
// (1.6e-15 relative); the session answers exactly its old coefficients now, for every kind of
// edit. A soft constraint of 5e38 is pulled about half way at mu_c = 1 (below float's 3.4e38) and
// all the way at mu_c = 1e6 (beyond it; mu_b changes too, so the undo refactorizes); so is one
// of 2e39 at mu_c = 1.
TEST_F(DesignEditorTest, FailedEditsLeaveTheCoefficientsBitForBit) {
  DesignEditor editor = NewEditor();
  v1::DesignUpdate u;
  ASSERT_TRUE(editor.Apply(Open(1, 0, 1), &u).ok());
  u.Clear();
  ASSERT_TRUE(editor.Apply(Add(1, 10, 5e38, 0, /*hard=*/false), &u).ok());
  ASSERT_TRUE(editor.Apply(Add(2, 600, 1, 2, /*hard=*/true), &u).ok());
  const Eigen::VectorXd before = editor.session()->coefficients();
  const auto expect_bitwise_unchanged = [&](const char* what) {
    const Eigen::VectorXd& x = editor.session()->coefficients();
    ASSERT_EQ(x.size(), before.size()) << what;
    EXPECT_EQ(std::memcmp(x.data(), before.data(), sizeof(double) * x.size()), 0) << what;
    EXPECT_EQ(editor.session()->num_constraints(), 2) << what;
  };
  v1::DesignRequest weights;
  weights.mutable_set_weights()->set_mu_c(1e6);
  weights.mutable_set_weights()->set_mu_b(0.64);
  EXPECT_EQ(editor.Apply(weights, &u).code(), absl::StatusCode::kInvalidArgument);
  expect_bitwise_unchanged("set_weights");
  v1::DesignRequest move;
  move.mutable_move()->set_id(1);
  move.mutable_move()->set_face(10);
  move.mutable_move()->add_value(2e39);
  move.mutable_move()->add_value(0);
  EXPECT_EQ(editor.Apply(move, &u).code(), absl::StatusCode::kInvalidArgument);
  expect_bitwise_unchanged("move");
  EXPECT_EQ(editor.Apply(Add(3, 10, 2e39, 0, /*hard=*/false), &u).code(),
            absl::StatusCode::kInvalidArgument);
  expect_bitwise_unchanged("add");
}

// Sessions opened with singularities: every update's changes, applied to the previous state, give
// the singularities of its own coefficients (computed afresh), and the indices sum to the sphere's
// Euler characteristic 2 after every edit that leaves a nonzero field.
TEST_F(DesignEditorTest, SingularityChangesTrackTheField) {
  DesignEditor editor = NewEditor();
  v1::DesignRequest open = Open(1, 0, 1);
  open.mutable_open()->set_singularities(true);
  std::map<int32_t, int32_t> state;  // vertex -> index, from the changes alone
  const auto check = [&](const v1::DesignUpdate& u) {
    ASSERT_TRUE(u.has_singularities());
    const v1::SingularityChanges& c = u.singularities();
    for (int32_t v : c.vanished()) {
      EXPECT_EQ(state.erase(v), 1u) << "vertex " << v << " vanished but was not singular";
    }
    for (const v1::Singularity& s : c.appeared()) state[s.vertex()] = s.index();
    EXPECT_EQ(c.count(), static_cast<int32_t>(state.size()));
    Eigen::VectorXd x(u.coefficients_size());
    for (int i = 0; i < x.size(); ++i) x[i] = u.coefficients(i);
    auto dofs = fieldspace::Lift(*(*basis_)->system, x);
    ASSERT_TRUE(dofs.ok());
    v1::SingularitiesResponse fresh;
    ASSERT_TRUE(SingularitiesToProto(**basis_, *dofs, 0, &fresh).ok());
    std::map<int32_t, int32_t> expected;
    for (const v1::Singularity& s : fresh.singularities()) expected[s.vertex()] = s.index();
    EXPECT_EQ(state, expected);
    // Poincare-Hopf once the field is not zero (with no constraint it is, and every vertex is
    // undefined).
    if (x.norm() > 0) EXPECT_EQ(c.index_sum(), 2.0);
  };
  v1::DesignUpdate u;
  ASSERT_TRUE(editor.Apply(open, &u).ok());
  EXPECT_EQ(u.singularities().vanished_size(), 0);
  check(u);
  int changes_seen = 0;
  for (int step = 0; step < 6; ++step) {
    u.Clear();
    ASSERT_TRUE(editor.Apply(Add(step + 1, 97 * step + 5, 1.0, 0.3 * step - 0.5, false), &u).ok());
    check(u);
    changes_seen += u.singularities().appeared_size() + u.singularities().vanished_size();
  }
  EXPECT_GT(changes_seen, 0);  // constraints in new places move the singularities
  // Without the option, updates carry none.
  DesignEditor plain = NewEditor();
  u.Clear();
  ASSERT_TRUE(plain.Apply(Open(1, 0, 1), &u).ok());
  EXPECT_FALSE(u.has_singularities());
}

// Issue 15, B10: an opening session's memory is admitted (DesignEditorOptions::admit_work) and
// held for the session's lifetime; a refusal leaves no session open.
TEST_F(DesignEditorTest, SessionMemoryIsAdmittedForTheSessionsLifetime) {
  struct Account : WorkAccount {
    void ReleaseWork(int64_t bytes) override { held -= bytes; }
    int64_t held = 0;
  } account;
  bool refuse = false;
  DesignEditorOptions options;
  options.admit_work = [&](int64_t bytes, absl::string_view what) -> absl::StatusOr<WorkGrant> {
    if (refuse) return absl::ResourceExhaustedError(absl::StrCat(what, " refused"));
    account.held += bytes;
    return WorkGrant(&account, bytes);
  };
  const auto lookup = [](const std::string&) -> absl::StatusOr<std::shared_ptr<const ServedBasis>> {
    return *basis_;
  };
  const int64_t expected = DesignSessionOpenBytes(*(*basis_)->system);
  EXPECT_GT(expected, 8 * (*basis_)->system->dimension());
  {
    DesignEditor editor(lookup, options);
    v1::DesignUpdate u;
    ASSERT_TRUE(editor.Apply(Open(1, 0, 1), &u).ok());
    EXPECT_EQ(account.held, expected);
    ASSERT_TRUE(editor.Apply(Add(1, 20, 1.0, 0.0, false), &u).ok());
    EXPECT_EQ(account.held, expected + DesignSessionConstraintBytes(*(*basis_)->system, 1));
  }
  EXPECT_EQ(account.held, 0);  // released with the session
  refuse = true;
  DesignEditor refused(lookup, options);
  v1::DesignUpdate u;
  const absl::Status st = refused.Apply(Open(1, 0, 1), &u);
  EXPECT_EQ(st.code(), absl::StatusCode::kResourceExhausted) << st;
  EXPECT_THAT(st.message(), ::testing::HasSubstr("this design session"));
  EXPECT_FALSE(refused.is_open());
  EXPECT_EQ(account.held, 0);
}

// Issue 15, B10: constraints are admitted as they are added (a session's dense constraint
// matrices grow with the square of their rows: 20,000 vector constraints would take 77 GB).
// Within a budget the account never holds more than it, always covers what the constraints
// need, and refuses only when they need more than a quarter of it (the grant grows by doubling,
// so it holds less than twice the need); a refused add leaves the session as it was.
TEST_F(DesignEditorTest, ConstraintMemoryIsAdmittedAsConstraintsAreAdded) {
  const ReducedSystem& system = *(*basis_)->system;
  const int64_t open_bytes = DesignSessionOpenBytes(system);
  const int64_t budget = open_bytes + DesignSessionConstraintBytes(system, 40);
  struct Account : WorkAccount {
    void ReleaseWork(int64_t bytes) override { held -= bytes; }
    int64_t held = 0;
  } account;
  DesignEditorOptions options;
  options.admit_work = [&](int64_t bytes, absl::string_view what) -> absl::StatusOr<WorkGrant> {
    if (account.held + bytes > budget) {
      return absl::ResourceExhaustedError(absl::StrCat(what, " refused"));
    }
    account.held += bytes;
    return WorkGrant(&account, bytes);
  };
  const auto lookup = [](const std::string&) -> absl::StatusOr<std::shared_ptr<const ServedBasis>> {
    return *basis_;
  };
  {
    DesignEditor editor(lookup, options);
    v1::DesignUpdate u;
    ASSERT_TRUE(editor.Apply(Open(1, 0, 1), &u).ok());
    v1::DesignUpdate last;
    int added = 0;
    absl::Status refused;
    for (int id = 1; id <= 60 && refused.ok(); ++id) {
      u.Clear();
      refused = editor.Apply(Add(id, 7 * id, 1.0, 0.5, false), &u);
      if (refused.ok()) {
        ++added;
        last = u;
        EXPECT_GE(account.held, open_bytes + DesignSessionConstraintBytes(system, added));
        EXPECT_LE(account.held, budget);
      }
    }
    EXPECT_EQ(refused.code(), absl::StatusCode::kResourceExhausted) << refused;
    EXPECT_THAT(refused.message(), ::testing::HasSubstr("constraints refused"));
    EXPECT_LT(added, 40);
    EXPECT_GT(4 * DesignSessionConstraintBytes(system, added + 1), budget - open_bytes);
    // The session still has `added` constraints: a weight change answers their field.
    v1::DesignRequest touch;
    touch.mutable_set_weights()->set_mu_c(1.0);
    u.Clear();
    ASSERT_TRUE(editor.Apply(touch, &u).ok());
    ASSERT_EQ(u.coefficients_size(), last.coefficients_size());
    for (int i = 0; i < u.coefficients_size(); ++i) {
      EXPECT_NEAR(u.coefficients(i), last.coefficients(i), 1e-9) << i;
    }
  }
  EXPECT_EQ(account.held, 0);
}

// The designer's tools: each is one group under its id (its faces' constraints as the core
// functions make them), moved and removed as one, every answer a fresh solve; a tool the mesh
// cannot take fails with its code and leaves the session as it was.
TEST_F(DesignEditorTest, ToolsAreConstraintGroupsMovedAndRemovedAsOne) {
  const TriangleMesh& mesh = *(*basis_)->mesh;
  DesignEditor editor = NewEditor();
  v1::DesignRequest open = Open(1, 0, 1);
  open.mutable_open()->set_singularities(true);
  v1::DesignUpdate u;
  ASSERT_TRUE(editor.Apply(open, &u).ok());
  v1::DesignRequest stroke;
  stroke.mutable_add_stroke()->set_id(1);
  v1::SurfacePoint::FacePoint* p = stroke.mutable_add_stroke()->add_points()->mutable_face_point();
  p->set_face(3);
  for (double w : {0.2, 0.3, 0.5}) p->add_barycentric(w);
  const Eigen::Vector3d far = mesh.face_barycenters().row(900).transpose();
  v1::Point3* q = stroke.mutable_add_stroke()->add_points()->mutable_position();
  q->set_x(1.1 * far.x());  // off the surface: snapped
  q->set_y(1.1 * far.y());
  q->set_z(1.1 * far.z());
  u.Clear();
  ASSERT_TRUE(editor.Apply(stroke, &u).ok());
  ExpectFresh(editor, u);
  auto expected =
      StrokeConstraints(mesh, FieldType::Vector(),
                        {SurfacePoint{3, {0.2, 0.3, 0.5}}, *SnapToSurface(mesh, 1.1 * far)});
  ASSERT_TRUE(expected.ok()) << expected.status();
  EXPECT_EQ(u.num_constraints(), static_cast<int32_t>(expected->size()));
  EXPECT_TRUE(editor.session()->IsConstraintGroup(1));

  // A +1 singularity at vertex 40 (soft: this 60-dimensional basis has too few fields around one
  // vertex for 12 hard rows): the update reports it there.
  v1::DesignRequest singularity;
  singularity.mutable_place_singularity()->set_id(2);
  singularity.mutable_place_singularity()->set_vertex(40);
  singularity.mutable_place_singularity()->set_index(1.0);
  singularity.mutable_place_singularity()->set_weight(100);
  u.Clear();
  ASSERT_TRUE(editor.Apply(singularity, &u).ok());
  ExpectFresh(editor, u);
  bool found = false;
  for (const v1::Singularity& s : u.singularities().appeared()) {
    if (s.vertex() == 40) found = s.index() == 1;
  }
  EXPECT_TRUE(found);
  const int32_t with_both = u.num_constraints();

  // Move the stroke (reversed: the same faces, opposite values) and then the singularity's group
  // to a stroke: each one edit.
  v1::DesignRequest move;
  move.mutable_move()->set_id(1);
  *move.mutable_move()->mutable_group()->mutable_stroke() = stroke.add_stroke();
  move.mutable_move()->mutable_group()->mutable_stroke()->mutable_points()->SwapElements(0, 1);
  u.Clear();
  ASSERT_TRUE(editor.Apply(move, &u).ok());
  ExpectFresh(editor, u);
  EXPECT_EQ(u.num_constraints(), with_both);
  move.mutable_move()->set_id(2);
  u.Clear();
  ASSERT_TRUE(editor.Apply(move, &u).ok());
  ExpectFresh(editor, u);

  // Tools a sphere cannot take, bad tools, a group move on a single constraint, a hard group on
  // hard faces: exact codes, session unchanged.
  const Eigen::VectorXd before = editor.session()->coefficients();
  const int32_t constraints = editor.session()->num_constraints();
  const auto expect_unchanged = [&](const char* what) {
    EXPECT_EQ(editor.session()->num_constraints(), constraints) << what;
    EXPECT_EQ(std::memcmp(editor.session()->coefficients().data(), before.data(),
                          sizeof(double) * before.size()),
              0)
        << what;
  };
  v1::DesignRequest boundary;
  boundary.mutable_align_boundary()->set_id(3);
  EXPECT_EQ(editor.Apply(boundary, &u).code(), absl::StatusCode::kFailedPrecondition);
  expect_unchanged("boundary");
  v1::DesignRequest features;
  features.mutable_align_features()->set_id(3);
  EXPECT_EQ(editor.Apply(features, &u).code(), absl::StatusCode::kFailedPrecondition);
  expect_unchanged("features");
  v1::DesignRequest bad = singularity;
  bad.mutable_place_singularity()->set_id(3);
  bad.mutable_place_singularity()->set_index(0.5);
  EXPECT_EQ(editor.Apply(bad, &u).code(), absl::StatusCode::kInvalidArgument);
  expect_unchanged("index 0.5");
  bad = stroke;
  bad.mutable_add_stroke()->set_id(3);
  bad.mutable_add_stroke()->mutable_points()->RemoveLast();
  EXPECT_EQ(editor.Apply(bad, &u).code(), absl::StatusCode::kInvalidArgument);
  expect_unchanged("one point");
  bad = stroke;
  bad.mutable_add_stroke()->set_id(1);
  EXPECT_EQ(editor.Apply(bad, &u).code(), absl::StatusCode::kAlreadyExists);
  expect_unchanged("id in use");
  ASSERT_TRUE(editor.Apply(Add(9, 1000, 1, 0, /*hard=*/true), &u).ok());
  move.mutable_move()->set_id(9);
  EXPECT_EQ(editor.Apply(move, &u).code(), absl::StatusCode::kFailedPrecondition);
  // A hard stroke inside face 1000, already hard-constrained: dependent.
  bad.Clear();
  bad.mutable_add_stroke()->set_id(5);
  bad.mutable_add_stroke()->set_hard(true);
  for (double w : {0.1, 0.8}) {
    v1::SurfacePoint::FacePoint* f = bad.mutable_add_stroke()->add_points()->mutable_face_point();
    f->set_face(1000);
    f->add_barycentric(w);
    f->add_barycentric(1 - w);
    f->add_barycentric(0);
  }
  const Eigen::VectorXd hard_before = editor.session()->coefficients();
  EXPECT_EQ(editor.Apply(bad, &u).code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_EQ(std::memcmp(editor.session()->coefficients().data(), hard_before.data(),
                        sizeof(double) * hard_before.size()),
            0);
  EXPECT_FALSE(editor.session()->HasConstraint(5));
  v1::DesignRequest remove;
  remove.mutable_remove()->set_id(9);
  ASSERT_TRUE(editor.Apply(remove, &u).ok());
  // Now the same stroke is accepted.
  ASSERT_TRUE(editor.Apply(bad, &u).ok());

  // Removing the groups, one edit each, leaves nothing.
  for (int id : {1, 2, 5}) {
    remove.mutable_remove()->set_id(id);
    u.Clear();
    ASSERT_TRUE(editor.Apply(remove, &u).ok()) << id;
    ExpectFresh(editor, u);
  }
  EXPECT_EQ(u.num_constraints(), 0);
}

}  // namespace
}  // namespace fieldspace::server
