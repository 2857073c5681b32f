#ifndef FIELDSPACE_CORE_OPERATORS_CURVATURE_H_
#define FIELDSPACE_CORE_OPERATORS_CURVATURE_H_

#include <cstdint>

#include "Eigen/Core"
#include "absl/status/statusor.h"
#include "core/common/cancel.h"
#include "core/mesh/triangle_mesh.h"
#include "core/operators/conversions.h"

namespace fieldspace {

// Curvature tensors and curvature-aligned n-field targets (paper section 8: tensor smoothing of the
// shape operator, curvature-aligned 4-fields, hatching along the maximum principal direction).
//
// Two published estimators, both per face (the tensor field kind stores one tensor per face):
//
// - kJetFit (default): F. Cazals and M. Pouget, "Estimating Differential Quantities Using
//   Polynomial Fitting of Osculating Jets", SGP 2003 (CAGD 22(2), 2005), degree 2. The height of
//   the vertices of every face that shares a vertex with f over f's plane is fitted by a quadric
//   (least squares, 6 coefficients), whose shape operator is taken at the barycenter. Cazals and
//   Pouget prove O(h) convergence of the curvature tensor for any non-degenerate sampling, which
//   the tests confirm in the maximum norm on irregular meshes (icosphere, ellipsoid, torus).
// - kNormalDifferences: the per-face step of S. Rusinkiewicz, "Estimating Curvatures and Their
//   Derivatives on Triangle Meshes", 3DPVT 2004 (section 3). B minimizes
//     sum_k |B [e_k . x_f, e_k . y_f]^T - [dn_k . x_f, dn_k . y_f]^T|^2
//   over symmetric B, e_k the three edges and dn_k the differences of the vertex normals at their
//   ends (six equations, three unknowns). Rusinkiewicz then averages face tensors at vertices; we
//   do not. Exact on a sphere with Max's normals, but its error is that of the vertex normals
//   divided by h: on irregular meshes the mean error falls while the largest one stalls (measured
//   in tests/core/operators/curvature_test.cc). Cheaper, and the jet fit's fallback.
//
// Sign: B is the derivative of the unit normal, B v = D_v n (the Weingarten map without the usual
// minus sign), with n on the side of the faces' orientation (n_f). A sphere of radius r whose
// faces are oriented outward (as core/mesh/shapes.h makes them) gives +(1/r) I; reversing every
// face negates B. Units: 1 / length of the mesh coordinates.

enum class CurvatureEstimator : uint8_t {
  kJetFit,             // Cazals and Pouget 2003, degree 2 (see above)
  kNormalDifferences,  // Rusinkiewicz 2004, per face (see above)
};

// How vertex normals are averaged from the normals of the faces around a vertex.
enum class VertexNormalWeighting : uint8_t {
  // N. Max, "Weights for Computing Vertex Normals from Facet Normals", JGT 4(2), 1999: each face
  // contributes (e1 x e2) / (|e1|^2 |e2|^2) for its two edges e1, e2 at the vertex. Exact when a
  // vertex and its neighbours lie on a common sphere.
  kMax1999,
  // Thurmer and Wuthrich 1998: the unit face normal times the face's angle at the vertex.
  kAngle,
  // The unit face normal times the face's area.
  kArea,
};

struct ShapeOperatorOptions {
  CurvatureEstimator estimator = CurvatureEstimator::kJetFit;
  // For kNormalDifferences, and for the jet fit's fallback faces.
  VertexNormalWeighting normal_weighting = VertexNormalWeighting::kMax1999;
  // Checked per block of faces: Cancelled once set (a million faces take seconds).
  const CancelFlag* cancel = nullptr;
};

// The unit vertex normals (#V x 3, row v is vertex v) with `weighting`, oriented like the faces.
// A vertex whose weighted sum vanishes (possible only at folded, non-smooth configurations) takes
// the unit normal of its area-weighted sum, and failing that the normal of one of its faces.
VertexMatrix ComputeVertexNormals(const TriangleMesh& mesh, VertexNormalWeighting weighting);

// The per-face shape operator as a symmetric (1,1)-tensor field: a vector of 3 #F DOFs, face f at
// 3f + c, Mandel-Voigt (B11, B22, sqrt(2) B12) of B in the frame (x_f, y_f)
// (docs/conventions.md, "DOF layout"); AmbientFromTensorDofs gives the 3 x 3 form
// B11 x x^T + B22 y y^T + B12 (x y^T + y x^T). Units 1 / length; sign as above.
// Never NaN. The jet fit uses whatever neighbours a face has (boundary faces have fewer, on one
// side); where they do not determine the quadric (fewer than 6 vertices, or a normal matrix with
// reciprocal condition below 1e-10 in coordinates scaled to the neighbourhood) the face falls
// back to normal differences. There, the components of B that a thin face's edges do not
// determine (least squares eigenvalues below 1e-12 of the largest, edges scaled to unit length)
// are set to zero (minimum-norm solution). Parallel over faces (oneTBB). InvalidArgument only for
// an out-of-range enum value in `options`; Cancelled when options.cancel is set meanwhile.
absl::StatusOr<Eigen::VectorXd> ComputeShapeOperator(const TriangleMesh& mesh,
                                                     const ShapeOperatorOptions& options = {});

// Per-face principal curvatures and directions of a symmetric tensor field.
struct PrincipalCurvatures {
  Eigen::VectorXd k1;  // #F, the larger eigenvalue of B
  Eigen::VectorXd k2;  // #F, the smaller one: k1 >= k2
  // #F x 3 unit ambient vectors tangent to the face: d1 the eigenvector of k1, d2 = n_f x d1 (so
  // (d1, d2, n_f) is right-handed). Each is defined up to sign; d1 has frame angle
  // atan2(2 B12, B11 - B22) / 2 in (-pi/2, pi/2]. Where k1 == k2 (umbilic) d1 = x_f.
  AmbientVectors d1;
  AmbientVectors d2;
};

// Eigen-decomposition of any tensor field in the tensor DOF layout (3 #F values, e.g. the output
// of ComputeShapeOperator or a smoothed version of it): k1,2 = (B11 + B22) / 2 +- |q| / 2 with
// q = (B11 - B22, 2 B12). InvalidArgument if `tensor_dofs` does not have 3 #F entries or holds a
// non-finite value (the message names the face).
absl::StatusOr<PrincipalCurvatures> ComputePrincipalCurvatures(
    const TriangleMesh& mesh, const Eigen::Ref<const Eigen::VectorXd>& tensor_dofs);

// Curvature-aligned n-field targets, ready for soft constraints (docs/conventions.md, "Model
// problem") or a data term.
struct CurvatureAlignedTargets {
  int32_t n = 2;
  // 2 #F n-field DOFs (representation vectors, angle times n, face f at 2f + c), of unit length
  // where the face is anisotropic and zero where k1 == k2 exactly.
  Eigen::VectorXd dofs;
  // #F per-face weights: the anisotropy |k1 - k2| (1 / length), so umbilic regions do not steer.
  // weights(f) * dofs(2f + c) is the field whose length is the anisotropy.
  Eigen::VectorXd weights;
};

// From a tensor field (3 #F DOFs, as ComputePrincipalCurvatures): for n = 2 the 2-field of the
// maximum principal direction d1 (representation angle 2 theta, theta the frame angle of d1; for
// n = 2 the DOFs are q / |q|); for n = 4 the principal 4-field, the cross {d1, d2} (angle
// 4 theta). InvalidArgument for another n, a wrong size or a non-finite value.
absl::StatusOr<CurvatureAlignedTargets> ComputeCurvatureAlignedTargets(
    const TriangleMesh& mesh, const Eigen::Ref<const Eigen::VectorXd>& tensor_dofs, int32_t n);

// An upper estimate of the bytes the curvature computations above hold for a mesh of `num_faces`
// faces (the shape operator, principal curvatures and directions, targets and per-vertex data,
// about 150 bytes a face), for admission against a memory budget.
inline int64_t CurvatureWorkingBytes(int64_t num_faces) { return 256 * num_faces; }

}  // namespace fieldspace

#endif  // FIELDSPACE_CORE_OPERATORS_CURVATURE_H_
