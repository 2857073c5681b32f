#include "core/mesh/shapes.h"

#include <cmath>
#include <cstdint>
#include <limits>
#include <numeric>
#include <random>
#include <unordered_map>
#include <vector>

#include "Eigen/Geometry"
#include "absl/status/status.h"
#include "absl/strings/str_format.h"

namespace fieldspace {
namespace {

constexpr double kPi = 3.14159265358979323846;

// Builds MeshArrays from growable lists, keeping only referenced vertices (in first-use order
// of the vertex list) so shapes never report dropped vertices.
MeshArrays Compact(const std::vector<Eigen::Vector3d>& points,
                   const std::vector<Eigen::Vector3i>& triangles) {
  std::vector<int32_t> remap(points.size(), -1);
  for (const auto& t : triangles) {
    for (int k = 0; k < 3; ++k) remap[t[k]] = 0;
  }
  int32_t next = 0;
  for (int32_t& r : remap) {
    if (r == 0) r = next++;
  }
  MeshArrays out;
  out.vertices.resize(next, 3);
  for (size_t i = 0; i < points.size(); ++i) {
    if (remap[i] >= 0) out.vertices.row(remap[i]) = points[i];
  }
  out.faces.resize(static_cast<int64_t>(triangles.size()), 3);
  for (size_t f = 0; f < triangles.size(); ++f) {
    for (int k = 0; k < 3; ++k) out.faces(f, k) = remap[triangles[f][k]];
  }
  return out;
}

// Adds the two triangles of quad (a, b, c, d), counter-clockwise seen from outside.
void AddQuad(std::vector<Eigen::Vector3i>& tris, int a, int b, int c, int d) {
  tris.emplace_back(a, b, c);
  tris.emplace_back(a, c, d);
}

// The torus grid of MakeTorus (staggered = false) and MakeStaggeredTorus (true: odd rings turned
// by half a major step, quads of even rings split along the other diagonal). Arguments checked.
MeshArrays TorusGrid(double major_radius, double minor_radius, int32_t major_segments,
                     int32_t minor_segments, bool staggered) {
  std::vector<Eigen::Vector3d> pts;
  pts.reserve(int64_t{major_segments} * minor_segments);
  for (int32_t i = 0; i < major_segments; ++i) {
    for (int32_t j = 0; j < minor_segments; ++j) {
      const double turn = staggered && j % 2 == 1 ? 0.5 : 0.0;
      const double u = 2 * kPi * (i + turn) / major_segments;
      const double v = 2 * kPi * j / minor_segments;
      const double rho = major_radius + minor_radius * std::cos(v);
      pts.emplace_back(rho * std::cos(u), rho * std::sin(u), minor_radius * std::sin(v));
    }
  }
  std::vector<Eigen::Vector3i> tris;
  auto id = [&](int32_t i, int32_t j) {
    return (i % major_segments) * minor_segments + (j % minor_segments);
  };
  for (int32_t i = 0; i < major_segments; ++i) {
    for (int32_t j = 0; j < minor_segments; ++j) {
      const int32_t a = id(i, j), b = id(i + 1, j), c = id(i + 1, j + 1), d = id(i, j + 1);
      if (staggered && j % 2 == 0) {  // ring j + 1 is turned: d between a and b, b between d, c
        tris.emplace_back(a, b, d);
        tris.emplace_back(b, c, d);
      } else {
        AddQuad(tris, a, b, c, d);
      }
    }
  }
  return Compact(pts, tris);
}

// Whether cell (i, j) of the plate of MakeGenusSurface (and MakePerforatedPlate) is solid: the
// plate is (2 holes + 1) x 3 units of `resolution` cells, and hole k is the unit square
// [2k + 1, 2k + 2] x [1, 2].
bool PlateCellIsSolid(int32_t holes, int32_t resolution, int32_t i, int32_t j) {
  const int32_t nx = (2 * holes + 1) * resolution, ny = 3 * resolution;
  if (i < 0 || j < 0 || i >= nx || j >= ny) return false;
  if (j < resolution || j >= 2 * resolution) return true;
  const int32_t unit = i / resolution;
  return unit % 2 == 0;  // odd units in the middle row are holes
}

absl::Status CheckPlate(const char* holes_name, int32_t holes, int32_t resolution) {
  if (holes < 0 || holes > 64) {
    return absl::InvalidArgumentError(
        absl::StrFormat("%s must be in [0, 64], got %d", holes_name, holes));
  }
  if (resolution < 1 || resolution > 256) {
    return absl::InvalidArgumentError(
        absl::StrFormat("resolution must be in [1, 256], got %d", resolution));
  }
  return absl::OkStatus();
}

absl::Status CheckTorusRadii(double major_radius, double minor_radius) {
  if (!(minor_radius > 0) || !(major_radius > minor_radius) || !std::isfinite(major_radius)) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "torus radii must satisfy 0 < r < R, got R = %g, r = %g", major_radius, minor_radius));
  }
  return absl::OkStatus();
}

// A grid of a x b segments: a >= 3 (around a closed direction), b >= b_min, a * b <= 2^24.
absl::Status CheckSegments(const char* shape, int32_t a, int32_t b, int32_t b_min) {
  if (a < 3 || b < b_min || int64_t{a} * b > (int64_t{1} << 24)) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "%s needs >= 3 x >= %d segments, at most 2^24 in all, got %d x %d", shape, b_min, a, b));
  }
  return absl::OkStatus();
}

}  // namespace

absl::StatusOr<MeshArrays> MakeIcosphere(int32_t subdivisions, double radius) {
  if (subdivisions < 0 || subdivisions > 8) {
    return absl::InvalidArgumentError(
        absl::StrFormat("icosphere subdivisions must be in [0, 8], got %d", subdivisions));
  }
  if (!(radius > 0) || !std::isfinite(radius)) {
    return absl::InvalidArgumentError(
        absl::StrFormat("icosphere radius must be > 0, got %g", radius));
  }
  const double t = (1.0 + std::sqrt(5.0)) / 2.0;
  std::vector<Eigen::Vector3d> pts = {{-1, t, 0}, {1, t, 0}, {-1, -t, 0}, {1, -t, 0},
                                      {0, -1, t}, {0, 1, t}, {0, -1, -t}, {0, 1, -t},
                                      {t, 0, -1}, {t, 0, 1}, {-t, 0, -1}, {-t, 0, 1}};
  for (auto& p : pts) p.normalize();
  std::vector<Eigen::Vector3i> tris = {{0, 11, 5}, {0, 5, 1},  {0, 1, 7},   {0, 7, 10}, {0, 10, 11},
                                       {1, 5, 9},  {5, 11, 4}, {11, 10, 2}, {10, 7, 6}, {7, 1, 8},
                                       {3, 9, 4},  {3, 4, 2},  {3, 2, 6},   {3, 6, 8},  {3, 8, 9},
                                       {4, 9, 5},  {2, 4, 11}, {6, 2, 10},  {8, 6, 7},  {9, 8, 1}};
  for (int32_t s = 0; s < subdivisions; ++s) {
    std::unordered_map<uint64_t, int32_t> midpoint;
    midpoint.reserve(tris.size() * 2);
    auto mid = [&](int32_t a, int32_t b) {
      const uint64_t key = (static_cast<uint64_t>(std::min(a, b)) << 32) | std::max(a, b);
      auto [it, inserted] = midpoint.try_emplace(key, static_cast<int32_t>(pts.size()));
      if (inserted) pts.push_back((pts[a] + pts[b]).normalized());
      return it->second;
    };
    std::vector<Eigen::Vector3i> next;
    next.reserve(tris.size() * 4);
    for (const auto& f : tris) {
      const int32_t ab = mid(f[0], f[1]), bc = mid(f[1], f[2]), ca = mid(f[2], f[0]);
      next.emplace_back(f[0], ab, ca);
      next.emplace_back(f[1], bc, ab);
      next.emplace_back(f[2], ca, bc);
      next.emplace_back(ab, bc, ca);
    }
    tris.swap(next);
  }
  for (auto& p : pts) p *= radius;
  return Compact(pts, tris);
}

absl::StatusOr<MeshArrays> MakeTorus(double major_radius, double minor_radius,
                                     int32_t major_segments, int32_t minor_segments) {
  if (absl::Status s = CheckTorusRadii(major_radius, minor_radius); !s.ok()) return s;
  if (major_segments < 3 || minor_segments < 3 ||
      int64_t{major_segments} * minor_segments > (int64_t{1} << 24)) {
    return absl::InvalidArgumentError(
        absl::StrFormat("torus segments must be >= 3 and their product <= 2^24, got %d x %d",
                        major_segments, minor_segments));
  }
  return TorusGrid(major_radius, minor_radius, major_segments, minor_segments, false);
}

absl::StatusOr<MeshArrays> MakeTorusKnot(const TorusKnotOptions& o) {
  if (o.p < 1 || o.q < 1 || std::gcd(o.p, o.q) != 1) {
    return absl::InvalidArgumentError(
        absl::StrFormat("torus knot needs coprime p, q >= 1, got (%d, %d)", o.p, o.q));
  }
  if (!(o.tube_radius > 0) || !(o.minor_radius > 0) || !(o.major_radius > o.minor_radius) ||
      !std::isfinite(o.major_radius)) {
    return absl::InvalidArgumentError("torus knot radii must satisfy 0 < r < R and tube > 0");
  }
  if (o.segments < 3 || o.tube_segments < 3 ||
      int64_t{o.segments} * o.tube_segments > (int64_t{1} << 24)) {
    return absl::InvalidArgumentError(
        absl::StrFormat("torus knot segments must be >= 3 and their product <= 2^24, got %d x %d",
                        o.segments, o.tube_segments));
  }
  std::vector<Eigen::Vector3d> pts;
  pts.reserve(int64_t{o.segments} * o.tube_segments);
  for (int32_t i = 0; i < o.segments; ++i) {
    const double t = 2 * kPi * i / o.segments;
    const double cp = std::cos(o.p * t), sp = std::sin(o.p * t);
    const double cq = std::cos(o.q * t), sq = std::sin(o.q * t);
    const double rho = o.major_radius + o.minor_radius * cq;
    const Eigen::Vector3d c(rho * cp, rho * sp, o.minor_radius * sq);
    // The knot lies on the torus, so the torus normal at c is orthogonal to the knot's tangent:
    // a periodic frame with no closure twist.
    const Eigen::Vector3d tangent =
        Eigen::Vector3d(-o.p * rho * sp - o.q * o.minor_radius * sq * cp,
                        o.p * rho * cp - o.q * o.minor_radius * sq * sp, o.q * o.minor_radius * cq)
            .normalized();
    const Eigen::Vector3d normal(cq * cp, cq * sp, sq);
    const Eigen::Vector3d binormal = tangent.cross(normal);
    for (int32_t j = 0; j < o.tube_segments; ++j) {
      const double s = 2 * kPi * j / o.tube_segments;
      pts.push_back(c + o.tube_radius * (std::cos(s) * normal + std::sin(s) * binormal));
    }
  }
  std::vector<Eigen::Vector3i> tris;
  auto id = [&](int32_t i, int32_t j) {
    return (i % o.segments) * o.tube_segments + (j % o.tube_segments);
  };
  for (int32_t i = 0; i < o.segments; ++i) {
    for (int32_t j = 0; j < o.tube_segments; ++j) {
      AddQuad(tris, id(i, j), id(i, j + 1), id(i + 1, j + 1), id(i + 1, j));
    }
  }
  return Compact(pts, tris);
}

absl::StatusOr<MeshArrays> MakeGenusSurface(int32_t genus, int32_t resolution) {
  if (absl::Status s = CheckPlate("genus", genus, resolution); !s.ok()) return s;
  // Plate of (2g + 1) x 3 unit squares; hole i is the unit square [2i + 1, 2i + 2] x [1, 2].
  const int32_t nx = (2 * genus + 1) * resolution, ny = 3 * resolution;
  const int32_t nz = std::max(1, resolution / 2);  // wall layers over thickness 0.5
  const double h = 1.0 / resolution, thickness = 0.5;
  auto solid = [&](int32_t i, int32_t j) { return PlateCellIsSolid(genus, resolution, i, j); };
  const int32_t columns = (nx + 1) * (ny + 1);
  std::vector<Eigen::Vector3d> pts(int64_t{columns} * (nz + 1));
  for (int32_t l = 0; l <= nz; ++l) {
    for (int32_t j = 0; j <= ny; ++j) {
      for (int32_t i = 0; i <= nx; ++i) {
        pts[int64_t{l} * columns + j * (nx + 1) + i] =
            Eigen::Vector3d(i * h, j * h, -thickness / 2 + thickness * l / nz);
      }
    }
  }
  auto id = [&](int32_t i, int32_t j, int32_t l) { return l * columns + j * (nx + 1) + i; };
  std::vector<Eigen::Vector3i> tris;
  for (int32_t j = 0; j < ny; ++j) {
    for (int32_t i = 0; i < nx; ++i) {
      if (!solid(i, j)) continue;
      // Top (seen from +z) and bottom (reversed).
      AddQuad(tris, id(i, j, nz), id(i + 1, j, nz), id(i + 1, j + 1, nz), id(i, j + 1, nz));
      AddQuad(tris, id(i, j, 0), id(i, j + 1, 0), id(i + 1, j + 1, 0), id(i + 1, j, 0));
      // Walls along sides whose neighbour cell is empty; each side p -> q runs counter-clockwise
      // around this cell, so the solid is on its left and the wall faces right (outward).
      const int32_t corners[4][2] = {{i, j}, {i + 1, j}, {i + 1, j + 1}, {i, j + 1}};
      const int32_t neighbour[4][2] = {{i, j - 1}, {i + 1, j}, {i, j + 1}, {i - 1, j}};
      for (int s = 0; s < 4; ++s) {
        if (solid(neighbour[s][0], neighbour[s][1])) continue;
        const auto* p = corners[s];
        const auto* q = corners[(s + 1) % 4];
        for (int32_t l = 0; l < nz; ++l) {
          AddQuad(tris, id(p[0], p[1], l), id(q[0], q[1], l), id(q[0], q[1], l + 1),
                  id(p[0], p[1], l + 1));
        }
      }
    }
  }
  return Compact(pts, tris);
}

absl::StatusOr<MeshArrays> MakeNonUniformSphere(int32_t subdivisions, double pull) {
  if (!(pull >= 0 && pull <= 0.9)) {
    return absl::InvalidArgumentError(
        absl::StrFormat("non-uniform sphere pull must be in [0, 0.9], got %g", pull));
  }
  absl::StatusOr<MeshArrays> sphere = MakeIcosphere(subdivisions, 1.0);
  if (!sphere.ok()) return sphere.status();
  for (Eigen::Index v = 0; v < sphere->vertices.rows(); ++v) {
    Eigen::Vector3d p = sphere->vertices.row(v);
    p.z() += pull;
    sphere->vertices.row(v) = p.normalized();
  }
  return sphere;
}

absl::StatusOr<MeshArrays> MakeStaggeredTorus(double major_radius, double minor_radius,
                                              int32_t major_segments, int32_t minor_segments) {
  if (absl::Status s = CheckTorusRadii(major_radius, minor_radius); !s.ok()) return s;
  if (absl::Status s = CheckSegments("staggered torus", major_segments, minor_segments, 4);
      !s.ok()) {
    return s;
  }
  if (minor_segments % 2 != 0) {
    return absl::InvalidArgumentError(
        absl::StrFormat("staggered torus minor segments must be even, got %d", minor_segments));
  }
  return TorusGrid(major_radius, minor_radius, major_segments, minor_segments, true);
}

absl::StatusOr<MeshArrays> PerturbVertices(const MeshArrays& mesh, double amplitude,
                                           uint64_t seed) {
  if (!(amplitude >= 0 && amplitude <= 0.4)) {
    return absl::InvalidArgumentError(
        absl::StrFormat("perturbation amplitude must be in [0, 0.4], got %g", amplitude));
  }
  const Eigen::Index nv = mesh.vertices.rows();
  std::vector<double> shortest(static_cast<size_t>(nv), std::numeric_limits<double>::infinity());
  for (Eigen::Index f = 0; f < mesh.faces.rows(); ++f) {
    for (int k = 0; k < 3; ++k) {
      const int32_t a = mesh.faces(f, k), b = mesh.faces(f, (k + 1) % 3);
      if (a < 0 || b < 0 || a >= nv || b >= nv) {
        return absl::InvalidArgumentError(
            absl::StrFormat("face %d: vertex index out of range", static_cast<int64_t>(f)));
      }
      const double len = (mesh.vertices.row(a) - mesh.vertices.row(b)).norm();
      shortest[a] = std::min(shortest[a], len);
      shortest[b] = std::min(shortest[b], len);
    }
  }
  // mt19937_64's sequence is fixed by the standard; the distributions of <random> are not.
  std::mt19937_64 rng(seed);
  auto uniform = [&] { return static_cast<double>(rng() >> 11) * 0x1.0p-52 - 1.0; };  // [-1, 1)
  MeshArrays out = mesh;
  for (Eigen::Index v = 0; v < nv; ++v) {
    if (!std::isfinite(shortest[v])) continue;  // unreferenced
    Eigen::Vector3d d;
    do {
      d = Eigen::Vector3d(uniform(), uniform(), uniform());
    } while (d.squaredNorm() > 1.0);
    out.vertices.row(v) += amplitude * shortest[v] * d.transpose();
  }
  return out;
}

absl::StatusOr<MeshArrays> MakeCylinder(double radius, double height, int32_t around,
                                        int32_t along) {
  if (!(radius > 0) || !(height > 0) || !std::isfinite(radius) || !std::isfinite(height)) {
    return absl::InvalidArgumentError(
        absl::StrFormat("cylinder radius and height must be > 0, got %g and %g", radius, height));
  }
  if (absl::Status s = CheckSegments("cylinder", around, along, 1); !s.ok()) return s;
  std::vector<Eigen::Vector3d> pts;
  for (int32_t j = 0; j <= along; ++j) {
    for (int32_t i = 0; i < around; ++i) {
      const double u = 2 * kPi * i / around;
      pts.emplace_back(radius * std::cos(u), radius * std::sin(u), height * j / along);
    }
  }
  std::vector<Eigen::Vector3i> tris;
  auto id = [&](int32_t i, int32_t j) { return j * around + i % around; };
  for (int32_t j = 0; j < along; ++j) {
    for (int32_t i = 0; i < around; ++i) {
      AddQuad(tris, id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1));
    }
  }
  return Compact(pts, tris);
}

absl::StatusOr<MeshArrays> MakePolarDisk(int32_t rings, int32_t segments) {
  if (absl::Status s = CheckSegments("polar disk", segments, rings, 1); !s.ok()) return s;
  std::vector<Eigen::Vector3d> pts = {Eigen::Vector3d::Zero()};
  for (int32_t k = 1; k <= rings; ++k) {
    for (int32_t s = 0; s < segments; ++s) {
      const double u = 2 * kPi * s / segments, r = static_cast<double>(k) / rings;
      pts.emplace_back(r * std::cos(u), r * std::sin(u), 0.0);
    }
  }
  auto id = [&](int32_t k, int32_t s) { return 1 + (k - 1) * segments + s % segments; };
  std::vector<Eigen::Vector3i> tris;
  for (int32_t s = 0; s < segments; ++s) tris.emplace_back(0, id(1, s), id(1, s + 1));
  for (int32_t k = 1; k < rings; ++k) {
    for (int32_t s = 0; s < segments; ++s) {
      AddQuad(tris, id(k, s), id(k + 1, s), id(k + 1, s + 1), id(k, s + 1));
    }
  }
  return Compact(pts, tris);
}

absl::StatusOr<MeshArrays> MakePerforatedPlate(int32_t holes, int32_t resolution) {
  if (absl::Status s = CheckPlate("holes", holes, resolution); !s.ok()) return s;
  const int32_t nx = (2 * holes + 1) * resolution, ny = 3 * resolution;
  const double h = 1.0 / resolution;
  std::vector<Eigen::Vector3d> pts;
  for (int32_t j = 0; j <= ny; ++j) {
    for (int32_t i = 0; i <= nx; ++i) pts.emplace_back(i * h, j * h, 0.0);
  }
  auto id = [&](int32_t i, int32_t j) { return j * (nx + 1) + i; };
  std::vector<Eigen::Vector3i> tris;
  for (int32_t j = 0; j < ny; ++j) {
    for (int32_t i = 0; i < nx; ++i) {
      if (PlateCellIsSolid(holes, resolution, i, j)) {
        AddQuad(tris, id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1));
      }
    }
  }
  return Compact(pts, tris);
}

}  // namespace fieldspace
