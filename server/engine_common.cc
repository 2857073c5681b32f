// Engine pieces that need no numerics: sizes, memory estimates, weight validation.

#include <cmath>

#include "absl/strings/str_cat.h"
#include "server/engine.h"

namespace fieldspace::server {

int32_t ValuesPerFace(const FieldType& type, ValueEncoding encoding) {
  if (encoding == ValueEncoding::kDof) return type.dofs_per_face();
  return type.kind == FieldKind::kTensor ? 6 : 3;
}

int64_t MeshBytes(const TriangleMesh& mesh) {
  const int64_t v = mesh.num_vertices(), f = mesh.num_faces(), e = mesh.num_edges();
  // vertices; faces, face_edges, face_neighbors; edges, edge_faces; areas, components; normals,
  // barycenters, frame x and y.
  return v * 24 + f * 12 * 3 + e * 8 * 2 + f * (8 + 4) + f * 24 * 4;
}

int64_t BasisBytes(const Basis& basis) {
  const int64_t nnz = basis.U.nonZeros();
  return nnz * (sizeof(float) + sizeof(int)) + (basis.U.outerSize() + 1) * sizeof(int) +
         static_cast<int64_t>(basis.local_eigenvalues.size() * sizeof(double) +
                              basis.sample_faces.size() * sizeof(int32_t)) +
         basis.params.face_weights.size() * static_cast<int64_t>(sizeof(double));
}

absl::Status ValidateWeights(const ModelWeights& w) {
  for (double v : {w.mu_s, w.mu_b, w.mu_c}) {
    if (!std::isfinite(v) || v < 0) {
      return absl::InvalidArgumentError(absl::StrCat("weights must be finite and >= 0, got mu_s=",
                                                     w.mu_s, " mu_b=", w.mu_b, " mu_c=", w.mu_c));
    }
  }
  if (w.mu_s == 0 && w.mu_b == 0) {
    return absl::InvalidArgumentError(
        "at least one of mu_s and mu_b must be > 0 (otherwise the energy does not determine the "
        "field away from the constraints)");
  }
  return absl::OkStatus();
}

}  // namespace fieldspace::server
