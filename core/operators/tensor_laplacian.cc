#include "core/operators/tensor_laplacian.h"

#include <cmath>

#include "core/operators/edge_transport.h"
#include "core/operators/face_block_assembly.h"

namespace fieldspace {

Eigen::Matrix3d MandelVoigtTransport(const Eigen::Matrix2d& G) {
  const double g1 = G(0, 0), g2 = G(0, 1), g3 = G(1, 0), g4 = G(1, 1);
  const double r2 = std::sqrt(2.0);
  Eigen::Matrix3d P;
  P << g1 * g1, g3 * g3, r2 * g1 * g3,  //
      g2 * g2, g4 * g4, r2 * g2 * g4,   //
      r2 * g1 * g2, r2 * g3 * g4, g1 * g4 + g2 * g3;
  return P;
}

absl::StatusOr<Eigen::SparseMatrix<double>> BuildTensorStiffness(const TriangleMesh& mesh) {
  const EdgeTransport transport = ComputeEdgeTransport(mesh);
  auto transport_fn = [&](int32_t e, double* T) {
    // R_f maps frame-f coordinates to edge-aligned ones (the edge direction (cos t, sin t) goes to
    // (1, 0)): R_f = R(-theta_f). Transport from f1 to f0 (appendix): A -> G^T A G with
    // G = R_f1^T R_f0 = R(theta_1 - theta_0) = [[c, s], [-s, c]], (c, s) = e^{i (theta_0 -
    // theta_1)}.
    const double c = transport.edges[e].cos_delta, s = transport.edges[e].sin_delta;
    Eigen::Matrix2d G;
    G << c, s, -s, c;
    const Eigen::Matrix3d P = MandelVoigtTransport(G);
    for (int c = 0; c < 3; ++c) {
      for (int d = 0; d < 3; ++d) T[3 * c + d] = P(c, d);
    }
  };
  return operators_internal::AssembleConnectionLaplacian<3>(mesh, transport, transport_fn);
}

}  // namespace fieldspace
