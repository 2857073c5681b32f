#ifndef FIELDSPACE_CORE_OPERATORS_TENSOR_LAPLACIAN_H_
#define FIELDSPACE_CORE_OPERATORS_TENSOR_LAPLACIAN_H_

#include "Eigen/Core"
#include "Eigen/SparseCore"
#include "absl/status/statusor.h"
#include "core/mesh/triangle_mesh.h"

namespace fieldspace {

// The 3 x 3 matrix P of appendix eq. 18: for a 2 x 2 matrix G and a symmetric 2 x 2 tensor A with
// Mandel-Voigt vector a = (a11, a22, sqrt(2) a12) (eq. 15), P a is the Mandel-Voigt vector of
// G^T A G. Orthogonal when G is a rotation.
Eigen::Matrix3d MandelVoigtTransport(const Eigen::Matrix2d& G);

// Stiffness of the symmetric (1,1)-tensor Laplacian (paper eq. 2 and 20, appendix eqs. 14-20):
//   x^T S x = sum over interior edges e = (f0, f1) of w_e |a_f0 - P_{f1->f0} a_f1|^2,
// with the weights of the n-field Laplacian and P_{f1->f0} = MandelVoigtTransport(G),
// G = R_f1^T R_f0, R_f the rotation from frame-f coordinates to the coordinates aligned with e
// (x along e's unit vector oriented from its lower to its higher vertex index).
// Returns S: 3F x 3F, DOF 3f + c (Mandel-Voigt in face f's frame), sparse, exactly symmetric,
// positive semi-definite. It decouples into a scalar face Laplacian on the trace part
// (a11 + a22) / sqrt(2) and the n = 2 Laplacian on ((a11 - a22) / sqrt(2), sqrt(2) a12).
absl::StatusOr<Eigen::SparseMatrix<double>> BuildTensorStiffness(const TriangleMesh& mesh);

}  // namespace fieldspace

#endif  // FIELDSPACE_CORE_OPERATORS_TENSOR_LAPLACIAN_H_
