#ifndef FIELDSPACE_CORE_OPERATORS_CONVERSIONS_H_
#define FIELDSPACE_CORE_OPERATORS_CONVERSIONS_H_

#include <cstdint>
#include <vector>

#include "Eigen/Core"
#include "absl/status/statusor.h"
#include "absl/types/span.h"
#include "core/mesh/triangle_mesh.h"
#include "core/operators/field_type.h"

namespace fieldspace {

// Conversions between per-face fields in ambient 3D form (what clients send and draw) and the DOF
// representation (frame coordinates; n-field representation vectors; Mandel-Voigt tensors) of
// docs/conventions.md, DOF layout. Ambient input is projected to the face's tangent plane.
// Errors are InvalidArgument: wrong sizes, a face index out of range, a non-finite value (the
// message names the face), an asymmetric tensor, an invalid FieldType.

// One ambient 3D vector per face, row-major (#F x 3, or one row per listed face).
using AmbientVectors = Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor>;
// One symmetric 3 x 3 tensor per face, its 9 entries row-major per row (#F x 9).
using AmbientTensors = Eigen::Matrix<double, Eigen::Dynamic, 9, Eigen::RowMajor>;

// Vector fields: DOF 2f + c = (v . x_f, v . y_f). Back: v = d0 x_f + d1 y_f (tangential).
absl::StatusOr<Eigen::VectorXd> VectorDofsFromAmbient(
    const TriangleMesh& mesh, const Eigen::Ref<const AmbientVectors>& vectors);
absl::StatusOr<AmbientVectors> AmbientFromVectorDofs(const TriangleMesh& mesh,
                                                     const Eigen::Ref<const Eigen::VectorXd>& dofs);

// n-fields from one representative direction per face (any of the n equivalent ones gives the
// same DOFs): the tangential part has angle phi and length r in the face frame; DOFs are
// r (cos n phi, sin n phi). A zero vector gives zero DOFs.
absl::StatusOr<Eigen::VectorXd> NFieldDofsFromAmbient(
    const TriangleMesh& mesh, int32_t n, const Eigen::Ref<const AmbientVectors>& vectors);
// The representative direction: length r = |DOFs|, angle atan2(d1, d0) / n in (-pi/n, pi/n].
absl::StatusOr<AmbientVectors> NFieldRepresentativeFromDofs(
    const TriangleMesh& mesh, int32_t n, const Eigen::Ref<const Eigen::VectorXd>& dofs);
// All n directions: element k is the representative rotated by 2 pi k / n in each face.
absl::StatusOr<std::vector<AmbientVectors>> NFieldDirectionsFromDofs(
    const TriangleMesh& mesh, int32_t n, const Eigen::Ref<const Eigen::VectorXd>& dofs);

// Tensors: the tangential part in face frame coordinates, B = [x y]^T A [x y], as the
// Mandel-Voigt vector (B11, B22, sqrt(2) B12) at 3f + c. Input must be symmetric up to a relative
// 1e-6 (it is symmetrized). Back: A = B11 x x^T + B22 y y^T + B12 (x y^T + y x^T).
absl::StatusOr<Eigen::VectorXd> TensorDofsFromAmbient(
    const TriangleMesh& mesh, const Eigen::Ref<const AmbientTensors>& tensors);
absl::StatusOr<AmbientTensors> AmbientFromTensorDofs(const TriangleMesh& mesh,
                                                     const Eigen::Ref<const Eigen::VectorXd>& dofs);

// Generic form on a list of faces (e.g. constraint faces): `values` has one row per listed face
// with 3 columns (vector, n-field representative) or 9 (tensor); the result holds
// type.dofs_per_face() DOFs per listed face, in list order. Faces may repeat.
absl::StatusOr<Eigen::VectorXd> DofsFromAmbient(const TriangleMesh& mesh, const FieldType& type,
                                                absl::Span<const int32_t> faces,
                                                const Eigen::Ref<const Eigen::MatrixXd>& values);
// Inverse of DofsFromAmbient: one row per listed face, 3 or 9 columns (n-fields: representative).
absl::StatusOr<Eigen::MatrixXd> AmbientFromDofs(const TriangleMesh& mesh, const FieldType& type,
                                                absl::Span<const int32_t> faces,
                                                const Eigen::Ref<const Eigen::VectorXd>& dofs);

// How per-face values travel between processes (fieldspace.v1.FieldEncoding mirrors it).
enum class FieldEncoding : uint8_t {
  kDof = 0,      // 2 (vector, n-field) or 3 (tensor) frame values per face, the DOF layout
  kAmbient = 1,  // 3 (vector; one of the n directions of an n-field) or 6 (tensor: xx yy zz xy
                 // yz zx) per face, projected to the face's tangent plane on input
};

int32_t ValuesPerFace(const FieldType& type, FieldEncoding encoding);

// Values in `encoding` for `faces` (values: faces.size() * ValuesPerFace) to DOFs written at
// dofs[i * dofs_per_face + c] (i the position in `faces`, not the face index). InvalidArgument
// for non-finite values, bad face indices or sizes.
absl::Status ValuesToDofs(const TriangleMesh& mesh, const FieldType& type, FieldEncoding encoding,
                          absl::Span<const int32_t> faces, absl::Span<const double> values,
                          absl::Span<double> dofs);

// The inverse: `dofs` (faces.size() * dofs_per_face) to `out` (faces.size() * ValuesPerFace),
// in float, as values travel on the wire.
absl::Status DofsToValues(const TriangleMesh& mesh, const FieldType& type, FieldEncoding encoding,
                          absl::Span<const int32_t> faces, absl::Span<const double> dofs,
                          absl::Span<float> out);

}  // namespace fieldspace

#endif  // FIELDSPACE_CORE_OPERATORS_CONVERSIONS_H_
