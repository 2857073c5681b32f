#include "core/operators/nfield_laplacian.h"

#include <cmath>

#include "absl/strings/str_format.h"
#include "core/operators/edge_transport.h"
#include "core/operators/face_block_assembly.h"

namespace fieldspace {

absl::StatusOr<Eigen::SparseMatrix<double>> BuildNFieldStiffness(const TriangleMesh& mesh,
                                                                 int32_t n) {
  if (n < 1 || n > 64) {
    return absl::InvalidArgumentError(
        absl::StrFormat("n-field Laplacian: n = %d outside [1, 64]", n));
  }
  const EdgeTransport transport = ComputeEdgeTransport(mesh);
  auto rotation = [&](int32_t e, double* T) {
    double pr, pi;
    TransportPower(transport.edges[e], n, &pr, &pi);
    // R(n (theta_0 - theta_1)) maps representation vectors of face f1 to face f0.
    T[0] = pr;
    T[1] = -pi;
    T[2] = pi;
    T[3] = pr;
  };
  return operators_internal::AssembleConnectionLaplacian<2>(mesh, transport, rotation);
}

}  // namespace fieldspace
