#ifndef FIELDSPACE_CORE_SUBSPACE_DESIGN_TOOLS_H_
#define FIELDSPACE_CORE_SUBSPACE_DESIGN_TOOLS_H_

#include <cstdint>
#include <vector>

#include "Eigen/Core"
#include "absl/status/statusor.h"
#include "absl/types/span.h"
#include "core/mesh/surface_path.h"
#include "core/mesh/triangle_mesh.h"
#include "core/operators/field_type.h"
#include "core/subspace/problem.h"

namespace fieldspace {

// The designer's tools (strokes, placed singularities, boundary and feature alignment) as groups
// of per-face constraints of the model problem (eq. 8; docs/conventions.md, "Design tools"): each
// tool becomes one FieldConstraint per face it touches, with a unit value in the face's DOF
// layout (vector: frame coordinates; n-field: the n-th power representation, so the direction is
// one of the n; tensor: Mandel-Voigt), so that a session or a Solve takes them like any other
// constraints. Every function is a pure function of the mesh and its arguments.
//
// Weights: a tool's `weight` is the mean soft weight of its faces; each face's share is
// proportional to the tool's length inside it (strokes, boundary and feature edges), so a face
// the stroke only grazes pulls little. Hard tools ignore weights.

struct StrokeOptions {
  ConstraintKind kind = ConstraintKind::kSoft;
  double weight = 1.0;  // soft: finite, > 0 (the mean per-face weight)
  // Tensors: the stroke sets the principal direction t with eigenvalues 1 (along t) and
  // 1 - anisotropy (across), anisotropy in (0, 1].
  double anisotropy = 1.0;
};

// A stroke through `points` (at least 2): consecutive points joined by ShortestSurfacePath; one
// constraint per face the stroke crosses (in order of first crossing), its value the stroke's
// direction inside the face (the length-weighted mean of its pieces there, as representation
// vectors for n-fields and tensors for tensor fields, then normalized to unit length for vector
// and n-fields), its soft weight options.weight * (length in the face) / (mean length per face).
// A face where the pieces cancel (a stroke going back over itself) gets no constraint.
// InvalidArgument for invalid points, fewer than 2, a stroke of zero length, a bad weight or
// anisotropy or field type.
absl::StatusOr<std::vector<FieldConstraint>> StrokeConstraints(
    const TriangleMesh& mesh, const FieldType& type, absl::Span<const SurfacePoint> points,
    const StrokeOptions& options = {});

struct PlacedSingularityOptions {
  ConstraintKind kind = ConstraintKind::kSoft;
  double weight = 1.0;  // soft: finite, > 0 (each fan face's weight)
};

// The vertex a singularity at a surface point is placed at (indices live on vertices, see
// core/operators/singularities.h): the face's corner with the largest barycentric coordinate.
int32_t NearestCorner(const TriangleMesh& mesh, const SurfacePoint& point);

// Constraints on the faces around interior vertex `vertex` (its one-ring, Brandt et al. 2018 style)
// that give the field index `turns` there (whole turns: a multiple of 1/n), measured exactly as
// ComputeVertexIndices does: walking the fan f_0, ..., f_{m-1} counter-clockwise, the values are
// u_0 = (1, 0) in f_0's frame and u_{j+1} = e^{i s} T_j u_j, T_j the n-field transport
// (TransportPower) from f_j to f_{j+1} and s = (2 pi k - n K_v) / m (k = n turns, K_v the angle
// defect): every crossing, the closing one included (the transport's holonomy is n K_v), turns
// the field by s relative to the connection, so the fan sums to index k whatever the field
// elsewhere, as long as these faces keep their values (hard constraints, or soft ones the solve
// nearly meets). Vector fields are n = 1. InvalidArgument for tensor fields, a vertex out of
// range or on the boundary, turns not a multiple of 1/n, |s| >= pi (an index too large for the
// vertex's m faces: the detector would see a smaller rotation), a bad weight.
absl::StatusOr<std::vector<FieldConstraint>> SingularityConstraints(
    const TriangleMesh& mesh, const FieldType& type, int32_t vertex, double turns,
    const PlacedSingularityOptions& options = {});

enum class BoundaryAlignment : uint8_t {
  kTangent = 0,  // along the boundary edge, as it runs counter-clockwise in its face
  kNormal = 1,   // the in-plane outward normal: tangent x face normal
};

struct BoundaryAlignmentOptions {
  BoundaryAlignment mode = BoundaryAlignment::kTangent;
  // Indices into mesh.boundary_loops(); empty: every loop.
  std::vector<int32_t> loops;
  ConstraintKind kind = ConstraintKind::kSoft;
  double weight = 1.0;  // soft: finite, > 0 (mean per-face weight)
};

// One constraint per face with an edge on the chosen boundary loops: the edge's direction (or its
// normal); a face with two boundary edges gets their length-weighted mean (for 4-fields at a
// right-angled corner both give the same value; for vector fields it is the bisector).
// FailedPrecondition for a mesh without boundary; InvalidArgument for a loop index out of range,
// a bad weight or field type.
absl::StatusOr<std::vector<FieldConstraint>> BoundaryAlignmentConstraints(
    const TriangleMesh& mesh, const FieldType& type, const BoundaryAlignmentOptions& options = {});

struct FeatureAlignmentOptions {
  // Sharp edges: interior edges whose faces' normals differ by more than this, in (0, 180).
  double angle_degrees = 60.0;
  ConstraintKind kind = ConstraintKind::kSoft;
  double weight = 1.0;  // soft: finite, > 0 (mean per-face weight)
};

// The interior edges whose dihedral angle (between the face normals) exceeds the threshold.
std::vector<int32_t> SharpEdges(const TriangleMesh& mesh, double angle_degrees);

// One constraint per face along a sharp edge (both faces of each): the edge's direction, oriented
// along its chain of sharp edges (walked from an end, or around a closed chain) so that a vector
// field follows a feature line consistently; a face on two sharp edges gets their length-weighted
// mean (a cube corner's faces: the same 4-field value). FailedPrecondition when no edge is sharp;
// InvalidArgument for a threshold outside (0, 180), a bad weight or field type.
absl::StatusOr<std::vector<FieldConstraint>> FeatureAlignmentConstraints(
    const TriangleMesh& mesh, const FieldType& type, const FeatureAlignmentOptions& options = {});

}  // namespace fieldspace

#endif  // FIELDSPACE_CORE_SUBSPACE_DESIGN_TOOLS_H_
