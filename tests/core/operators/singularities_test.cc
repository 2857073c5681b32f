#include "core/operators/singularities.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <optional>
#include <random>
#include <string>
#include <tuple>
#include <vector>

#include "Eigen/Geometry"
#include "core/mesh/shapes.h"
#include "core/operators/conversions.h"
#include "core/operators/field_operator.h"
#include "core/operators/reference_solvers.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tbb/global_control.h"
#include "tests/testing/fixtures.h"
#include "tests/testing/test_meshes.h"

namespace fieldspace {
namespace {

using ::fieldspace::testing::Arrays;
using ::fieldspace::testing::MustCreate;
using ::fieldspace::testing::PlanarStrip;

constexpr double kPi = std::numbers::pi;

// Rotates face f's corners cyclically by `shift(f)` places: same surface, other frames.
template <typename Shift>
MeshArrays RotateCorners(MeshArrays a, Shift shift) {
  for (int f = 0; f < a.faces.rows(); ++f) {
    const Eigen::Vector3i t = a.faces.row(f);
    const int r = shift(f) % 3;
    a.faces.row(f) << t[r], t[(r + 1) % 3], t[(r + 2) % 3];
  }
  return a;
}

// A planar disk of radius 1 around the origin (vertex 0): `rings` rings of `sectors` vertices,
// each ring turned by a little so the triangulation is irregular, corners rotated by f % 3.
MeshArrays PlanarDisk(int rings, int sectors) {
  std::vector<Eigen::Vector3d> v = {Eigen::Vector3d::Zero()};
  for (int k = 1; k <= rings; ++k) {
    for (int j = 0; j < sectors; ++j) {
      const double t = 2 * kPi * (j + 0.3 * k) / sectors;
      const double r = static_cast<double>(k) / rings;
      v.emplace_back(r * std::cos(t), r * std::sin(t), 0.0);
    }
  }
  auto id = [&](int k, int j) { return 1 + (k - 1) * sectors + (j % sectors); };
  std::vector<Eigen::Vector3i> f;
  for (int j = 0; j < sectors; ++j) f.emplace_back(0, id(1, j), id(1, j + 1));
  for (int k = 1; k < rings; ++k) {
    for (int j = 0; j < sectors; ++j) {
      f.emplace_back(id(k, j), id(k + 1, j), id(k + 1, j + 1));
      f.emplace_back(id(k, j), id(k + 1, j + 1), id(k, j + 1));
    }
  }
  return RotateCorners(Arrays(v, f), [](int i) { return i; });
}

// A planar grid [-m, m]^2 with a vertex at the origin (interior vertices other than the origin
// jittered), alternating diagonals.
MeshArrays CenteredGrid(int m) {
  std::vector<Eigen::Vector3d> v;
  const int s = 2 * m + 1;
  for (int j = -m; j <= m; ++j) {
    for (int i = -m; i <= m; ++i) {
      const bool jitter = std::abs(i) < m && std::abs(j) < m && (i != 0 || j != 0);
      v.emplace_back(i + (jitter ? 0.15 * std::sin(1.3 * i + 0.7 * j) : 0.0),
                     j + (jitter ? 0.15 * std::cos(0.9 * i - 1.9 * j) : 0.0), 0.0);
    }
  }
  auto id = [&](int i, int j) { return (j + m) * s + (i + m); };
  std::vector<Eigen::Vector3i> f;
  for (int j = -m; j < m; ++j) {
    for (int i = -m; i < m; ++i) {
      if ((i + j) % 2 == 0) {
        f.emplace_back(id(i, j), id(i + 1, j), id(i + 1, j + 1));
        f.emplace_back(id(i, j), id(i + 1, j + 1), id(i, j + 1));
      } else {
        f.emplace_back(id(i, j), id(i + 1, j), id(i, j + 1));
        f.emplace_back(id(i + 1, j), id(i + 1, j + 1), id(i, j + 1));
      }
    }
  }
  return RotateCorners(Arrays(v, f), [](int i) { return i; });
}

// One ambient vector per face from a function of the barycenter.
template <typename Fn>
AmbientVectors AtBarycenters(const TriangleMesh& mesh, Fn fn) {
  AmbientVectors a(mesh.num_faces(), 3);
  for (int f = 0; f < mesh.num_faces(); ++f) {
    a.row(f) = fn(Eigen::Vector3d(mesh.face_barycenters().row(f))).transpose();
  }
  return a;
}

Eigen::Vector3d Smooth(const Eigen::Vector3d& p) {
  return {std::sin(2 * p.y() + 0.3) + 0.5 * p.z(), std::cos(1.5 * p.z() - p.x()),
          std::sin(p.x() + p.y()) + 0.2};
}

Eigen::VectorXd Dofs(const TriangleMesh& mesh, int n, const AmbientVectors& a) {
  auto d = NFieldDofsFromAmbient(mesh, n, a);
  EXPECT_TRUE(d.ok()) << d.status();
  return *d;
}

Eigen::VectorXd RandomDofs(const TriangleMesh& mesh, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  Eigen::VectorXd d(2 * mesh.num_faces());
  for (int i = 0; i < d.size(); ++i) d[i] = u(rng);
  return d;
}

VertexIndices MustIndices(const TriangleMesh& mesh, const Eigen::VectorXd& dofs, int n) {
  SingularityOptions o;
  o.n = n;
  auto r = ComputeVertexIndices(mesh, dofs, o);
  EXPECT_TRUE(r.ok()) << r.status();
  return *r;
}

Singularities MustSingularities(const TriangleMesh& mesh, const Eigen::VectorXd& dofs, int n) {
  SingularityOptions o;
  o.n = n;
  auto r = ComputeSingularities(mesh, dofs, o);
  EXPECT_TRUE(r.ok()) << r.status();
  return *r;
}

// Sum of interior indices plus boundary values, units of 1/n turns (n chi on every mesh).
double TotalValue(const Singularities& s) {
  double t = static_cast<double>(s.index_sum);
  for (const BoundaryIndex& b : s.boundary) t += b.value;
  return t;
}

// ---------------------------------------------------------------------------------------------
// (a) Poincare-Hopf on closed shapes.

struct ClosedShape {
  std::string name;
  absl::StatusOr<MeshArrays> (*make)();
};

absl::StatusOr<MeshArrays> Icosphere() { return MakeIcosphere(3); }
absl::StatusOr<MeshArrays> Torus() { return MakeTorus(2.0, 0.7, 24, 12); }
absl::StatusOr<MeshArrays> Genus2() { return MakeGenusSurface(2, 2); }
absl::StatusOr<MeshArrays> Box() { return MakeGenusSurface(0, 2); }
absl::StatusOr<MeshArrays> TorusKnot() {
  TorusKnotOptions o;
  o.segments = 96;
  o.tube_segments = 8;
  return MakeTorusKnot(o);
}

class PoincareHopfTest : public ::testing::TestWithParam<std::tuple<ClosedShape, int>> {
 protected:
  void SetUp() override { mesh_.emplace(MustCreate(std::get<0>(GetParam()).make())); }
  const TriangleMesh& mesh() const { return *mesh_; }
  int n() const { return std::get<1>(GetParam()); }

  void ExpectPoincareHopf(const Eigen::VectorXd& dofs, const std::string& what) {
    const Singularities s = MustSingularities(mesh(), dofs, n());
    EXPECT_TRUE(s.boundary.empty());
    EXPECT_TRUE(s.undefined_vertices.empty()) << what;
    EXPECT_EQ(s.index_sum, int64_t{n()} * mesh().euler_characteristic()) << what;
    int64_t sum = 0;
    for (const Singularity& x : s.singularities) {
      sum += x.index;
      EXPECT_NE(x.index, 0);
      EXPECT_DOUBLE_EQ(x.turns, static_cast<double>(x.index) / n());
    }
    EXPECT_EQ(sum, s.index_sum) << what;
  }

  std::optional<TriangleMesh> mesh_;
};

TEST_P(PoincareHopfTest, SmoothField) {
  ExpectPoincareHopf(Dofs(mesh(), n(), AtBarycenters(mesh(), Smooth)), "smooth");
}

TEST_P(PoincareHopfTest, RandomFields) {
  for (uint32_t seed = 1; seed <= 3; ++seed) {
    ExpectPoincareHopf(RandomDofs(mesh(), seed), "random " + std::to_string(seed));
  }
}

TEST_P(PoincareHopfTest, LowestEigenfields) {
  auto op = BuildFieldOperator(mesh(), FieldType::NField(n()));
  ASSERT_TRUE(op.ok()) << op.status();
  EigenOptions options;
  options.count = 4;
  auto eig = ReferenceEigenpairs(*op, options);
  ASSERT_TRUE(eig.ok()) << eig.status();
  for (int i = 0; i < 4; ++i) {
    ExpectPoincareHopf(eig->vectors.col(i), "eigenfield " + std::to_string(i));
  }
}

INSTANTIATE_TEST_SUITE_P(ClosedShapes, PoincareHopfTest,
                         ::testing::Combine(::testing::Values(ClosedShape{"icosphere", Icosphere},
                                                              ClosedShape{"torus", Torus},
                                                              ClosedShape{"genus2", Genus2},
                                                              ClosedShape{"box", Box},
                                                              ClosedShape{"torus_knot", TorusKnot}),
                                            ::testing::Values(1, 2, 4)),
                         [](const ::testing::TestParamInfo<std::tuple<ClosedShape, int>>& info) {
                           return std::get<0>(info.param).name + "_n" +
                                  std::to_string(std::get<1>(info.param));
                         });

// ---------------------------------------------------------------------------------------------
// (b) Known singularities.

// An n-field whose representation vector turns k times around the origin of the plane: index
// k (units of 1/n turns) at the origin, 0 at the other interior vertices.
TEST(KnownSingularitiesTest, PlanarDiskWindingAtCenter) {
  const TriangleMesh mesh = MustCreate(PlanarDisk(6, 16));
  for (int n : {1, 2, 4}) {
    for (int k : {-2, -1, 1, 2, 3}) {
      const AmbientVectors a = AtBarycenters(mesh, [&](const Eigen::Vector3d& p) {
        const double t = k * std::atan2(p.y(), p.x()) / n;  // a representative direction
        return Eigen::Vector3d(std::cos(t), std::sin(t), 0.0);
      });
      const Singularities s = MustSingularities(mesh, Dofs(mesh, n, a), n);
      ASSERT_EQ(s.singularities.size(), 1u) << "n " << n << " k " << k;
      EXPECT_EQ(s.singularities[0].vertex, 0);
      EXPECT_EQ(s.singularities[0].index, k);
      EXPECT_DOUBLE_EQ(s.singularities[0].turns, static_cast<double>(k) / n);
      EXPECT_TRUE(s.undefined_vertices.empty());
      EXPECT_EQ(s.boundary.size(), 16u);
      // Interior indices plus boundary values: n chi = n for a disk.
      EXPECT_NEAR(TotalValue(s), n, 1e-9);
    }
  }
}

TEST(KnownSingularitiesTest, RadialVectorFieldHasIndexOne) {
  const TriangleMesh mesh = MustCreate(PlanarDisk(5, 12));
  const AmbientVectors a = AtBarycenters(mesh, [](const Eigen::Vector3d& p) { return p; });
  auto dofs = VectorDofsFromAmbient(mesh, a);
  ASSERT_TRUE(dofs.ok());
  const Singularities s = MustSingularities(mesh, *dofs, 1);
  ASSERT_EQ(s.singularities.size(), 1u);
  EXPECT_EQ(s.singularities[0].vertex, 0);
  EXPECT_EQ(s.singularities[0].index, 1);
  EXPECT_DOUBLE_EQ(s.singularities[0].turns, 1.0);
  // A field normal to a circular boundary turns with it: b(v) is the boundary's turning at v
  // (one turn spread over the boundary) minus the field's, so the values sum to 1 - 1 = 0.
  double boundary = 0.0;
  for (const BoundaryIndex& b : s.boundary) boundary += b.value;
  EXPECT_NEAR(boundary, 0.0, 1e-9);
}

TEST(KnownSingularitiesTest, SaddleOnGridHasIndexMinusOne) {
  const TriangleMesh mesh = MustCreate(CenteredGrid(4));
  const AmbientVectors a = AtBarycenters(
      mesh, [](const Eigen::Vector3d& p) { return Eigen::Vector3d(p.x(), -p.y(), 0.0); });
  const Singularities s = MustSingularities(mesh, Dofs(mesh, 1, a), 1);
  ASSERT_EQ(s.singularities.size(), 1u);
  EXPECT_EQ(mesh.vertices().row(s.singularities[0].vertex).norm(), 0.0);
  EXPECT_EQ(s.singularities[0].index, -1);
  EXPECT_NEAR(TotalValue(s), 1.0, 1e-9);
}

// A UV sphere of radius 1: poles 0 (north) and 1 (south) of valence `sectors`, `rings` - 1
// parallels, outward oriented, corners rotated by f % 3.
MeshArrays UvSphere(int rings, int sectors) {
  std::vector<Eigen::Vector3d> v = {{0, 0, 1}, {0, 0, -1}};
  for (int k = 1; k < rings; ++k) {
    const double t = kPi * k / rings;
    for (int j = 0; j < sectors; ++j) {
      const double p = 2 * kPi * (j + 0.5 * k) / sectors;
      v.emplace_back(std::sin(t) * std::cos(p), std::sin(t) * std::sin(p), std::cos(t));
    }
  }
  auto id = [&](int k, int j) { return 2 + (k - 1) * sectors + (j % sectors); };
  std::vector<Eigen::Vector3i> f;
  for (int j = 0; j < sectors; ++j) {
    f.emplace_back(0, id(1, j), id(1, j + 1));
    f.emplace_back(1, id(rings - 1, j + 1), id(rings - 1, j));
  }
  for (int k = 1; k + 1 < rings; ++k) {
    for (int j = 0; j < sectors; ++j) {
      f.emplace_back(id(k, j), id(k + 1, j), id(k + 1, j + 1));
      f.emplace_back(id(k, j), id(k + 1, j + 1), id(k, j + 1));
    }
  }
  return RotateCorners(Arrays(v, f), [](int i) { return i; });
}

// The rotational field z x p: +1 turn (n units of 1/n) at both poles, 0 elsewhere.
TEST(KnownSingularitiesTest, RotationalFieldOnSphereHasTwoPoles) {
  const TriangleMesh mesh = MustCreate(UvSphere(12, 24));
  const AmbientVectors a = AtBarycenters(
      mesh, [](const Eigen::Vector3d& p) { return Eigen::Vector3d(0, 0, 1).cross(p); });
  for (int n : {1, 2, 4}) {
    const Singularities s = MustSingularities(mesh, Dofs(mesh, n, a), n);
    ASSERT_EQ(s.singularities.size(), 2u) << "n " << n;
    for (int i = 0; i < 2; ++i) {
      EXPECT_EQ(s.singularities[i].vertex, i);
      EXPECT_EQ(s.singularities[i].index, n);
      EXPECT_DOUBLE_EQ(s.singularities[i].turns, 1.0);
    }
  }
}

// Indices do not depend on the field's scale, also where its squares overflow or underflow
// double (a field of 1e200 once gave NaN rotations; found by fuzz/requests_fuzzer.cc).
TEST(SingularitiesInvarianceTest, HugeAndTinyFieldsKeepTheirIndices) {
  const TriangleMesh mesh = MustCreate(UvSphere(12, 24));
  const AmbientVectors a = AtBarycenters(
      mesh, [](const Eigen::Vector3d& p) { return Eigen::Vector3d(0, 0, 1).cross(p); });
  for (int n : {1, 4}) {
    const Eigen::VectorXd dofs = Dofs(mesh, n, a);
    const VertexIndices unit = MustIndices(mesh, dofs, n);
    for (double scale : {1e200, 1e-200}) {
      const VertexIndices scaled = MustIndices(mesh, scale * dofs, n);
      EXPECT_EQ(scaled.index, unit.index) << "n " << n << " scale " << scale;
    }
  }
}

// The same field around an axis through a valence-5 vertex of an icosphere. For n = 1, 2 the
// poles carry the index. For n = 4 the field turns by 72 degrees from face to face around the
// pole, which as a set of 4 directions is the smaller turn of -18 degrees: the index is read as
// -1/4 at each pole and +1/4 at its 5 neighbors (the discrete rule picks the smallest rotation,
// so a pole of an n-field needs a fan that resolves it). The sum stays n chi.
TEST(KnownSingularitiesTest, RotationalFieldAtValenceFivePoles) {
  const TriangleMesh mesh = MustCreate(MakeIcosphere(2));
  const Eigen::Vector3d axis = mesh.vertices().row(0);
  int antipode = 0;
  (mesh.vertices() * axis).minCoeff(&antipode);
  ASSERT_LT((Eigen::Vector3d(mesh.vertices().row(antipode)) + axis).norm(), 1e-12);
  const AmbientVectors a =
      AtBarycenters(mesh, [&](const Eigen::Vector3d& p) { return axis.cross(p); });
  for (int n : {1, 2}) {
    const Singularities s = MustSingularities(mesh, Dofs(mesh, n, a), n);
    ASSERT_EQ(s.singularities.size(), 2u) << "n " << n;
    EXPECT_EQ(s.singularities[0].vertex, std::min(0, antipode));
    EXPECT_EQ(s.singularities[1].vertex, std::max(0, antipode));
    for (const Singularity& x : s.singularities) EXPECT_EQ(x.index, n);
  }
  const VertexIndices four = MustIndices(mesh, Dofs(mesh, 4, a), 4);
  EXPECT_EQ(four.index[0], -1);
  EXPECT_EQ(four.index[antipode], -1);
  int plus = 0;
  for (int x : four.index) plus += x == 1;
  EXPECT_EQ(plus, 10);
}

// The cross field of the coordinate axes (the face normals' frames on an axis-aligned box): zero
// rotation across every edge, so the indices are n K_v / 2 pi: +1/4 at the 8 convex corners,
// -1/4 at the 8 concave vertices of each hole, 0 elsewhere.
AmbientVectors AxisCrossField(const TriangleMesh& mesh) {
  AmbientVectors a(mesh.num_faces(), 3);
  for (int f = 0; f < mesh.num_faces(); ++f) {
    const Eigen::Vector3d nrm = mesh.face_normals().row(f);
    a.row(f) = std::abs(nrm.x()) > 0.5 ? Eigen::RowVector3d(0, 1, 0) : Eigen::RowVector3d(1, 0, 0);
  }
  return a;
}

TEST(KnownSingularitiesTest, CrossFieldOnBoxHasQuarterIndicesAtCorners) {
  const TriangleMesh mesh = MustCreate(MakeGenusSurface(0, 2));
  const Singularities s = MustSingularities(mesh, Dofs(mesh, 4, AxisCrossField(mesh)), 4);
  ASSERT_EQ(s.singularities.size(), 8u);
  const Eigen::RowVector3d lo = mesh.vertices().colwise().minCoeff();
  const Eigen::RowVector3d hi = mesh.vertices().colwise().maxCoeff();
  for (const Singularity& x : s.singularities) {
    EXPECT_EQ(x.index, 1);
    EXPECT_DOUBLE_EQ(x.turns, 0.25);
    const Eigen::RowVector3d p = mesh.vertices().row(x.vertex);
    for (int c = 0; c < 3; ++c) EXPECT_TRUE(p[c] == lo[c] || p[c] == hi[c]) << p;
  }
  EXPECT_EQ(s.index_sum, 8);
}

// The smoothest 4-field on the box: the axis cross field turned by any constant angle has zero
// energy (nothing turns across the folds), so the lowest eigenfields are such fields and carry
// +1/4 at exactly the 8 corners.
TEST(KnownSingularitiesTest, SmoothestCrossFieldOnBoxHasQuarterIndicesAtCorners) {
  const TriangleMesh mesh = MustCreate(MakeGenusSurface(0, 2));
  auto op = BuildFieldOperator(mesh, FieldType::NField(4));
  ASSERT_TRUE(op.ok()) << op.status();
  EigenOptions options;
  options.count = 2;
  auto eig = ReferenceEigenpairs(*op, options);
  ASSERT_TRUE(eig.ok()) << eig.status();
  const Singularities axis = MustSingularities(mesh, Dofs(mesh, 4, AxisCrossField(mesh)), 4);
  for (int i = 0; i < 2; ++i) {
    EXPECT_LT(std::abs(eig->values[i]), 1e-8);
    const Singularities s = MustSingularities(mesh, eig->vectors.col(i), 4);
    ASSERT_EQ(s.singularities.size(), 8u);
    for (size_t j = 0; j < 8; ++j) {
      EXPECT_EQ(s.singularities[j].vertex, axis.singularities[j].vertex);
      EXPECT_EQ(s.singularities[j].index, 1);
    }
  }
}

TEST(KnownSingularitiesTest, CrossFieldOnGenus2PlateHasNegativeQuartersAtHoles) {
  const TriangleMesh mesh = MustCreate(MakeGenusSurface(2, 2));
  const Singularities s = MustSingularities(mesh, Dofs(mesh, 4, AxisCrossField(mesh)), 4);
  int plus = 0, minus = 0;
  for (const Singularity& x : s.singularities) {
    if (x.index == 1) ++plus;
    if (x.index == -1) ++minus;
  }
  EXPECT_EQ(plus, 8);
  EXPECT_EQ(minus, 16);
  EXPECT_EQ(s.singularities.size(), 24u);
  EXPECT_EQ(s.index_sum, 4 * -2);
}

// Independent check on a plane: there the transport is the identity in global coordinates, so
// the index is the winding of the global representation angle around the vertex's ring.
TEST(KnownSingularitiesTest, PlanarIndicesMatchGlobalWinding) {
  const TriangleMesh mesh = MustCreate(PlanarStrip(9, 7));
  for (int n : {1, 3}) {
    const Eigen::VectorXd dofs = RandomDofs(mesh, 7);
    auto rep = NFieldRepresentativeFromDofs(mesh, n, dofs);
    ASSERT_TRUE(rep.ok());
    const int nv = mesh.num_vertices();
    std::vector<std::vector<int>> ring(nv);  // faces around v, counter-clockwise
    for (int v = 0; v < nv; ++v) {
      // Start at a face of v; walk across the edge (v, previous corner) until back or blocked.
      int start = -1;
      for (int f = 0; f < mesh.num_faces() && start < 0; ++f) {
        for (int k = 0; k < 3; ++k) start = mesh.faces()(f, k) == v ? f : start;
      }
      int f = start;
      do {
        ring[v].push_back(f);
        int k = 0;
        while (mesh.faces()(f, k) != v) ++k;
        f = mesh.face_neighbors()(f, (k + 1) % 3);
      } while (f != start && f != kNoFace);
      if (f == kNoFace) ring[v].clear();  // boundary vertex
    }
    auto index = MustIndices(mesh, dofs, n);
    int checked = 0;
    for (int v = 0; v < nv; ++v) {
      if (ring[v].empty()) {
        EXPECT_EQ(index.kind[v], VertexIndexKind::kBoundary);
        continue;
      }
      double total = 0.0;
      for (size_t i = 0; i < ring[v].size(); ++i) {
        const int f = ring[v][i], g = ring[v][(i + 1) % ring[v].size()];
        double d =
            n * (std::atan2((*rep)(g, 1), (*rep)(g, 0)) - std::atan2((*rep)(f, 1), (*rep)(f, 0)));
        d = std::remainder(d, 2 * kPi);
        total += d;
      }
      EXPECT_EQ(index.kind[v], VertexIndexKind::kInterior);
      EXPECT_EQ(index.index[v], std::lround(total / (2 * kPi))) << "vertex " << v;
      ++checked;
    }
    EXPECT_GT(checked, 30);
  }
}

// ---------------------------------------------------------------------------------------------
// (c) Frame invariance: the same ambient field on the same surface with other face frames.

TEST(SingularitiesInvarianceTest, RotatingFaceCornersKeepsIndices) {
  for (auto make : {Torus, Icosphere, Genus2}) {
    auto arrays = make();
    ASSERT_TRUE(arrays.ok());
    const TriangleMesh a = MustCreate(*arrays);
    const TriangleMesh b = MustCreate(RotateCorners(*arrays, [](int f) { return 1 + f % 2; }));
    std::mt19937 rng(3);
    std::uniform_real_distribution<double> u(-1.0, 1.0);
    AmbientVectors field(a.num_faces(), 3);
    for (int f = 0; f < a.num_faces(); ++f) field.row(f) << u(rng), u(rng), u(rng);
    for (int n : {1, 2, 4}) {
      const Eigen::VectorXd da = Dofs(a, n, field), db = Dofs(b, n, field);
      // The frames did change (a plain loop: GCC 12 warns falsely on AVX-512 reductions here).
      int changed = 0;
      for (int i = 0; i < da.size(); ++i) changed += std::abs(da[i] - db[i]) > 1e-3;
      EXPECT_GT(changed, a.num_faces() / 2);
      const VertexIndices ia = MustIndices(a, da, n), ib = MustIndices(b, db, n);
      EXPECT_EQ(ia.index, ib.index) << "n " << n;
      EXPECT_EQ(ia.kind, ib.kind);
      int singular = 0;
      for (int x : ia.index) singular += x != 0;
      EXPECT_GT(singular, 10);  // a random field: plenty of singularities to compare
    }
  }
}

TEST(SingularitiesInvarianceTest, RotatingFaceCornersKeepsBoundaryValues) {
  const MeshArrays arrays = PlanarStrip(6, 5);
  const TriangleMesh a = MustCreate(arrays);
  const TriangleMesh b = MustCreate(RotateCorners(arrays, [](int f) { return 2 + f; }));
  const AmbientVectors field = AtBarycenters(a, Smooth);
  const VertexIndices ia = MustIndices(a, Dofs(a, 2, field), 2);
  const VertexIndices ib = MustIndices(b, Dofs(b, 2, field), 2);
  ASSERT_EQ(ia.value.size(), ib.value.size());
  for (size_t v = 0; v < ia.value.size(); ++v) EXPECT_NEAR(ia.value[v], ib.value[v], 1e-12);
}

// ---------------------------------------------------------------------------------------------
// Zero faces, boundaries, diffs.

TEST(SingularitiesTest, ZeroFacesMakeTheirVerticesUndefined) {
  const TriangleMesh mesh = MustCreate(MakeIcosphere(2));
  Eigen::VectorXd dofs = RandomDofs(mesh, 5);
  dofs.segment<2>(2 * 7).setZero();
  auto idx = MustIndices(mesh, dofs, 2);
  for (int k = 0; k < 3; ++k) {
    const int v = mesh.faces()(7, k);
    EXPECT_EQ(idx.kind[v], VertexIndexKind::kUndefined);
    EXPECT_EQ(idx.index[v], 0);
    EXPECT_EQ(idx.value[v], 0.0);
  }
  int undefined = 0;
  for (size_t v = 0; v < idx.kind.size(); ++v) {
    undefined += idx.kind[v] == VertexIndexKind::kUndefined;
    EXPECT_TRUE(std::isfinite(idx.value[v]));
  }
  EXPECT_EQ(undefined, 3);
  const Singularities s = MustSingularities(mesh, dofs, 2);
  EXPECT_EQ(s.undefined_vertices.size(), 3u);

  // A tiny face counts as zero only with a tolerance.
  dofs.segment<2>(2 * 7) << 1e-9, 0.0;
  EXPECT_EQ(MustSingularities(mesh, dofs, 2).undefined_vertices.size(), 0u);
  dofs.segment<2>(2 * 7) << 1e-170, -1e-170;  // squares underflow, still a direction
  EXPECT_EQ(MustSingularities(mesh, dofs, 2).undefined_vertices.size(), 0u);
  dofs.segment<2>(2 * 7) << 1e-9, 0.0;
  SingularityOptions o;
  o.n = 2;
  o.zero_tolerance = 1e-6;
  auto tol = ComputeSingularities(mesh, dofs, o);
  ASSERT_TRUE(tol.ok());
  EXPECT_EQ(tol->undefined_vertices.size(), 3u);

  // All zero: everything undefined.
  const Singularities all = MustSingularities(mesh, Eigen::VectorXd::Zero(dofs.size()), 2);
  EXPECT_EQ(all.undefined_vertices.size(), static_cast<size_t>(mesh.num_vertices()));
  EXPECT_TRUE(all.singularities.empty());
}

TEST(SingularitiesTest, BoundaryValuesCompleteEulerCharacteristic) {
  const TriangleMesh mesh = MustCreate(PlanarStrip(8, 6));
  for (int n : {1, 2, 4}) {
    for (uint32_t seed = 1; seed <= 3; ++seed) {
      const Singularities s = MustSingularities(mesh, RandomDofs(mesh, seed), n);
      EXPECT_EQ(s.boundary.size(), 28u);
      EXPECT_NEAR(TotalValue(s), n * mesh.euler_characteristic(), 1e-9);
    }
  }
}

TEST(SingularitiesTest, ResultDoesNotDependOnThreadCount) {
  const TriangleMesh mesh = MustCreate(MakeIcosphere(5));  // several parallel chunks
  const Eigen::VectorXd dofs = RandomDofs(mesh, 9);
  const VertexIndices parallel = MustIndices(mesh, dofs, 4);
  VertexIndices serial;
  {
    tbb::global_control one(tbb::global_control::max_allowed_parallelism, 1);
    serial = MustIndices(mesh, dofs, 4);
  }
  EXPECT_EQ(parallel.index, serial.index);
  EXPECT_EQ(parallel.value, serial.value);  // bit for bit
}

TEST(SingularitiesTest, SeveralComponentsSumToTotalEulerCharacteristic) {
  auto sphere = MakeIcosphere(2);
  auto torus = MakeTorus(2.0, 0.7, 16, 8);
  ASSERT_TRUE(sphere.ok() && torus.ok());
  MeshArrays both;
  const int64_t sv = sphere->vertices.rows(), tv = torus->vertices.rows();
  both.vertices.resize(sv + tv, 3);
  both.vertices << sphere->vertices, torus->vertices.rowwise() + Eigen::RowVector3d(5, 0, 0);
  both.faces.resize(sphere->faces.rows() + torus->faces.rows(), 3);
  both.faces << sphere->faces, (torus->faces.array() + static_cast<int32_t>(sv)).matrix();
  const TriangleMesh mesh = MustCreate(both);
  ASSERT_EQ(mesh.num_components(), 2);
  for (int n : {1, 2, 4}) {
    EXPECT_EQ(MustSingularities(mesh, RandomDofs(mesh, 4), n).index_sum, 2 * n);
  }
}

TEST(SingularitiesTest, DiffListsChangedVertices) {
  const TriangleMesh mesh = MustCreate(MakeIcosphere(2));
  const Eigen::VectorXd d0 = RandomDofs(mesh, 1);
  Eigen::VectorXd d1 = d0;
  d1.segment<2>(2 * 11) *= -1.0;  // flips one face: changes its vertices' indices
  d1.segment<2>(2 * 40).setZero();
  const VertexIndices a = MustIndices(mesh, d0, 1), b = MustIndices(mesh, d1, 1);
  auto diff = DiffVertexIndices(a, b);
  ASSERT_TRUE(diff.ok());
  std::vector<IndexChange> expected;
  for (int v = 0; v < mesh.num_vertices(); ++v) {
    if (a.kind[v] != b.kind[v] || a.index[v] != b.index[v]) {
      expected.push_back({v, a.kind[v], b.kind[v], a.index[v], b.index[v]});
    }
  }
  ASSERT_EQ(diff->size(), expected.size());
  ASSERT_GE(diff->size(), 3u);  // at least face 40's vertices
  for (size_t i = 0; i < expected.size(); ++i) {
    EXPECT_EQ((*diff)[i].vertex, expected[i].vertex);
    EXPECT_EQ((*diff)[i].kind_after, expected[i].kind_after);
    EXPECT_EQ((*diff)[i].index_before, expected[i].index_before);
    EXPECT_EQ((*diff)[i].index_after, expected[i].index_after);
  }
  for (int k = 0; k < 3; ++k) {
    const int v = mesh.faces()(40, k);
    EXPECT_EQ(b.kind[v], VertexIndexKind::kUndefined);
  }
  auto same = DiffVertexIndices(a, a);
  ASSERT_TRUE(same.ok());
  EXPECT_TRUE(same->empty());
}

// ---------------------------------------------------------------------------------------------
// (d) Bad input.

TEST(SingularitiesTest, BadInputIsInvalidArgument) {
  const TriangleMesh mesh = MustCreate(MakeIcosphere(1));
  const int nf = mesh.num_faces();
  const Eigen::VectorXd good = RandomDofs(mesh, 2);
  auto code = [&](const Eigen::VectorXd& d, SingularityOptions o) {
    return ComputeVertexIndices(mesh, d, o).status().code();
  };
  EXPECT_EQ(code(good, {}), absl::StatusCode::kOk);
  EXPECT_EQ(code(Eigen::VectorXd::Ones(2 * nf - 1), {}), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(code(Eigen::VectorXd::Ones(3 * nf), {}), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(code(Eigen::VectorXd(), {}), absl::StatusCode::kInvalidArgument);
  Eigen::VectorXd bad = good;
  bad[2 * 5 + 1] = std::numeric_limits<double>::quiet_NaN();
  auto nan = ComputeSingularities(mesh, bad, {});
  EXPECT_EQ(nan.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(nan.status().message(), ::testing::HasSubstr("face 5"));
  bad[2 * 5 + 1] = std::numeric_limits<double>::infinity();
  EXPECT_EQ(code(bad, {}), absl::StatusCode::kInvalidArgument);
  for (int n : {0, -1, 65}) {
    SingularityOptions o;
    o.n = n;
    EXPECT_EQ(code(good, o), absl::StatusCode::kInvalidArgument) << n;
  }
  for (double t : {-1e-3, 1.0, std::numeric_limits<double>::quiet_NaN()}) {
    SingularityOptions o;
    o.zero_tolerance = t;
    EXPECT_EQ(code(good, o), absl::StatusCode::kInvalidArgument) << t;
  }
  // Diffs need the same n and vertex count.
  const VertexIndices a = MustIndices(mesh, good, 1), b = MustIndices(mesh, good, 2);
  EXPECT_EQ(DiffVertexIndices(a, b).status().code(), absl::StatusCode::kInvalidArgument);
  VertexIndices shorter = a;
  shorter.kind.pop_back();
  shorter.index.pop_back();
  shorter.value.pop_back();
  EXPECT_EQ(DiffVertexIndices(a, shorter).status().code(), absl::StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace fieldspace
