#include "core/mesh/surface_path.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <optional>
#include <queue>
#include <utility>

#include "Eigen/Geometry"
#include "absl/strings/str_format.h"
#include "core/common/index_check.h"
#include "core/common/status_macros.h"
#include "tbb/blocked_range.h"
#include "tbb/parallel_reduce.h"

namespace fieldspace {
namespace {

constexpr double kBarycentricTolerance = 1e-9;

Eigen::Vector3d Vertex(const TriangleMesh& mesh, int32_t v) {
  return mesh.vertices().row(v).transpose();
}

// The closest point of triangle (a, b, c) to p, as barycentric coordinates (Ericson, "Real-Time
// Collision Detection", 5.1.5).
Eigen::Vector3d ClosestBarycentric(const Eigen::Vector3d& p, const Eigen::Vector3d& a,
                                   const Eigen::Vector3d& b, const Eigen::Vector3d& c) {
  const Eigen::Vector3d ab = b - a, ac = c - a, ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0 && d2 <= 0) return {1, 0, 0};
  const Eigen::Vector3d bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0 && d4 <= d3) return {0, 1, 0};
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) {
    const double v = d1 / (d1 - d3);
    return {1 - v, v, 0};
  }
  const Eigen::Vector3d cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0 && d5 <= d6) return {0, 0, 1};
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) {
    const double w = d2 / (d2 - d6);
    return {1 - w, 0, w};
  }
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) {
    const double w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
    return {0, 1 - w, w};
  }
  const double denom = 1.0 / (va + vb + vc);
  const double v = vb * denom, w = vc * denom;
  return {1 - v - w, v, w};
}

// Faces of a shortest dual-graph path from `from` to `to` (both included), by A* with the
// straight-line distance between barycenters (a lower bound of any path's length).
absl::StatusOr<std::vector<int32_t>> DualPath(const TriangleMesh& mesh, int32_t from, int32_t to) {
  if (mesh.face_component()(from) != mesh.face_component()(to)) {
    return absl::InvalidArgumentError(
        absl::StrFormat("stroke: faces %d and %d are on different connected components", from, to));
  }
  const VertexMatrix& C = mesh.face_barycenters();
  auto dist = [&](int32_t f, int32_t g) { return (C.row(f) - C.row(g)).norm(); };
  using Item = std::pair<double, int32_t>;  // (estimate, face)
  std::priority_queue<Item, std::vector<Item>, std::greater<Item>> open;
  std::unordered_map<int32_t, std::pair<double, int32_t>> best;  // face -> (cost, parent)
  best[from] = {0.0, -1};
  open.push({dist(from, to), from});
  while (!open.empty()) {
    const auto [estimate, f] = open.top();
    open.pop();
    const double cost = best[f].first;
    if (estimate > cost + dist(f, to) + 1e-12 * (1 + estimate)) continue;  // stale
    if (f == to) break;
    for (int k = 0; k < 3; ++k) {
      const int32_t g = mesh.face_neighbors()(f, k);
      if (g == kNoFace) continue;
      const double c = cost + dist(f, g);
      auto [it, inserted] = best.try_emplace(g, c, f);
      if (!inserted) {
        if (c >= it->second.first) continue;
        it->second = {c, f};
      }
      open.push({c + dist(g, to), g});
    }
  }
  std::vector<int32_t> path;
  for (int32_t f = to; f != -1; f = best.at(f).second) path.push_back(f);
  std::reverse(path.begin(), path.end());
  return path;
}

// A strip of faces (consecutive ones sharing an edge) and the shortest polyline through it from
// x.front() (in faces.front()) to x.back() (in faces.back()): x[i] (0 < i < faces.size()) on
// the edge between faces[i - 1] and faces[i], `at_vertex[i]` the vertex it sits on, or -1.
struct Strip {
  std::vector<int32_t> faces;
  std::vector<Eigen::Vector3d> x;
  std::vector<int32_t> at_vertex;
  double length = 0;
};

double Cross2(const Eigen::Vector2d& u, const Eigen::Vector2d& v) {
  return u[0] * v[1] - u[1] * v[0];
}

// The shortest polyline through the strip, exactly: the strip unfolded into the plane face by
// face (each face's third vertex placed across the shared edge from the previous face's), then
// the funnel algorithm (Lee and Preparata 1984) on its portals, O(#faces) amortized.
Strip Straighten(const TriangleMesh& mesh, std::vector<int32_t> faces, const Eigen::Vector3d& p,
                 const Eigen::Vector3d& q) {
  Strip s;
  const int32_t m = static_cast<int32_t>(faces.size()) - 1;  // portals (edges crossed)
  s.faces = std::move(faces);
  // Unfolding: corner positions of the current face, by vertex id.
  std::array<std::pair<int32_t, Eigen::Vector2d>, 3> face2d;
  const auto corner = [&](int32_t v) -> const Eigen::Vector2d& {
    for (const auto& [id, x] : face2d) {
      if (id == v) return x;
    }
    return face2d[0].second;  // unreachable: v is a corner of the face
  };
  {
    const int32_t f = s.faces[0];
    const Eigen::Vector3d a = Vertex(mesh, mesh.faces()(f, 0)),
                          b = Vertex(mesh, mesh.faces()(f, 1));
    const Eigen::Vector3d c = Vertex(mesh, mesh.faces()(f, 2));
    const Eigen::Vector3d ex = (b - a).normalized();
    const Eigen::Vector3d ey = mesh.face_normals().row(f).transpose().cross(ex);
    face2d = {{{mesh.faces()(f, 0), Eigen::Vector2d::Zero()},
               {mesh.faces()(f, 1), Eigen::Vector2d((b - a).norm(), 0)},
               {mesh.faces()(f, 2), Eigen::Vector2d((c - a).dot(ex), (c - a).dot(ey))}}};
  }
  const auto in_face = [&](int32_t f, const Eigen::Vector3d& x) {
    const Eigen::Vector3d w =
        ClosestBarycentric(x, Vertex(mesh, mesh.faces()(f, 0)), Vertex(mesh, mesh.faces()(f, 1)),
                           Vertex(mesh, mesh.faces()(f, 2)));
    return Eigen::Vector2d(w[0] * corner(mesh.faces()(f, 0)) + w[1] * corner(mesh.faces()(f, 1)) +
                           w[2] * corner(mesh.faces()(f, 2)));
  };
  // Portals 0..m + 1: the start point, the shared edges (left and right as seen walking from
  // face i - 1 into face i), the end point.
  struct Portal {
    Eigen::Vector2d left, right;
    int32_t left_vertex = -1, right_vertex = -1;
  };
  std::vector<Portal> portal(m + 2);
  portal[0].left = portal[0].right = in_face(s.faces[0], p);
  for (int32_t i = 1; i <= m; ++i) {
    const int32_t e = SharedEdge(mesh, s.faces[i - 1], s.faces[i]);
    const int32_t a = mesh.edges()(e, 0), b = mesh.edges()(e, 1);
    int32_t behind = -1;  // the previous face's third vertex
    for (int k = 0; k < 3; ++k) {
      const int32_t v = mesh.faces()(s.faces[i - 1], k);
      if (v != a && v != b) behind = v;
    }
    const Eigen::Vector2d pa = corner(a), pb = corner(b), pbehind = corner(behind);
    // Walking away from `behind`: b is on the left when `behind` is left of a -> b.
    const bool b_left = Cross2(pb - pa, pbehind - pa) > 0;
    portal[i] = b_left ? Portal{pb, pa, b, a} : Portal{pa, pb, a, b};
    // The next face's third vertex, across a -> b from `behind`.
    const int32_t f = s.faces[i];
    int32_t c = -1;
    for (int k = 0; k < 3; ++k) {
      const int32_t v = mesh.faces()(f, k);
      if (v != a && v != b) c = v;
    }
    const Eigen::Vector3d a3 = Vertex(mesh, a), b3 = Vertex(mesh, b), c3 = Vertex(mesh, c);
    const Eigen::Vector3d u3 = (b3 - a3).normalized();
    const double along = (c3 - a3).dot(u3), height = (c3 - a3 - along * u3).norm();
    const Eigen::Vector2d u = (pb - pa).normalized();
    Eigen::Vector2d perp(-u[1], u[0]);
    if (Cross2(pb - pa, pbehind - pa) > 0) perp = -perp;
    face2d = {{{a, pa}, {b, pb}, {c, pa + along * u + height * perp}}};
  }
  portal[m + 1].left = portal[m + 1].right = in_face(s.faces[m], q);

  // Funnel: apex, and the cone of directions through every portal since the apex, bounded by
  // the left and right endpoints that last narrowed it.
  std::vector<std::pair<Eigen::Vector2d, int32_t>> corners = {
      {portal[0].left, 0}};  // (point, portal)
  std::vector<int32_t> corner_vertex = {-1};
  Eigen::Vector2d apex = portal[0].left, left = apex, right = apex;
  int32_t apex_index = 0, left_index = 0, right_index = 0;
  for (int32_t i = 1; i <= m + 1; ++i) {
    const Portal& g = portal[i];
    // Right side: narrow, or the portal passes left of the cone (bend around its left corner).
    // (A cone side still at the apex bounds nothing; bends move the apex forward only.)
    if (Cross2(right - apex, g.right - apex) >= 0) {
      if (apex == right || left_index == apex_index || Cross2(left - apex, g.right - apex) < 0) {
        right = g.right;
        right_index = i;
      } else {
        apex = left;
        apex_index = left_index;
        if (apex_index == m + 1) break;  // the end point itself: done
        corners.push_back({apex, apex_index});
        corner_vertex.push_back(portal[apex_index].left_vertex);
        left = right = apex;
        left_index = right_index = apex_index;
        i = apex_index;
        continue;
      }
    }
    if (Cross2(left - apex, g.left - apex) <= 0) {
      if (apex == left || right_index == apex_index || Cross2(right - apex, g.left - apex) > 0) {
        left = g.left;
        left_index = i;
      } else {
        apex = right;
        apex_index = right_index;
        if (apex_index == m + 1) break;  // the end point itself: done
        corners.push_back({apex, apex_index});
        corner_vertex.push_back(portal[apex_index].right_vertex);
        left = right = apex;
        left_index = right_index = apex_index;
        i = apex_index;
        continue;
      }
    }
  }
  corners.push_back({portal[m + 1].left, m + 1});
  corner_vertex.push_back(-1);

  // Crossing points: where the polyline between consecutive corners meets each portal.
  s.x.resize(m + 2);
  s.at_vertex.assign(m + 2, -1);
  s.x[0] = p;
  s.x[m + 1] = q;
  for (size_t c = 0; c + 1 < corners.size(); ++c) {
    const auto& [from, from_index] = corners[c];
    const auto& [to, to_index] = corners[c + 1];
    if (c > 0) {
      s.x[from_index] = Vertex(mesh, corner_vertex[c]);
      s.at_vertex[from_index] = corner_vertex[c];
    }
    for (int32_t i = from_index + 1; i < to_index; ++i) {
      const Portal& g = portal[i];
      // from + t (to - from) on the line through the portal: its parameter along the portal.
      const Eigen::Vector2d d = to - from, e = g.left - g.right;
      const double denom = Cross2(d, e);
      double t = std::abs(denom) > 0 ? Cross2(d, from - g.right) / denom : 0.5;
      t = std::clamp(t, 0.0, 1.0);
      s.x[i] = Vertex(mesh, g.right_vertex) +
               t * (Vertex(mesh, g.left_vertex) - Vertex(mesh, g.right_vertex));
    }
  }
  for (int32_t i = 0; i <= m; ++i) s.length += (s.x[i + 1] - s.x[i]).norm();
  // Crossings on a vertex (the corners, and the portals around them, to rounding).
  for (int32_t i = 1; i <= m; ++i) {
    for (int32_t v : {portal[i].left_vertex, portal[i].right_vertex}) {
      if ((s.x[i] - Vertex(mesh, v)).norm() <= 1e-9 * (1 + s.length)) s.at_vertex[i] = v;
    }
  }
  return s;
}

// The strip with its first run of crossings at one (interior) vertex v, from crossing `*first`
// on, replaced by the other way around v's fan (and *first moved past that run); nullopt when no
// crossing from there on sits on a vertex that can be passed the other way.
std::optional<std::vector<int32_t>> RerouteAroundVertex(const TriangleMesh& mesh,
                                                        const Strip& strip, int32_t* first) {
  const int32_t m = static_cast<int32_t>(strip.faces.size()) - 1;
  for (int32_t i = std::max(*first, 1); i <= m; ++i) {
    const int32_t v = strip.at_vertex[i];
    if (v < 0) continue;
    int32_t j = i;
    while (j + 1 <= m && strip.at_vertex[j + 1] == v) ++j;
    // faces[i - 1 .. j] go around v one way; the other way goes from faces[i - 1] to faces[j]
    // through the rest of the fan.
    const std::vector<int32_t> fan = VertexFan(mesh, v, strip.faces[i - 1]);
    if (fan.empty()) {
      i = j;
      continue;
    }
    const bool counter_clockwise = fan.size() > 1 && fan[1] == strip.faces[i];
    std::vector<int32_t> around;  // from faces[i - 1] (excluded) to faces[j] (excluded)
    const int32_t k = static_cast<int32_t>(fan.size());
    for (int32_t step = 1; step < k; ++step) {
      const int32_t f = fan[counter_clockwise ? k - step : step];
      if (f == strip.faces[j]) break;
      around.push_back(f);
    }
    std::vector<int32_t> faces(strip.faces.begin(), strip.faces.begin() + i);
    faces.insert(faces.end(), around.begin(), around.end());
    faces.insert(faces.end(), strip.faces.begin() + j, strip.faces.end());
    *first = j + 1;
    return faces;
  }
  return std::nullopt;
}

}  // namespace

int32_t SharedEdge(const TriangleMesh& mesh, int32_t f, int32_t g) {
  for (int k = 0; k < 3; ++k) {
    if (mesh.face_neighbors()(f, k) == g) return mesh.face_edges()(f, k);
  }
  return -1;
}

std::vector<int32_t> VertexFan(const TriangleMesh& mesh, int32_t v, int32_t start) {
  std::vector<int32_t> fan;
  for (int32_t f = start;;) {
    fan.push_back(f);
    int c = 0;
    while (mesh.faces()(f, c) != v) ++c;
    // Across the edge (v, corner c + 2).
    const int32_t next = mesh.face_neighbors()(f, (c + 1) % 3);
    if (next == kNoFace) return {};
    if (next == start) return fan;
    f = next;
  }
}

absl::Status ValidateSurfacePoint(const TriangleMesh& mesh, const SurfacePoint& point) {
  RETURN_IF_ERROR(CheckFace(point.face, mesh.num_faces(), "surface point"));
  const Eigen::Vector3d& b = point.barycentric;
  if (!b.allFinite() || b.minCoeff() < -kBarycentricTolerance ||
      b.maxCoeff() > 1 + kBarycentricTolerance || std::abs(b.sum() - 1.0) > kBarycentricTolerance) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "surface point on face %d: barycentric coordinates (%g, %g, %g) must be in [0, 1] and "
        "sum to 1",
        point.face, b[0], b[1], b[2]));
  }
  return absl::OkStatus();
}

Eigen::Vector3d SurfacePosition(const TriangleMesh& mesh, const SurfacePoint& point) {
  Eigen::Vector3d x = Eigen::Vector3d::Zero();
  for (int k = 0; k < 3; ++k) {
    x += point.barycentric[k] * Vertex(mesh, mesh.faces()(point.face, k));
  }
  return x;
}

absl::StatusOr<SurfacePoint> SnapToSurface(const TriangleMesh& mesh, const Eigen::Vector3d& p) {
  if (!p.allFinite()) {
    return absl::InvalidArgumentError(
        absl::StrFormat("surface point (%g, %g, %g) is not finite", p[0], p[1], p[2]));
  }
  struct Best {
    double dist2 = std::numeric_limits<double>::infinity();
    int32_t face = -1;
  };
  const auto better = [](const Best& x, const Best& y) {
    return x.dist2 < y.dist2 || (x.dist2 == y.dist2 && x.face < y.face && x.face >= 0);
  };
  const auto closest = [&](int32_t f) {
    return ClosestBarycentric(p, Vertex(mesh, mesh.faces()(f, 0)), Vertex(mesh, mesh.faces()(f, 1)),
                              Vertex(mesh, mesh.faces()(f, 2)));
  };
  const auto distance2 = [&](int32_t f) {
    const Eigen::Vector3d w = closest(f);
    return (w[0] * Vertex(mesh, mesh.faces()(f, 0)) + w[1] * Vertex(mesh, mesh.faces()(f, 1)) +
            w[2] * Vertex(mesh, mesh.faces()(f, 2)) - p)
        .squaredNorm();
  };
  const VertexMatrix& centers = mesh.face_barycenters();
  const tbb::blocked_range<int32_t> all(0, mesh.num_faces(), 8192);
  const auto reduce = [&](const auto& body) {
    return tbb::parallel_reduce(all, Best{}, body,
                                [&](const Best& x, const Best& y) { return better(y, x) ? y : x; });
  };
  // The nearest barycenter's face bounds the distance: D = its distance to p. A face within D of p
  // has its barycenter within D + max_face_radius, so only those faces (a ball's worth, read in
  // one pass over the contiguous barycenters) take the exact test.
  const Best nearest_center = reduce([&](const tbb::blocked_range<int32_t>& r, Best acc) {
    for (int32_t f = r.begin(); f != r.end(); ++f) {
      const Best here{(centers.row(f).transpose() - p).squaredNorm(), f};
      if (better(here, acc)) acc = here;
    }
    return acc;
  });
  if (nearest_center.face < 0) {
    // Every squared distance overflowed (coordinates beyond ~1e154).
    return absl::InvalidArgumentError(absl::StrFormat(
        "surface point (%g, %g, %g) is too far from the mesh to snap", p[0], p[1], p[2]));
  }
  const Best bound{distance2(nearest_center.face), nearest_center.face};
  // Rounding: the bound is widened by a relative 1e-9 (and the absolute scale of the query).
  const double reach =
      (std::sqrt(bound.dist2) + mesh.max_face_radius()) * (1 + 1e-9) + 1e-12 * p.norm();
  const double reach2 = reach * reach;
  Best best = reduce([&](const tbb::blocked_range<int32_t>& r, Best acc) {
    for (int32_t f = r.begin(); f != r.end(); ++f) {
      if ((centers.row(f).transpose() - p).squaredNorm() > reach2) continue;
      const Best here{distance2(f), f};
      if (better(here, acc)) acc = here;
    }
    return acc;
  });
  if (better(bound, best)) best = bound;  // (it is among the candidates, up to rounding)
  return SurfacePoint{best.face, closest(best.face)};
}

absl::StatusOr<std::vector<PathSegment>> ShortestSurfacePath(const TriangleMesh& mesh,
                                                             const SurfacePoint& from,
                                                             const SurfacePoint& to) {
  RETURN_IF_ERROR(ValidateSurfacePoint(mesh, from));
  RETURN_IF_ERROR(ValidateSurfacePoint(mesh, to));
  ASSIGN_OR_RETURN(std::vector<int32_t> faces, DualPath(mesh, from.face, to.face));
  Strip strip = Straighten(mesh, faces, SurfacePosition(mesh, from), SurfacePosition(mesh, to));
  // Where the taut path touches a vertex, the strip passes it on the wrong side: try the other
  // way around (a shorter path is kept; a convex vertex never lies on a geodesic).
  constexpr int kMaxReroutes = 200;
  int32_t first = 1;  // the first crossing not yet tried
  for (int reroute = 0; reroute < kMaxReroutes; ++reroute) {
    std::optional<std::vector<int32_t>> other = RerouteAroundVertex(mesh, strip, &first);
    if (!other.has_value()) break;
    Strip candidate = Straighten(mesh, *other, strip.x.front(), strip.x.back());
    if (candidate.length < strip.length * (1 - 1e-12)) {
      strip = std::move(candidate);
      first = 1;  // the strip changed: every vertex again
    }
  }
  const int32_t m = static_cast<int32_t>(strip.faces.size()) - 1;
  std::vector<PathSegment> out(m + 1);
  for (int32_t i = 0; i <= m; ++i) out[i] = {strip.faces[i], strip.x[i], strip.x[i + 1]};
  return out;
}

}  // namespace fieldspace
