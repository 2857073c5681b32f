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

// Every mesh of the catalogue has its known topology and consistent tables: shapes built in code
// (sphere, torus, genus 2, torus knot, disk, disk with holes, two components) and the shared
// meshes where present.
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

// Golden statistics from ../shared/meshes/README.md (an independent source).
struct SharedMeshCase {
  const char* name;
  int32_t vertices;
  int32_t faces;
  std::optional<int32_t> genus;
  std::optional<int32_t> boundary_loops;
  int32_t dropped = 0;
};

class SharedMeshTest : public ::testing::TestWithParam<SharedMeshCase> {};

TEST_P(SharedMeshTest, MatchesTheCatalogue) {
  const SharedMeshCase& c = GetParam();
  FS_REQUIRE_SHARED_MESH(path, c.name);
  auto read = ReadMeshFile(path);
  ASSERT_TRUE(read.ok()) << read.status();
  auto mesh = TriangleMesh::Create(std::move(read->arrays));
  ASSERT_TRUE(mesh.ok()) << mesh.status();
  EXPECT_EQ(mesh->num_vertices(), c.vertices);
  EXPECT_EQ(mesh->num_faces(), c.faces);
  EXPECT_EQ(mesh->dropped_unreferenced_vertices(), c.dropped);
  if (c.genus) {
    EXPECT_EQ(mesh->genus(), *c.genus);
  }
  if (c.boundary_loops) {
    EXPECT_EQ(static_cast<int>(mesh->boundary_loops().size()), *c.boundary_loops);
  }
  int32_t chi = 0;
  for (const MeshComponent& comp : mesh->components()) {
    EXPECT_EQ(comp.euler_characteristic, 2 - 2 * comp.genus - comp.num_boundary_loops);
    chi += comp.euler_characteristic;
  }
  EXPECT_EQ(chi, mesh->num_vertices() - mesh->num_edges() + mesh->num_faces());
}

INSTANTIATE_TEST_SUITE_P(
    Catalogue, SharedMeshTest,
    ::testing::Values(SharedMeshCase{"sphere_1k.obj", 642, 1280, 0, 0},
                      SharedMeshCase{"chipped_torus_1k.obj", 560, 1102, 1, 1},
                      SharedMeshCase{"rocker_arm_1k.off", 625, 1250, 1, 0},
                      SharedMeshCase{"bimba_1k.off", 697, 1390, 0, 0},
                      SharedMeshCase{"torus_5k.obj", 2304, 4608, 1, 0},
                      SharedMeshCase{"spot_6k.obj", 2930, 5856, 0, 0},
                      SharedMeshCase{"fertility_9k.off", 4494, 9000, 4, 0},
                      SharedMeshCase{"eight_11k.off", 5544, 11092, 2, 0},
                      SharedMeshCase{"blade_16k.off", 8231, 16222, std::nullopt, 2},
                      SharedMeshCase{"bimba_18k.obj", 8857, 17710, 0, 0},
                      SharedMeshCase{"cheese_18k.off", 8629, 17786, 133, 0},
                      SharedMeshCase{"chinese_dragon_20k.off", 10000, 19994, std::nullopt, 2},
                      SharedMeshCase{"rocker_arm_20k.obj", 10044, 20088, 1, 0},
                      SharedMeshCase{"camelhead_23k.off", 11381, 22704, 0, 1},
                      SharedMeshCase{"fertility_28k.obj", 13971, 27954, 4, 0},
                      SharedMeshCase{"kitten_29k.obj", 14472, 28944, 1, 0},
                      SharedMeshCase{"mountain_51k.obj", 25600, 50562, 0, 1},
                      SharedMeshCase{"fertility_60k.obj", 30000, 60012, 4, 0},
                      SharedMeshCase{"stanford_bunny_69k.obj", 34834, 69451, std::nullopt, 5, 1113},
                      SharedMeshCase{"bunny_70k.obj", 34835, 69666, 0, 0},
                      SharedMeshCase{"botijo_82k.obj", 41158, 82332, 5, 0},
                      SharedMeshCase{"armadillo_86k.obj", 43243, 86482, 0, 0},
                      SharedMeshCase{"nefertiti_100k.obj", 49971, 99938, 0, 0},
                      SharedMeshCase{"rolling_stage_100k.obj", 49988, 100000, 7, 0},
                      SharedMeshCase{"skull_100k.obj", 49999, 100002, 2, 0},
                      SharedMeshCase{"igea_269k.obj", 134345, 268686, 0, 0},
                      SharedMeshCase{"stanford_bunny_loop2_1111k.ply", 556051, 1111216,
                                     std::nullopt, 5},
                      SharedMeshCase{"armadillo_loop2_1384k.ply", 691858, 1383712, 0, 0},
                      SharedMeshCase{"fertility_loop3_1789k.ply", 894522, 1789056, 4, 0}),
    [](const auto& info) {
      std::string name = info.param.name;
      for (char& ch : name) {
        if (!std::isalnum(static_cast<unsigned char>(ch))) ch = '_';
      }
      return name;
    });

TEST(SharedMeshRejectTest, TeapotIsNonManifold) {
  FS_REQUIRE_SHARED_MESH(path, "teapot_6k.obj");
  auto read = ReadMeshFile(path);
  ASSERT_TRUE(read.ok()) << read.status();
  auto mesh = TriangleMesh::Create(std::move(read->arrays));
  ASSERT_FALSE(mesh.ok());
  EXPECT_THAT(mesh, StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(std::string(mesh.status().message()), HasSubstr("non-manifold"));
}

}  // namespace
}  // namespace fieldspace
