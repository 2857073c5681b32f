#include "core/mesh/triangle_mesh.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "Eigen/Geometry"
#include "core/mesh/mesh_io.h"
#include "core/mesh/shapes.h"
#include "core/mesh/surface_path.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tests/testing/matchers.h"
#include "tests/testing/test_meshes.h"

namespace fieldspace {
namespace {

using ::fieldspace::testing::Arrays;
using ::fieldspace::testing::MustCreate;
using ::fieldspace::testing::StatusIs;
using ::testing::HasSubstr;

constexpr double kPi = 3.14159265358979323846;

// Checks that every table of `mesh` agrees with every other one.
void ExpectConsistentTopology(const TriangleMesh& mesh) {
  const auto& F = mesh.faces();
  for (int32_t f = 0; f < mesh.num_faces(); ++f) {
    for (int k = 0; k < 3; ++k) {
      const int32_t e = mesh.face_edges()(f, k);
      ASSERT_GE(e, 0);
      ASSERT_LT(e, mesh.num_edges());
      const int32_t a = std::min(F(f, (k + 1) % 3), F(f, (k + 2) % 3));
      const int32_t b = std::max(F(f, (k + 1) % 3), F(f, (k + 2) % 3));
      EXPECT_EQ(mesh.edges()(e, 0), a);
      EXPECT_EQ(mesh.edges()(e, 1), b);
      const int32_t g = mesh.face_neighbors()(f, k);
      if (g == kNoFace) {
        EXPECT_EQ(mesh.edge_faces()(e, 1), kNoFace);
      } else {
        // The neighbour sees this face across the same edge.
        bool found = false;
        for (int j = 0; j < 3; ++j) {
          if (mesh.face_neighbors()(g, j) == f) {
            found = true;
            EXPECT_EQ(mesh.face_edges()(g, j), e);
          }
        }
        EXPECT_TRUE(found) << "face " << f << " neighbour " << g;
        EXPECT_EQ(mesh.edge_faces()(e, 0), std::min(f, g));
        EXPECT_EQ(mesh.edge_faces()(e, 1), std::max(f, g));
      }
    }
  }
}

// Every mesh of the catalogue (tests/testing/test_meshes.h: regular, irregular, obtuse, noisy,
// high-genus, bordered, two components) has its known topology and consistent tables.
class CatalogueTopologyTest : public testing::MeshCaseTest {};

TEST_P(CatalogueTopologyTest, MatchesKnownTopology) {
  const testing::MeshCase& c = GetParam();
  EXPECT_EQ(mesh().genus(), c.genus);
  EXPECT_EQ(mesh().euler_characteristic(), c.euler_characteristic);
  EXPECT_EQ(static_cast<int>(mesh().boundary_loops().size()), c.boundary_loops);
  EXPECT_EQ(mesh().num_components(), c.components);
  // chi = sum over components of 2 - 2 g - loops.
  EXPECT_EQ(c.euler_characteristic, 2 * c.components - 2 * c.genus - c.boundary_loops);
  ExpectConsistentTopology(mesh());
}

INSTANTIATE_TEST_SUITE_P(Catalogue, CatalogueTopologyTest,
                         ::testing::ValuesIn(testing::MeshCatalogue()), testing::MeshCaseName);

TEST(TriangleMeshTest, IcosphereCountsAndInvariants) {
  for (int s = 0; s <= 4; ++s) {
    TriangleMesh mesh = MustCreate(MakeIcosphere(s, 2.0));
    const int64_t faces = 20 * (int64_t{1} << (2 * s));
    EXPECT_EQ(mesh.num_faces(), faces);
    EXPECT_EQ(mesh.num_vertices(), 10 * (int64_t{1} << (2 * s)) + 2);
    EXPECT_EQ(mesh.num_edges(), faces * 3 / 2);
    EXPECT_EQ(mesh.euler_characteristic(), 2);
    EXPECT_EQ(mesh.genus(), 0);
    EXPECT_EQ(mesh.num_components(), 1);
    EXPECT_TRUE(mesh.boundary_loops().empty());
    EXPECT_EQ(mesh.dropped_unreferenced_vertices(), 0);
    ExpectConsistentTopology(mesh);
    // Inscribed polyhedra: area increases towards 4 pi r^2 from below.
    EXPECT_LT(mesh.total_area(), 4 * kPi * 4.0);
    if (s == 4) {
      EXPECT_NEAR(mesh.total_area(), 4 * kPi * 4.0, 0.02 * 4 * kPi * 4.0);
    }
    // Outward orientation: normals point away from the centre.
    for (int32_t f = 0; f < mesh.num_faces(); ++f) {
      EXPECT_GT(mesh.face_normals().row(f).dot(mesh.face_barycenters().row(f)), 0);
    }
  }
}

TEST(TriangleMeshTest, FramesFollowTheDesignConvention) {
  TriangleMesh mesh = MustCreate(MakeTorus(2.0, 0.7, 24, 12));
  const auto& V = mesh.vertices();
  const auto& F = mesh.faces();
  for (int32_t f = 0; f < mesh.num_faces(); ++f) {
    const Eigen::Vector3d p0 = V.row(F(f, 0)), p1 = V.row(F(f, 1)), p2 = V.row(F(f, 2));
    const Eigen::Vector3d x = mesh.frame_x().row(f), y = mesh.frame_y().row(f);
    const Eigen::Vector3d n = mesh.face_normals().row(f);
    EXPECT_NEAR((x - (p1 - p0).normalized()).norm(), 0, 1e-14);
    EXPECT_NEAR((n - (p1 - p0).cross(p2 - p0).normalized()).norm(), 0, 1e-14);
    EXPECT_NEAR((y - n.cross(x)).norm(), 0, 1e-14);
    EXPECT_NEAR(x.dot(y), 0, 1e-14);
    EXPECT_NEAR(y.norm(), 1, 1e-14);
    EXPECT_NEAR(mesh.face_areas()(f), 0.5 * (p1 - p0).cross(p2 - p0).norm(), 1e-14);
    EXPECT_NEAR((mesh.face_barycenters().row(f).transpose() - (p0 + p1 + p2) / 3).norm(), 0, 1e-14);
  }
}

TEST(TriangleMeshTest, ShapesHaveTheirGenus) {
  TriangleMesh torus = MustCreate(MakeTorus(1.0, 0.3, 40, 16));
  EXPECT_EQ(torus.num_faces(), 2 * 40 * 16);
  EXPECT_EQ(torus.genus(), 1);
  EXPECT_EQ(torus.euler_characteristic(), 0);
  TorusKnotOptions knot;
  knot.segments = 200;
  knot.tube_segments = 16;
  TriangleMesh knot_mesh = MustCreate(MakeTorusKnot(knot));
  EXPECT_EQ(knot_mesh.genus(), 1);
  EXPECT_EQ(knot_mesh.num_faces(), 2 * 200 * 16);
  for (int g = 0; g <= 4; ++g) {
    TriangleMesh mesh = MustCreate(MakeGenusSurface(g, 4));
    EXPECT_EQ(mesh.genus(), g) << "genus surface " << g;
    EXPECT_EQ(mesh.euler_characteristic(), 2 - 2 * g);
    EXPECT_TRUE(mesh.boundary_loops().empty());
    ExpectConsistentTopology(mesh);
  }
}

TEST(TriangleMeshTest, ShapeParametersAreChecked) {
  EXPECT_THAT(MakeIcosphere(-1), StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(MakeIcosphere(9), StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(MakeIcosphere(2, 0.0), StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(MakeTorus(1.0, 2.0, 8, 8), StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(MakeTorus(2.0, 1.0, 2, 8), StatusIs(absl::StatusCode::kInvalidArgument));
  TorusKnotOptions knot;
  knot.p = 2;
  knot.q = 4;
  EXPECT_THAT(MakeTorusKnot(knot), StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(MakeGenusSurface(-1, 4), StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(MakeGenusSurface(2, 0), StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(MakeNonUniformSphere(2, 0.95), StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(MakeNonUniformSphere(9, 0.5), StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(MakeStaggeredTorus(1.0, 0.4, 8, 9), StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(MakeStaggeredTorus(1.0, 1.4, 8, 8), StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(MakeCylinder(1.0, 1.0, 2, 4), StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(MakeCylinder(1.0, 1.0, 8, 0), StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(MakeCylinder(-1.0, 1.0, 8, 4), StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(MakePolarDisk(0, 8), StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(MakePolarDisk(100000, 100000), StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(MakePerforatedPlate(65, 2), StatusIs(absl::StatusCode::kInvalidArgument));
  const MeshArrays sphere = *MakeIcosphere(1);
  EXPECT_THAT(PerturbVertices(sphere, 0.5, 1), StatusIs(absl::StatusCode::kInvalidArgument));
  MeshArrays bad = sphere;
  bad.faces(3, 1) = 1000;
  EXPECT_THAT(PerturbVertices(bad, 0.1, 1), StatusIs(absl::StatusCode::kInvalidArgument));
}

// The variants' promises: counts, obtuse angles, the size of the noise, non-uniform density.
TEST(TriangleMeshTest, IrregularAndBorderedShapesKeepTheirPromises) {
  // Staggered torus: every triangle has an angle above 90 degrees once minor > 2 major r / (R - r).
  const TriangleMesh obtuse = MustCreate(MakeStaggeredTorus(1.0, 0.4, 16, 48));
  EXPECT_EQ(obtuse.num_faces(), 2 * 16 * 48);
  EXPECT_EQ(obtuse.genus(), 1);
  double smallest_largest_angle = kPi;
  for (int32_t f = 0; f < obtuse.num_faces(); ++f) {
    double largest = 0;
    for (int k = 0; k < 3; ++k) {
      const Eigen::Vector3d p = obtuse.vertices().row(obtuse.faces()(f, k));
      const Eigen::Vector3d a =
          obtuse.vertices().row(obtuse.faces()(f, (k + 1) % 3)) - p.transpose();
      const Eigen::Vector3d b =
          obtuse.vertices().row(obtuse.faces()(f, (k + 2) % 3)) - p.transpose();
      largest = std::max(largest, std::acos(a.normalized().dot(b.normalized())));
    }
    smallest_largest_angle = std::min(smallest_largest_angle, largest);
  }
  EXPECT_GT(smallest_largest_angle, kPi / 2 + 0.3);

  // Perturbation: deterministic, every vertex within amplitude x its shortest edge, faces kept.
  const MeshArrays torus = *MakeTorus(1.0, 0.4, 24, 12);
  const MeshArrays noisy = *PerturbVertices(torus, 0.3, 9);
  EXPECT_EQ(noisy.vertices, PerturbVertices(torus, 0.3, 9)->vertices);
  EXPECT_NE(noisy.vertices, PerturbVertices(torus, 0.3, 10)->vertices);
  EXPECT_EQ(noisy.faces, torus.faces);
  const TriangleMesh before = MustCreate(torus);
  double moved = 0;
  for (int32_t v = 0; v < before.num_vertices(); ++v) {
    double shortest = std::numeric_limits<double>::infinity();
    for (int32_t e = 0; e < before.num_edges(); ++e) {
      if (before.edges()(e, 0) == v || before.edges()(e, 1) == v) {
        shortest = std::min(shortest, (before.vertices().row(before.edges()(e, 0)) -
                                       before.vertices().row(before.edges()(e, 1)))
                                          .norm());
      }
    }
    const double d = (noisy.vertices.row(v) - torus.vertices.row(v)).norm();
    EXPECT_LE(d, 0.3 * shortest) << v;
    moved = std::max(moved, d / shortest);
  }
  EXPECT_GT(moved, 0.15);  // the noise is not negligible

  // Non-uniform sphere: on the unit sphere, faces near +z much smaller than near -z.
  const TriangleMesh dense = MustCreate(MakeNonUniformSphere(3, 0.6));
  EXPECT_EQ(dense.num_faces(), 1280);
  EXPECT_NEAR(dense.vertices().rowwise().norm().maxCoeff(), 1.0, 1e-15);
  double top = 0, bottom = 0;
  for (int32_t f = 0; f < dense.num_faces(); ++f) {
    const double z = dense.face_barycenters()(f, 2);
    if (z > 0.9) top = std::max(top, dense.face_areas()(f));
    if (z < -0.9) bottom = std::max(bottom, dense.face_areas()(f));
  }
  EXPECT_GT(bottom, 10 * top);

  // Open shapes: counts and the loops they promise.
  const TriangleMesh disk = MustCreate(MakePolarDisk(5, 12));
  EXPECT_EQ(disk.num_faces(), 12 * (2 * 5 - 1));
  EXPECT_EQ(disk.num_vertices(), 1 + 5 * 12);
  EXPECT_EQ(disk.boundary_loops().size(), 1u);
  EXPECT_NEAR(disk.total_area(), 0.5 * 12 * std::sin(2 * kPi / 12), 1e-12);  // inscribed 12-gon
  const TriangleMesh tube = MustCreate(MakeCylinder(0.5, 2.0, 10, 3));
  EXPECT_EQ(tube.num_faces(), 2 * 10 * 3);
  EXPECT_EQ(tube.boundary_loops().size(), 2u);
  EXPECT_EQ(tube.euler_characteristic(), 0);
  for (int32_t f = 0; f < tube.num_faces(); ++f) {  // outward
    const Eigen::Vector3d c = tube.face_barycenters().row(f);
    EXPECT_GT(tube.face_normals().row(f).dot(Eigen::Vector3d(c.x(), c.y(), 0)), 0);
  }
  const TriangleMesh plate = MustCreate(MakePerforatedPlate(3, 2));
  EXPECT_EQ(plate.boundary_loops().size(), 4u);
  EXPECT_EQ(plate.genus(), 0);
  EXPECT_DOUBLE_EQ(plate.total_area(), 7.0 * 3.0 - 3.0);
}

TEST(TriangleMeshTest, OpenSurfacesHaveBoundaryLoops) {
  // One triangle: a disk.
  TriangleMesh tri = MustCreate(Arrays({{0, 0, 0}, {1, 0, 0}, {0, 1, 0}}, {{0, 1, 2}}));
  EXPECT_EQ(tri.num_edges(), 3);
  ASSERT_EQ(tri.boundary_loops().size(), 1u);
  EXPECT_EQ(tri.boundary_loops()[0].size(), 3u);
  EXPECT_EQ(tri.genus(), 0);
  EXPECT_EQ(tri.euler_characteristic(), 1);
  // An icosphere with two faces that share no vertex removed: a cylinder (2 loops, genus 0).
  auto sphere = MakeIcosphere(2);
  ASSERT_TRUE(sphere.ok());
  const auto& F = sphere->faces;
  int32_t second = -1;
  for (int32_t f = 1; f < F.rows() && second < 0; ++f) {
    bool shares = false;
    for (int a = 0; a < 3; ++a) {
      for (int b = 0; b < 3; ++b) shares |= F(0, a) == F(f, b);
    }
    if (!shares) second = f;
  }
  MeshArrays holed;
  holed.vertices = sphere->vertices;
  holed.faces.resize(F.rows() - 2, 3);
  for (int32_t f = 0, out = 0; f < F.rows(); ++f) {
    if (f != 0 && f != second) holed.faces.row(out++) = F.row(f);
  }
  TriangleMesh cylinder = MustCreate(holed);
  EXPECT_EQ(cylinder.boundary_loops().size(), 2u);
  EXPECT_EQ(cylinder.components()[0].num_boundary_loops, 2);
  EXPECT_EQ(cylinder.genus(), 0);
  EXPECT_EQ(cylinder.euler_characteristic(), 0);
  ExpectConsistentTopology(cylinder);
}

TEST(TriangleMeshTest, ComponentsAreCountedSeparately) {
  auto a = MakeIcosphere(1);
  auto b = MakeTorus(3.0, 1.0, 12, 8);
  ASSERT_TRUE(a.ok() && b.ok());
  MeshArrays both;
  both.vertices.resize(a->vertices.rows() + b->vertices.rows(), 3);
  both.vertices << a->vertices, b->vertices;
  both.faces.resize(a->faces.rows() + b->faces.rows(), 3);
  both.faces << a->faces, (b->faces.array() + static_cast<int32_t>(a->vertices.rows())).matrix();
  TriangleMesh mesh = MustCreate(both);
  ASSERT_EQ(mesh.num_components(), 2);
  EXPECT_EQ(mesh.components()[0].genus, 0);
  EXPECT_EQ(mesh.components()[1].genus, 1);
  EXPECT_EQ(mesh.components()[0].num_faces, a->faces.rows());
  EXPECT_EQ(mesh.genus(), 1);
  EXPECT_EQ(mesh.euler_characteristic(), 2);
  for (int32_t f = 0; f < mesh.num_faces(); ++f) {
    EXPECT_EQ(mesh.face_component()(f), f < a->faces.rows() ? 0 : 1);
  }
}

TEST(TriangleMeshTest, UnreferencedVerticesAreDroppedAndCounted) {
  // Vertices 0 and 3 unused; 3 is even non-finite, which is fine because it is dropped.
  const double nan = std::nan("");
  TriangleMesh mesh =
      MustCreate(Arrays({{9, 9, 9}, {0, 0, 0}, {1, 0, 0}, {nan, 0, 0}, {0, 1, 0}}, {{1, 2, 4}}));
  EXPECT_EQ(mesh.dropped_unreferenced_vertices(), 2);
  EXPECT_EQ(mesh.num_vertices(), 3);
  EXPECT_EQ(mesh.faces()(0, 0), 0);
  EXPECT_EQ(mesh.faces()(0, 2), 2);
  EXPECT_EQ(mesh.vertices().row(2), Eigen::RowVector3d(0, 1, 0));
}

void ExpectInvalid(const MeshArrays& arrays, const std::string& message_part) {
  auto mesh = TriangleMesh::Create(arrays);
  ASSERT_FALSE(mesh.ok()) << "expected an error containing '" << message_part << "'";
  EXPECT_THAT(mesh, StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(std::string(mesh.status().message()), HasSubstr(message_part));
}

TEST(TriangleMeshTest, RejectsBadInputWithPreciseErrors) {
  const std::vector<Eigen::Vector3d> quad = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}};
  ExpectInvalid(Arrays(quad, {}), "no faces");
  ExpectInvalid(Arrays(quad, {{0, 1, 2}, {0, 2, 7}}), "face 1: vertex index 7 out of range");
  ExpectInvalid(Arrays(quad, {{0, 1, 2}, {-1, 2, 3}}), "face 1: vertex index -1 out of range");
  ExpectInvalid(Arrays(quad, {{0, 1, 2}, {0, 2, 2}}), "face 1: repeated vertex index");
  ExpectInvalid(
      Arrays({{0, 0, 0}, {1, 0, 0}, {0, std::numeric_limits<double>::infinity(), 0}}, {{0, 1, 2}}),
      "vertex 2: non-finite coordinate");
  ExpectInvalid(Arrays({{0, 0, 0}, {1, 0, 0}, {2, 0, 0}}, {{0, 1, 2}}), "face 0: zero area");
  // Inconsistent orientation: the second triangle runs the shared edge the same way.
  ExpectInvalid(Arrays(quad, {{0, 1, 2}, {0, 3, 2}}), "inconsistent orientation");
  // Three triangles on one edge (0, 1).
  ExpectInvalid(Arrays({{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, -1, 0}, {0, 0, 1}},
                       {{0, 1, 2}, {1, 0, 3}, {0, 1, 4}}),
                "edge (0, 1): non-manifold, shared by 3 faces");
  // Bow tie: two triangles that share only vertex 0.
  ExpectInvalid(
      Arrays({{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {-1, 0, 0}, {-1, -1, 0}}, {{0, 1, 2}, {0, 3, 4}}),
      "vertex 0: non-manifold");
}

TEST(TriangleMeshTest, ErrorsNameInputVertexIndicesEvenAfterDropping) {
  // Vertex 0 is unreferenced; the zero-area face must be reported with input indices 1, 2, 3.
  auto mesh =
      TriangleMesh::Create(Arrays({{5, 5, 5}, {0, 0, 0}, {1, 0, 0}, {2, 0, 0}}, {{1, 2, 3}}));
  ASSERT_FALSE(mesh.ok());
  EXPECT_THAT(std::string(mesh.status().message()), HasSubstr("vertices 1, 2, 3"));
}

TEST(TriangleMeshTest, FlippedFaceInClosedMeshIsRejected) {
  auto sphere = MakeIcosphere(2);
  ASSERT_TRUE(sphere.ok());
  std::swap(sphere->faces(17, 1), sphere->faces(17, 2));
  ExpectInvalid(*sphere, "inconsistent orientation");
}

// What real files bring (the shared teapot has non-manifold vertices, other scans have
// non-manifold edges, repeated corners or unreferenced vertices), at mesh scale and through the
// file readers: the fault is named, or the unused vertices are dropped and counted.
absl::StatusOr<TriangleMesh> ReadBack(const MeshArrays& arrays, const std::string& format,
                                      const testing::MeshTextOptions& options) {
  absl::StatusOr<MeshReadResult> read =
      ReadMesh(testing::MeshText(arrays, format, options),
               format == "obj" ? MeshFormat::kObj : MeshFormat::kOff);
  if (!read.ok()) return read.status();
  return TriangleMesh::Create(std::move(read->arrays));
}

TEST(TriangleMeshTest, NonManifoldVertexInAnObjFileIsRejected) {
  // Two noisy spheres touching at one vertex: the second is the first reflected through its
  // vertex 0 (faces reversed to stay outward), and shares that vertex.
  const MeshArrays a = testing::CatalogueArrays("NoisySphere");
  const Eigen::Index nv = a.vertices.rows();
  const Eigen::RowVector3d p0 = a.vertices.row(0);
  MeshArrays b = a;
  for (Eigen::Index v = 0; v < nv; ++v) b.vertices.row(v) = 2 * p0 - a.vertices.row(v);
  b.faces.col(1).swap(b.faces.col(2));
  MeshArrays touching = testing::DisjointUnion(a, b, Eigen::Vector3d::Zero());
  for (Eigen::Index i = 0; i < touching.faces.size(); ++i) {
    if (touching.faces.data()[i] == nv) touching.faces.data()[i] = 0;
  }
  ASSERT_TRUE(TriangleMesh::Create(b).ok()) << "the reflected sphere alone is valid";
  absl::StatusOr<TriangleMesh> mesh = ReadBack(
      touching, "obj", {.crlf = true, .normals = true, .texcoords = true, .material = true});
  EXPECT_THAT(mesh, StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr("non-manifold")));
  EXPECT_THAT(std::string(mesh.status().message()), HasSubstr("vertex 0"));
}

TEST(TriangleMeshTest, NonManifoldEdgeInAnOffFileIsRejected) {
  // A fin on the chipped torus: a third face on the edge of face 100's first two corners.
  MeshArrays m = testing::CatalogueArrays("ChippedTorus");
  const Eigen::Index nv = m.vertices.rows(), nf = m.faces.rows();
  const int32_t a = m.faces(100, 0), b = m.faces(100, 1);
  m.vertices.conservativeResize(nv + 1, 3);
  m.vertices.row(nv) = 0.5 * (m.vertices.row(a) + m.vertices.row(b)) + Eigen::RowVector3d(0, 0, 3);
  m.faces.conservativeResize(nf + 1, 3);
  m.faces.row(nf) << a, b, static_cast<int32_t>(nv);
  absl::StatusOr<TriangleMesh> mesh = ReadBack(m, "off", {.crlf = true});
  EXPECT_THAT(mesh, StatusIs(absl::StatusCode::kInvalidArgument,
                             HasSubstr("non-manifold, shared by 3 faces")));
}

TEST(TriangleMeshTest, RepeatedCornerInAFileIsRejected) {
  MeshArrays m = testing::CatalogueArrays("ObtuseTorus");
  m.faces(321, 2) = m.faces(321, 0);
  EXPECT_THAT(ReadBack(m, "obj", {}), StatusIs(absl::StatusCode::kInvalidArgument,
                                               HasSubstr("face 321: repeated vertex index")));
}

TEST(TriangleMeshTest, UnreferencedVerticesInAFileAreDroppedAndCounted) {
  const MeshArrays m = testing::CatalogueArrays("PlateWithFiveHoles");
  absl::StatusOr<TriangleMesh> mesh = ReadBack(m, "obj", {.unreferenced_vertices = 1113});
  ASSERT_TRUE(mesh.ok()) << mesh.status();
  EXPECT_EQ(mesh->dropped_unreferenced_vertices(), 1113);
  EXPECT_EQ(mesh->num_vertices(), m.vertices.rows());
  EXPECT_EQ(static_cast<int>(mesh->boundary_loops().size()), 6);
  EXPECT_EQ(mesh->genus(), 0);
}

// The distance from p to triangle (a, b, c), computed apart from SnapToSurface's closest point:
// inside the prism over the triangle, the distance to its plane; else the nearest of its sides.
double TriangleDistance(const Eigen::Vector3d& p, const Eigen::Vector3d& a,
                        const Eigen::Vector3d& b, const Eigen::Vector3d& c) {
  const Eigen::Vector3d n = (b - a).cross(c - a).normalized();
  const Eigen::Vector3d q = p - n.dot(p - a) * n;
  const auto side = [&](const Eigen::Vector3d& u, const Eigen::Vector3d& v) {
    return n.dot((v - u).cross(q - u));
  };
  if (side(a, b) >= 0 && side(b, c) >= 0 && side(c, a) >= 0) return (p - q).norm();
  const auto segment = [&](const Eigen::Vector3d& u, const Eigen::Vector3d& v) {
    const double t = std::clamp((p - u).dot(v - u) / (v - u).squaredNorm(), 0.0, 1.0);
    return (p - (u + t * (v - u))).norm();
  };
  return std::min({segment(a, b), segment(b, c), segment(c, a)});
}

// SnapToSurface prunes faces by their barycenter's distance and max_face_radius: on every mesh of
// the catalogue (irregular, noisy, two components among them) it finds the same distance as a
// test of every face, for points on, near and far from the surface.
class SnapToSurfaceTest : public testing::MeshCaseTest {};

TEST_P(SnapToSurfaceTest, FindsTheClosestFaceOfAll) {
  const TriangleMesh& m = mesh();
  const auto corner = [&](int32_t f, int k) -> Eigen::Vector3d {
    return m.vertices().row(m.faces()(f, k)).transpose();
  };
  double radius = 0;
  for (int32_t f = 0; f < m.num_faces(); ++f) {
    for (int k = 0; k < 3; ++k) {
      radius = std::max(radius, (corner(f, k) - m.face_barycenters().row(f).transpose()).norm());
    }
  }
  EXPECT_NEAR(m.max_face_radius(), radius, 1e-12 * radius);
  const Eigen::Vector3d lo = m.vertices().colwise().minCoeff().transpose();
  const Eigen::Vector3d hi = m.vertices().colwise().maxCoeff().transpose();
  uint64_t state = 12345;
  const auto uniform = [&]() {
    state = state * 6364136223846793005ull + 1442695040888963407ull;
    return static_cast<double>(state >> 11) * 0x1.0p-53;
  };
  for (int i = 0; i < 40; ++i) {
    // Around the bounding box (up to half its size outside), or a face's corner pushed off.
    Eigen::Vector3d p;
    if (i % 2 == 0) {
      for (int k = 0; k < 3; ++k) p[k] = lo[k] + (2 * uniform() - 0.5) * (hi[k] - lo[k]);
    } else {
      const int32_t f = static_cast<int32_t>(uniform() * m.num_faces());
      p = corner(f, i % 3) + 0.01 * (hi - lo).norm() * m.face_normals().row(f).transpose();
    }
    absl::StatusOr<SurfacePoint> snapped = SnapToSurface(m, p);
    ASSERT_TRUE(snapped.ok()) << snapped.status();
    double best = std::numeric_limits<double>::infinity();
    for (int32_t f = 0; f < m.num_faces(); ++f) {
      best = std::min(best, TriangleDistance(p, corner(f, 0), corner(f, 1), corner(f, 2)));
    }
    const double found = (SurfacePosition(m, *snapped) - p).norm();
    EXPECT_NEAR(found, best, 1e-9 * (hi - lo).norm()) << "point " << i;
  }
}

TEST(SnapToSurfaceTest, APointWhoseDistancesOverflowIsAnError) {
  auto arrays = MakeIcosphere(1);
  ASSERT_TRUE(arrays.ok());
  auto m = TriangleMesh::Create(*std::move(arrays));
  ASSERT_TRUE(m.ok());
  EXPECT_THAT(SnapToSurface(*m, Eigen::Vector3d(1e300, -1e300, 0)),
              StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr("too far")));
  // Far, and the distances still tell the faces apart: the nearest point is found.
  absl::StatusOr<SurfacePoint> far = SnapToSurface(*m, Eigen::Vector3d(1e6, 0, 0));
  ASSERT_TRUE(far.ok()) << far.status();
  EXPECT_GT(SurfacePosition(*m, *far)[0], 0.9);
}

INSTANTIATE_TEST_SUITE_P(Catalogue, SnapToSurfaceTest,
                         ::testing::ValuesIn(testing::MeshCatalogue()), testing::MeshCaseName);

}  // namespace
}  // namespace fieldspace
