#include "core/basis/basis.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <limits>
#include <random>
#include <set>
#include <utility>
#include <vector>

#include "Eigen/Eigenvalues"
#include "core/basis/basis_io.h"
#include "core/mesh/shapes.h"
#include "core/operators/kernel_fields.h"
#include "core/operators/reference_solvers.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tests/testing/fixtures.h"
#include "tests/testing/matchers.h"
#include "tests/testing/reference.h"
#include "tests/testing/test_meshes.h"

namespace fieldspace {
namespace {

using ::fieldspace::testing::IsOk;
using ::fieldspace::testing::StatusIs;
using testing::ColumnMajor;
using testing::DenseColumn;
using testing::DenseRestricted;
using testing::DualDistances;
using testing::Icosphere;
using testing::MustBuildOperator;
using testing::MustCreate;
using testing::RegionFaces;
using testing::TwoSpheres;

Basis Build(const TriangleMesh& mesh, const FieldOperator& op, int32_t d, double sigma = 40.0,
            int32_t threads = 0, uint64_t seed = 0) {
  BasisOptions options;
  options.params.dimension = d;
  options.params.sigma = sigma;
  options.params.seed = seed;
  options.threads = threads;
  auto basis = BuildBasis(mesh, op, options);
  EXPECT_TRUE(basis.ok()) << basis.status();
  return *std::move(basis);
}

int32_t FieldsPerRegion(const Basis& b) {
  return b.params.fields_per_region.value_or(b.type.default_fields_per_region());
}

// The invariants every basis satisfies: exact size (d local columns, then the kernel columns),
// support inside the regions (independent Dijkstra), M-orthonormal fields per region, every face
// covered.
void CheckStructure(const TriangleMesh& mesh, const FieldOperator& op, const Basis& basis,
                    int32_t regions_to_check) {
  const int32_t d = basis.dimension() - basis.kernel_columns;
  const int32_t m = FieldsPerRegion(basis);
  const int32_t dpf = op.type.dofs_per_face();
  ASSERT_EQ(basis.U.rows(), op.dofs());
  ASSERT_EQ(basis.params.dimension, basis.dimension());
  ASSERT_EQ(basis.num_regions(), (d + m - 1) / m);
  ASSERT_EQ(static_cast<int32_t>(basis.local_eigenvalues.size()), basis.dimension());
  const double expected_r = std::sqrt(basis.params.sigma * mesh.total_area() / (d * M_PI));
  EXPECT_NEAR(basis.radius, expected_r, 1e-12 * expected_r);
  // Distinct samples.
  std::set<int32_t> distinct(basis.sample_faces.begin(), basis.sample_faces.end());
  EXPECT_EQ(static_cast<int32_t>(distinct.size()), basis.num_regions());
  // Every row has entries (all faces covered) when r exceeds the covering radius.
  ASSERT_LT(basis.coverage_radius, basis.radius);
  EXPECT_EQ(basis.uncovered_faces, 0);
  for (Eigen::Index r = 0; r < basis.U.rows(); ++r) {
    ASSERT_GT(basis.U.outerIndexPtr()[r + 1], basis.U.outerIndexPtr()[r]) << "row " << r;
  }
  const Eigen::SparseMatrix<double> Uc = ColumnMajor(basis);
  const int32_t step = std::max(1, basis.num_regions() / regions_to_check);
  for (int32_t region = 0; region < basis.num_regions(); region += step) {
    const std::vector<int32_t> faces = RegionFaces(mesh, basis, region);
    std::vector<char> inside(mesh.num_faces(), 0);
    for (int32_t f : faces) inside[f] = 1;
    const int32_t first = region * m;
    const int32_t count = std::min(m, d - first);
    Eigen::MatrixXd block(op.dofs(), count);
    for (int32_t c = 0; c < count; ++c) block.col(c) = DenseColumn(Uc, first + c);
    // Support: zero outside the region, and the region's faces are all used.
    for (int64_t i = 0; i < op.dofs(); ++i) {
      if (!inside[i / dpf]) {
        ASSERT_EQ(block.row(i).norm(), 0.0)
            << "region " << region << " leaks into face " << i / dpf;
      }
    }
    // M-orthonormal: U_D^T M U_D = I.
    const Eigen::MatrixXd gram = block.transpose() * op.mass.asDiagonal() * block;
    EXPECT_LT((gram - Eigen::MatrixXd::Identity(count, count)).cwiseAbs().maxCoeff(), 1e-5)
        << "region " << region << "\n"
        << gram;
  }
}

// On a noisy sphere of non-uniform density with about as many faces as the shared bimba_18k.obj.
TEST(BasisTest, VectorBasisOnAnIrregularMeshHasPaperStructure) {
  const TriangleMesh mesh =
      MustCreate(PerturbVertices(*MakeNonUniformSphere(5, 0.5), 0.3, /*seed=*/18));
  const FieldOperator op = MustBuildOperator(mesh, FieldType::Vector());
  const Basis basis = Build(mesh, op, 200);
  CheckStructure(mesh, op, basis, 25);
  // About 0.6 sigma nonzeros per row with dual-graph distances (docs/conventions.md, Basis
  // construction).
  const double per_row = static_cast<double>(basis.U.nonZeros()) / basis.U.rows();
  EXPECT_GT(per_row, 15.0);
  EXPECT_LT(per_row, 45.0);
  EXPECT_EQ(basis.stats.lanczos_fallbacks, 0);
  // Each column's eigenvalue is its Rayleigh quotient: U_j^T S U_j (U_j has unit M-norm).
  const Eigen::SparseMatrix<double> Uc = ColumnMajor(basis);
  for (int32_t j = 0; j < basis.dimension(); j += 17) {
    const Eigen::VectorXd u = DenseColumn(Uc, j);
    const double rq = u.dot(op.stiffness * u);
    EXPECT_NEAR(rq, basis.local_eigenvalues[j], 1e-4 * basis.local_eigenvalues[j]) << j;
  }
}

// The local eigenproblem (eq. 7) against an independent dense solve of S_bar built from the
// operator: same eigenvalues, same eigenspace.
void CheckLocalEigenproblems(const TriangleMesh& mesh, const FieldOperator& op, const Basis& basis,
                             int32_t regions_to_check) {
  const int32_t m = FieldsPerRegion(basis);
  const int32_t dpf = op.type.dofs_per_face();
  const Eigen::SparseMatrix<double> Uc = ColumnMajor(basis);
  const int32_t step = std::max(1, basis.num_regions() / regions_to_check);
  for (int32_t region = 0; region < basis.num_regions(); region += step) {
    const std::vector<int32_t> faces = RegionFaces(mesh, basis, region);
    const Eigen::MatrixXd S = DenseRestricted(op, faces);
    Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(S);
    ASSERT_EQ(es.info(), Eigen::Success);
    const int32_t first = region * m;
    const int32_t count = std::min(m, basis.dimension() - first);
    // phi = V^-1 U_D restricted to the region.
    Eigen::MatrixXd phi(faces.size() * dpf, count);
    for (int32_t c = 0; c < count; ++c) {
      const Eigen::VectorXd u = DenseColumn(Uc, first + c);
      for (size_t i = 0; i < faces.size(); ++i) {
        for (int32_t q = 0; q < dpf; ++q) {
          const int64_t g = static_cast<int64_t>(dpf) * faces[i] + q;
          phi(dpf * i + q, c) = u[g] * std::sqrt(op.mass[g]);
        }
      }
    }
    for (int32_t c = 0; c < count; ++c) {
      const double lambda = es.eigenvalues()[c];
      EXPECT_NEAR(basis.local_eigenvalues[first + c], lambda, 1e-6 * lambda + 1e-9)
          << "region " << region << " field " << c;
      // Residual of the stored (float) field, relative to the operator's scale.
      const double res = (S * phi.col(c) - lambda * phi.col(c)).norm();
      EXPECT_LT(res, 1e-4 * es.eigenvalues().maxCoeff()) << "region " << region;
    }
    // The span agrees with the dense eigenvectors (when the m-th eigenvalue is separated).
    if (count == m && es.eigenvalues()[m] > 1.05 * es.eigenvalues()[m - 1]) {
      const Eigen::MatrixXd ref = es.eigenvectors().leftCols(m);
      const Eigen::MatrixXd proj = ref.transpose() * phi;  // m x m, orthogonal if spans agree
      const Eigen::VectorXd sv = Eigen::JacobiSVD<Eigen::MatrixXd>(proj).singularValues();
      EXPECT_GT(sv.minCoeff(), 1.0 - 1e-4) << "region " << region;
    }
  }
}

TEST(BasisTest, LocalEigenproblemsMatchDenseSolveVector) {
  const TriangleMesh mesh = Icosphere(3);  // 1280 faces; sigma 20 keeps the dense checks fast
  const FieldOperator op = MustBuildOperator(mesh, FieldType::Vector());
  const Basis basis = Build(mesh, op, 120, 20.0);
  CheckStructure(mesh, op, basis, 20);
  CheckLocalEigenproblems(mesh, op, basis, 4);
}

TEST(BasisTest, LocalEigenproblemsMatchDenseSolveNField) {
  const TriangleMesh mesh = Icosphere(3);  // 1280 faces; sigma 20 keeps the dense checks fast
  const FieldOperator op = MustBuildOperator(mesh, FieldType::NField(4));
  const Basis basis = Build(mesh, op, 120, 20.0);
  CheckStructure(mesh, op, basis, 20);
  CheckLocalEigenproblems(mesh, op, basis, 4);
}

TEST(BasisTest, LocalEigenproblemsMatchDenseSolveTensor) {
  const TriangleMesh mesh = Icosphere(3);  // 1280 faces; sigma 20 keeps the dense checks fast
  const FieldOperator op = MustBuildOperator(mesh, FieldType::Tensor());
  const Basis basis = Build(mesh, op, 120, 20.0);  // 40 regions x 3 fields
  CheckStructure(mesh, op, basis, 20);
  CheckLocalEigenproblems(mesh, op, basis, 4);
}

TEST(BasisTest, FactoredAndGenericVectorPathsAgree) {
  const TriangleMesh mesh = Icosphere(4);
  const FieldOperator op = MustBuildOperator(mesh, FieldType::Vector());
  BasisOptions options;
  options.params.dimension = 60;
  auto fast = BuildBasis(mesh, op, options);
  ASSERT_TRUE(fast.ok()) << fast.status();
  EXPECT_TRUE(fast->stats.hodge_factor_used);
  options.use_factored_vector_operator = false;
  auto generic = BuildBasis(mesh, op, options);
  ASSERT_TRUE(generic.ok()) << generic.status();
  EXPECT_FALSE(generic->stats.hodge_factor_used);
  ASSERT_EQ(fast->sample_faces, generic->sample_faces);
  for (int32_t j = 0; j < 60; ++j) {
    EXPECT_NEAR(fast->local_eigenvalues[j], generic->local_eigenvalues[j],
                1e-7 * generic->local_eigenvalues[j]);
  }
  // Same spans per region (the two lowest eigenvalues can be nearly equal, so compare spans).
  const Eigen::SparseMatrix<double> Uf = ColumnMajor(*fast), Ug = ColumnMajor(*generic);
  for (int32_t r = 0; r < fast->num_regions(); ++r) {
    Eigen::MatrixXd a(op.dofs(), 2), b(op.dofs(), 2);
    for (int c = 0; c < 2; ++c) {
      a.col(c) = DenseColumn(Uf, 2 * r + c);
      b.col(c) = DenseColumn(Ug, 2 * r + c);
    }
    const Eigen::MatrixXd proj = a.transpose() * op.mass.asDiagonal() * b;
    const Eigen::VectorXd sv = Eigen::JacobiSVD<Eigen::MatrixXd>(proj).singularValues();
    EXPECT_GT(sv.minCoeff(), 1.0 - 1e-5) << "region " << r;
  }
}

// A vector build through the Hodge factor does not read S: given an operator without it, the same
// basis bit for bit (also the low-modes levels and the torus's kernel columns, which then take
// their scale from the mesh).
TEST(BasisTest, VectorBuildWithoutStiffnessIsTheSame) {
  const TriangleMesh mesh = testing::Torus(24, 12, 1.0, 0.4);
  const FieldOperator op = MustBuildOperator(mesh, FieldType::Vector());
  absl::StatusOr<FieldOperator> no_s =
      BuildFieldOperatorWithoutStiffness(mesh, FieldType::Vector());
  ASSERT_TRUE(no_s.ok());
  BasisOptions options;
  EXPECT_FALSE(BuildReadsStiffness(FieldType::Vector(), options));
  options.params.dimension = 60;
  auto with = BuildBasis(mesh, op, options);
  auto without = BuildBasis(mesh, *no_s, options);
  ASSERT_TRUE(with.ok()) << with.status();
  ASSERT_TRUE(without.ok()) << without.status();
  EXPECT_TRUE(without->stats.hodge_factor_used);
  EXPECT_EQ(without->kernel_columns, 2);
  EXPECT_EQ(Eigen::MatrixXf(without->U), Eigen::MatrixXf(with->U));
  EXPECT_EQ(without->local_eigenvalues, with->local_eigenvalues);
  auto levels = QualityLevels(BasisQuality::kLowModes, 80, options.params.sigma);
  ASSERT_TRUE(levels.ok());
  EXPECT_FALSE(BuildReadsStiffness(FieldType::Vector(), options, *levels));
  auto low_with = BuildMultiLevelBasis(mesh, op, options, *levels);
  auto low_without = BuildMultiLevelBasis(mesh, *no_s, options, *levels);
  ASSERT_TRUE(low_with.ok()) << low_with.status();
  ASSERT_TRUE(low_without.ok()) << low_without.status();
  EXPECT_EQ(Eigen::MatrixXf(low_without->U), Eigen::MatrixXf(low_with->U));
}

// Every other build reads S and refuses an operator without it, before any work.
TEST(BasisTest, BuildsThatReadStiffnessRefuseAnOperatorWithoutIt) {
  const TriangleMesh mesh = Icosphere(3);
  BasisOptions options;
  options.params.dimension = 40;
  const auto refused =
      StatusIs(absl::StatusCode::kInvalidArgument, ::testing::HasSubstr("reads S"));
  for (FieldType type : {FieldType::Tensor(), FieldType::NField(4)}) {
    SCOPED_TRACE(type.ToString());
    EXPECT_TRUE(BuildReadsStiffness(type, options));
    absl::StatusOr<FieldOperator> no_s = BuildFieldOperatorWithoutStiffness(mesh, type);
    ASSERT_TRUE(no_s.ok());
    EXPECT_THAT(BuildBasis(mesh, *no_s, options), refused);
  }
  absl::StatusOr<FieldOperator> no_s =
      BuildFieldOperatorWithoutStiffness(mesh, FieldType::Vector());
  ASSERT_TRUE(no_s.ok());
  BasisOptions generic = options;
  generic.use_factored_vector_operator = false;
  EXPECT_TRUE(BuildReadsStiffness(FieldType::Vector(), generic));
  EXPECT_THAT(BuildBasis(mesh, *no_s, generic), refused);
  BasisOptions clamped = options;
  clamped.clamped_local_fields = true;
  EXPECT_TRUE(BuildReadsStiffness(FieldType::Vector(), clamped));
  EXPECT_THAT(BuildBasis(mesh, *no_s, clamped), refused);
  // A clamped level anywhere among the levels: refused before the first level is built.
  auto smooth = QualityLevels(BasisQuality::kSmooth, 80, options.params.sigma);
  ASSERT_TRUE(smooth.ok());
  EXPECT_TRUE(BuildReadsStiffness(FieldType::Vector(), options, *smooth));
  const std::vector<BasisLevel> last_clamped = {{60, 30.0, false}, {12, 25.0, true}};
  EXPECT_TRUE(BuildReadsStiffness(FieldType::Vector(), options, last_clamped));
  std::atomic<int> progress_calls{0};
  options.progress = [&](BasisPhase, double) { ++progress_calls; };
  EXPECT_THAT(BuildMultiLevelBasis(mesh, *no_s, options, last_clamped), refused);
  EXPECT_EQ(progress_calls.load(), 0);
}

// BuildBasisOfQuality is the named quality's build, and assembles S into the operator only for
// a build that reads it.
TEST(BasisTest, BuildOfQualityIsTheLevelsBuildAndAssemblesSOnlyWhenRead) {
  const TriangleMesh mesh = Icosphere(3);
  BasisOptions options;
  options.params.dimension = 80;
  options.kernel_columns = false;
  const FieldOperator op = MustBuildOperator(mesh, FieldType::Vector());
  absl::StatusOr<FieldOperator> vector = BuildFieldOperatorWithoutStiffness(mesh, op.type);
  ASSERT_TRUE(vector.ok());
  auto low = BuildBasisOfQuality(mesh, &*vector, options, BasisQuality::kLowModes);
  ASSERT_TRUE(low.ok()) << low.status();
  EXPECT_FALSE(vector->has_stiffness());
  auto levels = QualityLevels(BasisQuality::kLowModes, 80, options.params.sigma);
  ASSERT_TRUE(levels.ok());
  auto low_levels = BuildMultiLevelBasis(mesh, op, options, *levels);
  ASSERT_TRUE(low_levels.ok()) << low_levels.status();
  EXPECT_EQ(Eigen::MatrixXf(low->U), Eigen::MatrixXf(low_levels->U));
  auto two = BuildBasisOfQuality(mesh, &*vector, options, BasisQuality::kPaper, 20);
  auto two_levels = BuildTwoLevelBasis(mesh, op, options, 20);
  ASSERT_TRUE(two.ok()) << two.status();
  ASSERT_TRUE(two_levels.ok()) << two_levels.status();
  EXPECT_EQ(two->num_regions(), 40);
  EXPECT_EQ(Eigen::MatrixXf(two->U), Eigen::MatrixXf(two_levels->U));
  EXPECT_THAT(BuildBasisOfQuality(mesh, &*vector, options, BasisQuality::kLowModes, 20),
              StatusIs(absl::StatusCode::kInvalidArgument, ::testing::HasSubstr("coarse")));
  // The smooth levels read S: it is assembled, and is the operator's S.
  options.params.dimension = 40;
  auto smooth = BuildBasisOfQuality(mesh, &*vector, options, BasisQuality::kSmooth);
  ASSERT_TRUE(smooth.ok()) << smooth.status();
  ASSERT_TRUE(vector->has_stiffness());
  EXPECT_EQ((vector->stiffness - op.stiffness).norm(), 0.0);
  absl::StatusOr<FieldOperator> tensor =
      BuildFieldOperatorWithoutStiffness(mesh, FieldType::Tensor());
  ASSERT_TRUE(tensor.ok());
  auto paper = BuildBasisOfQuality(mesh, &*tensor, options, BasisQuality::kPaper);
  ASSERT_TRUE(paper.ok()) << paper.status();
  EXPECT_TRUE(tensor->has_stiffness());
  // Cancelled before any work, after S.
  std::atomic<bool> cancel{true};
  options.cancel = &cancel;
  EXPECT_THAT(BuildBasisOfQuality(mesh, &*vector, options, BasisQuality::kPaper),
              StatusIs(absl::StatusCode::kCancelled));
}

TEST(BasisTest, DeterministicAndIndependentOfThreadCount) {
  const TriangleMesh mesh = Icosphere(4);
  const FieldOperator op = MustBuildOperator(mesh, FieldType::Vector());
  const Basis a = Build(mesh, op, 80, 40.0, /*threads=*/1, /*seed=*/7);
  const Basis b = Build(mesh, op, 80, 40.0, /*threads=*/1, /*seed=*/7);
  const Basis c = Build(mesh, op, 80, 40.0, /*threads=*/2, /*seed=*/7);
  ASSERT_EQ(a.sample_faces, b.sample_faces);
  ASSERT_EQ(a.sample_faces, c.sample_faces);
  ASSERT_EQ(a.U.nonZeros(), c.U.nonZeros());
  // Same seed, same threads: bitwise. Other thread count: equal up to rounding and column sign.
  EXPECT_TRUE(std::equal(a.U.valuePtr(), a.U.valuePtr() + a.U.nonZeros(), b.U.valuePtr()));
  const Eigen::SparseMatrix<double> Ua = ColumnMajor(a), Uc = ColumnMajor(c);
  for (int32_t j = 0; j < 80; ++j) {
    const Eigen::VectorXd u = DenseColumn(Ua, j), v = DenseColumn(Uc, j);
    const double diff = std::min((u - v).cwiseAbs().maxCoeff(), (u + v).cwiseAbs().maxCoeff());
    EXPECT_LT(diff, 1e-6 * u.cwiseAbs().maxCoeff()) << "column " << j;
  }
  const Basis other = Build(mesh, op, 80, 40.0, 1, /*seed=*/8);
  EXPECT_NE(a.sample_faces, other.sample_faces);
}

// Only ratios of the adaptivity weights matter: all weights c scale every distance and eq. 12's
// radius (from the weighted area) alike, so the basis is the uniform one.
TEST(BasisTest, UniformAdaptivityWeightsGiveTheUniformBasis) {
  // A sphere with jittered vertices: no ties between distances that a scaling could reorder.
  absl::StatusOr<MeshArrays> arrays = MakeIcosphere(3);
  ASSERT_TRUE(arrays.ok()) << arrays.status();
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> jitter(0.97, 1.03);
  for (Eigen::Index i = 0; i < arrays->vertices.size(); ++i)
    arrays->vertices.data()[i] *= jitter(rng);
  absl::StatusOr<TriangleMesh> jittered = TriangleMesh::Create(*std::move(arrays));
  ASSERT_TRUE(jittered.ok()) << jittered.status();
  const TriangleMesh& mesh = *jittered;
  const FieldOperator op = MustBuildOperator(mesh, FieldType::Vector());
  BasisOptions options;
  options.params.dimension = 60;
  auto uniform = BuildBasis(mesh, op, options);
  ASSERT_TRUE(uniform.ok()) << uniform.status();
  options.params.face_weights = Eigen::VectorXd::Constant(mesh.num_faces(), 3.0);
  auto scaled = BuildBasis(mesh, op, options);
  ASSERT_TRUE(scaled.ok()) << scaled.status();
  EXPECT_NEAR(scaled->radius, 3.0 * uniform->radius, 1e-9 * uniform->radius);
  EXPECT_EQ(scaled->sample_faces, uniform->sample_faces);
  const Eigen::SparseMatrix<double> a = ColumnMajor(*uniform), b = ColumnMajor(*scaled);
  ASSERT_EQ(a.nonZeros(), b.nonZeros());
  EXPECT_LT((Eigen::MatrixXd(a) - Eigen::MatrixXd(b)).cwiseAbs().maxCoeff(), 1e-6);
}

TEST(BasisTest, AdaptivityWeightsConcentrateSamples) {
  const TriangleMesh mesh = Icosphere(4);
  const FieldOperator op = MustBuildOperator(mesh, FieldType::Vector());
  // Weight 4 on the cap z > 0.6 (20% of the sphere's area).
  Eigen::VectorXd w = Eigen::VectorXd::Ones(mesh.num_faces());
  double cap_area = 0;
  for (int32_t f = 0; f < mesh.num_faces(); ++f) {
    if (mesh.face_barycenters()(f, 2) > 0.6) {
      w[f] = 4.0;
      cap_area += mesh.face_areas()[f];
    }
  }
  const double cap_fraction = cap_area / mesh.total_area();
  auto fraction_in_cap = [&](const Basis& b) {
    int32_t in = 0;
    for (int32_t s : b.sample_faces) in += w[s] > 1.0;
    return static_cast<double>(in) / b.num_regions();
  };
  BasisOptions options;
  options.params.dimension = 100;
  auto uniform = BuildBasis(mesh, op, options);
  ASSERT_TRUE(uniform.ok()) << uniform.status();
  options.params.face_weights = w;
  auto adaptive = BuildBasis(mesh, op, options);
  ASSERT_TRUE(adaptive.ok()) << adaptive.status();
  EXPECT_NEAR(fraction_in_cap(*uniform), cap_fraction, 0.1);
  // Weighted area 16 x 0.2 vs 0.8: about 80% of the samples should fall in the cap.
  EXPECT_GT(fraction_in_cap(*adaptive), 0.6);
  // Regions use the weighted distance: a cap region is smaller than a uniform one.
  int32_t cap_region = -1;
  for (int32_t r = 0; r < adaptive->num_regions(); ++r) {
    if (mesh.face_barycenters()(adaptive->sample_faces[r], 2) > 0.8) cap_region = r;
  }
  ASSERT_GE(cap_region, 0);
  const std::vector<int32_t> faces = RegionFaces(mesh, *adaptive, cap_region, w);
  std::vector<char> inside(mesh.num_faces(), 0);
  for (int32_t f : faces) inside[f] = 1;
  const Eigen::SparseMatrix<double> Ua = ColumnMajor(*adaptive);
  for (int c = 0; c < 2; ++c) {
    const Eigen::VectorXd u = DenseColumn(Ua, 2 * cap_region + c);
    for (int32_t f = 0; f < mesh.num_faces(); ++f) {
      if (!inside[f]) {
        ASSERT_EQ(u.segment(2 * f, 2).norm(), 0.0);
      }
    }
  }
  // In the weighted metric the regions of the adaptive basis have radius r_a (from the weighted
  // area, 4x the area here, so r_a = 2 r_u); a cap region reaches only r_a / 4 = r_u / 2 while in
  // the cap, so it is smaller than a uniform region of radius r_u.
  EXPECT_NEAR(adaptive->radius,
              2.0 * uniform->radius * std::sqrt((16 * cap_fraction + 1 - cap_fraction) / 4), 1e-9);
  EXPECT_LT(faces.size(), 0.8 * RegionFaces(mesh, *uniform, 0).size());
}

TEST(BasisTest, MultiComponentMeshSamplesEveryComponentByArea) {
  const TriangleMesh mesh = TwoSpheres(3, 2.0);  // areas 1 : 4
  ASSERT_EQ(mesh.num_components(), 2);
  const FieldOperator op = MustBuildOperator(mesh, FieldType::Vector());
  const Basis basis = Build(mesh, op, 100);  // 50 regions: 10 + 40
  CheckStructure(mesh, op, basis, 50);
  int32_t in_first = 0;
  for (int32_t s : basis.sample_faces) in_first += mesh.face_component()[s] == 0;
  EXPECT_EQ(in_first, 10);
  // Component 0's samples come first.
  for (int32_t r = 0; r < 10; ++r) EXPECT_EQ(mesh.face_component()[basis.sample_faces[r]], 0);
}

TEST(BasisTest, TinyDimensionStillGivesEveryComponentASample) {
  const TriangleMesh mesh = TwoSpheres(2, 3.0);
  const FieldOperator op = MustBuildOperator(mesh, FieldType::Vector());
  BasisOptions options;
  options.params.dimension = 3;  // 2 regions: one per component, the second with one field
  auto basis = BuildBasis(mesh, op, options);
  ASSERT_TRUE(basis.ok()) << basis.status();
  ASSERT_EQ(basis->num_regions(), 2);
  EXPECT_NE(mesh.face_component()[basis->sample_faces[0]],
            mesh.face_component()[basis->sample_faces[1]]);
  EXPECT_EQ(basis->dimension(), 3);
  options.params.dimension = 2;  // 1 region for 2 components
  EXPECT_THAT(BuildBasis(mesh, op, options), StatusIs(absl::StatusCode::kInvalidArgument));
}

// Open meshes of about 10k faces (as the shared camelhead_23k.off and blade_16k.off): a noisy
// polar disk (one boundary loop) and a long noisy cylinder (two).
TEST(BasisTest, MeshesWithBoundary) {
  const std::pair<const char*, absl::StatusOr<MeshArrays>> meshes[] = {
      {"polar disk", PerturbVertices(*MakePolarDisk(40, 128), 0.3, /*seed=*/23)},
      {"cylinder", PerturbVertices(*MakeCylinder(0.3, 4.0, 64, 80), 0.3, /*seed=*/16)}};
  for (const auto& [name, arrays] : meshes) {
    const TriangleMesh mesh = MustCreate(arrays);
    const FieldOperator op = MustBuildOperator(mesh, FieldType::Vector());
    const Basis basis = Build(mesh, op, 150);
    SCOPED_TRACE(name);
    CheckStructure(mesh, op, basis, 15);
  }
}

TEST(BasisTest, OddDimensionDropsTheLastRegionsSecondField) {
  const TriangleMesh mesh = Icosphere(3);
  const FieldOperator op = MustBuildOperator(mesh, FieldType::Vector());
  const Basis basis = Build(mesh, op, 41);
  EXPECT_EQ(basis.num_regions(), 21);
  EXPECT_EQ(basis.dimension(), 41);
  CheckStructure(mesh, op, basis, 21);
  // The last region's single field is its lowest one: a Rayleigh quotient no larger than the
  // other regions' second fields typically are, and equal to its own local eigenvalue.
  const Eigen::VectorXd u = DenseColumn(ColumnMajor(basis), 40);
  EXPECT_NEAR(u.dot(op.stiffness * u), basis.local_eigenvalues[40],
              1e-4 * basis.local_eigenvalues[40]);
}

TEST(BasisTest, CustomFieldsPerRegion) {
  const TriangleMesh mesh = Icosphere(3);
  const FieldOperator op = MustBuildOperator(mesh, FieldType::Vector());
  BasisOptions options;
  options.params.dimension = 40;
  options.params.sigma = 16.0;  // small regions keep the dense checks fast
  options.params.fields_per_region = 4;
  auto basis = BuildBasis(mesh, op, options);
  ASSERT_TRUE(basis.ok()) << basis.status();
  EXPECT_EQ(basis->num_regions(), 10);
  CheckStructure(mesh, op, *basis, 10);
  CheckLocalEigenproblems(mesh, op, *basis, 3);
}

TEST(BasisTest, ProgressAndCancellation) {
  const TriangleMesh mesh = Icosphere(4);
  const FieldOperator op = MustBuildOperator(mesh, FieldType::Vector());
  BasisOptions options;
  options.params.dimension = 100;
  std::vector<std::pair<BasisPhase, double>> calls;
  options.progress = [&](BasisPhase phase, double fraction) { calls.push_back({phase, fraction}); };
  auto basis = BuildBasis(mesh, op, options);
  ASSERT_TRUE(basis.ok());
  ASSERT_FALSE(calls.empty());
  bool saw_eigensolve = false;
  for (auto [phase, fraction] : calls) {
    EXPECT_GE(fraction, 0.0);
    EXPECT_LE(fraction, 1.0);
    saw_eigensolve |= phase == BasisPhase::kEigensolve;
  }
  EXPECT_TRUE(saw_eigensolve);
  EXPECT_EQ(calls.back().first, BasisPhase::kAssembly);
  EXPECT_EQ(calls.back().second, 1.0);

  // Cancelled before starting, and from inside the eigensolve phase.
  std::atomic<bool> cancel{true};
  options.cancel = &cancel;
  options.progress = nullptr;
  EXPECT_THAT(BuildBasis(mesh, op, options), StatusIs(absl::StatusCode::kCancelled));
  cancel = false;
  options.progress = [&](BasisPhase phase, double) {
    if (phase == BasisPhase::kEigensolve) cancel = true;
  };
  EXPECT_THAT(BuildBasis(mesh, op, options), StatusIs(absl::StatusCode::kCancelled));
}

// Eigen 3.4's SparseMatrix has no move operations of its own (core/common/
// eigen_sparse_matrix_plugin.h adds them): without them each of these moves copied U.
TEST(BasisTest, MovingABasisTakesOverItsArrays) {
  const TriangleMesh mesh = Icosphere(3);
  FieldOperator op = MustBuildOperator(mesh, FieldType::Vector());
  BasisOptions options;
  options.params.dimension = 40;
  absl::StatusOr<Basis> built = BuildBasis(mesh, op, options);
  ASSERT_TRUE(built.ok()) << built.status();
  const float* values = built->U.valuePtr();
  const int* columns = built->U.innerIndexPtr();
  const Eigen::MatrixXf dense = Eigen::MatrixXf(built->U);

  Basis moved = *std::move(built);
  EXPECT_EQ(moved.U.valuePtr(), values);
  EXPECT_EQ(moved.U.innerIndexPtr(), columns);
  EXPECT_EQ(built->U.nonZeros(), 0);
  absl::StatusOr<Basis> again;
  again = std::move(moved);
  EXPECT_EQ(again->U.valuePtr(), values);
  EXPECT_EQ(Eigen::MatrixXf(again->U), dense);

  const double* stiffness = op.stiffness.valuePtr();
  const FieldOperator taken = std::move(op);
  EXPECT_EQ(taken.stiffness.valuePtr(), stiffness);
  EXPECT_EQ(op.stiffness.rows(), 0);
}

TEST(BasisTest, StackBasesConcatenatesColumns) {
  const TriangleMesh mesh = Icosphere(3);  // 1280 faces
  const FieldOperator op = MustBuildOperator(mesh, FieldType::Vector());
  BasisOptions options;
  options.params.dimension = 60;
  auto fine = BuildBasis(mesh, op, options);
  ASSERT_TRUE(fine.ok()) << fine.status();
  options.params.dimension = 9;  // odd: the last coarse region has one field
  auto coarse = BuildBasis(mesh, op, options);
  ASSERT_TRUE(coarse.ok()) << coarse.status();
  auto stacked = StackBases(*fine, *coarse);
  ASSERT_TRUE(stacked.ok()) << stacked.status();
  EXPECT_EQ(stacked->dimension(), 69);
  EXPECT_EQ(stacked->U.rows(), fine->U.rows());
  EXPECT_EQ(stacked->U.nonZeros(), fine->U.nonZeros() + coarse->U.nonZeros());
  EXPECT_EQ(stacked->num_regions(), fine->num_regions() + coarse->num_regions());
  EXPECT_EQ(stacked->local_eigenvalues.size(), 69u);
  EXPECT_EQ(stacked->uncovered_faces, 0);
  const Eigen::MatrixXf s = Eigen::MatrixXf(stacked->U);
  EXPECT_EQ(s.leftCols(60), Eigen::MatrixXf(fine->U));
  EXPECT_EQ(s.rightCols(9), Eigen::MatrixXf(coarse->U));
  // A fine basis laid out with room for the coarse one's entries (reserve_entries) takes them in
  // place, in its own arrays, and is the same stack.
  options.params.dimension = 60;
  options.reserve_entries = coarse->U.nonZeros();
  auto roomy = BuildBasis(mesh, op, options);
  ASSERT_TRUE(roomy.ok()) << roomy.status();
  EXPECT_EQ(Eigen::MatrixXf(roomy->U), Eigen::MatrixXf(fine->U));
  const float* arrays = roomy->U.valuePtr();
  auto in_place = StackBases(*std::move(roomy), *coarse);
  ASSERT_TRUE(in_place.ok()) << in_place.status();
  EXPECT_EQ(in_place->U.valuePtr(), arrays);
  EXPECT_EQ(Eigen::MatrixXf(in_place->U), s);
  EXPECT_EQ(in_place->U.nonZeros(), stacked->U.nonZeros());
  options.params.dimension = 9;
  options.reserve_entries = 0;

  const TriangleMesh small = Icosphere(2);
  auto other = BuildBasis(small, MustBuildOperator(small, FieldType::Vector()), options);
  ASSERT_TRUE(other.ok());
  EXPECT_THAT(StackBases(*fine, *other), StatusIs(absl::StatusCode::kInvalidArgument));
  auto nfield = BuildBasis(mesh, MustBuildOperator(mesh, FieldType::NField(4)), options);
  ASSERT_TRUE(nfield.ok());
  EXPECT_THAT(StackBases(*fine, *nfield), StatusIs(absl::StatusCode::kInvalidArgument));
}

TEST(BasisTest, TwoLevelBasisIsTheStackOfItsLevels) {
  const TriangleMesh mesh = Icosphere(3);
  const FieldOperator op = MustBuildOperator(mesh, FieldType::Vector());
  BasisOptions options;
  options.params.dimension = 69;
  std::vector<std::pair<BasisPhase, double>> seen;
  options.progress = [&](BasisPhase phase, double fraction) { seen.emplace_back(phase, fraction); };
  auto two = BuildTwoLevelBasis(mesh, op, options, 9);
  ASSERT_TRUE(two.ok()) << two.status();
  options.progress = nullptr;
  options.params.dimension = 60;
  auto fine = BuildBasis(mesh, op, options);
  options.params.dimension = 9;
  auto coarse = BuildBasis(mesh, op, options);
  ASSERT_TRUE(fine.ok() && coarse.ok());
  auto stacked = StackBases(*fine, *coarse);
  ASSERT_TRUE(stacked.ok());
  EXPECT_EQ(two->dimension(), 69);
  EXPECT_EQ(two->params.dimension, 69);
  EXPECT_EQ(Eigen::MatrixXf(two->U), Eigen::MatrixXf(stacked->U));
  // It is stored and loaded like any basis.
  auto bytes = EncodeBasis(*two, "m-0000000000000001");
  ASSERT_TRUE(bytes.ok()) << bytes.status();
  auto decoded = DecodeBasis(*bytes);
  ASSERT_TRUE(decoded.ok()) << decoded.status();
  EXPECT_EQ(Eigen::MatrixXf(decoded->basis.U), Eigen::MatrixXf(two->U));
  EXPECT_EQ(decoded->basis.local_eigenvalues, two->local_eigenvalues);
  // Progress stays in [0, 1]. The coarse level is built first, in the first 9/69; the fine level
  // reports past it, up to the end.
  ASSERT_FALSE(seen.empty());
  double highest = 0;
  double first_eigensolve = -1;
  for (const auto& [phase, fraction] : seen) {
    EXPECT_GE(fraction, 0.0);
    EXPECT_LE(fraction, 1.0);
    highest = std::max(highest, fraction);
    if (phase == BasisPhase::kEigensolve && first_eigensolve < 0) first_eigensolve = fraction;
  }
  EXPECT_LE(first_eigensolve, 9.0 / 69.0 + 1e-12);
  EXPECT_GT(highest, 60.0 / 69.0);
  // C = 0 is the one-level basis; C outside [0, d) is rejected.
  options.params.dimension = 60;
  auto one = BuildTwoLevelBasis(mesh, op, options, 0);
  ASSERT_TRUE(one.ok());
  EXPECT_EQ(Eigen::MatrixXf(one->U), Eigen::MatrixXf(fine->U));
  EXPECT_THAT(BuildTwoLevelBasis(mesh, op, options, 60),
              StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(BuildTwoLevelBasis(mesh, op, options, -1),
              StatusIs(absl::StatusCode::kInvalidArgument));
}

TEST(BasisTest, MultiLevelBasisIsTheStackOfItsLevels) {
  const TriangleMesh mesh = Icosphere(3);
  const FieldOperator op = MustBuildOperator(mesh, FieldType::Vector());
  BasisOptions options;
  options.params.dimension = 1;  // ignored: the levels give the dimensions and sigmas
  const std::vector<BasisLevel> levels = {{60, 30.0}, {12, 25.0}, {4, 20.0}};
  auto three = BuildMultiLevelBasis(mesh, op, options, levels);
  ASSERT_TRUE(three.ok()) << three.status();
  std::vector<Basis> built;
  for (const BasisLevel& level : levels) {
    options.params.dimension = level.dimension;
    options.params.sigma = level.sigma;
    auto b = BuildBasis(mesh, op, options);
    ASSERT_TRUE(b.ok()) << b.status();
    built.push_back(*std::move(b));
  }
  auto two = StackBases(built[0], built[1]);
  ASSERT_TRUE(two.ok());
  auto stacked = StackBases(*std::move(two), built[2]);
  ASSERT_TRUE(stacked.ok());
  EXPECT_EQ(three->dimension(), 76);
  EXPECT_EQ(three->params.dimension, 76);
  EXPECT_EQ(three->kernel_columns, 0);  // genus 0
  EXPECT_EQ(Eigen::MatrixXf(three->U), Eigen::MatrixXf(stacked->U));
  EXPECT_GT(three->timings.eigensolve_seconds, built[0].timings.eigensolve_seconds * 0.5);
  // Bad levels.
  EXPECT_THAT(BuildMultiLevelBasis(mesh, op, options, {}),
              StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(BuildMultiLevelBasis(mesh, op, options, {{60, 40.0}, {0, 40.0}}),
              StatusIs(absl::StatusCode::kInvalidArgument));
}

TEST(BasisTest, MultiLevelBasisOnATorusEndsWithTheKernelColumns) {
  const TriangleMesh mesh = testing::Torus(24, 12, 1.0, 0.4);
  const FieldOperator op = MustBuildOperator(mesh, FieldType::Vector());
  BasisOptions options;
  auto levels = QualityLevels(BasisQuality::kLowModes, 80, options.params.sigma);
  ASSERT_TRUE(levels.ok()) << levels.status();
  auto basis = BuildMultiLevelBasis(mesh, op, options, *levels);
  ASSERT_TRUE(basis.ok()) << basis.status();
  EXPECT_EQ(basis->kernel_columns, 2);  // 2 g
  EXPECT_EQ(basis->dimension(), 82);
}

// The kernel columns go into the room BuildBasis leaves in U's layout (the build's peak then
// holds one U, not two): the same matrix, bit for bit, as appending them to a basis built without
// that room (AppendColumns into a new U), and U keeps the arrays it was written to.
TEST(BasisTest, KernelColumnsFillTheRoomLeftInU) {
  const TriangleMesh mesh = testing::Torus(24, 12, 1.0, 0.4);  // genus 1: 2 harmonic fields
  const FieldOperator op = MustBuildOperator(mesh, FieldType::Vector());
  EXPECT_EQ(KernelEntriesBound(mesh, FieldType::Vector()), 2 * 2 * int64_t{mesh.num_faces()});
  BasisOptions options;
  options.params.dimension = 60;
  options.kernel_columns = true;
  auto with_room = BuildBasis(mesh, op, options);
  ASSERT_TRUE(with_room.ok()) << with_room.status();
  ASSERT_EQ(with_room->kernel_columns, 2);
  options.kernel_columns = false;
  auto local = BuildBasis(mesh, op, options);
  ASSERT_TRUE(local.ok()) << local.status();
  auto K = ComputeKernelFields(mesh, op);
  ASSERT_TRUE(K.ok()) << K.status();
  const auto same_matrix = [](const Eigen::SparseMatrix<float, Eigen::RowMajor>& a,
                              const Eigen::SparseMatrix<float, Eigen::RowMajor>& b) {
    ASSERT_EQ(a.rows(), b.rows());
    ASSERT_EQ(a.cols(), b.cols());
    ASSERT_EQ(a.nonZeros(), b.nonZeros());
    EXPECT_TRUE(std::equal(a.outerIndexPtr(), a.outerIndexPtr() + a.rows() + 1, b.outerIndexPtr()));
    EXPECT_TRUE(std::equal(a.innerIndexPtr(), a.innerIndexPtr() + a.nonZeros(), b.innerIndexPtr()));
    EXPECT_TRUE(std::equal(a.valuePtr(), a.valuePtr() + a.nonZeros(), b.valuePtr()));
  };
  // A copy has no room: a new U.
  Basis copied = *local;
  ASSERT_LT(copied.U.data().allocatedSize(), copied.U.nonZeros() + 2 * copied.U.rows());
  ASSERT_TRUE(AppendKernelColumns(*K, &copied).ok());
  same_matrix(copied.U, with_room->U);
  // With room: the same arrays, the same result.
  Basis roomy = *local;
  roomy.U.data().reserve(2 * roomy.U.rows());
  const float* values = roomy.U.valuePtr();
  const int32_t* columns = roomy.U.innerIndexPtr();
  ASSERT_TRUE(AppendKernelColumns(*K, &roomy).ok());
  EXPECT_EQ(roomy.U.valuePtr(), values);
  EXPECT_EQ(roomy.U.innerIndexPtr(), columns);
  same_matrix(roomy.U, with_room->U);
  EXPECT_EQ(roomy.kernel_columns, 2);
  EXPECT_EQ(roomy.dimension(), 62);
}

TEST(BasisTest, QualityLevels) {
  auto paper = QualityLevels(BasisQuality::kPaper, 2000, 40.0);
  ASSERT_TRUE(paper.ok());
  ASSERT_EQ(paper->size(), 1u);
  EXPECT_EQ((*paper)[0].dimension, 2000);
  EXPECT_EQ((*paper)[0].sigma, 40.0);
  auto low = QualityLevels(BasisQuality::kLowModes, 2000, 40.0);
  ASSERT_TRUE(low.ok());
  ASSERT_EQ(low->size(), 3u);
  EXPECT_EQ((*low)[0].dimension, 1750);
  EXPECT_EQ((*low)[1].dimension, 200);
  EXPECT_EQ((*low)[2].dimension, 50);
  for (const BasisLevel& level : *low) EXPECT_EQ(level.sigma, 25.0);
  // The total is d for any d >= 40.
  for (int32_t d : {40, 41, 99, 1001}) {
    auto levels = QualityLevels(BasisQuality::kLowModes, d, 40.0);
    ASSERT_TRUE(levels.ok());
    int32_t total = 0;
    for (const BasisLevel& level : *levels) {
      EXPECT_GE(level.dimension, 1);
      total += level.dimension;
    }
    EXPECT_EQ(total, d);
  }
  EXPECT_THAT(QualityLevels(BasisQuality::kLowModes, 39, 40.0),
              StatusIs(absl::StatusCode::kInvalidArgument));
  for (const BasisLevel& level : *low) EXPECT_FALSE(level.clamped);
  // Smooth: low-modes' levels, clamped.
  for (int32_t d : {40, 2000}) {
    auto smooth = QualityLevels(BasisQuality::kSmooth, d, 40.0);
    auto levels = QualityLevels(BasisQuality::kLowModes, d, 40.0);
    ASSERT_TRUE(smooth.ok() && levels.ok());
    ASSERT_EQ(smooth->size(), levels->size());
    for (size_t i = 0; i < smooth->size(); ++i) {
      EXPECT_EQ((*smooth)[i].dimension, (*levels)[i].dimension);
      EXPECT_EQ((*smooth)[i].sigma, (*levels)[i].sigma);
      EXPECT_TRUE((*smooth)[i].clamped);
    }
  }
  EXPECT_THAT(QualityLevels(BasisQuality::kSmooth, 39, 40.0),
              StatusIs(absl::StatusCode::kInvalidArgument));
  // The paper's with a coarse dimension C: {d - C, sigma} then {C, sigma}; C = 0 is one level.
  auto two = QualityLevels(BasisQuality::kPaper, 2000, 40.0, 200);
  ASSERT_TRUE(two.ok());
  ASSERT_EQ(two->size(), 2u);
  EXPECT_EQ((*two)[0].dimension, 1800);
  EXPECT_EQ((*two)[1].dimension, 200);
  for (const BasisLevel& level : *two) {
    EXPECT_EQ(level.sigma, 40.0);
    EXPECT_FALSE(level.clamped);
  }
  EXPECT_EQ(QualityLevels(BasisQuality::kPaper, 2000, 40.0, 0)->size(), 1u);
  for (int32_t coarse : {-1, 2000, 2001}) {
    EXPECT_THAT(QualityLevels(BasisQuality::kPaper, 2000, 40.0, coarse),
                StatusIs(absl::StatusCode::kInvalidArgument,
                         ::testing::HasSubstr("must be in [0, d = 2000)")));
  }
  // The other qualities set their own levels.
  for (BasisQuality quality : {BasisQuality::kLowModes, BasisQuality::kSmooth}) {
    EXPECT_THAT(
        QualityLevels(quality, 2000, 40.0, 200),
        StatusIs(absl::StatusCode::kInvalidArgument, ::testing::HasSubstr("coarse dimension")));
  }
}

// A clamped local field vanishes outside its region, so its full-space biharmonic energy
// x^T S M^-1 S x (every row of S x, also outside the region) is exactly its local eigenvalue; the
// paper's Dirichlet fields kink at the region's edge and carry several times the square of
// theirs. Also through the multilevel builder, for n-fields (the same generic local problem).
TEST(BasisTest, ClampedLocalFieldsCarryTheirEigenvalueAsBiharmonicEnergy) {
  const TriangleMesh mesh = Icosphere(3);  // 1280 faces
  for (const FieldType& type : {FieldType::Vector(), FieldType::NField(4)}) {
    SCOPED_TRACE(type.kind == FieldKind::kVector ? "vector" : "4-field");
    const FieldOperator op = MustBuildOperator(mesh, type);
    const Eigen::SparseMatrix<double> B = BiharmonicMatrix(op);
    BasisOptions options;
    options.params.sigma = 20.0;
    options.kernel_columns = false;
    options.threads = 2;
    auto clamped = BuildMultiLevelBasis(mesh, op, options, {{60, 20.0, true}, {10, 20.0, true}});
    auto dirichlet = BuildMultiLevelBasis(mesh, op, options, {{60, 20.0}, {10, 20.0}});
    ASSERT_TRUE(clamped.ok()) << clamped.status();
    ASSERT_TRUE(dirichlet.ok()) << dirichlet.status();
    ASSERT_EQ(clamped->dimension(), 70);
    // Same regions, so the same sparsity.
    EXPECT_EQ(clamped->U.nonZeros(), dirichlet->U.nonZeros());
    double min_dirichlet_ratio = std::numeric_limits<double>::infinity();
    for (int32_t j = 0; j < 70; ++j) {
      const Eigen::VectorXd c = Eigen::MatrixXd(clamped->U.col(j).cast<double>());
      const double mass = c.dot(op.mass.asDiagonal() * c);
      EXPECT_NEAR(mass, 1.0, 1e-5);
      const double energy = c.dot(B * c) / mass;
      EXPECT_NEAR(energy, clamped->local_eigenvalues[j], 1e-4 * energy) << "column " << j;
      if (j >= 60) continue;  // the coarse level's regions may cover the sphere: no edge
      const Eigen::VectorXd u = Eigen::MatrixXd(dirichlet->U.col(j).cast<double>());
      const double lambda = dirichlet->local_eigenvalues[j];
      min_dirichlet_ratio = std::min(min_dirichlet_ratio, u.dot(B * u) / (lambda * lambda));
    }
    EXPECT_GT(min_dirichlet_ratio, 2.0);
  }
}

TEST(BasisTest, InvalidParameters) {
  const TriangleMesh mesh = Icosphere(2);  // 320 faces, 640 DOFs
  const FieldOperator op = MustBuildOperator(mesh, FieldType::Vector());
  auto status_of = [&](auto mutate) {
    BasisOptions options;
    options.params.dimension = 20;
    mutate(options);
    return BuildBasis(mesh, op, options).status();
  };
  using absl::StatusCode;
  EXPECT_THAT(status_of([](BasisOptions&) {}), IsOk());
  EXPECT_THAT(status_of([](BasisOptions& o) { o.params.dimension = 0; }),
              StatusIs(StatusCode::kInvalidArgument));
  EXPECT_THAT(status_of([](BasisOptions& o) { o.params.dimension = -3; }),
              StatusIs(StatusCode::kInvalidArgument));
  EXPECT_THAT(status_of([](BasisOptions& o) { o.params.dimension = 641; }),
              StatusIs(StatusCode::kInvalidArgument));
  EXPECT_THAT(status_of([](BasisOptions& o) { o.params.sigma = 0; }),
              StatusIs(StatusCode::kInvalidArgument));
  EXPECT_THAT(status_of([](BasisOptions& o) { o.params.sigma = -1; }),
              StatusIs(StatusCode::kInvalidArgument));
  EXPECT_THAT(status_of([](BasisOptions& o) { o.params.sigma = std::nan(""); }),
              StatusIs(StatusCode::kInvalidArgument));
  EXPECT_THAT(status_of([](BasisOptions& o) { o.params.sigma = INFINITY; }),
              StatusIs(StatusCode::kInvalidArgument));
  EXPECT_THAT(status_of([](BasisOptions& o) { o.params.fields_per_region = 0; }),
              StatusIs(StatusCode::kInvalidArgument));
  EXPECT_THAT(
      status_of([](BasisOptions& o) { o.params.face_weights = Eigen::VectorXd::Ones(319); }),
      StatusIs(StatusCode::kInvalidArgument));
  EXPECT_THAT(status_of([](BasisOptions& o) {
                o.params.face_weights = Eigen::VectorXd::Ones(320);
                o.params.face_weights[5] = 0.0;
              }),
              StatusIs(StatusCode::kInvalidArgument));
  EXPECT_THAT(status_of([](BasisOptions& o) {
                o.params.face_weights = Eigen::VectorXd::Ones(320);
                o.params.face_weights[7] = -2.0;
              }),
              StatusIs(StatusCode::kInvalidArgument));
  EXPECT_THAT(status_of([](BasisOptions& o) {
                o.params.face_weights = Eigen::VectorXd::Ones(320);
                o.params.face_weights[9] = std::nan("");
              }),
              StatusIs(StatusCode::kInvalidArgument));
  EXPECT_THAT(status_of([](BasisOptions& o) { o.threads = -1; }),
              StatusIs(StatusCode::kInvalidArgument));
  EXPECT_THAT(status_of([](BasisOptions& o) { o.eigen_tolerance = 0; }),
              StatusIs(StatusCode::kInvalidArgument));
  // Memory limits: the sigma * k estimate, and the exact count.
  EXPECT_THAT(status_of([](BasisOptions& o) { o.max_basis_bytes = 1000; }),
              StatusIs(StatusCode::kResourceExhausted));
  // An operator for another mesh.
  const TriangleMesh other = Icosphere(1);
  const FieldOperator other_op = MustBuildOperator(other, FieldType::Vector());
  BasisOptions options;
  options.params.dimension = 10;
  EXPECT_THAT(BuildBasis(mesh, other_op, options), StatusIs(StatusCode::kInvalidArgument));
}

TEST(BasisTest, DimensionEqualToDofCountIsAllowed) {
  const TriangleMesh mesh = Icosphere(1);  // 80 faces, 160 DOFs
  const FieldOperator op = MustBuildOperator(mesh, FieldType::Vector());
  BasisOptions options;
  options.params.dimension = 160;  // 80 regions: every face a sample
  options.params.sigma = 2.0;
  auto basis = BuildBasis(mesh, op, options);
  ASSERT_TRUE(basis.ok()) << basis.status();
  EXPECT_EQ(basis->num_regions(), 80);
  EXPECT_GT(basis->stats.dense_regions, 0);
}

// The admission estimate covers the peaks measured with `fieldspace-bench basis ... --stats`
// at d = 2000, sigma 40, 2 threads (bench/RESULTS.md, "Session 28": vector builds hold no S) and
// stays within 1.5x of the one-level ones, so that it does not refuse what fits.
TEST(BasisTest, BuildPeakEstimateCoversMeasuredPeaks) {
  constexpr int64_t kMiB = int64_t{1} << 20;
  const FieldType vector = FieldType::Vector();
  const auto estimate = [&](int64_t faces, bool kernel, BasisQuality quality, int32_t coarse = 0) {
    return EstimateBuildPeakBytes(faces, vector, 2000, 40.0, kernel, quality, coarse, 2);
  };
  struct Measured {
    int64_t faces;
    bool kernel;  // kernel columns (genus > 0)
    int64_t paper_mib, low_modes_mib;
  };
  // armadillo_86k, igea_269k, armadillo_loop2_1384k, fertility_loop3_1789k (genus 4).
  for (const Measured& m :
       {Measured{86482, false, 89, 183}, Measured{268686, false, 232, 515},
        Measured{1383712, false, 1223, 2665}, Measured{1789056, true, 2346, 4366}}) {
    SCOPED_TRACE(m.faces);
    const int64_t paper = estimate(m.faces, m.kernel, BasisQuality::kPaper);
    EXPECT_GE(paper, m.paper_mib * kMiB);
    EXPECT_LE(paper, m.paper_mib * kMiB * 3 / 2);
    const int64_t low_modes = estimate(m.faces, m.kernel, BasisQuality::kLowModes);
    EXPECT_GE(low_modes, m.low_modes_mib * kMiB);
    EXPECT_LE(low_modes, m.low_modes_mib * kMiB * 3 / 2);
  }
  // A coarse second level (--coarse-dim 200) on armadillo_86k: 160 MiB.
  EXPECT_GE(estimate(86482, false, BasisQuality::kPaper, 200), 160 * kMiB);
  // The smooth quality level with 2 threads (Session 22): kitten_29k (28,944 faces) peaked at
  // 557 MiB, fertility_60k (60,012) at 1193 MiB and armadillo_86k at 1460 MiB; the clamped term
  // is what covers them.
  EXPECT_GE(estimate(28944, false, BasisQuality::kSmooth), 557 * kMiB);
  EXPECT_LT(estimate(28944, false, BasisQuality::kLowModes), 557 * kMiB);
  EXPECT_GE(estimate(60012, false, BasisQuality::kSmooth), 1193 * kMiB);
  EXPECT_GE(estimate(86482, false, BasisQuality::kSmooth), 1460 * kMiB);
  EXPECT_LE(estimate(86482, false, BasisQuality::kSmooth), 2 * 1460 * kMiB);
  // Builds that read S hold it: an n-field build's estimate is above a vector build's of the
  // same size (2 DOFs per face both).
  EXPECT_GT(EstimateBuildPeakBytes(86482, FieldType::NField(4), 2000, 40.0, false,
                                   BasisQuality::kPaper, 0, 2),
            estimate(86482, false, BasisQuality::kPaper));
}

}  // namespace
}  // namespace fieldspace
