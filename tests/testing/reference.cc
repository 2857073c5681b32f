#include "tests/testing/reference.h"

#include <cmath>
#include <functional>
#include <limits>
#include <queue>
#include <utility>

namespace fieldspace::testing {

std::vector<double> DualDistances(const TriangleMesh& mesh, int32_t source,
                                  const Eigen::VectorXd& weights) {
  const int32_t nf = mesh.num_faces();
  std::vector<double> dist(nf, std::numeric_limits<double>::infinity());
  using Item = std::pair<double, int32_t>;
  std::priority_queue<Item, std::vector<Item>, std::greater<Item>> pq;
  dist[source] = 0;
  pq.push({0, source});
  while (!pq.empty()) {
    auto [d, f] = pq.top();
    pq.pop();
    if (d > dist[f]) continue;
    for (int k = 0; k < 3; ++k) {
      const int32_t g = mesh.face_neighbors()(f, k);
      if (g == kNoFace) continue;
      double len = (mesh.face_barycenters().row(f) - mesh.face_barycenters().row(g)).norm();
      if (weights.size() > 0) len *= 0.5 * (weights[f] + weights[g]);
      if (d + len < dist[g]) {
        dist[g] = d + len;
        pq.push({dist[g], g});
      }
    }
  }
  return dist;
}

Eigen::MatrixXd DenseRestricted(const FieldOperator& op, const std::vector<int32_t>& faces) {
  const int32_t dpf = op.type.dofs_per_face();
  std::vector<int64_t> dofs;
  for (int32_t f : faces) {
    for (int32_t c = 0; c < dpf; ++c) dofs.push_back(static_cast<int64_t>(dpf) * f + c);
  }
  const Eigen::Index n = static_cast<Eigen::Index>(dofs.size());
  Eigen::MatrixXd S(n, n);
  for (Eigen::Index i = 0; i < n; ++i) {
    for (Eigen::Index j = 0; j < n; ++j) {
      S(i, j) =
          op.stiffness.coeff(dofs[i], dofs[j]) / std::sqrt(op.mass[dofs[i]] * op.mass[dofs[j]]);
    }
  }
  return S;
}

std::vector<int32_t> RegionFaces(const TriangleMesh& mesh, const Basis& basis, int32_t region,
                                 const Eigen::VectorXd& weights) {
  const std::vector<double> dist = DualDistances(mesh, basis.sample_faces[region], weights);
  std::vector<int32_t> faces;
  for (int32_t f = 0; f < mesh.num_faces(); ++f) {
    if (dist[f] <= basis.radius) faces.push_back(f);
  }
  return faces;
}

}  // namespace fieldspace::testing
