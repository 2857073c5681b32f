#include "core/operators/edge_transport.h"

#include <algorithm>
#include <cmath>

#include "Eigen/Core"
#include "core/operators/complex_power.h"
#include "tbb/blocked_range.h"
#include "tbb/parallel_for.h"

namespace fieldspace {
namespace {

// Edges ahead whose (randomly placed) vertex and face rows are prefetched.
constexpr int32_t kPrefetchDistance = 16;

}  // namespace

EdgeTransport::Edge EdgeTransportOf(const TriangleMesh& mesh, int32_t e) {
  EdgeTransport::Edge out;
  const int32_t f0 = mesh.edge_faces()(e, 0), f1 = mesh.edge_faces()(e, 1);
  if (f1 == kNoFace) return out;  // no transport, weight 0
  const VertexMatrix& V = mesh.vertices();
  const VertexMatrix& X = mesh.frame_x();
  const VertexMatrix& Y = mesh.frame_y();
  const Eigen::VectorXd& area = mesh.face_areas();
  // edges() stores (a, b) with a < b: the lower-to-higher orientation.
  const Eigen::Vector3d d = (V.row(mesh.edges()(e, 1)) - V.row(mesh.edges()(e, 0))).transpose();
  const double len2 = d.squaredNorm();
  // The unit edge vector lies in both faces' planes, so its frame coordinates are unit vectors up
  // to rounding; normalize so the transport is an exact rotation.
  double c0 = d.dot(X.row(f0).transpose()), s0 = d.dot(Y.row(f0).transpose());
  double c1 = d.dot(X.row(f1).transpose()), s1 = d.dot(Y.row(f1).transpose());
  const double n0 = 1.0 / std::sqrt(c0 * c0 + s0 * s0);
  const double n1 = 1.0 / std::sqrt(c1 * c1 + s1 * s1);
  c0 *= n0;
  s0 *= n0;
  c1 *= n1;
  s1 *= n1;
  out.weight = 3.0 * len2 / (area[f0] + area[f1]);
  // e^{i theta_0} conj(e^{i theta_1}).
  out.cos_delta = c0 * c1 + s0 * s1;
  out.sin_delta = s0 * c1 - c0 * s1;
  return out;
}

EdgeTransport ComputeEdgeTransport(const TriangleMesh& mesh) {
  const int32_t ne = mesh.num_edges();
  EdgeTransport t;
  t.edges.resize(ne);
  const VertexMatrix& V = mesh.vertices();
  const VertexMatrix& X = mesh.frame_x();
  const VertexMatrix& Y = mesh.frame_y();
  const PairMatrix& E = mesh.edges();
  const PairMatrix& EF = mesh.edge_faces();
  const Eigen::VectorXd& area = mesh.face_areas();
  auto prefetch = [&](int32_t e) {
    __builtin_prefetch(&V(E(e, 0), 0));
    __builtin_prefetch(&V(E(e, 1), 0));
    for (int s = 0; s < 2; ++s) {
      const int32_t f = EF(e, s);
      if (f == kNoFace) continue;
      __builtin_prefetch(&X(f, 0));
      __builtin_prefetch(&Y(f, 0));
      __builtin_prefetch(&area[f]);
    }
  };
  tbb::parallel_for(
      tbb::blocked_range<int32_t>(0, ne, 4096), [&](const tbb::blocked_range<int32_t>& r) {
        for (int32_t e = r.begin(); e < std::min(r.end(), r.begin() + kPrefetchDistance); ++e) {
          prefetch(e);
        }
        for (int32_t e = r.begin(); e != r.end(); ++e) {
          if (e + kPrefetchDistance < r.end()) prefetch(e + kPrefetchDistance);
          t.edges[e] = EdgeTransportOf(mesh, e);
        }
      });
  return t;
}

void TransportPower(const EdgeTransport::Edge& edge, int32_t n, double* cos_out, double* sin_out) {
  const Eigen::Vector2d p = UnitComplexPower({edge.cos_delta, edge.sin_delta}, n);
  *cos_out = p[0];
  *sin_out = p[1];
}

}  // namespace fieldspace
