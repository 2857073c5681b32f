#include "core/mesh/shapes.h"

#include <cmath>
#include <cstdint>
#include <numeric>
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
  if (!(minor_radius > 0) || !(major_radius > minor_radius) || !std::isfinite(major_radius)) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "torus radii must satisfy 0 < r < R, got R = %g, r = %g", major_radius, minor_radius));
  }
  if (major_segments < 3 || minor_segments < 3 ||
      int64_t{major_segments} * minor_segments > (int64_t{1} << 24)) {
    return absl::InvalidArgumentError(
        absl::StrFormat("torus segments must be >= 3 and their product <= 2^24, got %d x %d",
                        major_segments, minor_segments));
  }
  std::vector<Eigen::Vector3d> pts;
  pts.reserve(int64_t{major_segments} * minor_segments);
  for (int32_t i = 0; i < major_segments; ++i) {
    const double u = 2 * kPi * i / major_segments;
    for (int32_t j = 0; j < minor_segments; ++j) {
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
      AddQuad(tris, id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1));
    }
  }
  return Compact(pts, tris);
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
  if (genus < 0 || genus > 64) {
    return absl::InvalidArgumentError(absl::StrFormat("genus must be in [0, 64], got %d", genus));
  }
  if (resolution < 1 || resolution > 256) {
    return absl::InvalidArgumentError(
        absl::StrFormat("resolution must be in [1, 256], got %d", resolution));
  }
  // Plate of (2g + 1) x 3 unit squares; hole i is the unit square [2i + 1, 2i + 2] x [1, 2].
  const int32_t nx = (2 * genus + 1) * resolution, ny = 3 * resolution;
  const int32_t nz = std::max(1, resolution / 2);  // wall layers over thickness 0.5
  const double h = 1.0 / resolution, thickness = 0.5;
  auto solid = [&](int32_t i, int32_t j) {
    if (i < 0 || j < 0 || i >= nx || j >= ny) return false;
    if (j < resolution || j >= 2 * resolution) return true;
    const int32_t unit = i / resolution;
    return unit % 2 == 0;  // odd units in the middle row are holes
  };
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

}  // namespace fieldspace
