#ifndef FIELDSPACE_CORE_OPERATORS_EDGE_TRANSPORT_H_
#define FIELDSPACE_CORE_OPERATORS_EDGE_TRANSPORT_H_

#include <vector>

#include "core/mesh/triangle_mesh.h"

namespace fieldspace {

// Per-edge data of the face-based connection Laplacians (n-field and tensor; docs/conventions.md,
// Operators).
// For an interior edge e with faces (f0, f1) = mesh.edge_faces().row(e), f0 < f1:
//   weight = w_e = 3 |e|^2 / (area_f0 + area_f1),
//   (cos_delta, sin_delta) = e^{i (theta_f0 - theta_f1)},
// theta_f the angle of e's unit vector (oriented from its lower to its higher vertex index) in
// face f's frame: the rotation that transports frame-f1 coordinates to frame-f0 coordinates.
// Boundary edges have weight 0 and no transport (they carry none).
struct EdgeTransport {
  // One cache-line-friendly record per edge: the assembly reads them in face order, i.e. at
  // random, so one miss per edge instead of one per array.
  struct alignas(32) Edge {
    double weight = 0.0;
    double cos_delta = 1.0;
    double sin_delta = 0.0;
  };
  std::vector<Edge> edges;  // #E
};

// O(#E), parallel.
EdgeTransport ComputeEdgeTransport(const TriangleMesh& mesh);
// One edge's record (e in [0, #E)): what ComputeEdgeTransport stores for it, for callers that
// need a few edges (a vertex's fan).
EdgeTransport::Edge EdgeTransportOf(const TriangleMesh& mesh, int32_t e);

// e^{i n delta} of an edge's transport e^{i delta} by repeated squaring (exact rotations, no
// trigonometry), renormalized against rounding drift: the rotation that maps n-field
// representation vectors of face f1 to face f0. The n-field Laplacian and the singularity
// indices use this one function, so they agree to the last bit.
void TransportPower(const EdgeTransport::Edge& edge, int32_t n, double* cos_out, double* sin_out);

}  // namespace fieldspace

#endif  // FIELDSPACE_CORE_OPERATORS_EDGE_TRANSPORT_H_
