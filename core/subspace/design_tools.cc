#include "core/subspace/design_tools.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <complex>
#include <limits>
#include <numbers>
#include <optional>
#include <queue>
#include <unordered_map>
#include <utility>

#include "Eigen/Geometry"
#include "absl/strings/str_format.h"
#include "core/common/status_macros.h"
#include "core/operators/conversions.h"
#include "core/operators/edge_transport.h"
#include "tbb/blocked_range.h"
#include "tbb/parallel_reduce.h"

namespace fieldspace {
namespace {

constexpr double kTwoPi = 2.0 * std::numbers::pi;
constexpr double kBarycentricTolerance = 1e-9;

Eigen::Vector3d Vertex(const TriangleMesh& mesh, int32_t v) {
  return mesh.vertices().row(v).transpose();
}

absl::Status ValidateKindAndWeight(ConstraintKind kind, double weight, const char* tool) {
  if (kind == ConstraintKind::kSoft && !(std::isfinite(weight) && weight > 0)) {
    return absl::InvalidArgumentError(
        absl::StrFormat("%s: weight %g must be finite and > 0", tool, weight));
  }
  return absl::OkStatus();
}

absl::Status ValidateType(const FieldType& type, const char* tool) {
  if (absl::Status st = type.Validate(); !st.ok()) {
    return absl::InvalidArgumentError(absl::StrFormat("%s: %s", tool, st.message()));
  }
  return absl::OkStatus();
}

// Per-face sums of length-weighted directions, as DOFs: the tools' values are means of their
// pieces in each face. Faces in order of first touch.
class DirectionSums {
 public:
  DirectionSums(const TriangleMesh& mesh, const FieldType& type, double anisotropy = 1.0)
      : mesh_(mesh), type_(type), anisotropy_(anisotropy) {}

  // Adds direction `d` (3D, any length > 0; projected to the face) with weight `length`.
  absl::Status Add(int32_t face, const Eigen::Vector3d& d, double length) {
    if (!(length > 0)) return absl::OkStatus();
    const Eigen::Vector3d n = mesh_.face_normals().row(face).transpose();
    Eigen::Vector3d t = d - d.dot(n) * n;
    const double norm = t.norm();
    if (!(norm > 0)) return absl::OkStatus();
    t /= norm;
    Eigen::MatrixXd value;
    if (type_.kind == FieldKind::kTensor) {
      const Eigen::Vector3d across = n.cross(t);
      const Eigen::Matrix3d A =
          t * t.transpose() + (1.0 - anisotropy_) * across * across.transpose();
      value = Eigen::Map<const Eigen::Matrix<double, 1, 9>>(A.data());
    } else {
      value = t.transpose();
    }
    const int32_t faces[] = {face};
    ASSIGN_OR_RETURN(Eigen::VectorXd dofs, DofsFromAmbient(mesh_, type_, faces, value));
    auto [it, inserted] = index_.try_emplace(face, static_cast<int32_t>(faces_.size()));
    if (inserted) {
      faces_.push_back(face);
      sums_.push_back(Eigen::VectorXd::Zero(type_.dofs_per_face()));
      lengths_.push_back(0.0);
    }
    sums_[it->second] += length * dofs;
    lengths_[it->second] += length;
    return absl::OkStatus();
  }

  // One constraint per face: the mean (unit length for vector and n-fields), weight times the
  // face's share of the total length relative to the mean. Faces whose pieces cancel are left
  // out. InvalidArgument when nothing is left.
  absl::StatusOr<std::vector<FieldConstraint>> Constraints(ConstraintKind kind, double weight,
                                                           const char* tool) const {
    double total = 0;
    for (double l : lengths_) total += l;
    std::vector<FieldConstraint> out;
    if (!(total > 0)) {
      return absl::InvalidArgumentError(absl::StrFormat("%s: touches no face", tool));
    }
    const double mean = total / static_cast<double>(faces_.size());
    for (size_t i = 0; i < faces_.size(); ++i) {
      Eigen::VectorXd mean_value = sums_[i] / lengths_[i];
      // Pieces that nearly cancel have no direction.
      constexpr double kCancelled = 1e-3;
      if (!(mean_value.norm() > kCancelled)) continue;
      if (type_.kind != FieldKind::kTensor) mean_value.normalize();
      FieldConstraint c;
      c.face = faces_[i];
      c.value = std::move(mean_value);
      c.weight = weight * lengths_[i] / mean;
      c.kind = kind;
      out.push_back(std::move(c));
    }
    if (out.empty()) {
      return absl::InvalidArgumentError(
          absl::StrFormat("%s: its directions cancel in every face it touches", tool));
    }
    return out;
  }

 private:
  const TriangleMesh& mesh_;
  FieldType type_;
  double anisotropy_;
  std::unordered_map<int32_t, int32_t> index_;
  std::vector<int32_t> faces_;
  std::vector<Eigen::VectorXd> sums_;
  std::vector<double> lengths_;
};

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

// The edge shared by faces f and g (neighbours), or -1.
int32_t SharedEdge(const TriangleMesh& mesh, int32_t f, int32_t g) {
  for (int k = 0; k < 3; ++k) {
    if (mesh.face_neighbors()(f, k) == g) return mesh.face_edges()(f, k);
  }
  return -1;
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

// The faces around interior vertex v, counter-clockwise from `start` (a face at v); empty for a
// boundary vertex.
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

// Signed angle defect at interior vertex v: 2 pi - sum of its corner angles, the corner angles
// as ComputeVertexIndices takes them (atan2(|a x b|, a . b)).
double AngleDefect(const TriangleMesh& mesh, const std::vector<int32_t>& fan, int32_t v) {
  double sum = 0;
  for (int32_t f : fan) {
    int k = 0;
    while (mesh.faces()(f, k) != v) ++k;
    const Eigen::Vector3d p = Vertex(mesh, v);
    const Eigen::Vector3d a = Vertex(mesh, mesh.faces()(f, (k + 1) % 3)) - p;
    const Eigen::Vector3d b = Vertex(mesh, mesh.faces()(f, (k + 2) % 3)) - p;
    sum += std::atan2(a.cross(b).norm(), a.dot(b));
  }
  return kTwoPi - sum;
}

}  // namespace

absl::Status ValidateSurfacePoint(const TriangleMesh& mesh, const SurfacePoint& point) {
  if (point.face < 0 || point.face >= mesh.num_faces()) {
    return absl::InvalidArgumentError(absl::StrFormat("surface point: face %d out of range [0, %d)",
                                                      point.face, mesh.num_faces()));
  }
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
  const Best best = tbb::parallel_reduce(
      tbb::blocked_range<int32_t>(0, mesh.num_faces(), 8192), Best{},
      [&](const tbb::blocked_range<int32_t>& r, Best acc) {
        for (int32_t f = r.begin(); f != r.end(); ++f) {
          const Eigen::Vector3d a = Vertex(mesh, mesh.faces()(f, 0));
          const Eigen::Vector3d b = Vertex(mesh, mesh.faces()(f, 1));
          const Eigen::Vector3d c = Vertex(mesh, mesh.faces()(f, 2));
          const Eigen::Vector3d w = ClosestBarycentric(p, a, b, c);
          const Best here{(w[0] * a + w[1] * b + w[2] * c - p).squaredNorm(), f};
          if (better(here, acc)) acc = here;
        }
        return acc;
      },
      [&](const Best& x, const Best& y) { return better(y, x) ? y : x; });
  const int32_t f = best.face;
  return SurfacePoint{
      f, ClosestBarycentric(p, Vertex(mesh, mesh.faces()(f, 0)), Vertex(mesh, mesh.faces()(f, 1)),
                            Vertex(mesh, mesh.faces()(f, 2)))};
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

absl::StatusOr<std::vector<FieldConstraint>> StrokeConstraints(
    const TriangleMesh& mesh, const FieldType& type, absl::Span<const SurfacePoint> points,
    const StrokeOptions& options) {
  RETURN_IF_ERROR(ValidateType(type, "stroke"));
  RETURN_IF_ERROR(ValidateKindAndWeight(options.kind, options.weight, "stroke"));
  if (type.kind == FieldKind::kTensor && !(options.anisotropy > 0 && options.anisotropy <= 1)) {
    return absl::InvalidArgumentError(
        absl::StrFormat("stroke: anisotropy %g must be in (0, 1]", options.anisotropy));
  }
  if (points.size() < 2) {
    return absl::InvalidArgumentError(
        absl::StrFormat("stroke: needs at least 2 points, got %d", points.size()));
  }
  DirectionSums sums(mesh, type, options.anisotropy);
  for (size_t i = 0; i + 1 < points.size(); ++i) {
    ASSIGN_OR_RETURN(std::vector<PathSegment> path,
                     ShortestSurfacePath(mesh, points[i], points[i + 1]));
    for (const PathSegment& s : path) {
      RETURN_IF_ERROR(sums.Add(s.face, s.b - s.a, (s.b - s.a).norm()));
    }
  }
  return sums.Constraints(options.kind, options.weight, "stroke");
}

int32_t NearestCorner(const TriangleMesh& mesh, const SurfacePoint& point) {
  int k = 0;
  point.barycentric.maxCoeff(&k);
  return mesh.faces()(point.face, k);
}

absl::StatusOr<std::vector<FieldConstraint>> SingularityConstraints(
    const TriangleMesh& mesh, const FieldType& type, int32_t vertex, double turns,
    const PlacedSingularityOptions& options) {
  RETURN_IF_ERROR(ValidateType(type, "singularity"));
  RETURN_IF_ERROR(ValidateKindAndWeight(options.kind, options.weight, "singularity"));
  if (type.kind == FieldKind::kTensor) {
    return absl::InvalidArgumentError(
        "singularity: indices are defined for vector and n-fields, not tensors");
  }
  if (vertex < 0 || vertex >= mesh.num_vertices()) {
    return absl::InvalidArgumentError(absl::StrFormat("singularity: vertex %d out of range [0, %d)",
                                                      vertex, mesh.num_vertices()));
  }
  const int32_t n = type.kind == FieldKind::kNField ? type.n : 1;
  const double units = turns * n;
  const double k = std::round(units);
  if (!std::isfinite(turns) || std::abs(units - k) > 1e-9 * std::max(1.0, std::abs(units))) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "singularity: index %g turns is not a multiple of 1/%d (the field's symmetry)", turns, n));
  }
  // The fan, counter-clockwise from the lowest face at v (deterministic).
  int32_t start = -1;
  for (int32_t f = 0; f < mesh.num_faces() && start < 0; ++f) {
    for (int c = 0; c < 3; ++c) {
      if (mesh.faces()(f, c) == vertex) start = f;
    }
  }
  const std::vector<int32_t> fan = VertexFan(mesh, vertex, start);
  if (fan.empty()) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "singularity: vertex %d is on the boundary (indices are defined at interior vertices)",
        vertex));
  }
  const int32_t m = static_cast<int32_t>(fan.size());
  const double defect = AngleDefect(mesh, fan, vertex);
  const double s = (kTwoPi * k - n * defect) / m;
  constexpr double kMaxStep = std::numbers::pi * (1 - 1e-6);
  if (!(std::abs(s) < kMaxStep)) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "singularity: index %g turns needs the field to turn %.1f degrees (representation "
        "angle) between neighbouring faces of vertex %d's %d faces; at most 180",
        turns, s * 180 / std::numbers::pi, vertex, m));
  }
  const EdgeTransport transport = ComputeEdgeTransport(mesh);
  std::vector<FieldConstraint> out;
  std::complex<double> u(1.0, 0.0);
  const std::complex<double> step = std::polar(1.0, s);
  for (int32_t j = 0; j < m; ++j) {
    FieldConstraint c;
    c.face = fan[j];
    c.value = Eigen::Vector2d(u.real(), u.imag());
    c.weight = options.weight;
    c.kind = options.kind;
    out.push_back(std::move(c));
    if (j + 1 == m) break;
    // T maps representation vectors of fan[j] to fan[j + 1]: TransportPower maps f1's to f0's.
    const int32_t e = SharedEdge(mesh, fan[j], fan[j + 1]);
    double cr, ci;
    TransportPower(transport.edges[e], n, &cr, &ci);
    std::complex<double> T(cr, ci);
    if (mesh.edge_faces()(e, 1) == fan[j + 1]) T = std::conj(T);  // fan[j] is f1: the inverse
    u = step * T * u;
    u /= std::abs(u);
  }
  return out;
}

absl::StatusOr<std::vector<FieldConstraint>> BoundaryAlignmentConstraints(
    const TriangleMesh& mesh, const FieldType& type, const BoundaryAlignmentOptions& options) {
  RETURN_IF_ERROR(ValidateType(type, "boundary alignment"));
  RETURN_IF_ERROR(ValidateKindAndWeight(options.kind, options.weight, "boundary alignment"));
  const auto& loops = mesh.boundary_loops();
  if (loops.empty()) {
    return absl::FailedPreconditionError("boundary alignment: the mesh has no boundary");
  }
  std::vector<char> chosen(loops.size(), options.loops.empty() ? 1 : 0);
  for (int32_t l : options.loops) {
    if (l < 0 || l >= static_cast<int32_t>(loops.size())) {
      return absl::InvalidArgumentError(
          absl::StrFormat("boundary alignment: loop %d out of range [0, %d)", l, loops.size()));
    }
    chosen[l] = 1;
  }
  std::vector<int32_t> loop_of(mesh.num_vertices(), -1);
  for (size_t l = 0; l < loops.size(); ++l) {
    for (int32_t v : loops[l]) loop_of[v] = static_cast<int32_t>(l);
  }
  DirectionSums sums(mesh, type);
  for (int32_t f = 0; f < mesh.num_faces(); ++f) {
    for (int k = 0; k < 3; ++k) {
      if (mesh.face_neighbors()(f, k) != kNoFace) continue;
      const int32_t a = mesh.faces()(f, (k + 1) % 3), b = mesh.faces()(f, (k + 2) % 3);
      if (!chosen[loop_of[a]]) continue;
      const Eigen::Vector3d t = Vertex(mesh, b) - Vertex(mesh, a);
      const Eigen::Vector3d normal = mesh.face_normals().row(f).transpose();
      const Eigen::Vector3d d = options.mode == BoundaryAlignment::kTangent ? t : t.cross(normal);
      RETURN_IF_ERROR(sums.Add(f, d, t.norm()));
    }
  }
  return sums.Constraints(options.kind, options.weight, "boundary alignment");
}

std::vector<int32_t> SharpEdges(const TriangleMesh& mesh, double angle_degrees) {
  const double cos_max = std::cos(angle_degrees * std::numbers::pi / 180);
  std::vector<int32_t> out;
  for (int32_t e = 0; e < mesh.num_edges(); ++e) {
    const int32_t f0 = mesh.edge_faces()(e, 0), f1 = mesh.edge_faces()(e, 1);
    if (f1 == kNoFace) continue;
    if (mesh.face_normals().row(f0).dot(mesh.face_normals().row(f1)) < cos_max) out.push_back(e);
  }
  return out;
}

absl::StatusOr<std::vector<FieldConstraint>> FeatureAlignmentConstraints(
    const TriangleMesh& mesh, const FieldType& type, const FeatureAlignmentOptions& options) {
  RETURN_IF_ERROR(ValidateType(type, "feature alignment"));
  RETURN_IF_ERROR(ValidateKindAndWeight(options.kind, options.weight, "feature alignment"));
  if (!(options.angle_degrees > 0 && options.angle_degrees < 180)) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "feature alignment: angle_degrees %g must be in (0, 180)", options.angle_degrees));
  }
  const std::vector<int32_t> sharp = SharpEdges(mesh, options.angle_degrees);
  if (sharp.empty()) {
    return absl::FailedPreconditionError(absl::StrFormat(
        "feature alignment: no edge has a dihedral angle above %g degrees", options.angle_degrees));
  }
  // Orient the sharp edges along their chains: walk from every chain end (a vertex not on exactly
  // two sharp edges), then around the closed chains that remain.
  std::unordered_map<int32_t, std::vector<int32_t>> at;  // vertex -> sharp edges
  for (int32_t e : sharp) {
    at[mesh.edges()(e, 0)].push_back(e);
    at[mesh.edges()(e, 1)].push_back(e);
  }
  std::unordered_map<int32_t, int32_t> tail;  // sharp edge -> the vertex it starts at
  const auto walk = [&](int32_t v, int32_t e) {
    while (!tail.count(e) > 0) {
      tail[e] = v;
      v = mesh.edges()(e, 0) == v ? mesh.edges()(e, 1) : mesh.edges()(e, 0);
      const std::vector<int32_t>& next = at[v];
      if (next.size() != 2) return;
      e = next[0] == e ? next[1] : next[0];
    }
  };
  std::vector<int32_t> ends;
  for (const auto& [v, edges] : at) {
    if (edges.size() != 2) ends.push_back(v);
  }
  std::sort(ends.begin(), ends.end());  // deterministic
  for (int32_t v : ends) {
    for (int32_t e : at[v]) walk(v, e);
  }
  for (int32_t e : sharp) walk(mesh.edges()(e, 0), e);
  DirectionSums sums(mesh, type);
  for (int32_t e : sharp) {
    const int32_t a = tail[e];
    const int32_t b = mesh.edges()(e, 0) == a ? mesh.edges()(e, 1) : mesh.edges()(e, 0);
    const Eigen::Vector3d d = Vertex(mesh, b) - Vertex(mesh, a);
    for (int s = 0; s < 2; ++s) RETURN_IF_ERROR(sums.Add(mesh.edge_faces()(e, s), d, d.norm()));
  }
  return sums.Constraints(options.kind, options.weight, "feature alignment");
}

}  // namespace fieldspace
