#include "core/subspace/design_tools.h"

#include <algorithm>
#include <cmath>
#include <complex>
#include <numbers>
#include <unordered_map>
#include <utility>

#include "Eigen/Geometry"
#include "absl/strings/str_format.h"
#include "core/common/status_macros.h"
#include "core/operators/conversions.h"
#include "core/operators/edge_transport.h"

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
    TransportPower(EdgeTransportOf(mesh, e), n, &cr, &ci);
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
