#include "tests/testing/test_meshes.h"

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <system_error>
#include <utility>
#include <vector>

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"
#include "core/mesh/mesh_io.h"
#include "core/mesh/shapes.h"

namespace fieldspace::testing {

std::filesystem::path SharedMeshDir() {
  if (const char* env = std::getenv("FIELDSPACE_MESH_DIR"); env != nullptr && *env != '\0') {
    return env;
  }
  return FIELDSPACE_DEFAULT_MESH_DIR;
}

std::string SharedMeshPath(const std::string& name) {
  std::filesystem::path p = SharedMeshDir() / name;
  std::error_code ec;
  return std::filesystem::exists(p, ec) ? p.string() : std::string();
}

absl::StatusOr<TriangleMesh> LoadMesh(const std::string& path) {
  absl::StatusOr<MeshReadResult> read = ReadMeshFile(path);
  if (!read.ok()) return read.status();
  return TriangleMesh::Create(std::move(read->arrays));
}

TriangleMesh MustCreate(absl::StatusOr<MeshArrays> arrays) {
  EXPECT_TRUE(arrays.ok()) << arrays.status();
  absl::StatusOr<TriangleMesh> mesh = TriangleMesh::Create(*std::move(arrays));
  EXPECT_TRUE(mesh.ok()) << mesh.status();
  return *std::move(mesh);
}

TriangleMesh MustLoadMesh(const std::string& path) {
  absl::StatusOr<TriangleMesh> mesh = LoadMesh(path);
  EXPECT_TRUE(mesh.ok()) << path << ": " << mesh.status();
  return *std::move(mesh);
}

MeshArrays Arrays(const std::vector<Eigen::Vector3d>& vertices,
                  const std::vector<Eigen::Vector3i>& faces) {
  MeshArrays a;
  a.vertices.resize(static_cast<Eigen::Index>(vertices.size()), 3);
  for (size_t i = 0; i < vertices.size(); ++i) a.vertices.row(i) = vertices[i];
  a.faces.resize(static_cast<Eigen::Index>(faces.size()), 3);
  for (size_t i = 0; i < faces.size(); ++i) a.faces.row(i) = faces[i];
  return a;
}

MeshArrays DisjointUnion(const MeshArrays& a, const MeshArrays& b,
                         const Eigen::Vector3d& offset_b) {
  MeshArrays m;
  const Eigen::Index va = a.vertices.rows(), vb = b.vertices.rows();
  m.vertices.resize(va + vb, 3);
  m.vertices.topRows(va) = a.vertices;
  m.vertices.bottomRows(vb) = b.vertices.rowwise() + offset_b.transpose();
  m.faces.resize(a.faces.rows() + b.faces.rows(), 3);
  m.faces.topRows(a.faces.rows()) = a.faces;
  m.faces.bottomRows(b.faces.rows()) = b.faces.array() + static_cast<int32_t>(va);
  return m;
}

TriangleMesh Icosphere(int32_t subdivisions, double radius) {
  return MustCreate(MakeIcosphere(subdivisions, radius));
}

TriangleMesh Torus(int32_t major_segments, int32_t minor_segments, double major_radius,
                   double minor_radius) {
  return MustCreate(MakeTorus(major_radius, minor_radius, major_segments, minor_segments));
}

MeshArrays PlanarStrip(int nx, int ny) {
  std::vector<Eigen::Vector3d> v;
  for (int j = 0; j <= ny; ++j) {
    for (int i = 0; i <= nx; ++i) {
      const bool inner = i > 0 && i < nx && j > 0 && j < ny;
      const double jx = inner ? 0.2 * std::sin(1.7 * i + 2.3 * j) : 0.0;
      const double jy = inner ? 0.2 * std::cos(2.9 * i - 1.1 * j) : 0.0;
      v.emplace_back(i + jx, j + jy, 0.0);
    }
  }
  auto id = [&](int i, int j) { return j * (nx + 1) + i; };
  std::vector<Eigen::Vector3i> f;
  for (int j = 0; j < ny; ++j) {
    for (int i = 0; i < nx; ++i) {
      std::vector<Eigen::Vector3i> two;
      if ((i + j) % 2 == 0) {
        two = {{id(i, j), id(i + 1, j), id(i + 1, j + 1)},
               {id(i, j), id(i + 1, j + 1), id(i, j + 1)}};
      } else {
        two = {{id(i, j), id(i + 1, j), id(i, j + 1)},
               {id(i + 1, j), id(i + 1, j + 1), id(i, j + 1)}};
      }
      for (Eigen::Vector3i t : two) {
        const int r = static_cast<int>(f.size()) % 3;
        f.emplace_back(t[r], t[(r + 1) % 3], t[(r + 2) % 3]);
      }
    }
  }
  return Arrays(v, f);
}

MeshArrays PerforatedStrip(int nx, int ny, int holes) {
  const MeshArrays strip = PlanarStrip(nx, ny);
  std::vector<bool> removed(strip.faces.rows(), false);
  for (int k = 0; k < holes; ++k) {
    const int cell = (ny / 2) * nx + 2 + 3 * k;
    removed[2 * cell] = removed[2 * cell + 1] = true;
  }
  MeshArrays m;
  m.vertices = strip.vertices;  // the removed cells' corners stay on the hole boundaries
  m.faces.resize(strip.faces.rows() - 2 * holes, 3);
  Eigen::Index out = 0;
  for (Eigen::Index f = 0; f < strip.faces.rows(); ++f) {
    if (!removed[f]) m.faces.row(out++) = strip.faces.row(f);
  }
  return m;
}

TriangleMesh TwoSpheres(int32_t subdivisions, double r2) {
  absl::StatusOr<MeshArrays> a = MakeIcosphere(subdivisions, 1.0);
  absl::StatusOr<MeshArrays> b = MakeIcosphere(subdivisions, r2);
  EXPECT_TRUE(a.ok() && b.ok());
  return MustCreate(DisjointUnion(*a, *b, Eigen::Vector3d(5.0, 0.0, 0.0)));
}

std::vector<MeshCase> BuiltInMeshCases() {
  std::vector<MeshCase> cases;
  auto add = [&](std::string name, std::function<absl::StatusOr<MeshArrays>()> build, int genus,
                 int chi, int loops, int components) {
    MeshCase c;
    c.name = std::move(name);
    c.build = std::move(build);
    c.genus = genus;
    c.euler_characteristic = chi;
    c.boundary_loops = loops;
    c.components = components;
    cases.push_back(std::move(c));
  };
  add(
      "Sphere", [] { return MakeIcosphere(3); }, 0, 2, 0, 1);
  add(
      "Torus", [] { return MakeTorus(1.0, 0.4, 32, 16); }, 1, 0, 0, 1);
  add(
      "Genus2", [] { return MakeGenusSurface(2, 4); }, 2, -2, 0, 1);
  add(
      "TorusKnot",
      [] {
        TorusKnotOptions knot;
        knot.segments = 96;
        knot.tube_segments = 12;
        return MakeTorusKnot(knot);
      },
      1, 0, 0, 1);
  add(
      "Disk", [] { return PlanarStrip(12, 8); }, 0, 1, 1, 1);
  add(
      "DiskWithThreeHoles", [] { return PerforatedStrip(16, 8, 3); }, 0, -2, 4, 1);
  add(
      "SphereAndTorus",
      []() -> absl::StatusOr<MeshArrays> {
        absl::StatusOr<MeshArrays> sphere = MakeIcosphere(2);
        absl::StatusOr<MeshArrays> torus = MakeTorus(1.0, 0.4, 24, 12);
        if (!sphere.ok()) return sphere.status();
        if (!torus.ok()) return torus.status();
        return DisjointUnion(*sphere, *torus, Eigen::Vector3d(4.0, 0.0, 0.0));
      },
      1, 2, 0, 2);
  return cases;
}

std::vector<MeshCase> SharedMeshCases() {
  std::vector<MeshCase> cases;
  auto add = [&](std::string name, std::string file, int genus, int chi, int loops) {
    MeshCase c;
    c.name = std::move(name);
    c.shared_file = std::move(file);
    c.genus = genus;
    c.euler_characteristic = chi;
    c.boundary_loops = loops;
    cases.push_back(std::move(c));
  };
  // chi = 2 - 2 g - loops for one component.
  add("SharedSphere1k", "sphere_1k.obj", 0, 2, 0);
  add("SharedBimba1k", "bimba_1k.off", 0, 2, 0);
  add("SharedRockerArm1k", "rocker_arm_1k.off", 1, 0, 0);
  add("SharedChippedTorus1k", "chipped_torus_1k.obj", 1, -1, 1);
  add("SharedTorus5k", "torus_5k.obj", 1, 0, 0);
  add("SharedFertility9k", "fertility_9k.off", 4, -6, 0);
  add("SharedEight11k", "eight_11k.off", 2, -2, 0);
  add("SharedCamelhead23k", "camelhead_23k.off", 0, 1, 1);
  add("SharedKitten29k", "kitten_29k.obj", 1, 0, 0);
  return cases;
}

std::vector<MeshCase> MeshCatalogue() {
  std::vector<MeshCase> cases = BuiltInMeshCases();
  for (MeshCase& c : SharedMeshCases()) cases.push_back(std::move(c));
  return cases;
}

std::vector<MeshCase> ClosedMeshCases(const std::vector<MeshCase>& cases) {
  std::vector<MeshCase> closed;
  for (const MeshCase& c : cases) {
    if (c.closed()) closed.push_back(c);
  }
  return closed;
}

absl::StatusOr<TriangleMesh> LoadMeshCase(const MeshCase& c) {
  if (c.built_in()) {
    absl::StatusOr<MeshArrays> arrays = c.build();
    if (!arrays.ok()) return arrays.status();
    return TriangleMesh::Create(*std::move(arrays));
  }
  const std::string path = SharedMeshPath(c.shared_file);
  if (path.empty()) {
    return absl::NotFoundError(absl::StrCat("shared mesh ", c.shared_file, " not found in ",
                                            SharedMeshDir().string(),
                                            " (set FIELDSPACE_MESH_DIR to the folder of "
                                            "../shared/meshes)"));
  }
  return LoadMesh(path);
}

std::string MeshCaseName(const ::testing::TestParamInfo<MeshCase>& info) { return info.param.name; }

void PrintTo(const MeshCase& c, std::ostream* os) {
  *os << c.name << " (" << (c.built_in() ? "built in code" : c.shared_file) << ", genus " << c.genus
      << ", chi " << c.euler_characteristic << ", " << c.boundary_loops << " boundary loops, "
      << c.components << " components)";
}

void MeshCaseTest::SetUp() {
  const MeshCase& c = GetParam();
  absl::StatusOr<TriangleMesh> mesh = LoadMeshCase(c);
  if (!c.built_in() && absl::IsNotFound(mesh.status())) {
    GTEST_SKIP() << mesh.status().message();
  }
  ASSERT_TRUE(mesh.ok()) << c.name << ": " << mesh.status();
  mesh_.emplace(*std::move(mesh));
}

}  // namespace fieldspace::testing
