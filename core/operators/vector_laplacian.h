#ifndef FIELDSPACE_CORE_OPERATORS_VECTOR_LAPLACIAN_H_
#define FIELDSPACE_CORE_OPERATORS_VECTOR_LAPLACIAN_H_

#include "Eigen/SparseCore"
#include "absl/status/statusor.h"
#include "core/mesh/triangle_mesh.h"

namespace fieldspace {

// Stiffness of the discrete Hodge Laplacian on piecewise constant tangent vector fields (paper
// eq. 1, docs/conventions.md, Vector Hodge Laplacian):
//   S = M G_V Mv^-1 G_V^T M + M J G_E Me^-1 G_E^T J^T M,
// G_V (2F x #V) the gradients of the Lagrange hat functions, G_E (2F x #E) those of the
// Crouzeix-Raviart edge functions (grad psi_e = -2 grad phi_k on a face, k opposite e), Mv / Me
// the lumped vertex / CR edge masses (a third of the incident face areas), M = diag(area) per DOF,
// J the 90-degree rotation (a, b) -> (-b, a). All vertices and edges are used.
// Returns S: 2F x 2F, DOF 2f + c (frame coordinates of face f), sparse, symmetric (exactly: both
// triangles are bitwise mirror images), positive semi-definite, kernel = harmonic fields (2g on a
// closed genus-g surface). Row 2f + c couples face f with every face sharing a vertex with it.
//
// Assembled without forming G: for faces f, g sharing vertex v,
//   S_fg += (1 / Mv_v) (area_f grad phi_v|f) (area_g grad phi_v|g)^T,
// and for faces sharing edge e (including f = g) S_fg += (1 / Me_e) t_f t_g^T with t_f the
// edge vector of e in face f (area_f J grad psi_e|f = t_f for e traversed counter-clockwise).
// O(F) time and memory, parallel over faces. ResourceExhausted beyond 2^31 nonzeros.
absl::StatusOr<Eigen::SparseMatrix<double>> BuildVectorHodgeStiffness(const TriangleMesh& mesh);

}  // namespace fieldspace

#endif  // FIELDSPACE_CORE_OPERATORS_VECTOR_LAPLACIAN_H_
