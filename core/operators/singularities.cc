#include "core/operators/singularities.h"

#include <algorithm>
#include <cmath>
#include <numbers>

#include "Eigen/Core"
#include "Eigen/Geometry"
#include "absl/status/status.h"
#include "absl/strings/str_format.h"
#include "core/operators/edge_transport.h"
#include "tbb/blocked_range.h"
#include "tbb/parallel_for.h"

namespace fieldspace {
namespace {

constexpr double kTwoPi = 2.0 * std::numbers::pi;
// How far a closed fan's sum may be from an integer (in units of 1/n turns) before it is an
// error: the terms are exact rotations up to rounding, so the sum is off by ~1e-15 per edge.
constexpr double kIntegerTolerance = 1e-6;

absl::Status Validate(const TriangleMesh& mesh, const Eigen::Ref<const Eigen::VectorXd>& dofs,
                      const SingularityOptions& options) {
  if (options.n < 1 || options.n > 64) {
    return absl::InvalidArgumentError(
        absl::StrFormat("singularities: n = %d outside [1, 64]", options.n));
  }
  if (!std::isfinite(options.zero_tolerance) || options.zero_tolerance < 0.0 ||
      options.zero_tolerance >= 1.0) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "singularities: zero_tolerance = %g outside [0, 1)", options.zero_tolerance));
  }
  const int64_t expected = 2 * int64_t{mesh.num_faces()};
  if (dofs.size() != expected) {
    return absl::InvalidArgumentError(
        absl::StrFormat("singularities: %d DOFs, expected 2 per face = %d", dofs.size(), expected));
  }
  for (int64_t i = 0; i < dofs.size(); ++i) {
    if (!std::isfinite(dofs[i])) {
      return absl::InvalidArgumentError(
          absl::StrFormat("singularities: non-finite DOF %d of face %d", i % 2, i / 2));
    }
  }
  return absl::OkStatus();
}

}  // namespace

absl::StatusOr<VertexIndices> ComputeVertexIndices(const TriangleMesh& mesh,
                                                   const Eigen::Ref<const Eigen::VectorXd>& dofs,
                                                   const SingularityOptions& options) {
  if (absl::Status s = Validate(mesh, dofs, options); !s.ok()) return s;
  // Indices depend on directions only. A field whose products below would overflow to inf and
  // then NaN (|u| beyond ~1e150) or underflow (below ~1e-150) is rescaled by its largest
  // magnitude first.
  const double max_abs = dofs.size() > 0 ? dofs.cwiseAbs().maxCoeff() : 0.0;
  if (max_abs > 1e150 || (max_abs > 0 && max_abs < 1e-150)) {
    const Eigen::VectorXd scaled = dofs / max_abs;
    return ComputeVertexIndices(mesh, scaled, options);
  }
  const int32_t nf = mesh.num_faces(), ne = mesh.num_edges(), nv = mesh.num_vertices();
  const int32_t n = options.n;
  const FaceMatrix& F = mesh.faces();
  const FaceMatrix& FE = mesh.face_edges();
  const PairMatrix& EF = mesh.edge_faces();
  const VertexMatrix& V = mesh.vertices();

  // Zero faces: no direction (squared norms: no hypot, which is slow).
  auto norm2 = [&](int32_t f) {
    return dofs[2 * f] * dofs[2 * f] + dofs[2 * f + 1] * dofs[2 * f + 1];
  };
  double max_norm2 = 0.0;
  for (int32_t f = 0; f < nf; ++f) max_norm2 = std::max(max_norm2, norm2(f));
  const double zero_norm2 = options.zero_tolerance * options.zero_tolerance * max_norm2;
  std::vector<uint8_t> zero_face(nf);
  for (int32_t f = 0; f < nf; ++f) {
    // Without a tolerance only exact zeros (a squared norm could underflow for tiny vectors).
    zero_face[f] = options.zero_tolerance == 0.0 ? dofs[2 * f] == 0.0 && dofs[2 * f + 1] == 0.0
                                                 : norm2(f) <= zero_norm2;
  }

  // Per interior edge between nonzero faces: omega_e, the rotation from f1 to f0 relative to the
  // transport, in representation angles; and the vertex p with p -> q counter-clockwise in f0
  // (the walk around p crosses e from f1 to f0, the walk around q from f0 to f1).
  const EdgeTransport transport = ComputeEdgeTransport(mesh);
  std::vector<double> omega(ne, 0.0);
  std::vector<int32_t> tail(ne, -1);  // p; -1 for boundary edges and edges at zero faces
  tbb::parallel_for(tbb::blocked_range<int32_t>(0, ne, 4096),
                    [&](const tbb::blocked_range<int32_t>& r) {
                      for (int32_t e = r.begin(); e != r.end(); ++e) {
                        const int32_t f0 = EF(e, 0), f1 = EF(e, 1);
                        if (f1 == kNoFace || zero_face[f0] || zero_face[f1]) continue;
                        double cr, ci;
                        TransportPower(transport.edges[e], n, &cr, &ci);
                        // t = R(n delta) u_f1 in f0's frame; omega = arg(u_f0 conj(t)).
                        const double a0 = dofs[2 * f0], b0 = dofs[2 * f0 + 1];
                        const double a1 = dofs[2 * f1], b1 = dofs[2 * f1 + 1];
                        const double tr = cr * a1 - ci * b1, ti = ci * a1 + cr * b1;
                        double w = std::atan2(b0 * tr - a0 * ti, a0 * tr + b0 * ti);
                        if (w == -std::numbers::pi) w = std::numbers::pi;  // atan2(-0, x < 0)
                        omega[e] = w;
                        int k = 0;
                        while (FE(f0, k) != e) ++k;
                        tail[e] = F(f0, (k + 1) % 3);
                      }
                    });

  // Corner angles, atan2(|a x b|, a . b) (accurate for any angle).
  std::vector<double> corner_angle(3 * int64_t{nf});
  tbb::parallel_for(
      tbb::blocked_range<int32_t>(0, nf, 4096), [&](const tbb::blocked_range<int32_t>& r) {
        for (int32_t f = r.begin(); f != r.end(); ++f) {
          for (int k = 0; k < 3; ++k) {
            const Eigen::Vector3d p = V.row(F(f, k)).transpose();
            const Eigen::Vector3d a = V.row(F(f, (k + 1) % 3)).transpose() - p;
            const Eigen::Vector3d b = V.row(F(f, (k + 2) % 3)).transpose() - p;
            corner_angle[3 * int64_t{f} + k] = std::atan2(a.cross(b).norm(), a.dot(b));
          }
        }
      });

  // Per-vertex sums in a fixed order (independent of the thread count).
  std::vector<double> rotation(nv, 0.0), angle_sum(nv, 0.0);
  std::vector<uint8_t> boundary(nv, 0), undefined(nv, 0);
  for (int32_t e = 0; e < ne; ++e) {
    const int32_t a = mesh.edges()(e, 0), b = mesh.edges()(e, 1);
    if (EF(e, 1) == kNoFace) {
      boundary[a] = boundary[b] = 1;
      continue;
    }
    if (tail[e] < 0) continue;
    const int32_t p = tail[e], q = p == a ? b : a;
    rotation[p] += omega[e];
    rotation[q] -= omega[e];
  }
  for (int32_t f = 0; f < nf; ++f) {
    for (int k = 0; k < 3; ++k) {
      const int32_t v = F(f, k);
      angle_sum[v] += corner_angle[3 * int64_t{f} + k];
      if (zero_face[f]) undefined[v] = 1;
    }
  }

  VertexIndices out;
  out.n = n;
  out.kind.resize(nv);
  out.index.assign(nv, 0);
  out.value.assign(nv, 0.0);
  for (int32_t v = 0; v < nv; ++v) {
    if (undefined[v]) {
      out.kind[v] = VertexIndexKind::kUndefined;
      continue;
    }
    const double defect = (boundary[v] ? std::numbers::pi : kTwoPi) - angle_sum[v];
    const double x = (rotation[v] + n * defect) / kTwoPi;
    if (boundary[v]) {
      out.kind[v] = VertexIndexKind::kBoundary;
      out.value[v] = x;
      continue;
    }
    const double r = std::round(x);
    if (std::abs(x - r) > kIntegerTolerance) {
      return absl::InternalError(absl::StrFormat(
          "singularities: vertex %d sums to %.12g (1/n turns), not an integer", v, x));
    }
    out.kind[v] = VertexIndexKind::kInterior;
    out.index[v] = static_cast<int32_t>(r);
    out.value[v] = r;
  }
  return out;
}

absl::StatusOr<Singularities> ComputeSingularities(const TriangleMesh& mesh,
                                                   const Eigen::Ref<const Eigen::VectorXd>& dofs,
                                                   const SingularityOptions& options) {
  absl::StatusOr<VertexIndices> indices = ComputeVertexIndices(mesh, dofs, options);
  if (!indices.ok()) return indices.status();
  Singularities out;
  out.n = indices->n;
  const double n = indices->n;
  for (int32_t v = 0; v < static_cast<int32_t>(indices->kind.size()); ++v) {
    switch (indices->kind[v]) {
      case VertexIndexKind::kInterior:
        out.index_sum += indices->index[v];
        if (indices->index[v] != 0) {
          out.singularities.push_back({v, indices->index[v], indices->index[v] / n});
        }
        break;
      case VertexIndexKind::kBoundary:
        out.boundary.push_back({v, indices->value[v], indices->value[v] / n});
        break;
      case VertexIndexKind::kUndefined:
        out.undefined_vertices.push_back(v);
        break;
    }
  }
  return out;
}

absl::StatusOr<std::vector<IndexChange>> DiffVertexIndices(const VertexIndices& before,
                                                           const VertexIndices& after) {
  if (before.n != after.n) {
    return absl::InvalidArgumentError(
        absl::StrFormat("singularities diff: n = %d before, %d after", before.n, after.n));
  }
  if (before.kind.size() != after.kind.size() || before.index.size() != before.kind.size() ||
      after.index.size() != after.kind.size()) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "singularities diff: %d vertices before, %d after", before.kind.size(), after.kind.size()));
  }
  std::vector<IndexChange> changes;
  for (int32_t v = 0; v < static_cast<int32_t>(before.kind.size()); ++v) {
    if (before.kind[v] != after.kind[v] || before.index[v] != after.index[v]) {
      changes.push_back({v, before.kind[v], after.kind[v], before.index[v], after.index[v]});
    }
  }
  return changes;
}

}  // namespace fieldspace
