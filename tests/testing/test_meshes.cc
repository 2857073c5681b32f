#include "tests/testing/test_meshes.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <system_error>
#include <utility>
#include <vector>

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
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

TriangleMesh MustCreate(absl::StatusOr<MeshArrays> arrays) {
  EXPECT_TRUE(arrays.ok()) << arrays.status();
  absl::StatusOr<TriangleMesh> mesh = TriangleMesh::Create(*std::move(arrays));
  EXPECT_TRUE(mesh.ok()) << mesh.status();
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

MeshArrays WithoutFaces(const MeshArrays& arrays, const std::vector<int32_t>& faces) {
  std::vector<bool> removed(arrays.faces.rows(), false);
  for (int32_t f : faces) removed[f] = true;
  MeshArrays m;
  m.vertices = arrays.vertices;
  m.faces.resize(std::count(removed.begin(), removed.end(), false), 3);
  Eigen::Index out = 0;
  for (Eigen::Index f = 0; f < arrays.faces.rows(); ++f) {
    if (!removed[f]) m.faces.row(out++) = arrays.faces.row(f);
  }
  return m;
}

MeshArrays PerforatedStrip(int nx, int ny, int holes) {
  std::vector<int32_t> removed;
  for (int k = 0; k < holes; ++k) {
    const int cell = (ny / 2) * nx + 2 + 3 * k;
    removed.push_back(2 * cell);
    removed.push_back(2 * cell + 1);
  }
  return WithoutFaces(PlanarStrip(nx, ny), removed);
}

TriangleMesh TwoSpheres(int32_t subdivisions, double r2) {
  absl::StatusOr<MeshArrays> a = MakeIcosphere(subdivisions, 1.0);
  absl::StatusOr<MeshArrays> b = MakeIcosphere(subdivisions, r2);
  EXPECT_TRUE(a.ok() && b.ok());
  return MustCreate(DisjointUnion(*a, *b, Eigen::Vector3d(5.0, 0.0, 0.0)));
}

std::string MeshText(const MeshArrays& arrays, const std::string& format,
                     const MeshTextOptions& options) {
  const char* eol = options.crlf ? "\r\n" : "\n";
  const Eigen::Index nv = arrays.vertices.rows(), nf = arrays.faces.rows();
  const Eigen::Index extra = options.unreferenced_vertices;
  auto vertex = [&](Eigen::Index v) {
    // The unreferenced extras sit beside the mesh, off its bounding box.
    const Eigen::Vector3d p = v < nv ? Eigen::Vector3d(arrays.vertices.row(v))
                                     : Eigen::Vector3d(10.0 + static_cast<double>(v - nv), 0.5, -3);
    return absl::StrFormat("%.17g %.17g %.17g", p.x(), p.y(), p.z());
  };
  std::string text;
  if (format == "off") {
    absl::StrAppend(&text, "OFF", eol, nv + extra, " ", nf, " 0", eol);
    for (Eigen::Index v = 0; v < nv + extra; ++v) absl::StrAppend(&text, vertex(v), eol);
    for (Eigen::Index f = 0; f < nf; ++f) {
      absl::StrAppend(&text, "3 ", arrays.faces(f, 0), " ", arrays.faces(f, 1), " ",
                      arrays.faces(f, 2), eol);
    }
    return text;
  }
  absl::StrAppend(&text, "# written by the fieldspace tests", eol);
  if (options.material) absl::StrAppend(&text, "mtllib shape.mtl", eol, "o shape", eol);
  for (Eigen::Index v = 0; v < nv + extra; ++v) {
    absl::StrAppend(&text, "v ", vertex(v), eol);
    if (options.texcoords) {
      absl::StrAppend(&text, "vt ", absl::StrFormat("%.6f %.6f", (v % 97) / 97.0, (v % 89) / 89.0),
                      eol);
    }
    if (options.normals) {
      Eigen::Vector3d n =
          v < nv ? Eigen::Vector3d(arrays.vertices.row(v)) : Eigen::Vector3d::UnitZ();
      n = n.norm() > 0 ? n.normalized() : Eigen::Vector3d::UnitZ();
      absl::StrAppend(&text, "vn ", absl::StrFormat("%.6f %.6f %.6f", n.x(), n.y(), n.z()), eol);
    }
  }
  auto corner = [&](int32_t v) {
    const std::string i = absl::StrCat(v + 1);  // one-based; vt and vn share the vertex index
    if (options.texcoords && options.normals) return absl::StrCat(i, "/", i, "/", i);
    if (options.texcoords) return absl::StrCat(i, "/", i);
    if (options.normals) return absl::StrCat(i, "//", i);
    return i;
  };
  for (Eigen::Index f = 0; f < nf; ++f) {
    if (options.material && (f == 0 || f == nf / 2)) {
      absl::StrAppend(&text, "g part", f == 0 ? 0 : 1, eol, "usemtl material", f == 0 ? 0 : 1, eol,
                      "s ", f == 0 ? "1" : "off", eol);
    }
    absl::StrAppend(&text, "f ", corner(arrays.faces(f, 0)), " ", corner(arrays.faces(f, 1)), " ",
                    corner(arrays.faces(f, 2)), eol);
  }
  return text;
}

namespace {

// `arrays` with PerturbVertices(amplitude, seed) applied.
absl::StatusOr<MeshArrays> Perturbed(absl::StatusOr<MeshArrays> arrays, double amplitude,
                                     uint64_t seed) {
  if (!arrays.ok()) return arrays.status();
  return PerturbVertices(*arrays, amplitude, seed);
}

}  // namespace

std::vector<MeshCase> MeshCatalogue() {
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
  // chi = sum over components of 2 - 2 g - loops.
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
  // Irregular, obtuse and noisy closed surfaces.
  add(
      "NoisySphere", [] { return Perturbed(MakeIcosphere(3), 0.3, 1); }, 0, 2, 0, 1);
  add(
      "Blob",
      []() -> absl::StatusOr<MeshArrays> {
        absl::StatusOr<MeshArrays> m = MakeNonUniformSphere(3, 0.6);
        if (!m.ok()) return m.status();
        for (Eigen::Index v = 0; v < m->vertices.rows(); ++v) {  // no symmetry left
          const double x = m->vertices(v, 0), y = m->vertices(v, 1), z = m->vertices(v, 2);
          m->vertices.row(v) << 1.3 * x, y + 0.2 * z * z, 0.7 * z + 0.25 * x * y;
        }
        return PerturbVertices(*m, 0.15, 2);
      },
      0, 2, 0, 1);
  add(
      "ObtuseTorus", [] { return MakeStaggeredTorus(1.0, 0.4, 16, 48); }, 1, 0, 0, 1);
  add(
      "NoisyGenus4", [] { return Perturbed(MakeGenusSurface(4, 4), 0.25, 4); }, 4, -6, 0, 1);
  add(
      "Genus5", [] { return MakeGenusSurface(5, 3); }, 5, -8, 0, 1);
  // Surfaces with borders.
  add(
      "Disk", [] { return PlanarStrip(12, 8); }, 0, 1, 1, 1);
  add(
      "PolarDisk", [] { return Perturbed(MakePolarDisk(12, 48), 0.2, 5); }, 0, 1, 1, 1);
  add(
      "Cylinder", [] { return Perturbed(MakeCylinder(0.5, 2.0, 32, 16), 0.2, 6); }, 0, 0, 2, 1);
  add(
      "ChippedTorus",
      []() -> absl::StatusOr<MeshArrays> {
        absl::StatusOr<MeshArrays> torus = MakeTorus(1.0, 0.4, 32, 16);
        if (!torus.ok()) return torus.status();
        return PerturbVertices(WithoutFaces(*torus, {0, 1}), 0.25, 7);  // one quad chipped off
      },
      1, -1, 1, 1);
  add(
      "DiskWithThreeHoles", [] { return PerforatedStrip(16, 8, 3); }, 0, -2, 4, 1);
  add(
      "PlateWithFiveHoles", [] { return Perturbed(MakePerforatedPlate(5, 3), 0.2, 8); }, 0, -4, 6,
      1);
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

std::vector<MeshCase> ClosedMeshCases(const std::vector<MeshCase>& cases) {
  std::vector<MeshCase> closed;
  for (const MeshCase& c : cases) {
    if (c.closed()) closed.push_back(c);
  }
  return closed;
}

absl::StatusOr<TriangleMesh> LoadMeshCase(const MeshCase& c) {
  absl::StatusOr<MeshArrays> arrays = c.build();
  if (!arrays.ok()) return arrays.status();
  return TriangleMesh::Create(*std::move(arrays));
}

MeshArrays CatalogueArrays(const std::string& name) {
  for (const MeshCase& c : MeshCatalogue()) {
    if (c.name != name) continue;
    absl::StatusOr<MeshArrays> arrays = c.build();
    EXPECT_TRUE(arrays.ok()) << name << ": " << arrays.status();
    return *std::move(arrays);
  }
  ADD_FAILURE() << "no catalogue mesh named " << name;
  std::abort();
}

TriangleMesh CatalogueMesh(const std::string& name) { return MustCreate(CatalogueArrays(name)); }

std::string MeshCaseName(const ::testing::TestParamInfo<MeshCase>& info) { return info.param.name; }

void PrintTo(const MeshCase& c, std::ostream* os) {
  *os << c.name << " (genus " << c.genus << ", chi " << c.euler_characteristic << ", "
      << c.boundary_loops << " boundary loops, " << c.components << " components)";
}

void MeshCaseTest::SetUp() {
  const MeshCase& c = GetParam();
  absl::StatusOr<TriangleMesh> mesh = LoadMeshCase(c);
  ASSERT_TRUE(mesh.ok()) << c.name << ": " << mesh.status();
  mesh_.emplace(*std::move(mesh));
}

}  // namespace fieldspace::testing
