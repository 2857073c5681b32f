#include "core/subspace/reduced_system.h"

#include <atomic>
#include <limits>
#include <memory>

#include "Eigen/Dense"
#include "core/subspace/model_problem.h"
#include "core/subspace/projection.h"
#include "core/subspace/subspace_util.h"
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
using ::fieldspace::testing::RelativeDifference;
using ::fieldspace::testing::StatusIs;
using ::fieldspace::testing::Torus;

struct DenseReference {
  Eigen::MatrixXd S, B, M;
};

// U^T S U, U^T S M^-1 S U, U^T M U computed densely (independent of the sparse row pass).
DenseReference Reference(const FieldOperator& op, const Basis& basis) {
  const Eigen::MatrixXd U = DenseU(basis);
  const Eigen::MatrixXd S = Eigen::MatrixXd(op.stiffness);
  const Eigen::MatrixXd SU = S * U;
  DenseReference r;
  r.S = U.transpose() * SU;
  r.B = SU.transpose() * op.mass.cwiseInverse().asDiagonal() * SU;
  r.M = U.transpose() * op.mass.asDiagonal() * U;
  return r;
}

void ExpectMatchesReference(const ReducedSystem& sys, const DenseReference& ref) {
  EXPECT_LT(RelativeDifference(Eigen::MatrixXd(sys.stiffness()), ref.S), 1e-12);
  EXPECT_LT(RelativeDifference(Eigen::MatrixXd(sys.bilaplacian()), ref.B), 1e-12);
  EXPECT_LT(RelativeDifference(Eigen::MatrixXd(sys.mass_matrix()), ref.M), 1e-12);
  // Exactly symmetric storage, one shared pattern.
  for (const auto* m : {&sys.stiffness(), &sys.bilaplacian(), &sys.mass_matrix()}) {
    const Eigen::MatrixXd D = *m;
    EXPECT_EQ((D - D.transpose()).cwiseAbs().maxCoeff(), 0.0);
    EXPECT_TRUE(sys.pattern_symbolic()->SamePattern(*m));
  }
}

TEST(ReducedSystemTest, MatchesDenseProductsForEachFieldType) {
  const TriangleMesh mesh = Icosphere(2);  // 320 faces
  for (const FieldType& type : {FieldType::Vector(), FieldType::NField(4), FieldType::Tensor()}) {
    const FieldOperator op = MustBuildOperator(mesh, type);
    auto basis = RandomBasis(type, op.dofs(), 60, 12, 7);
    auto sys = ReducedSystem::Build(basis, op);
    ASSERT_TRUE(sys.ok()) << sys.status();
    EXPECT_EQ((*sys)->dimension(), 60);
    EXPECT_EQ((*sys)->dofs(), op.dofs());
    EXPECT_EQ((*sys)->num_faces(), mesh.num_faces());
    ExpectMatchesReference(**sys, Reference(op, *basis));
    const ReducedSystemStats& st = (*sys)->stats();
    EXPECT_GT(st.bilaplacian_nonzeros, 0);
    EXPECT_LE(st.mass_nonzeros, st.pattern_nonzeros);
    EXPECT_GE(st.factor_nonzeros, (st.pattern_nonzeros + 60) / 2);
    EXPECT_GT(st.memory_bytes, (*sys)->lift_plan().memory_bytes());
    EXPECT_EQ((*sys)->lift_plan().num_faces(), mesh.num_faces());
  }
}

// From the mesh alone: a vector field's S rows computed face by face give the system of the
// assembled S, bit for bit on one thread (threads sum their accumulators in the order they
// finish); other fields assemble S and match too. A mesh of another size is refused.
TEST(ReducedSystemTest, FromTheMeshIsTheSystemOfTheAssembledOperator) {
  const TriangleMesh mesh = Torus(24, 12);
  for (const FieldType& type : {FieldType::Vector(), FieldType::Tensor()}) {
    SCOPED_TRACE(type.ToString());
    const FieldOperator op = MustBuildOperator(mesh, type);
    auto basis = RandomBasis(type, op.dofs(), 90, 30, 11);
    ReducedSystemOptions banded;
    banded.accumulator_budget_bytes = 1;
    banded.threads = 1;
    for (const ReducedSystemOptions& options : {ReducedSystemOptions(), banded}) {
      auto assembled = ReducedSystem::Build(basis, op, options);
      auto from_mesh = ReducedSystem::Build(basis, mesh, options);
      ASSERT_TRUE(assembled.ok()) << assembled.status();
      ASSERT_TRUE(from_mesh.ok()) << from_mesh.status();
      for (int which = 0; which < 3; ++which) {
        const auto pick = [&](const ReducedSystem& sys) -> const Eigen::SparseMatrix<double>& {
          return which == 0 ? sys.stiffness() : which == 1 ? sys.bilaplacian() : sys.mass_matrix();
        };
        const Eigen::SparseMatrix<double>& a = pick(**assembled);
        const Eigen::SparseMatrix<double>& b = pick(**from_mesh);
        ASSERT_EQ(a.nonZeros(), b.nonZeros());
        if (options.threads == 1) {
          EXPECT_TRUE(std::equal(a.valuePtr(), a.valuePtr() + a.nonZeros(), b.valuePtr()))
              << "matrix " << which;
        } else {  // threads sum their accumulators in whatever order they finish
          EXPECT_LT(RelativeDifference(Eigen::MatrixXd(a), Eigen::MatrixXd(b)), 1e-14)
              << "matrix " << which;
        }
        EXPECT_TRUE(
            std::equal(a.innerIndexPtr(), a.innerIndexPtr() + a.nonZeros(), b.innerIndexPtr()));
      }
      EXPECT_EQ((*from_mesh)->mass(), op.mass);
    }
  }
  const TriangleMesh other = Icosphere(2);
  auto basis = RandomBasis(FieldType::Vector(), 2 * mesh.num_faces(), 40, 20, 3);
  EXPECT_THAT(ReducedSystem::Build(basis, other), StatusIs(absl::StatusCode::kInvalidArgument));
}

TEST(ReducedSystemTest, BandedAccumulationAndThreadCountGiveTheSameMatrices) {
  const TriangleMesh mesh = Torus(24, 12);
  const FieldOperator op = MustBuildOperator(mesh, FieldType::Vector());
  auto basis = RandomBasis(FieldType::Vector(), op.dofs(), 90, 30, 11);
  auto full = ReducedSystem::Build(basis, op);
  ReducedSystemOptions banded;
  banded.accumulator_budget_bytes = 1;  // one output column per band
  banded.threads = 1;
  auto narrow = ReducedSystem::Build(basis, op, banded);
  ASSERT_TRUE(full.ok() && narrow.ok());
  ExpectMatchesReference(**narrow, Reference(op, *basis));
  EXPECT_LT(RelativeDifference(Eigen::MatrixXd((*full)->bilaplacian()),
                               Eigen::MatrixXd((*narrow)->bilaplacian())),
            1e-14);
}

TEST(ReducedSystemTest, MassFactorSolvesTheReducedMass) {
  const TriangleMesh mesh = Icosphere(2);
  const FieldOperator op = MustBuildOperator(mesh, FieldType::Vector());
  auto sys = ReducedSystem::Build(RandomBasis(FieldType::Vector(), op.dofs(), 50, 20, 3), op);
  ASSERT_TRUE(sys.ok());
  const Eigen::VectorXd b = Eigen::VectorXd::Random(50);
  const Eigen::VectorXd x = (*sys)->mass_factor().Solve(b);
  EXPECT_LT(((*sys)->mass_matrix() * x - b).norm() / b.norm(), 1e-12);
}

TEST(ReducedSystemTest, ProgressAndCancellation) {
  const TriangleMesh mesh = Icosphere(2);
  const FieldOperator op = MustBuildOperator(mesh, FieldType::Vector());
  auto basis = RandomBasis(FieldType::Vector(), op.dofs(), 40, 20, 9);
  std::atomic<int> calls{0};
  std::atomic<bool> saw_end{false};
  ReducedSystemOptions options;
  options.progress = [&](double fraction) {
    EXPECT_GT(fraction, 0.0);
    EXPECT_LE(fraction, 1.0);
    ++calls;
    if (fraction == 1.0) saw_end = true;
  };
  ASSERT_TRUE(ReducedSystem::Build(basis, op, options).ok());
  EXPECT_GT(calls.load(), 0);
  EXPECT_TRUE(saw_end.load());
  std::atomic<bool> cancel{true};
  ReducedSystemOptions cancelled;
  cancelled.cancel = &cancel;
  EXPECT_THAT(ReducedSystem::Build(basis, op, cancelled), StatusIs(absl::StatusCode::kCancelled));
}

TEST(ReducedSystemTest, InvalidInputs) {
  const TriangleMesh mesh = Icosphere(1);
  const FieldOperator op = MustBuildOperator(mesh, FieldType::Vector());
  auto basis = RandomBasis(FieldType::Vector(), op.dofs(), 10, 8, 1);
  EXPECT_THAT(ReducedSystem::Build(nullptr, op), StatusIs(absl::StatusCode::kInvalidArgument));
  // Basis for another field type.
  auto tensor_basis = RandomBasis(FieldType::Tensor(), op.dofs(), 10, 8, 1);
  EXPECT_THAT(ReducedSystem::Build(tensor_basis, op), StatusIs(absl::StatusCode::kInvalidArgument));
  // Wrong number of rows.
  auto short_basis = RandomBasis(FieldType::Vector(), op.dofs() - 2, 10, 8, 1);
  EXPECT_THAT(ReducedSystem::Build(short_basis, op), StatusIs(absl::StatusCode::kInvalidArgument));
  // No columns.
  auto empty = std::make_shared<Basis>();
  empty->U.resize(op.dofs(), 0);
  EXPECT_THAT(ReducedSystem::Build(empty, op), StatusIs(absl::StatusCode::kInvalidArgument));
  // Non-finite basis value.
  auto nan_basis = RandomBasis(FieldType::Vector(), op.dofs(), 10, 8, 1);
  nan_basis->U.valuePtr()[5] = std::numeric_limits<float>::quiet_NaN();
  EXPECT_THAT(ReducedSystem::Build(nan_basis, op), StatusIs(absl::StatusCode::kInvalidArgument));
  // Non-positive mass.
  FieldOperator bad_mass = op;
  bad_mass.mass[0] = 0;
  EXPECT_THAT(ReducedSystem::Build(basis, bad_mass), StatusIs(absl::StatusCode::kInvalidArgument));
  // Bad options.
  ReducedSystemOptions bad_options;
  bad_options.threads = -1;
  EXPECT_THAT(ReducedSystem::Build(basis, op, bad_options),
              StatusIs(absl::StatusCode::kInvalidArgument));
  // Linearly dependent columns: U^T M U singular.
  auto dependent = std::make_shared<Basis>(*basis);
  Eigen::MatrixXf dense = Eigen::MatrixXf(dependent->U);
  dense.col(3) = dense.col(4);
  dependent->U = dense.sparseView();
  EXPECT_THAT(ReducedSystem::Build(dependent, op), StatusIs(absl::StatusCode::kFailedPrecondition));
  // A zero column.
  dense = Eigen::MatrixXf(basis->U);
  dense.col(2).setZero();
  auto zero_column = std::make_shared<Basis>(*basis);
  zero_column->U = dense.sparseView();
  EXPECT_THAT(ReducedSystem::Build(zero_column, op),
              StatusIs(absl::StatusCode::kFailedPrecondition));
}

// A store keeps the reduced matrices (EncodeReducedMatrices) so that a basis loaded again skips
// the product pass: the bytes give back the same matrices bit for bit, and a system built from
// them equals one built from U (same matrices, same factorization, same lift).
TEST(ReducedSystemTest, EncodedMatricesBuildTheSameSystem) {
  const TriangleMesh mesh = Torus(24, 12);
  for (const FieldType& type : {FieldType::Vector(), FieldType::NField(4), FieldType::Tensor()}) {
    const FieldOperator op = MustBuildOperator(mesh, type);
    auto basis = RandomBasis(type, op.dofs(), 48, 10, 3);
    auto built = ReducedSystem::Build(basis, op);
    ASSERT_TRUE(built.ok()) << built.status();
    EXPECT_FALSE((*built)->stats().products_given);
    const std::string bytes = EncodeReducedMatrices(**built);
    auto decoded = DecodeReducedMatrices(bytes);
    ASSERT_TRUE(decoded.ok()) << decoded.status();
    auto given = ReducedSystem::Build(basis, op.mass, *std::move(decoded));
    ASSERT_TRUE(given.ok()) << given.status();
    const ReducedSystem& a = **built;
    const ReducedSystem& b = **given;
    EXPECT_TRUE(b.stats().products_given);
    EXPECT_EQ(b.stats().products_seconds, 0.0);
    for (auto [x, y] :
         {std::pair{&a.stiffness(), &b.stiffness()}, std::pair{&a.bilaplacian(), &b.bilaplacian()},
          std::pair{&a.mass_matrix(), &b.mass_matrix()}}) {
      EXPECT_EQ(Eigen::MatrixXd(*x), Eigen::MatrixXd(*y));
    }
    EXPECT_EQ(b.stats().pattern_nonzeros, a.stats().pattern_nonzeros);
    EXPECT_EQ(b.stats().stiffness_nonzeros, a.stats().stiffness_nonzeros);
    EXPECT_EQ(b.stats().factor_nonzeros, a.stats().factor_nonzeros);
    const Eigen::VectorXd rhs = Eigen::VectorXd::LinSpaced(48, -1.0, 2.0);
    EXPECT_EQ(a.mass_factor().Solve(rhs), b.mass_factor().Solve(rhs));
    // The given system is a full one: it still matches the dense products.
    ExpectMatchesReference(b, Reference(op, *basis));
  }
}

// A served system keeps only the LiftPlan (ReducedSystemOptions::release_basis_rows): its basis
// has U's dimensions and none of its nonzeros, it holds no reference to the caller's Basis, and
// everything that reads U's rows (projections, weighted masses, constraint rows, solves, lifts)
// gives what the system with U gives.
TEST(ReducedSystemTest, ReleasedRowsServeTheSameResults) {
  const TriangleMesh mesh = Torus(24, 12);
  for (const FieldType& type : {FieldType::Vector(), FieldType::NField(4), FieldType::Tensor()}) {
    SCOPED_TRACE(type.ToString());
    const FieldOperator op = MustBuildOperator(mesh, type);
    std::shared_ptr<const Basis> basis = RandomBasis(type, op.dofs(), 48, 10, 3);
    auto full = ReducedSystem::Build(basis, op);
    ReducedSystemOptions release;
    release.release_basis_rows = true;
    auto served = ReducedSystem::Build(basis, op, release);
    ASSERT_TRUE(full.ok() && served.ok());
    const ReducedSystem& a = **full;
    const ReducedSystem& b = **served;
    EXPECT_FALSE(a.basis_rows_released());
    EXPECT_TRUE(b.basis_rows_released());
    EXPECT_EQ(b.basis().U.nonZeros(), 0);
    EXPECT_EQ(b.dofs(), a.dofs());
    EXPECT_EQ(b.dimension(), a.dimension());
    // Everything but U's nonzeros is kept.
    EXPECT_TRUE(b.basis().type == basis->type);
    EXPECT_EQ(b.basis().params.dimension, basis->params.dimension);
    EXPECT_EQ(b.basis().params.sigma, basis->params.sigma);
    EXPECT_EQ(b.basis().params.face_weights, basis->params.face_weights);
    EXPECT_EQ(b.basis().radius, basis->radius);
    EXPECT_EQ(b.basis().sample_faces, basis->sample_faces);
    EXPECT_EQ(b.basis().local_eigenvalues, basis->local_eigenvalues);
    EXPECT_EQ(b.basis().coverage_radius, basis->coverage_radius);
    EXPECT_EQ(b.basis().uncovered_faces, basis->uncovered_faces);
    EXPECT_EQ(b.basis().kernel_columns, basis->kernel_columns);
    // U's 8 bytes a nonzero are gone (its k + 1 row offsets stay).
    EXPECT_LE(b.basis().MemoryBytes(), basis->MemoryBytes() - 8 * basis->U.nonZeros());
    EXPECT_EQ(basis.use_count(), 2);  // here and in `full`: `served` holds no reference

    // Every row, from the LiftPlan, equals U's.
    BasisRowScratch scratch;
    for (int64_t i = 0; i < a.dofs(); ++i) {
      const BasisRow u = GetBasisRow(basis->U, i);
      const BasisRow r = b.BasisRowOf(i, &scratch);
      ASSERT_EQ(r.size, u.size) << i;
      for (int64_t q = 0; q < u.size; ++q) {
        ASSERT_EQ(r.cols[q], u.cols[q]) << i;
        ASSERT_EQ(r.vals[q], u.vals[q]) << i;
      }
    }

    // Projections, a weighted mass, a solve with soft (scale-free) and hard constraints, lifts.
    Eigen::MatrixXd fields(a.dofs(), 2);
    fields.col(0) = RandomVector(a.dofs(), 5);
    fields.col(1) = RandomVector(a.dofs(), 6);
    auto pa = ProjectMany(a, fields);
    auto pb = ProjectMany(b, fields);
    ASSERT_TRUE(pa.ok() && pb.ok());
    EXPECT_LT(RelativeDifference(pb->coefficients, pa->coefficients), 1e-12);
    EXPECT_LT(RelativeDifference(pb->relative_errors, pa->relative_errors), 1e-12);
    auto qa = Project(a, fields.col(0));  // one field: its own loop over the plan
    auto qb = Project(b, fields.col(0));
    ASSERT_TRUE(qa.ok() && qb.ok());
    EXPECT_LT(RelativeDifference(qb->coefficients, qa->coefficients), 1e-12);
    EXPECT_LT(RelativeDifference(qb->coefficients, pa->coefficients.col(0)), 1e-12);
    EXPECT_NEAR(qb->relative_error, qa->relative_error, 1e-10 * qa->relative_error);
    EXPECT_GT(qa->relative_error, 0.1);  // a random field is far from the span
    const Eigen::VectorXd weights = Eigen::VectorXd::LinSpaced(a.dofs(), 0.5, 2.0);
    auto wa = WeightedMassMatrix(a, weights);
    auto wb = WeightedMassMatrix(b, weights);
    ASSERT_TRUE(wa.ok() && wb.ok());
    EXPECT_LT(RelativeDifference(Eigen::MatrixXd(*wb), Eigen::MatrixXd(*wa)), 1e-13);
    ModelProblem problem;
    problem.weights.mu_s = 1.0;
    problem.weights.mu_c = 10.0;
    problem.scale_free = true;
    const int32_t p = type.dofs_per_face();
    for (int32_t face : {3, 100, 401}) {
      problem.constraints.push_back({face, Eigen::VectorXd::Ones(p), 1.0, ConstraintKind::kSoft});
    }
    problem.constraints.push_back(
        {250, Eigen::VectorXd::LinSpaced(p, -1.0, 1.0), 1.0, ConstraintKind::kHard});
    auto sa = SolveReducedModelProblem(a, problem);
    auto sb = SolveReducedModelProblem(b, problem);
    ASSERT_TRUE(sa.ok()) << sa.status();
    ASSERT_TRUE(sb.ok()) << sb.status();
    EXPECT_LT(RelativeDifference(sb->coefficients, sa->coefficients), 1e-10);
    auto la = Lift(a, sa->coefficients);
    auto lb = Lift(b, sa->coefficients);
    ASSERT_TRUE(la.ok() && lb.ok());
    EXPECT_EQ(*lb, *la);
    // The basis alone cannot lift any more: its rows are gone.
    EXPECT_THAT(Lift(b.basis(), sa->coefficients), StatusIs(absl::StatusCode::kFailedPrecondition));
    EXPECT_THAT(LiftFaces(b.basis(), sa->coefficients, std::vector<int32_t>{0}),
                StatusIs(absl::StatusCode::kFailedPrecondition));
  }
}

// What a daemon's load builds (U read from the store straight into a LiftPlan, the reduced
// matrices from their cache): the system of the basis with U, released rows and all.
TEST(ReducedSystemTest, BasisReadAsALiftPlan) {
  const TriangleMesh mesh = Torus(24, 12);
  for (const FieldType& type : {FieldType::Vector(), FieldType::NField(4), FieldType::Tensor()}) {
    SCOPED_TRACE(type.ToString());
    const FieldOperator op = MustBuildOperator(mesh, type);
    std::shared_ptr<const Basis> basis = RandomBasis(type, op.dofs(), 48, 10, 3);
    auto full = ReducedSystem::Build(basis, op);
    ASSERT_TRUE(full.ok()) << full.status();
    const ReducedSystem& a = **full;
    auto matrices = DecodeReducedMatrices(EncodeReducedMatrices(a));
    ASSERT_TRUE(matrices.ok()) << matrices.status();
    auto without_rows = std::make_shared<Basis>(*basis);
    without_rows->U.resize(basis->U.rows(), basis->U.cols());
    without_rows->U.makeCompressed();
    const int32_t p = type.dofs_per_face();
    auto read =
        ReducedSystem::Build(without_rows, LiftPlan::Build(basis->U, p), op.mass, *matrices);
    ASSERT_TRUE(read.ok()) << read.status();
    const ReducedSystem& b = **read;
    EXPECT_TRUE(b.basis_rows_released());
    EXPECT_TRUE(b.stats().products_given);
    EXPECT_EQ(b.basis().U.nonZeros(), 0);
    EXPECT_EQ(b.dofs(), a.dofs());
    EXPECT_EQ(b.dimension(), a.dimension());
    EXPECT_EQ(Eigen::MatrixXd(b.bilaplacian()), Eigen::MatrixXd(a.bilaplacian()));
    BasisRowScratch scratch;
    for (int64_t i = 0; i < a.dofs(); ++i) {
      const BasisRow u = GetBasisRow(basis->U, i);
      const BasisRow r = b.BasisRowOf(i, &scratch);
      ASSERT_EQ(std::vector<int>(r.cols, r.cols + r.size),
                std::vector<int>(u.cols, u.cols + u.size));
      ASSERT_EQ(std::vector<float>(r.vals, r.vals + r.size),
                std::vector<float>(u.vals, u.vals + u.size));
    }
    ModelProblem problem;
    problem.weights.mu_s = 1.0;
    problem.weights.mu_c = 10.0;
    problem.constraints.push_back({7, Eigen::VectorXd::Ones(p), 1.0, ConstraintKind::kSoft});
    problem.constraints.push_back(
        {300, Eigen::VectorXd::LinSpaced(p, -1.0, 1.0), 1.0, ConstraintKind::kHard});
    auto sa = SolveReducedModelProblem(a, problem);
    auto sb = SolveReducedModelProblem(b, problem);
    ASSERT_TRUE(sa.ok() && sb.ok());
    EXPECT_LT(RelativeDifference(sb->coefficients, sa->coefficients), 1e-10);
    auto la = Lift(a, sa->coefficients);
    auto lb = Lift(b, sa->coefficients);
    ASSERT_TRUE(la.ok() && lb.ok());
    EXPECT_EQ(*lb, *la);
    auto pa = Project(a, RandomVector(a.dofs(), 9));
    auto pb = Project(b, RandomVector(a.dofs(), 9));
    ASSERT_TRUE(pa.ok() && pb.ok());
    EXPECT_LT(RelativeDifference(pb->coefficients, pa->coefficients), 1e-12);

    // A basis that kept its rows, or a plan of another shape: refused.
    EXPECT_THAT(ReducedSystem::Build(basis, LiftPlan::Build(basis->U, p), op.mass, *matrices),
                StatusIs(absl::StatusCode::kInvalidArgument));
    const BasisMatrix fewer = basis->U.topRows(basis->U.rows() - p);
    EXPECT_THAT(ReducedSystem::Build(without_rows, LiftPlan::Build(fewer, p), op.mass, *matrices),
                StatusIs(absl::StatusCode::kInvalidArgument));
    if (p % 2 == 0) {
      EXPECT_THAT(
          ReducedSystem::Build(without_rows, LiftPlan::Build(basis->U, p / 2), op.mass, *matrices),
          StatusIs(absl::StatusCode::kInvalidArgument));
    }
  }
}

TEST(ReducedSystemTest, DamagedOrForeignMatricesAreRefused) {
  const TriangleMesh mesh = Icosphere(2);
  const FieldOperator op = MustBuildOperator(mesh, FieldType::Vector());
  auto basis = RandomBasis(FieldType::Vector(), op.dofs(), 40, 10, 5);
  auto sys = ReducedSystem::Build(basis, op);
  ASSERT_TRUE(sys.ok()) << sys.status();
  const std::string bytes = EncodeReducedMatrices(**sys);
  // Bytes: another magic, another version, one byte short or long, a header that lies about d.
  std::string bad = bytes;
  bad[0] = 'X';
  EXPECT_THAT(DecodeReducedMatrices(bad), StatusIs(absl::StatusCode::kDataLoss));
  bad = bytes;
  bad[8] = 2;
  EXPECT_THAT(DecodeReducedMatrices(bad), StatusIs(absl::StatusCode::kDataLoss));
  EXPECT_THAT(DecodeReducedMatrices(bytes.substr(0, bytes.size() - 1)),
              StatusIs(absl::StatusCode::kDataLoss));
  EXPECT_THAT(DecodeReducedMatrices(bytes + "x"), StatusIs(absl::StatusCode::kDataLoss));
  EXPECT_THAT(DecodeReducedMatrices(bytes.substr(0, 20)), StatusIs(absl::StatusCode::kDataLoss));
  bad = bytes;
  bad[16] = static_cast<char>(bad[16] + 1);
  EXPECT_THAT(DecodeReducedMatrices(bad), StatusIs(absl::StatusCode::kDataLoss));
  // A basis with a non-finite value (the matrices themselves sound).
  auto nan_basis = std::make_shared<Basis>(*basis);
  nan_basis->U.valuePtr()[3] = std::numeric_limits<float>::quiet_NaN();
  EXPECT_THAT(ReducedSystem::Build(nan_basis, op.mass, *DecodeReducedMatrices(bytes)),
              StatusIs(absl::StatusCode::kInvalidArgument));
  // A mass of another size, or not positive.
  EXPECT_THAT(
      ReducedSystem::Build(basis, op.mass.head(op.dofs() - 2), *DecodeReducedMatrices(bytes)),
      StatusIs(absl::StatusCode::kInvalidArgument));
  Eigen::VectorXd zero_mass = op.mass;
  zero_mass[4] = 0.0;
  EXPECT_THAT(ReducedSystem::Build(basis, zero_mass, *DecodeReducedMatrices(bytes)),
              StatusIs(absl::StatusCode::kInvalidArgument));
  // Matrices that decode but are not a reduced system's: for another dimension, a row index out
  // of range, rows out of order, a missing diagonal, an asymmetric pattern, a NaN.
  auto other = RandomBasis(FieldType::Vector(), op.dofs(), 41, 10, 5);
  EXPECT_THAT(ReducedSystem::Build(other, op.mass, *DecodeReducedMatrices(bytes)),
              StatusIs(absl::StatusCode::kInvalidArgument));
  const auto edited = [&](const auto& edit) {
    ReducedMatrices m = *DecodeReducedMatrices(bytes);
    edit(m);
    return ReducedSystem::Build(basis, op.mass, std::move(m));
  };
  const auto all_patterns = [](ReducedMatrices& m, const auto& edit) {
    for (auto* a : {&m.stiffness, &m.bilaplacian, &m.mass_matrix}) edit(*a);
  };
  EXPECT_THAT(edited([&](ReducedMatrices& m) {
                all_patterns(m, [](auto& a) { a.innerIndexPtr()[3] = 1000; });
              }),
              StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(edited([&](ReducedMatrices& m) {
                all_patterns(m, [](auto& a) {
                  std::swap(a.innerIndexPtr()[a.outerIndexPtr()[1]],
                            a.innerIndexPtr()[a.outerIndexPtr()[1] + 1]);
                });
              }),
              StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(edited([&](ReducedMatrices& m) {
                all_patterns(m, [](auto& a) {
                  a.prune([](Eigen::Index row, Eigen::Index col, double) {
                    return !(row == 5 && col == 5);
                  });
                });
              }),
              StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(edited([&](ReducedMatrices& m) {
                // Entry (r, 0) dropped, (0, r) kept (r: column 0's largest row).
                const int r = m.stiffness.innerIndexPtr()[m.stiffness.outerIndexPtr()[1] - 1];
                ASSERT_GT(r, 0);
                all_patterns(m, [r](auto& a) {
                  a.prune([r](Eigen::Index row, Eigen::Index col, double) {
                    return !(row == r && col == 0);
                  });
                });
              }),
              StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(edited([&](ReducedMatrices& m) {
                m.bilaplacian.valuePtr()[7] = std::numeric_limits<double>::quiet_NaN();
              }),
              StatusIs(absl::StatusCode::kInvalidArgument));
  // Column pointers that claim more entries than the arrays hold (all three alike, so that only
  // the storage can tell; a fuzzer's finding: they were trusted).
  EXPECT_THAT(edited([&](ReducedMatrices& m) {
                all_patterns(m, [](auto& a) { a.outerIndexPtr()[40] += 5; });
              }),
              StatusIs(absl::StatusCode::kInvalidArgument));
  // Patterns that differ between the matrices.
  EXPECT_THAT(edited([&](ReducedMatrices& m) { m.stiffness.innerIndexPtr()[1] += 1; }),
              StatusIs(absl::StatusCode::kInvalidArgument));
}

}  // namespace
}  // namespace fieldspace
