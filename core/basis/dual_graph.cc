#include "core/basis/dual_graph.h"

#include <cmath>
#include <numeric>

#include "absl/strings/str_format.h"
#include "tbb/parallel_sort.h"

namespace fieldspace {
namespace {

// Spreads the low 21 bits of x so that there are two zero bits between consecutive bits.
uint64_t SpreadBits(uint64_t x) {
  x &= 0x1fffff;
  x = (x | x << 32) & 0x1f00000000ffffull;
  x = (x | x << 16) & 0x1f0000ff0000ffull;
  x = (x | x << 8) & 0x100f00f00f00f00full;
  x = (x | x << 4) & 0x10c30c30c30c30c3ull;
  x = (x | x << 2) & 0x1249249249249249ull;
  return x;
}

}  // namespace

absl::StatusOr<DualGraph> BuildDualGraph(const TriangleMesh& mesh,
                                         const Eigen::VectorXd& face_weights) {
  const int32_t nf = mesh.num_faces();
  const bool weighted = face_weights.size() > 0;
  if (weighted) {
    if (face_weights.size() != nf) {
      return absl::InvalidArgumentError(absl::StrFormat(
          "face_weights has %d entries; the mesh has %d faces (one weight per face, or none)",
          face_weights.size(), nf));
    }
    for (int32_t f = 0; f < nf; ++f) {
      const double w = face_weights[f];
      if (!std::isfinite(w) || !(w > 0.0)) {
        return absl::InvalidArgumentError(absl::StrFormat(
            "face_weights[%d] = %g; adaptivity weights must be finite and > 0", f, w));
      }
    }
  }
  const FaceMatrix& FN = mesh.face_neighbors();
  const VertexMatrix& bc = mesh.face_barycenters();
  DualGraph g;
  g.num_nodes = nf;
  // Morton order of the barycenters in their bounding box (ties by face index).
  Eigen::RowVector3d lo = bc.colwise().minCoeff();
  Eigen::RowVector3d hi = bc.colwise().maxCoeff();
  const double extent = std::max((hi - lo).maxCoeff(), 1e-300);
  std::vector<std::pair<uint64_t, int32_t>> keys(nf);
  for (int32_t f = 0; f < nf; ++f) {
    uint64_t code = 0;
    for (int a = 0; a < 3; ++a) {
      const double t = (bc(f, a) - lo[a]) / extent;
      const uint64_t q = static_cast<uint64_t>(std::clamp(t, 0.0, 1.0) * 2097151.0);
      code |= SpreadBits(q) << a;
    }
    keys[f] = {code, f};
  }
  tbb::parallel_sort(keys.begin(), keys.end());
  g.node_face.resize(nf);
  g.face_node.resize(nf);
  for (int32_t v = 0; v < nf; ++v) {
    g.node_face[v] = keys[v].second;
    g.face_node[keys[v].second] = v;
  }
  g.arcs.resize(3 * static_cast<size_t>(nf));
  for (int32_t v = 0; v < nf; ++v) {
    const int32_t f = g.node_face[v];
    for (int k = 0; k < 3; ++k) {
      const int32_t h = FN(f, k);
      DualArc& arc = g.arcs[3 * static_cast<size_t>(v) + k];
      if (h == kNoFace) continue;
      double length = (bc.row(f) - bc.row(h)).norm();
      if (weighted) length *= 0.5 * (face_weights[f] + face_weights[h]);
      arc.target = g.face_node[h];
      arc.length = length;
    }
  }
  return g;
}

}  // namespace fieldspace
