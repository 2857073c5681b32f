#include "core/basis/dual_graph.h"

#include <cmath>

#include "absl/strings/str_format.h"

namespace fieldspace {

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
  g.offsets.resize(static_cast<size_t>(nf) + 1);
  g.offsets[0] = 0;
  for (int32_t f = 0; f < nf; ++f) {
    int32_t degree = 0;
    for (int k = 0; k < 3; ++k) degree += FN(f, k) != kNoFace;
    g.offsets[f + 1] = g.offsets[f] + degree;
  }
  g.targets.resize(g.offsets[nf]);
  g.lengths.resize(g.offsets[nf]);
  for (int32_t f = 0; f < nf; ++f) {
    int32_t a = g.offsets[f];
    for (int k = 0; k < 3; ++k) {
      const int32_t h = FN(f, k);
      if (h == kNoFace) continue;
      double length = (bc.row(f) - bc.row(h)).norm();
      if (weighted) length *= 0.5 * (face_weights[f] + face_weights[h]);
      g.targets[a] = h;
      g.lengths[a] = length;
      ++a;
    }
  }
  return g;
}

}  // namespace fieldspace
