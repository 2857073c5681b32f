#ifndef FIELDSPACE_TESTS_TESTING_TEST_MESHES_H_
#define FIELDSPACE_TESTS_TESTING_TEST_MESHES_H_

// Test meshes: shapes built in code and a catalogue of them with their known topology for
// parameterized tests, mesh files written from them (the variants real files come in), and the
// path of the shared real meshes (../shared/meshes), which only the large-mesh checks read.

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

// The folder of the shared real meshes: $FIELDSPACE_MESH_DIR, else ../shared/meshes next to the
// source tree. Only the large-mesh checks (not in the default suite) read them.
std::filesystem::path SharedMeshDir();

// Full path of a shared mesh, or empty if it is absent.
std::string SharedMeshPath(const std::string& name);

// ---- Meshes from arrays -------------------------------------------------------------------------

// Validates `arrays` into a mesh; a failure (of building or validating) fails the current test
// and then aborts, so use it only for inputs that must be valid.
TriangleMesh MustCreate(absl::StatusOr<MeshArrays> arrays);

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

// `arrays` without the faces listed (vertices kept, so the removed faces' corners stay on the new
// boundary).
MeshArrays WithoutFaces(const MeshArrays& arrays, const std::vector<int32_t>& faces);

// PlanarStrip with `holes` single cells removed (cells (2 + 3 k, ny / 2), k < holes, none
// touching the border or each other): genus 0, chi = 1 - holes, 1 + holes boundary loops.
// Requires 3 * holes + 1 < nx and ny >= 4.
MeshArrays PerforatedStrip(int nx, int ny, int holes);

// Two disjoint icospheres: radius 1 at the origin, radius `r2` at x = 5.
TriangleMesh TwoSpheres(int32_t subdivisions, double r2);

// ---- Mesh files ---------------------------------------------------------------------------------

// How MeshText writes a mesh: the variants real files come in.
struct MeshTextOptions {
  bool crlf = false;                  // "\r\n" line endings
  bool normals = false;               // OBJ: a `vn` per vertex and corners `v//n` (or `v/t/n`)
  bool texcoords = false;             // OBJ: a `vt` per vertex and corners `v/t`
  bool material = false;              // OBJ: `mtllib`, `usemtl`, `o`, `g` and `s` statements
  int32_t unreferenced_vertices = 0;  // extra vertices no face uses, after the mesh's own
};

// The text of `arrays` as an OBJ ("obj") or OFF ("off") file, coordinates written with 17
// significant digits (read back exactly).
std::string MeshText(const MeshArrays& arrays, const std::string& format,
                     const MeshTextOptions& options = {});

// ---- The mesh catalogue -------------------------------------------------------------------------

// One mesh built in code with its known topology.
struct MeshCase {
  std::string name;                                   // a valid test-name suffix
  std::function<absl::StatusOr<MeshArrays>()> build;  // the mesh
  int32_t genus = 0;                                  // sum over components
  int32_t euler_characteristic = 0;                   // V - E + F
  int32_t boundary_loops = 0;
  int32_t components = 1;

  bool closed() const { return boundary_loops == 0; }
};

// Every checkout's test meshes (1k-6k faces each), in the kinds real meshes come in: regular
// closed surfaces (sphere, torus, genus 2, torus knot); irregular, obtuse and noisy ones (a noisy
// sphere, a blob without symmetry from a sphere of non-uniform density, a torus of obtuse slivers,
// a noisy genus-4 surface, a genus-5 surface); surfaces with borders (disk, polar disk, cylinder,
// chipped torus, disk and plate with holes); two components (a sphere and a torus).
std::vector<MeshCase> MeshCatalogue();

// The cases without boundary.
std::vector<MeshCase> ClosedMeshCases(const std::vector<MeshCase>& cases);

// Builds the mesh of `c` (validated).
absl::StatusOr<TriangleMesh> LoadMeshCase(const MeshCase& c);

// The arrays of the catalogue case named `name`; fails the test and aborts if there is none.
MeshArrays CatalogueArrays(const std::string& name);

// The mesh of the catalogue case named `name` (same failure behaviour as MustCreate).
TriangleMesh CatalogueMesh(const std::string& name);

// For INSTANTIATE_TEST_SUITE_P(..., MeshCaseName).
std::string MeshCaseName(const ::testing::TestParamInfo<MeshCase>& info);
void PrintTo(const MeshCase& c, std::ostream* os);

// A test fixture parameterized over MeshCase: SetUp builds the mesh.
class MeshCaseTest : public ::testing::TestWithParam<MeshCase> {
 protected:
  void SetUp() override;
  const TriangleMesh& mesh() const { return *mesh_; }

 private:
  std::optional<TriangleMesh> mesh_;
};

}  // namespace fieldspace::testing

// Declares `var` as the path of shared mesh `name`, or skips the test with a clear message. For
// the large-mesh checks only: a test of the default suite uses meshes every checkout has.
#define FS_REQUIRE_SHARED_MESH(var, name)                                           \
  const std::string var = ::fieldspace::testing::SharedMeshPath(name);              \
  if (var.empty()) {                                                                \
    GTEST_SKIP() << "shared mesh " << (name) << " not found in "                    \
                 << ::fieldspace::testing::SharedMeshDir()                          \
                 << " (set FIELDSPACE_MESH_DIR to the folder of ../shared/meshes)"; \
  }

#endif  // FIELDSPACE_TESTS_TESTING_TEST_MESHES_H_
