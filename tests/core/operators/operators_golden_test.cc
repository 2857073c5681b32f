// Golden values: the assembled operators against hand computations and against literal,
// independent constructions of the formulas in docs/conventions.md, Operators (explicit gradient
// matrices multiplied out; per-edge transports from atan2 angles and tensor basis transforms).
#include <cmath>
#include <string>
#include <vector>

#include "Eigen/Dense"
#include "Eigen/SparseCore"
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
using Triplets = std::vector<Eigen::Triplet<double>>;
using ::fieldspace::testing::Arrays;
using ::fieldspace::testing::CatalogueMesh;
using ::fieldspace::testing::MaxAbs;
using ::fieldspace::testing::MaxAbsDiff;
using ::fieldspace::testing::MustCreate;

Eigen::Matrix2d Rot(double a) {
  Eigen::Matrix2d R;
  R << std::cos(a), -std::sin(a), std::sin(a), std::cos(a);
  return R;
}

// Corner positions of face f in its own frame: (0, 0), (|p1 - p0|, 0), ...
Eigen::Matrix<double, 3, 2> LocalCorners(const TriangleMesh& mesh, int f) {
  const Eigen::Vector3d p0 = mesh.vertices().row(mesh.faces()(f, 0));
  const Eigen::Vector3d x = mesh.frame_x().row(f), y = mesh.frame_y().row(f);
  Eigen::Matrix<double, 3, 2> P;
  for (int k = 0; k < 3; ++k) {
    const Eigen::Vector3d d = Eigen::Vector3d(mesh.vertices().row(mesh.faces()(f, k))) - p0;
    P(k, 0) = d.dot(x);
    P(k, 1) = d.dot(y);
  }
  return P;
}

// Gradient (frame coordinates) of the affine function on face f with the given corner values.
Eigen::Vector2d AffineGradient(const Eigen::Matrix<double, 3, 2>& P, const Eigen::Vector3d& vals) {
  Eigen::Matrix2d E;
  E.row(0) = P.row(1) - P.row(0);
  E.row(1) = P.row(2) - P.row(0);
  return E.fullPivLu().solve(Eigen::Vector2d(vals[1] - vals[0], vals[2] - vals[0]));
}

// S = M G_V Mv^-1 G_V^T M + M J G_E Me^-1 G_E^T J^T M with every matrix built explicitly.
SpMat LiteralVectorHodge(const TriangleMesh& mesh) {
  const int nf = mesh.num_faces(), nv = mesh.num_vertices(), ne = mesh.num_edges();
  Triplets gv, ge, j, m;
  Eigen::VectorXd mv = Eigen::VectorXd::Zero(nv), me = Eigen::VectorXd::Zero(ne);
  // Corner values of a CR function that is 1 at the midpoint of the edge opposite corner k and 0
  // at the other two midpoints: solve (c_{k+1} + c_{k+2}) / 2 = delta.
  Eigen::Matrix3d midpoint_average;
  for (int k = 0; k < 3; ++k) {
    midpoint_average.row(k).setZero();
    midpoint_average(k, (k + 1) % 3) = 0.5;
    midpoint_average(k, (k + 2) % 3) = 0.5;
  }
  for (int f = 0; f < nf; ++f) {
    const double area = mesh.face_areas()[f];
    const auto P = LocalCorners(mesh, f);
    for (int k = 0; k < 3; ++k) {
      const Eigen::Vector2d g = AffineGradient(P, Eigen::Vector3d::Unit(k));
      gv.emplace_back(2 * f, mesh.faces()(f, k), g[0]);
      gv.emplace_back(2 * f + 1, mesh.faces()(f, k), g[1]);
      const Eigen::Vector3d cr = midpoint_average.fullPivLu().solve(Eigen::Vector3d::Unit(k));
      const Eigen::Vector2d h = AffineGradient(P, cr);
      ge.emplace_back(2 * f, mesh.face_edges()(f, k), h[0]);
      ge.emplace_back(2 * f + 1, mesh.face_edges()(f, k), h[1]);
      mv[mesh.faces()(f, k)] += area / 3;
      me[mesh.face_edges()(f, k)] += area / 3;
    }
    j.emplace_back(2 * f, 2 * f + 1, -1.0);  // J (a, b) = (-b, a)
    j.emplace_back(2 * f + 1, 2 * f, 1.0);
    m.emplace_back(2 * f, 2 * f, area);
    m.emplace_back(2 * f + 1, 2 * f + 1, area);
  }
  SpMat GV(2 * nf, nv), GE(2 * nf, ne), J(2 * nf, 2 * nf), M(2 * nf, 2 * nf);
  GV.setFromTriplets(gv.begin(), gv.end());
  GE.setFromTriplets(ge.begin(), ge.end());
  J.setFromTriplets(j.begin(), j.end());
  M.setFromTriplets(m.begin(), m.end());
  const Eigen::VectorXd inv_mv = mv.cwiseInverse(), inv_me = me.cwiseInverse();
  const SpMat A = M * GV;
  const SpMat B = M * J * GE;
  SpMat S1 = A * inv_mv.asDiagonal() * SpMat(A.transpose());
  SpMat S2 = B * inv_me.asDiagonal() * SpMat(B.transpose());
  return S1 + S2;
}

// Edge unit vector (lower to higher vertex) angle in face f's frame, via atan2.
double EdgeAngle(const TriangleMesh& mesh, int e, int f) {
  const Eigen::Vector3d d = Eigen::Vector3d(mesh.vertices().row(mesh.edges()(e, 1))) -
                            Eigen::Vector3d(mesh.vertices().row(mesh.edges()(e, 0)));
  return std::atan2(d.dot(Eigen::Vector3d(mesh.frame_y().row(f))),
                    d.dot(Eigen::Vector3d(mesh.frame_x().row(f))));
}

double EdgeWeight(const TriangleMesh& mesh, int e) {
  const Eigen::Vector3d d = Eigen::Vector3d(mesh.vertices().row(mesh.edges()(e, 1))) -
                            Eigen::Vector3d(mesh.vertices().row(mesh.edges()(e, 0)));
  const int i = mesh.edge_faces()(e, 0), j = mesh.edge_faces()(e, 1);
  return 3 * d.squaredNorm() / (mesh.face_areas()[i] + mesh.face_areas()[j]);
}

// Connection Laplacian from per-edge transports T(e) (face j -> face i), built from triplets.
template <int P, typename Transport>
SpMat LiteralConnection(const TriangleMesh& mesh, Transport transport) {
  Triplets t;
  for (int e = 0; e < mesh.num_edges(); ++e) {
    const int i = mesh.edge_faces()(e, 0), j = mesh.edge_faces()(e, 1);
    if (j == kNoFace) continue;
    const double w = EdgeWeight(mesh, e);
    const Eigen::Matrix<double, P, P> T = transport(e, i, j);
    for (int c = 0; c < P; ++c) {
      t.emplace_back(P * i + c, P * i + c, w);
      t.emplace_back(P * j + c, P * j + c, w);
      for (int d = 0; d < P; ++d) {
        t.emplace_back(P * i + c, P * j + d, -w * T(c, d));
        t.emplace_back(P * j + c, P * i + d, -w * T(d, c));
      }
    }
  }
  SpMat S(P * mesh.num_faces(), P * mesh.num_faces());
  S.setFromTriplets(t.begin(), t.end());
  return S;
}

SpMat LiteralNField(const TriangleMesh& mesh, int n) {
  return LiteralConnection<2>(mesh, [&](int e, int i, int j) {
    return Eigen::Matrix2d(Rot(n * (EdgeAngle(mesh, e, i) - EdgeAngle(mesh, e, j))));
  });
}

Eigen::Matrix2d FromMandelVoigt(const Eigen::Vector3d& a) {
  Eigen::Matrix2d A;
  A << a[0], a[2] / std::sqrt(2.0), a[2] / std::sqrt(2.0), a[1];
  return A;
}
Eigen::Vector3d ToMandelVoigt(const Eigen::Matrix2d& A) {
  return {A(0, 0), A(1, 1), std::sqrt(2.0) * A(0, 1)};
}

SpMat LiteralTensor(const TriangleMesh& mesh) {
  return LiteralConnection<3>(mesh, [&](int e, int i, int j) {
    // R_f: frame-f coordinates -> coordinates with x along the edge: rows u_f and J u_f.
    auto R = [&](int f) {
      const double t = EdgeAngle(mesh, e, f);
      Eigen::Matrix2d r;
      r << std::cos(t), std::sin(t), -std::sin(t), std::cos(t);
      return r;
    };
    // Tensor A in face j: to edge coordinates R_j A R_j^T, then to face i: R_i^T (.) R_i.
    Eigen::Matrix3d T;
    for (int k = 0; k < 3; ++k) {
      const Eigen::Matrix2d A = FromMandelVoigt(Eigen::Vector3d::Unit(k));
      T.col(k) = ToMandelVoigt(R(i).transpose() * R(j) * A * R(j).transpose() * R(i));
    }
    return T;
  });
}

TEST(VectorHodgeGoldenTest, SingleRightTriangleByHand) {
  // Right triangle with legs 1: area 1/2, Mv = Me = 1/6. Vertex term 6 * sum(q q^T) with
  // q = area * grad phi = (-1/2, -1/2), (1/2, 0), (0, 1/2): [[3, 1.5], [1.5, 3]]. Edge term
  // 6 * sum(t t^T) with edge vectors (-1, 1), (0, -1), (1, 0): [[12, -6], [-6, 12]].
  const TriangleMesh mesh = MustCreate(Arrays({{0, 0, 0}, {1, 0, 0}, {0, 1, 0}}, {{0, 1, 2}}));
  auto S = BuildVectorHodgeStiffness(mesh);
  ASSERT_TRUE(S.ok()) << S.status();
  Eigen::Matrix2d expected;
  expected << 15.0, -4.5, -4.5, 15.0;
  EXPECT_LT((Eigen::MatrixXd(*S) - expected).cwiseAbs().maxCoeff(), 1e-14) << Eigen::MatrixXd(*S);
}

// On irregular, obtuse, noisy and bordered meshes of the catalogue, like real meshes.
TEST(VectorHodgeGoldenTest, MatchesExplicitGradientMatricesOnIrregularMeshes) {
  for (const char* name : {"NoisySphere", "ChippedTorus", "ObtuseTorus", "PolarDisk"}) {
    const TriangleMesh mesh = CatalogueMesh(name);
    auto S = BuildVectorHodgeStiffness(mesh);
    ASSERT_TRUE(S.ok()) << S.status();
    const SpMat expected = LiteralVectorHodge(mesh);
    EXPECT_LT(MaxAbsDiff(*S, expected), 1e-11 * MaxAbs(expected)) << name;
    // Stored pattern: one 2 x 2 block per pair of faces sharing a vertex (entries may be exact
    // zeros, e.g. where an edge lies along a frame axis), counted from the face-vertex incidence.
    std::vector<Eigen::Triplet<double>> incidence;
    for (int f = 0; f < mesh.num_faces(); ++f) {
      for (int k = 0; k < 3; ++k) incidence.emplace_back(f, mesh.faces()(f, k), 1.0);
    }
    SpMat FV(mesh.num_faces(), mesh.num_vertices());
    FV.setFromTriplets(incidence.begin(), incidence.end());
    const SpMat shares_vertex = FV * SpMat(FV.transpose());
    EXPECT_EQ(S->nonZeros(), 4 * shares_vertex.nonZeros()) << name;
  }
}

TEST(NFieldGoldenTest, TwoTrianglesByHand) {
  // Unit square split along (0, 2): face 0 frame x = (1, 0, 0), the edge at 45 degrees; face 1
  // frame x along the edge itself. w = 3 * 2 / (1/2 + 1/2) = 6; transport R(n * 45 degrees).
  const TriangleMesh mesh =
      MustCreate(Arrays({{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}}, {{0, 1, 2}, {0, 2, 3}}));
  for (int n : {1, 2, 4}) {
    auto S = BuildNFieldStiffness(mesh, n);
    ASSERT_TRUE(S.ok()) << S.status();
    Eigen::MatrixXd expected(4, 4);
    expected.setZero();
    expected.block<2, 2>(0, 0) = 6 * Eigen::Matrix2d::Identity();
    expected.block<2, 2>(2, 2) = 6 * Eigen::Matrix2d::Identity();
    expected.block<2, 2>(0, 2) = -6 * Rot(n * M_PI / 4);
    expected.block<2, 2>(2, 0) = -6 * Rot(n * M_PI / 4).transpose();
    EXPECT_LT((Eigen::MatrixXd(*S) - expected).cwiseAbs().maxCoeff(), 1e-13) << "n = " << n;
  }
}

TEST(TensorGoldenTest, TwoTrianglesByHand) {
  // Same square: the tensor x1 x1^T of face 1 (x1 = (1, 1) / sqrt 2) reads [[.5, .5], [.5, .5]]
  // in face 0's frame, so column 0 of P is (1/2, 1/2, sqrt(2)/2); eq. 18 with G = R(-45 deg).
  const TriangleMesh mesh =
      MustCreate(Arrays({{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}}, {{0, 1, 2}, {0, 2, 3}}));
  auto S = BuildTensorStiffness(mesh);
  ASSERT_TRUE(S.ok()) << S.status();
  const double h = std::sqrt(0.5);
  Eigen::Matrix3d P;
  P << 0.5, 0.5, -h, 0.5, 0.5, h, h, -h, 0.0;
  Eigen::MatrixXd expected = Eigen::MatrixXd::Zero(6, 6);
  expected.block<3, 3>(0, 0) = 6 * Eigen::Matrix3d::Identity();
  expected.block<3, 3>(3, 3) = 6 * Eigen::Matrix3d::Identity();
  expected.block<3, 3>(0, 3) = -6 * P;
  expected.block<3, 3>(3, 0) = -6 * P.transpose();
  EXPECT_LT((Eigen::MatrixXd(*S) - expected).cwiseAbs().maxCoeff(), 1e-13) << Eigen::MatrixXd(*S);
}

TEST(MandelVoigtTransportTest, MatchesConjugationForGeneralMatrices) {
  // Eq. 18 holds for any G, not only rotations.
  Eigen::Matrix2d G;
  G << 0.3, -1.7, 2.1, 0.4;
  for (int k = 0; k < 3; ++k) {
    const Eigen::Matrix2d A = FromMandelVoigt(Eigen::Vector3d::Unit(k));
    const Eigen::Vector3d expected = ToMandelVoigt(G.transpose() * A * G);
    EXPECT_LT((MandelVoigtTransport(G).col(k) - expected).norm(), 1e-14);
  }
}

TEST(ConnectionGoldenTest, MatchesLiteralPerEdgeFormulas) {
  for (const char* name : {"Blob", "ChippedTorus", "ObtuseTorus", "NoisyGenus4"}) {
    const TriangleMesh mesh = CatalogueMesh(name);
    for (int n : {1, 2, 3, 4, 6}) {
      auto S = BuildNFieldStiffness(mesh, n);
      ASSERT_TRUE(S.ok()) << S.status();
      const SpMat expected = LiteralNField(mesh, n);
      EXPECT_LT(MaxAbsDiff(*S, expected), 1e-11 * MaxAbs(expected)) << name << " n = " << n;
    }
    auto T = BuildTensorStiffness(mesh);
    ASSERT_TRUE(T.ok()) << T.status();
    const SpMat expected = LiteralTensor(mesh);
    EXPECT_LT(MaxAbsDiff(*T, expected), 1e-11 * MaxAbs(expected)) << name;
  }
}

TEST(FieldOperatorTest, BuildsEveryTypeWithMass) {
  const TriangleMesh mesh = CatalogueMesh("ChippedTorus");
  for (FieldType type : {FieldType::Vector(), FieldType::NField(4), FieldType::Tensor()}) {
    auto op = BuildFieldOperator(mesh, type);
    ASSERT_TRUE(op.ok()) << op.status();
    const int p = type.dofs_per_face();
    EXPECT_EQ(op->type, type);
    EXPECT_EQ(op->dofs(), p * mesh.num_faces());
    EXPECT_EQ(op->stiffness.rows(), op->dofs());
    for (int f = 0; f < mesh.num_faces(); ++f) {
      for (int c = 0; c < p; ++c) EXPECT_EQ(op->mass[p * f + c], mesh.face_areas()[f]);
    }
  }
  auto bad = BuildFieldOperator(mesh, FieldType::NField(0));
  EXPECT_THAT(bad, StatusIs(absl::StatusCode::kInvalidArgument));
  auto bad_n = BuildNFieldStiffness(mesh, 65);
  EXPECT_THAT(bad_n, StatusIs(absl::StatusCode::kInvalidArgument));
}

}  // namespace
}  // namespace fieldspace
