#ifndef FIELDSPACE_TESTS_TESTING_TEST_MESHES_H_
#define FIELDSPACE_TESTS_TESTING_TEST_MESHES_H_

// Test meshes: the shared real meshes (../shared/meshes, optional), shapes built in code, and a
// catalogue of both with their known topology for parameterized tests.

#include <cstdint>
#include <filesystem>
#include <functional>
#include <optional>
#include <ostream>
#include <string>
#include <vector>

#include "Eigen/Core"
#include "absl/status/statusor.h"
#include "core/mesh/triangle_mesh.h"
#include "gtest/gtest.h"

namespace fieldspace::testing {

// ---- Shared meshes ------------------------------------------------------------------------------

// The folder of the shared test meshes: $FIELDSPACE_MESH_DIR, else ../shared/meshes next to the
// source tree.
std::filesystem::path SharedMeshDir();

// Full path of a shared mesh, or empty if it is absent.
std::string SharedMeshPath(const std::string& name);

// Reads a mesh file (any format ReadMeshFile knows) and validates it.
absl::StatusOr<TriangleMesh> LoadMesh(const std::string& path);

// ---- Meshes from arrays -------------------------------------------------------------------------

// Validates `arrays` into a mesh; a failure (of building or validating) fails the current test
// and then aborts, so use it only for inputs that must be valid.
TriangleMesh MustCreate(absl::StatusOr<MeshArrays> arrays);

// LoadMesh that must succeed (same failure behaviour as MustCreate).
TriangleMesh MustLoadMesh(const std::string& path);

// Arrays from vertex positions and zero-based faces.
MeshArrays Arrays(const std::vector<Eigen::Vector3d>& vertices,
                  const std::vector<Eigen::Vector3i>& faces);

// The disjoint union of `a` and `b`, with `b` translated by `offset_b`.
MeshArrays DisjointUnion(const MeshArrays& a, const MeshArrays& b, const Eigen::Vector3d& offset_b);

// ---- Shapes built in code -----------------------------------------------------------------------

// Icosphere (core/mesh/shapes.h): 20 * 4^s faces, genus 0.
TriangleMesh Icosphere(int32_t subdivisions, double radius = 1.0);

// Torus of revolution (R = 1, r = 0.4 unless given): 2 * major * minor faces, genus 1.
TriangleMesh Torus(int32_t major_segments, int32_t minor_segments, double major_radius = 1.0,
                   double minor_radius = 0.4);

// A planar rectangular strip [0, nx] x [0, ny] (z = 0), a disk: interior vertices jittered
// deterministically, each cell split along a varying diagonal, face vertex orders cyclically
// rotated by f % 3 so the frames differ from face to face. Cell (i, j) is faces 2 (j nx + i) and
// 2 (j nx + i) + 1. (nx + 1)(ny + 1) vertices, 2 nx ny faces, chi = 1, one boundary loop.
MeshArrays PlanarStrip(int nx, int ny);

// PlanarStrip with `holes` single cells removed (cells (2 + 3 k, ny / 2), k < holes, none
// touching the border or each other): genus 0, chi = 1 - holes, 1 + holes boundary loops.
// Requires 3 * holes + 1 < nx and ny >= 4.
MeshArrays PerforatedStrip(int nx, int ny, int holes);

// Two disjoint icospheres: radius 1 at the origin, radius `r2` at x = 5.
TriangleMesh TwoSpheres(int32_t subdivisions, double r2);

// ---- The mesh catalogue -------------------------------------------------------------------------

// One mesh with its known topology: a shape built in code, or a shared mesh file (an optional
// extra: tests skip it with a message when ../shared/meshes does not have it).
struct MeshCase {
  std::string name;         // a valid test-name suffix
  std::string shared_file;  // file in SharedMeshDir(); empty for shapes built in code
  std::function<absl::StatusOr<MeshArrays>()> build;  // for shapes built in code
  int32_t genus = 0;                                  // sum over components
  int32_t euler_characteristic = 0;                   // V - E + F
  int32_t boundary_loops = 0;
  int32_t components = 1;

  bool built_in() const { return shared_file.empty(); }
  bool closed() const { return boundary_loops == 0; }
};

// Shapes built in code, present in every checkout: sphere, torus, genus-2 surface, torus knot
// tube (closed); disk, disk with holes (open); a sphere and a torus (two components).
std::vector<MeshCase> BuiltInMeshCases();

// Shared meshes with the topology of ../shared/meshes/README.md (small and medium ones only).
std::vector<MeshCase> SharedMeshCases();

// BuiltInMeshCases() followed by SharedMeshCases().
std::vector<MeshCase> MeshCatalogue();

// The cases without boundary.
std::vector<MeshCase> ClosedMeshCases(const std::vector<MeshCase>& cases);

// Builds or reads the mesh of `c`; NotFound if it is a shared mesh that is absent.
absl::StatusOr<TriangleMesh> LoadMeshCase(const MeshCase& c);

// For INSTANTIATE_TEST_SUITE_P(..., MeshCaseName).
std::string MeshCaseName(const ::testing::TestParamInfo<MeshCase>& info);
void PrintTo(const MeshCase& c, std::ostream* os);

// A test fixture parameterized over MeshCase: SetUp loads the mesh, skipping (with a message
// naming the folder) a shared mesh that is absent.
class MeshCaseTest : public ::testing::TestWithParam<MeshCase> {
 protected:
  void SetUp() override;
  const TriangleMesh& mesh() const { return *mesh_; }

 private:
  std::optional<TriangleMesh> mesh_;
};

}  // namespace fieldspace::testing

// Declares `var` as the path of shared mesh `name`, or skips the test with a clear message.
#define FS_REQUIRE_SHARED_MESH(var, name)                                           \
  const std::string var = ::fieldspace::testing::SharedMeshPath(name);              \
  if (var.empty()) {                                                                \
    GTEST_SKIP() << "shared mesh " << (name) << " not found in "                    \
                 << ::fieldspace::testing::SharedMeshDir()                          \
                 << " (set FIELDSPACE_MESH_DIR to the folder of ../shared/meshes)"; \
  }

#endif  // FIELDSPACE_TESTS_TESTING_TEST_MESHES_H_
