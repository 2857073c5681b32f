// ComputeKernelFields: the columns are M-orthonormal and in the kernel of S to 1e-10 relative,
// their number is 2 g for vector fields on closed surfaces and agrees with the number of zero
// eigenvalues of S x = lambda M x on every mesh of the catalogue and every field kind.

#include "core/operators/kernel_fields.h"

#include <cmath>
#include <cstdio>
#include <string>
#include <utility>
#include <vector>

#include "Eigen/Dense"
#include "core/linalg/eigensolver.h"
#include "core/mesh/shapes.h"
#include "core/operators/field_operator.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tests/testing/fixtures.h"
#include "tests/testing/matchers.h"
#include "tests/testing/test_meshes.h"

namespace fieldspace {
namespace {

using ::fieldspace::testing::MustBuildOperator;
using ::fieldspace::testing::MustCreate;
using ::fieldspace::testing::PlanarStrip;
using ::fieldspace::testing::StatusIs;

double LambdaRef(const FieldOperator& op) { return op.stiffness.diagonal().sum() / op.mass.sum(); }

// max over columns of ||S x||_{M^-1} / (lambda_ref ||x||_M).
double KernelResidual(const FieldOperator& op, const Eigen::MatrixXd& X) {
  const Eigen::MatrixXd SX = op.stiffness * X;
  double worst = 0;
  for (Eigen::Index j = 0; j < X.cols(); ++j) {
    const double num = std::sqrt(SX.col(j).cwiseAbs2().cwiseQuotient(op.mass).sum());
    const double den = LambdaRef(op) * std::sqrt(X.col(j).cwiseAbs2().dot(op.mass));
    worst = std::max(worst, num / den);
  }
  return worst;
}

double OrthonormalityError(const FieldOperator& op, const Eigen::MatrixXd& X) {
  const Eigen::MatrixXd G = X.transpose() * op.mass.asDiagonal() * X;
  return (G - Eigen::MatrixXd::Identity(X.cols(), X.cols())).cwiseAbs().maxCoeff();
}

// Number of eigenvalues of S x = lambda M x below 1e-9 lambda_ref among the lowest `count`.
int ZeroEigenvalues(const FieldOperator& op, int count, Eigen::VectorXd* values) {
  EigenOptions eo;
  eo.count = count;
  eo.compute_vectors = false;
  absl::StatusOr<EigenResult> r = LowestEigenpairs(op.stiffness, op.mass, eo);
  EXPECT_TRUE(r.ok()) << r.status();
  if (!r.ok()) return -1;
  *values = r->values;
  int zeros = 0;
  for (Eigen::Index i = 0; i < r->values.size(); ++i) {
    zeros += r->values[i] < 1e-9 * LambdaRef(op) ? 1 : 0;
  }
  return zeros;
}

struct KindCase {
  const char* name;
  FieldType type;
};

class KernelFieldsTest : public testing::MeshCaseTest {};

TEST_P(KernelFieldsTest, ColumnsSpanTheKernelOfEveryFieldKind) {
  const testing::MeshCase& c = GetParam();
  for (const KindCase& kind :
       {KindCase{"vector", FieldType::Vector()}, KindCase{"tensor", FieldType::Tensor()},
        KindCase{"nfield4", FieldType::NField(4)}}) {
    const FieldOperator op = MustBuildOperator(mesh(), kind.type);
    KernelFieldStats stats;
    absl::StatusOr<Eigen::MatrixXd> X = ComputeKernelFields(mesh(), op, {}, &stats);
    ASSERT_TRUE(X.ok()) << c.name << " " << kind.name << ": " << X.status();
    ASSERT_EQ(X->rows(), op.dofs());
    const int q = static_cast<int>(X->cols());
    if (kind.type.kind == FieldKind::kVector && c.closed()) {
      EXPECT_EQ(q, 2 * c.genus) << c.name;
      EXPECT_EQ(stats.expected_harmonic, 2 * c.genus) << c.name;
    }
    if (kind.type.kind == FieldKind::kTensor) {
      EXPECT_GE(q, c.components) << c.name << ": the isotropic fields c I";
    }
    if (q > 0) {
      EXPECT_LT(OrthonormalityError(op, *X), 1e-10) << c.name << " " << kind.name;
      EXPECT_LT(KernelResidual(op, *X), 1e-10) << c.name << " " << kind.name;
    }
    // The count is the dimension of the kernel: the (q + 1)-th eigenvalue is not zero.
    Eigen::VectorXd values;
    const int zeros = ZeroEigenvalues(op, q + 2, &values);
    EXPECT_EQ(zeros, q) << c.name << " " << kind.name;
    std::printf(
        "%s %s: %d kernel fields (%d candidates, max Rayleigh %.2g, min rejected %.2g, "
        "%.3f s); lowest eigenvalues / lambda_ref:",
        c.name.c_str(), kind.name, q, stats.candidates, stats.max_rayleigh, stats.min_rejected,
        stats.seconds);
    for (Eigen::Index i = 0; i < values.size(); ++i) {
      std::printf(" %.3g", values[i] / LambdaRef(op));
    }
    std::printf("\n");
  }
}

// The multigrid Poisson solve (the default) and the CHOLMOD one give the same harmonic fields:
// the columns of each lie in the span of the other's to 1e-9 in the M-norm. On the meshes with
// harmonic fields (genus > 0 or more than one boundary loop).
class KernelFieldsPoissonTest : public testing::MeshCaseTest {};

std::vector<testing::MeshCase> CasesWithGenerators() {
  std::vector<testing::MeshCase> cases;
  for (testing::MeshCase& c : testing::MeshCatalogue()) {
    if (c.genus > 0 || c.boundary_loops > 1) cases.push_back(std::move(c));
  }
  return cases;
}

TEST_P(KernelFieldsPoissonTest, MultigridAndCholeskyPoissonSolvesAgree) {
  const testing::MeshCase& c = GetParam();
  const FieldOperator op = MustBuildOperator(mesh(), FieldType::Vector());
  KernelFieldStats mg_stats, ch_stats;
  KernelFieldOptions cholesky;
  cholesky.poisson_solver = PoissonSolver::kCholesky;
  absl::StatusOr<Eigen::MatrixXd> X = ComputeKernelFields(mesh(), op, {}, &mg_stats);
  absl::StatusOr<Eigen::MatrixXd> Y = ComputeKernelFields(mesh(), op, cholesky, &ch_stats);
  ASSERT_TRUE(X.ok()) << X.status();
  ASSERT_TRUE(Y.ok()) << Y.status();
  ASSERT_EQ(X->cols(), Y->cols());
  EXPECT_FALSE(mg_stats.poisson_fallback) << c.name;
  EXPECT_GT(mg_stats.poisson_iterations, 0) << c.name;
  EXPECT_LE(mg_stats.poisson_iterations, 40) << c.name;
  EXPECT_EQ(ch_stats.poisson_iterations, 0);
  // Y - X (X^T M Y): what of Y lies outside span(X).
  const Eigen::MatrixXd C = X->transpose() * op.mass.asDiagonal() * *Y;
  const Eigen::MatrixXd outside = *Y - *X * C;
  for (Eigen::Index j = 0; j < outside.cols(); ++j) {
    EXPECT_LT(std::sqrt(outside.col(j).cwiseAbs2().dot(op.mass)), 1e-9) << c.name << " " << j;
  }
}

// HodgeGram (the Ritz step's Z^T S Z through the factored form, divergence part per vertex and
// curl part per edge) against the assembled S, for random Z: the harmonic candidates are
// curl-free, so the kernel tests above would not see a wrong curl sum.
TEST_P(KernelFieldsTest, HodgeGramEqualsTheAssembledStiffnessGram) {
  const testing::MeshCase& c = GetParam();
  const FieldOperator op = MustBuildOperator(mesh(), FieldType::Vector());
  const Eigen::MatrixXd Z = Eigen::MatrixXd::Random(op.dofs(), 5);
  const Eigen::MatrixXd expected = Z.transpose() * (op.stiffness * Z);
  const Eigen::MatrixXd gram = HodgeGram(mesh(), MultigridRowMatrix(Z));
  EXPECT_LT((gram - expected).norm(), 1e-12 * expected.norm()) << c.name;
}

INSTANTIATE_TEST_SUITE_P(Catalogue, KernelFieldsTest, ::testing::ValuesIn(testing::MeshCatalogue()),
                         testing::MeshCaseName);
INSTANTIATE_TEST_SUITE_P(Catalogue, KernelFieldsPoissonTest,
                         ::testing::ValuesIn(CasesWithGenerators()), testing::MeshCaseName);

TEST(KernelFieldsTest, GenusSurfacesHaveTwiceTheGenusHarmonicFields) {
  for (int genus = 0; genus <= 3; ++genus) {
    const TriangleMesh mesh = MustCreate(MakeGenusSurface(genus, 4));
    absl::StatusOr<Eigen::MatrixXd> X = ComputeKernelFields(mesh, FieldType::Vector());
    ASSERT_TRUE(X.ok()) << X.status();
    EXPECT_EQ(X->cols(), 2 * genus) << "genus " << genus;
  }
}

TEST(KernelFieldsTest, TensorKernelIsTheIsotropicFieldOnACurvedSurface) {
  const TriangleMesh mesh = MustCreate(MakeTorus(1.0, 0.4, 32, 16));
  absl::StatusOr<Eigen::MatrixXd> X = ComputeKernelFields(mesh, FieldType::Tensor());
  ASSERT_TRUE(X.ok()) << X.status();
  ASSERT_EQ(X->cols(), 1);
  // c I: (a11, a22, sqrt2 a12) = (c, c, 0) on every face, c = 1 / sqrt(2 area).
  const double c = std::abs((*X)(0, 0));
  for (int32_t f = 0; f < mesh.num_faces(); ++f) {
    EXPECT_NEAR(std::abs((*X)(3 * f, 0)), c, 1e-12);
    EXPECT_NEAR((*X)(3 * f, 0), (*X)(3 * f + 1, 0), 1e-12);
    EXPECT_NEAR((*X)(3 * f + 2, 0), 0.0, 1e-12);
  }
  EXPECT_NEAR(c, 1.0 / std::sqrt(2.0 * mesh.total_area()), 1e-12);
}

TEST(KernelFieldsTest, FlatStripHasParallelFieldsButNoHarmonicOnes) {
  const TriangleMesh mesh = MustCreate(PlanarStrip(20, 6));
  absl::StatusOr<Eigen::MatrixXd> vector = ComputeKernelFields(mesh, FieldType::Vector());
  ASSERT_TRUE(vector.ok()) << vector.status();
  EXPECT_EQ(vector->cols(), 0);
  absl::StatusOr<Eigen::MatrixXd> tensor = ComputeKernelFields(mesh, FieldType::Tensor());
  ASSERT_TRUE(tensor.ok()) << tensor.status();
  EXPECT_EQ(tensor->cols(), 3);
  for (int n : {1, 2, 3, 6}) {
    absl::StatusOr<Eigen::MatrixXd> nfield = ComputeKernelFields(mesh, FieldType::NField(n));
    ASSERT_TRUE(nfield.ok()) << nfield.status();
    EXPECT_EQ(nfield->cols(), 2) << "n = " << n;
  }
}

TEST(KernelFieldsTest, RejectsAnOperatorOfAnotherMesh) {
  const TriangleMesh a = MustCreate(MakeIcosphere(1));
  const TriangleMesh b = MustCreate(MakeIcosphere(2));
  const FieldOperator op = MustBuildOperator(a, FieldType::Vector());
  EXPECT_THAT(ComputeKernelFields(b, op), StatusIs(absl::StatusCode::kInvalidArgument));
}

// A vector field's kernel needs no S: without it the same columns and the same lambda_ref (the
// trace then comes from the mesh); n-fields and tensors read S and say so.
TEST(KernelFieldsTest, VectorKernelWithoutStiffnessIsTheSame) {
  const TriangleMesh mesh = MustCreate(MakeGenusSurface(2, 4));
  const FieldOperator op = MustBuildOperator(mesh, FieldType::Vector());
  absl::StatusOr<FieldOperator> no_s =
      BuildFieldOperatorWithoutStiffness(mesh, FieldType::Vector());
  ASSERT_TRUE(no_s.ok());
  KernelFieldStats with_stats, without_stats;
  absl::StatusOr<Eigen::MatrixXd> with = ComputeKernelFields(mesh, op, {}, &with_stats);
  absl::StatusOr<Eigen::MatrixXd> without = ComputeKernelFields(mesh, *no_s, {}, &without_stats);
  ASSERT_TRUE(with.ok()) << with.status();
  ASSERT_TRUE(without.ok()) << without.status();
  ASSERT_EQ(with->cols(), 4);
  EXPECT_EQ(*with, *without);
  EXPECT_NEAR(without_stats.lambda_ref, with_stats.lambda_ref, 1e-12 * with_stats.lambda_ref);
  EXPECT_GT(with_stats.lambda_ref, 0.0);
  for (FieldType type : {FieldType::Tensor(), FieldType::NField(4)}) {
    absl::StatusOr<FieldOperator> other = BuildFieldOperatorWithoutStiffness(mesh, type);
    ASSERT_TRUE(other.ok());
    EXPECT_THAT(ComputeKernelFields(mesh, *other), StatusIs(absl::StatusCode::kInvalidArgument,
                                                            ::testing::HasSubstr("not assembled")));
  }
}

// When the multigrid does not converge within poisson_max_iterations, CHOLMOD solves instead and
// the harmonic fields are the same (here the genus-2 surface, 4 right-hand sides, 1 iteration).
TEST(KernelFieldsTest, FallsBackToCholeskyWhenTheMultigridDoesNotConverge) {
  const TriangleMesh mesh = MustCreate(MakeGenusSurface(2, 6));
  const FieldOperator op = MustBuildOperator(mesh, FieldType::Vector());
  KernelFieldOptions one_iteration;
  one_iteration.poisson_max_iterations = 1;
  KernelFieldStats fallback_stats, stats;
  absl::StatusOr<Eigen::MatrixXd> X = ComputeKernelFields(mesh, op, one_iteration, &fallback_stats);
  absl::StatusOr<Eigen::MatrixXd> Y = ComputeKernelFields(mesh, op, {}, &stats);
  ASSERT_TRUE(X.ok()) << X.status();
  ASSERT_TRUE(Y.ok()) << Y.status();
  EXPECT_TRUE(fallback_stats.poisson_fallback);
  EXPECT_FALSE(stats.poisson_fallback);
  EXPECT_GT(stats.poisson_iterations, 1);
  ASSERT_EQ(X->cols(), 4);
  ASSERT_EQ(Y->cols(), 4);
  EXPECT_LT(KernelResidual(op, *X), 1e-10);
  const Eigen::MatrixXd outside = *Y - *X * (X->transpose() * op.mass.asDiagonal() * *Y);
  EXPECT_LT(std::sqrt(outside.cwiseAbs2().colwise().sum().maxCoeff() * op.mass.maxCoeff()), 1e-9);
  KernelFieldOptions zero;
  zero.poisson_max_iterations = 0;
  EXPECT_THAT(ComputeKernelFields(mesh, op, zero), StatusIs(absl::StatusCode::kInvalidArgument));
}

TEST(KernelFieldsTest, Cancels) {
  const TriangleMesh mesh = MustCreate(MakeTorus(1.0, 0.4, 32, 16));
  const FieldOperator op = MustBuildOperator(mesh, FieldType::Vector());
  CancelFlag cancel{true};
  KernelFieldOptions options;
  options.cancel = &cancel;
  EXPECT_THAT(ComputeKernelFields(mesh, op, options), StatusIs(absl::StatusCode::kCancelled));
}

}  // namespace
}  // namespace fieldspace
