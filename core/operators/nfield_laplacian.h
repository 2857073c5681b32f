#ifndef FIELDSPACE_CORE_OPERATORS_NFIELD_LAPLACIAN_H_
#define FIELDSPACE_CORE_OPERATORS_NFIELD_LAPLACIAN_H_

#include <cstdint>

#include "Eigen/SparseCore"
#include "absl/status/statusor.h"
#include "core/mesh/triangle_mesh.h"

namespace fieldspace {

// Stiffness of the face-based n-field connection Laplacian on representation vectors
// (docs/conventions.md, n-field connection Laplacian; [BSEH18]):
//   x^T S x = sum over interior edges e = (f0, f1) of w_e |u_f0 - R(n (theta_f0 - theta_f1))
//   u_f1|^2,
// u_f the representation vector (angle times n, length kept) in face f's frame, theta_f the angle
// of e's unit vector (lower to higher vertex index) in face f's frame, w_e = 3|e|^2 / (A_f0 +
// A_f1). Boundary edges contribute nothing. Returns S: 2F x 2F, DOF 2f + c, sparse (blocks on f and
// its edge neighbors), exactly symmetric, positive semi-definite; S_ff = (sum of w over f's
// interior edges) I, S_f0f1 = -w R. InvalidArgument unless 1 <= n <= 64.
absl::StatusOr<Eigen::SparseMatrix<double>> BuildNFieldStiffness(const TriangleMesh& mesh,
                                                                 int32_t n);

}  // namespace fieldspace

#endif  // FIELDSPACE_CORE_OPERATORS_NFIELD_LAPLACIAN_H_
