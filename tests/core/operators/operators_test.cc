// Invariants of the assembled operators on real meshes and shapes built in code: symmetry,
// positive semi-definiteness, kernel dimension = 2 * genus, the analytic spectrum of the sphere,
// the tensor = scalar + 2-field decoupling, and independence of the per-face frame choice.
#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include "Eigen/Dense"
#include "Eigen/SparseCore"
#include "core/linalg/eigensolver.h"
#include "core/linalg/sparse_checks.h"
#include "core/mesh/shapes.h"
#include "core/operators/conversions.h"
#include "core/operators/field_operator.h"
#include "core/operators/nfield_laplacian.h"
#include "core/operators/tensor_laplacian.h"
#include "core/operators/vector_laplacian.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tests/testing/fixtures.h"
#include "tests/testing/matchers.h"
#include "tests/testing/test_meshes.h"

namespace fieldspace {
namespace {

using ::fieldspace::testing::StatusIs;
using SpMat = Eigen::SparseMatrix<double>;
using ::fieldspace::testing::CatalogueArrays;
using ::fieldspace::testing::CatalogueMesh;
using ::fieldspace::testing::MaxAbs;
using ::fieldspace::testing::MaxAbsDiff;
using ::fieldspace::testing::MustBuildOperator;
using ::fieldspace::testing::MustCreate;
using ::fieldspace::testing::PlanarStrip;

EigenResult Lowest(const SpMat& S, const Eigen::VectorXd& mass, int count, bool vectors = false) {
  EigenOptions options;
  options.count = count;
  options.compute_vectors = vectors;
  auto result = LowestEigenpairs(S, mass, options);
  EXPECT_TRUE(result.ok()) << result.status();
  return result.ok() ? *result : EigenResult{};
}

// max_i S_ii / M_ii: the scale of the largest eigenvalues.
double Scale(const FieldOperator& op) {
  double m = 0;
  for (int i = 0; i < op.dofs(); ++i) m = std::max(m, op.stiffness.coeff(i, i) / op.mass[i]);
  return m;
}

// On the irregular, obtuse, noisy and bordered meshes of the catalogue (what real meshes are like).
TEST(OperatorPropertiesTest, SymmetricPsdPositiveMassOnIrregularMeshes) {
  for (const char* name : {"NoisySphere", "ChippedTorus", "ObtuseTorus", "Cylinder"}) {
    const TriangleMesh mesh = CatalogueMesh(name);
    for (FieldType type : {FieldType::Vector(), FieldType::NField(3), FieldType::Tensor()}) {
      SCOPED_TRACE(std::string(name) + " " + type.ToString());
      const FieldOperator op = MustBuildOperator(mesh, type);
      // Bitwise symmetric (the assembly mirrors blocks exactly).
      EXPECT_TRUE(CheckSymmetric(op.stiffness, 0.0, "S").ok());
      EXPECT_TRUE(op.stiffness.isCompressed());
      EXPECT_GT(op.mass.minCoeff(), 0.0);
      // PSD: the smallest eigenvalue of S x = lambda M x is >= -1e-10 relative to the largest.
      // (The shift-invert solver also fails outright if an eigenvalue is below its shift.)
      const EigenResult r = Lowest(op.stiffness, op.mass, 3);
      ASSERT_EQ(r.values.size(), 3);
      EXPECT_GE(r.values[0], -1e-10 * Scale(op));
    }
  }
}

TEST(OperatorPropertiesTest, DensePsdCheckOnSmallShapes) {
  // Independent of the sparse eigensolver: all eigenvalues of M^-1/2 S M^-1/2 by dense LAPACK-free
  // Eigen on small meshes, with and without boundary.
  std::vector<TriangleMesh> meshes;
  meshes.push_back(MustCreate(MakeIcosphere(2)));
  meshes.push_back(MustCreate(MakeTorus(1.0, 0.3, 16, 8)));
  meshes.push_back(MustCreate(PlanarStrip(12, 6)));
  for (const TriangleMesh& mesh : meshes) {
    for (FieldType type : {FieldType::Vector(), FieldType::NField(5), FieldType::Tensor()}) {
      const FieldOperator op = MustBuildOperator(mesh, type);
      const Eigen::VectorXd d = op.mass.cwiseSqrt().cwiseInverse();
      const Eigen::MatrixXd A = d.asDiagonal() * Eigen::MatrixXd(op.stiffness) * d.asDiagonal();
      Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(A, Eigen::EigenvaluesOnly);
      EXPECT_GE(es.eigenvalues()[0], -1e-12 * es.eigenvalues().maxCoeff()) << type.ToString();
    }
  }
}

// Whether the ascending eigenvalues `values` (at least dimension + 2 of them) show a kernel of
// exactly `dimension`: lambda_1 .. lambda_dimension are rounding noise next to the first nonzero
// eigenvalue lambda_{dimension+1}, and lambda_{dimension+1} is clearly positive next to
// lambda_{dimension+2} (one more near-zero mode, as a wrong operator might have, fails).
::testing::AssertionResult HasKernelDimension(const Eigen::VectorXd& values, int dimension) {
  if (values.size() < dimension + 2) {
    return ::testing::AssertionFailure() << "only " << values.size() << " eigenvalues";
  }
  const double first_nonzero = values[dimension];
  const double next = values[dimension + 1];
  if (!(first_nonzero > 1e-4 * next)) {
    return ::testing::AssertionFailure()
           << "lambda_" << dimension + 1 << " = " << first_nonzero
           << " is not clearly positive next to lambda_" << dimension + 2 << " = " << next
           << ": the kernel is larger than " << dimension;
  }
  for (int i = 0; i < dimension; ++i) {
    if (!(std::abs(values[i]) < 1e-9 * first_nonzero)) {
      return ::testing::AssertionFailure()
             << "lambda_" << i + 1 << " = " << values[i] << " is not ~0 next to lambda_"
             << dimension + 1 << " = " << first_nonzero << ": the kernel is smaller than "
             << dimension;
    }
  }
  return ::testing::AssertionSuccess()
         << "largest kernel eigenvalue "
         << (dimension > 0 ? values.head(dimension).cwiseAbs().maxCoeff() : 0.0)
         << ", smallest nonzero " << first_nonzero;
}

// The vector Hodge Laplacian of a closed surface has a kernel of dimension exactly 2 g (the
// harmonic fields), on every closed mesh of the catalogue: genus 0 to 5, regular, irregular,
// obtuse and noisy, and two components.
class VectorHodgeKernelTest : public testing::MeshCaseTest {};

TEST_P(VectorHodgeKernelTest, DimensionIsTwiceTheGenus) {
  const testing::MeshCase& c = GetParam();
  ASSERT_EQ(mesh().genus(), c.genus);
  const FieldOperator op = MustBuildOperator(mesh(), FieldType::Vector());
  const int kernel = 2 * c.genus;
  const EigenResult r = Lowest(op.stiffness, op.mass, kernel + 3);
  ASSERT_EQ(r.values.size(), kernel + 3);
  EXPECT_TRUE(HasKernelDimension(r.values, kernel)) << c.name;
  // The first nonzero eigenvalue is far above rounding noise on the scale of the operator.
  EXPECT_GT(r.values[kernel], 1e-8 * Scale(op)) << c.name;
  // The check itself tells a kernel one too large or one too small.
  EXPECT_FALSE(HasKernelDimension(r.values, kernel + 1)) << c.name;
  if (kernel > 0) {
    EXPECT_FALSE(HasKernelDimension(r.values, kernel - 1)) << c.name;
  }
  std::printf("%s (genus %d, %d faces): lowest eigenvalues", c.name.c_str(), c.genus,
              mesh().num_faces());
  for (double v : r.values) std::printf(" %.3g", v);
  std::printf("\n");
}

INSTANTIATE_TEST_SUITE_P(Catalogue, VectorHodgeKernelTest,
                         ::testing::ValuesIn(testing::ClosedMeshCases(testing::MeshCatalogue())),
                         testing::MeshCaseName);

TEST(VectorHodgeTest, UnitSphereSpectrumConvergesToLTimesLPlusOne) {
  // l(l+1) with multiplicity 2(2l+1): 2 (x6), 6 (x10), 12 (x14).
  std::vector<double> exact;
  for (int l = 1; l <= 3; ++l) exact.insert(exact.end(), 2 * (2 * l + 1), l * (l + 1.0));
  double previous_error = 1e300;
  for (int level = 3; level <= 5; ++level) {
    const TriangleMesh mesh = MustCreate(MakeIcosphere(level, 1.0));
    const FieldOperator op = MustBuildOperator(mesh, FieldType::Vector());
    const EigenResult r = Lowest(op.stiffness, op.mass, static_cast<int>(exact.size()));
    double error = 0;
    for (size_t i = 0; i < exact.size(); ++i) {
      error = std::max(error, std::abs(r.values[i] - exact[i]) / exact[i]);
    }
    std::printf(
        "icosphere level %d (%d faces): max relative eigenvalue error %.3g (%d pairs "
        "recovered by the multiplicity check)\n",
        level, mesh.num_faces(), error, r.recovered);
    EXPECT_LT(error, previous_error) << "level " << level;
    EXPECT_LT(error, level == 3 ? 0.05 : level == 4 ? 0.015 : 0.004) << "level " << level;
    previous_error = error;
  }
}

TEST(NFieldTest, ConstantFieldOnPlanarStripIsInTheKernel) {
  const TriangleMesh mesh = MustCreate(PlanarStrip(20, 5));
  for (int n : {1, 2, 4}) {
    auto S = BuildNFieldStiffness(mesh, n);
    ASSERT_TRUE(S.ok()) << S.status();
    fieldspace::AmbientVectors v(mesh.num_faces(), 3);
    v.rowwise() = Eigen::RowVector3d(0.8, -0.35, 0.0);
    auto x = NFieldDofsFromAmbient(mesh, n, v);
    ASSERT_TRUE(x.ok()) << x.status();
    const double scale = MaxAbs(*S) * x->norm();
    EXPECT_LT((*S * *x).norm(), 1e-12 * scale) << "n = " << n;
    // A field that turns is not in the kernel.
    for (int f = 0; f < mesh.num_faces(); ++f) {
      const double a = 0.3 * mesh.face_barycenters()(f, 0);
      v.row(f) << std::cos(a), std::sin(a), 0.0;
    }
    x = NFieldDofsFromAmbient(mesh, n, v);
    ASSERT_TRUE(x.ok());
    EXPECT_GT(x->dot(*S * *x), 1e-3 * x->squaredNorm()) << "n = " << n;
  }
}

TEST(NFieldTest, FourFieldOnSphereHasNoKernel) {
  // A sphere admits no continuous 4-direction field: the lowest eigenvalue stays clearly positive
  // (and converges under refinement), unlike on the plane.
  double previous = 0;
  for (int level = 3; level <= 4; ++level) {
    const TriangleMesh mesh = MustCreate(MakeIcosphere(level, 1.0));
    const FieldOperator op = MustBuildOperator(mesh, FieldType::NField(4));
    const EigenResult r = Lowest(op.stiffness, op.mass, 4);
    std::printf("4-field on icosphere level %d: lowest eigenvalues %.6g %.6g %.6g\n", level,
                r.values[0], r.values[1], r.values[2]);
    EXPECT_GT(r.values[0], 1.0);
    if (level > 3) {
      EXPECT_NEAR(r.values[0], previous, 0.1 * previous);
    }
    previous = r.values[0];
  }
}

TEST(TensorTest, SpectrumIsUnionOfScalarAndTwoFieldSpectra) {
  const TriangleMesh mesh = CatalogueMesh("Blob");
  const FieldOperator tensor = MustBuildOperator(mesh, FieldType::Tensor());
  const FieldOperator two = MustBuildOperator(mesh, FieldType::NField(2));
  // Scalar face Laplacian with the same weights w_e = 3 |e|^2 / (A_i + A_j), built here.
  std::vector<Eigen::Triplet<double>> t;
  for (int e = 0; e < mesh.num_edges(); ++e) {
    const int i = mesh.edge_faces()(e, 0), j = mesh.edge_faces()(e, 1);
    if (j == kNoFace) continue;
    const double len2 =
        (mesh.vertices().row(mesh.edges()(e, 1)) - mesh.vertices().row(mesh.edges()(e, 0)))
            .squaredNorm();
    const double w = 3 * len2 / (mesh.face_areas()[i] + mesh.face_areas()[j]);
    t.emplace_back(i, i, w);
    t.emplace_back(j, j, w);
    t.emplace_back(i, j, -w);
    t.emplace_back(j, i, -w);
  }
  SpMat scalar(mesh.num_faces(), mesh.num_faces());
  scalar.setFromTriplets(t.begin(), t.end());

  const int count = 24;
  const EigenResult rt = Lowest(tensor.stiffness, tensor.mass, count);
  const EigenResult rs = Lowest(scalar, mesh.face_areas(), count);
  const EigenResult r2 = Lowest(two.stiffness, two.mass, count);
  std::vector<double> merged(rs.values.data(), rs.values.data() + count);
  merged.insert(merged.end(), r2.values.data(), r2.values.data() + count);
  std::sort(merged.begin(), merged.end());
  const double tol = 1e-8 * rt.values[count - 1];
  for (int i = 0; i < count; ++i) EXPECT_NEAR(rt.values[i], merged[i], tol) << i;

  // Entrywise: in per-face coordinates (t, d1, d2) = ((a11 + a22)/sqrt2, (a11 - a22)/sqrt2,
  // sqrt2 a12) the tensor stiffness is exactly blockdiag(scalar, 2-field).
  const int nf = mesh.num_faces();
  std::vector<Eigen::Triplet<double>> q;
  const double h = std::sqrt(0.5);
  for (int f = 0; f < nf; ++f) {
    // a = Q (t, d1, d2): a11 = h (t + d1), a22 = h (t - d1), a3 = d2.
    q.emplace_back(3 * f, 3 * f, h);
    q.emplace_back(3 * f, 3 * f + 1, h);
    q.emplace_back(3 * f + 1, 3 * f, h);
    q.emplace_back(3 * f + 1, 3 * f + 1, -h);
    q.emplace_back(3 * f + 2, 3 * f + 2, 1.0);
  }
  SpMat Q(3 * nf, 3 * nf);
  Q.setFromTriplets(q.begin(), q.end());
  const SpMat rotated = SpMat(Q.transpose()) * tensor.stiffness * Q;
  std::vector<Eigen::Triplet<double>> e;
  for (int j = 0; j < scalar.outerSize(); ++j) {
    for (SpMat::InnerIterator it(scalar, j); it; ++it) {
      e.emplace_back(3 * it.row(), 3 * it.col(), it.value());
    }
  }
  for (int j = 0; j < two.stiffness.outerSize(); ++j) {
    for (SpMat::InnerIterator it(two.stiffness, j); it; ++it) {
      e.emplace_back(3 * (it.row() / 2) + 1 + it.row() % 2, 3 * (it.col() / 2) + 1 + it.col() % 2,
                     it.value());
    }
  }
  SpMat expected(3 * nf, 3 * nf);
  expected.setFromTriplets(e.begin(), e.end());
  EXPECT_LT(MaxAbsDiff(rotated, expected), 1e-12 * MaxAbs(expected));
}

// Per-face change of DOF coordinates when the frame of face f is rotated by phi_f: vectors
// rotate by R(-phi), n-field representation vectors by R(-n phi), tensors by the Mandel-Voigt
// form of A -> R(-phi) A R(-phi)^T (built from the basis tensors, not from eq. 18).
SpMat FrameChange(const TriangleMesh& a, const TriangleMesh& b, FieldType type) {
  std::vector<Eigen::Triplet<double>> t;
  const int p = type.dofs_per_face();
  for (int f = 0; f < a.num_faces(); ++f) {
    const Eigen::Vector3d xb = b.frame_x().row(f);
    const double phi = std::atan2(xb.dot(Eigen::Vector3d(a.frame_y().row(f))),
                                  xb.dot(Eigen::Vector3d(a.frame_x().row(f))));
    Eigen::MatrixXd block;
    if (type.kind == FieldKind::kTensor) {
      Eigen::Matrix2d R;
      R << std::cos(phi), std::sin(phi), -std::sin(phi), std::cos(phi);  // R(-phi)
      block.resize(3, 3);
      for (int k = 0; k < 3; ++k) {
        Eigen::Matrix2d A = Eigen::Matrix2d::Zero();
        if (k == 0) A(0, 0) = 1;
        if (k == 1) A(1, 1) = 1;
        if (k == 2) A(0, 1) = A(1, 0) = std::sqrt(0.5);
        const Eigen::Matrix2d B = R * A * R.transpose();
        block.col(k) << B(0, 0), B(1, 1), std::sqrt(2.0) * B(0, 1);
      }
    } else {
      const double angle = -(type.kind == FieldKind::kNField ? type.n : 1) * phi;
      block.resize(2, 2);
      block << std::cos(angle), -std::sin(angle), std::sin(angle), std::cos(angle);
    }
    for (int r = 0; r < p; ++r) {
      for (int c = 0; c < p; ++c) t.emplace_back(p * f + r, p * f + c, block(r, c));
    }
  }
  SpMat Q(p * a.num_faces(), p * a.num_faces());
  Q.setFromTriplets(t.begin(), t.end());
  return Q;
}

TEST(FrameIndependenceTest, CyclicVertexOrderOnlyRotatesTheDofs) {
  const MeshArrays arrays = CatalogueArrays("NoisySphere");
  MeshArrays permuted = arrays;
  for (int f = 0; f < permuted.faces.rows(); ++f) {
    const Eigen::RowVector3i c = permuted.faces.row(f);
    const int r = f % 3;
    permuted.faces.row(f) << c[r], c[(r + 1) % 3], c[(r + 2) % 3];
  }
  const TriangleMesh a = MustCreate(arrays);
  const TriangleMesh b = MustCreate(permuted);
  for (FieldType type :
       {FieldType::Vector(), FieldType::NField(1), FieldType::NField(4), FieldType::Tensor()}) {
    const FieldOperator oa = MustBuildOperator(a, type);
    const FieldOperator ob = MustBuildOperator(b, type);
    // DOFs in frame b are Q times DOFs in frame a, energies agree: S_b = Q S_a Q^T.
    const SpMat Q = FrameChange(a, b, type);
    const SpMat expected = Q * oa.stiffness * SpMat(Q.transpose());
    EXPECT_LT(MaxAbsDiff(ob.stiffness, expected), 1e-11 * MaxAbs(expected)) << type.ToString();
    EXPECT_LT((oa.mass - ob.mass).cwiseAbs().maxCoeff(), 1e-15 * oa.mass.maxCoeff());
    const EigenResult ra = Lowest(oa.stiffness, oa.mass, 8);
    const EigenResult rb = Lowest(ob.stiffness, ob.mass, 8);
    for (int i = 0; i < 8; ++i) {
      EXPECT_NEAR(ra.values[i], rb.values[i], 1e-8 * ra.values[7]) << type.ToString();
    }
  }
}

// S assembled after the mass is S of BuildFieldOperator bit for bit; until then the operator
// says it has none and the steps that need S refuse it.
TEST(FieldOperatorTest, StiffnessAssembledLaterIsTheSameOperator) {
  const TriangleMesh mesh = CatalogueMesh("ChippedTorus");
  for (FieldType type : {FieldType::Vector(), FieldType::NField(4), FieldType::Tensor()}) {
    SCOPED_TRACE(type.ToString());
    const FieldOperator whole = MustBuildOperator(mesh, type);
    absl::StatusOr<FieldOperator> op = BuildFieldOperatorWithoutStiffness(mesh, type);
    ASSERT_TRUE(op.ok()) << op.status();
    EXPECT_FALSE(op->has_stiffness());
    EXPECT_TRUE(whole.has_stiffness());
    EXPECT_EQ(op->mass, whole.mass);
    EXPECT_THAT(ValidateOperatorShape(*op),
                StatusIs(absl::StatusCode::kInvalidArgument, ::testing::HasSubstr("assembled")));
    ASSERT_TRUE(AssembleStiffness(mesh, &*op).ok());
    EXPECT_TRUE(op->has_stiffness());
    EXPECT_TRUE(ValidateOperatorShape(*op).ok());
    EXPECT_EQ(MaxAbsDiff(op->stiffness, whole.stiffness), 0.0);
    EXPECT_EQ(op->stiffness.nonZeros(), whole.stiffness.nonZeros());
  }
  // The mass must be the mesh's.
  FieldOperator wrong = *BuildFieldOperatorWithoutStiffness(mesh, FieldType::Vector());
  wrong.mass.conservativeResize(wrong.mass.size() - 2);
  EXPECT_THAT(AssembleStiffness(mesh, &wrong), StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(BuildFieldOperatorWithoutStiffness(mesh, FieldType::NField(0)),
              StatusIs(absl::StatusCode::kInvalidArgument));
}

// S's rows computed one face at a time (what the reduced system's products read instead of S)
// are the assembled S's bit for bit, and their trace (the kernel's scale) is S's.
TEST(VectorHodgeTest, RowsWithoutAssemblyAreTheAssembledRows) {
  for (const char* name : {"NoisySphere", "ChippedTorus", "ObtuseTorus", "Cylinder"}) {
    SCOPED_TRACE(name);
    const TriangleMesh mesh = CatalogueMesh(name);
    const FieldOperator op = MustBuildOperator(mesh, FieldType::Vector());
    const double trace = op.stiffness.diagonal().sum();
    absl::StatusOr<VectorHodgeRows> rows = VectorHodgeRows::Create(mesh);
    ASSERT_TRUE(rows.ok()) << rows.status();
    EXPECT_NEAR(rows->Trace(), trace, 1e-12 * trace);
    // Row 2 f + c of S, entry by entry in S's order (S symmetric: column = row).
    int64_t mismatches = 0, visited = 0;
    for (int32_t f = 0; f < mesh.num_faces(); ++f) {
      std::vector<std::pair<int64_t, double>> row[2];
      int32_t blocks = 0;
      rows->ForEachBlock(f, [&](int32_t g, const double* block) {
        ++blocks;
        for (int c = 0; c < 2; ++c) {
          for (int d = 0; d < 2; ++d) row[c].emplace_back(2 * int64_t{g} + d, block[2 * c + d]);
        }
      });
      EXPECT_EQ(blocks, rows->CountBlocks(f));
      for (int c = 0; c < 2; ++c) {
        std::vector<std::pair<int64_t, double>> expected;
        for (SpMat::InnerIterator it(op.stiffness, 2 * int64_t{f} + c); it; ++it) {
          expected.emplace_back(it.row(), it.value());
        }
        mismatches += row[c] != expected;
        visited += static_cast<int64_t>(row[c].size());
      }
    }
    EXPECT_EQ(mismatches, 0);
    EXPECT_EQ(visited, op.stiffness.nonZeros());
  }
}

TEST(VectorHodgeTest, InverseMassesAreAThirdOfTheIncidentAreas) {
  // Each face gives a third of its area to each of its vertices and edges, so the lumped masses
  // each sum to the area, and a vertex's or an edge's is a third of its faces' areas.
  for (const char* name : {"NoisySphere", "ChippedTorus", "Cylinder"}) {
    SCOPED_TRACE(name);
    const TriangleMesh mesh = CatalogueMesh(name);
    const HodgeInverseMasses inv = BuildHodgeInverseMasses(mesh);
    ASSERT_EQ(inv.vertex.size(), static_cast<size_t>(mesh.num_vertices()));
    ASSERT_EQ(inv.edge.size(), static_cast<size_t>(mesh.num_edges()));
    double vertex_total = 0.0, edge_total = 0.0;
    for (double m : inv.vertex) vertex_total += 1.0 / m;
    for (double m : inv.edge) edge_total += 1.0 / m;
    EXPECT_NEAR(vertex_total, mesh.total_area(), 1e-12 * mesh.total_area());
    EXPECT_NEAR(edge_total, mesh.total_area(), 1e-12 * mesh.total_area());
    const Eigen::VectorXd& area = mesh.face_areas();
    const PairMatrix& EF = mesh.edge_faces();
    for (int32_t e = 0; e < mesh.num_edges(); ++e) {
      const double faces = area[EF(e, 0)] + (EF(e, 1) != kNoFace ? area[EF(e, 1)] : 0.0);
      ASSERT_NEAR(inv.edge[e], 3.0 / faces, 1e-12 * inv.edge[e]) << "edge " << e;
    }
    std::vector<double> around(mesh.num_vertices(), 0.0);
    for (int32_t f = 0; f < mesh.num_faces(); ++f) {
      for (int k = 0; k < 3; ++k) around[mesh.faces()(f, k)] += area[f];
    }
    for (int32_t v = 0; v < mesh.num_vertices(); ++v) {
      ASSERT_NEAR(inv.vertex[v], 3.0 / around[v], 1e-12 * inv.vertex[v]) << "vertex " << v;
    }
  }
}

TEST(FieldTypeTest, ValidateAndToString) {
  EXPECT_TRUE(FieldType::Vector().Validate().ok());
  EXPECT_TRUE(FieldType::Tensor().Validate().ok());
  EXPECT_TRUE(FieldType::NField(1).Validate().ok());
  EXPECT_TRUE(FieldType::NField(64).Validate().ok());
  EXPECT_THAT(FieldType::NField(0).Validate(), StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(FieldType::NField(65).Validate(), StatusIs(absl::StatusCode::kInvalidArgument));
  FieldType bogus;
  bogus.kind = static_cast<FieldKind>(7);
  EXPECT_THAT(bogus.Validate(), StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_EQ(FieldType::Vector().ToString(), "vector");
  EXPECT_EQ(FieldType::NField(4).ToString(), "nfield4");
  EXPECT_EQ(FieldType::Tensor().ToString(), "tensor");
  EXPECT_EQ(FieldType::Tensor().dofs_per_face(), 3);
}

TEST(FieldTypeTest, Parse) {
  EXPECT_EQ(*ParseFieldType("vector"), FieldType::Vector());
  EXPECT_EQ(*ParseFieldType("tensor"), FieldType::Tensor());
  EXPECT_EQ(*ParseFieldType("nfield", 4), FieldType::NField(4));
  EXPECT_EQ(*ParseFieldType("nfield6"), FieldType::NField(6));
  EXPECT_EQ(*ParseFieldType("nfield6", 6), FieldType::NField(6));
  for (auto bad :
       {ParseFieldType("nfield"), ParseFieldType("nfield", 0), ParseFieldType("nfield", 65),
        ParseFieldType("nfield4", 3), ParseFieldType("nfieldx"), ParseFieldType("vector", 1),
        ParseFieldType("tensor", 2), ParseFieldType("scalar"), ParseFieldType("")}) {
    EXPECT_THAT(bad, StatusIs(absl::StatusCode::kInvalidArgument));
  }
}

}  // namespace
}  // namespace fieldspace
