#ifndef FIELDSPACE_CORE_OPERATORS_SINGULARITIES_H_
#define FIELDSPACE_CORE_OPERATORS_SINGULARITIES_H_

#include <cstdint>
#include <vector>

#include "Eigen/Core"
#include "absl/status/statusor.h"
#include "core/mesh/triangle_mesh.h"

namespace fieldspace {

// Vertex indices (singularities) of per-face vector fields and n-fields.
//
// Input: 2 DOFs per face at 2f + c (docs/conventions.md): for an n-field the representation
// vector u_f (angle times n, length kept) in face f's frame; a vector field is the case n = 1 with
// its frame coordinates as u_f.
//
// Formula: the discrete index of Ray, Vallet, Li and Levy 2008, "N-symmetry direction field
// design" (ACM TOG 27(2)): angle defect plus the field's rotation relative to the connection
// around the vertex, written with a discrete connection as in Crane, Desbrun and Schroder 2010,
// "Trivial connections on discrete surfaces" (holonomy around a vertex = angle defect), here with
// the connection of the n-field Laplacian:
//
//   omega_e = arg( u_f0 conj( R(n (theta_f0 - theta_f1)) u_f1 ) )   in (-pi, pi]
//
// for an interior edge e = (f0, f1), f0 < f1: the field's rotation from f1 to f0 relative to the
// transport of core/operators/edge_transport.h (the same rotation, computed the same way by
// repeated squaring, as in BuildNFieldStiffness), in representation angles: the n directions
// turn by omega_e / n, the smallest of the equivalent rotations, in (-pi/n, pi/n]. Walking
// counter-clockwise (seen from the normals) around a vertex v crosses each interior edge at v
// once; the crossing from f1 to f0 counts +omega_e, the other -omega_e. With the angle defect
// K_v = 2 pi - (sum of the corner angles at v),
//
//   index(v) = ( sum_{interior e at v} +-omega_e  +  n K_v ) / (2 pi)     [units of 1/n turns]
//
// is an integer (the transport's holonomy around v is K_v mod 2 pi), rounded from a value that
// differs from it only by rounding error. Each omega_e enters its two endpoints with opposite
// signs and sum_v K_v = 2 pi chi (discrete Gauss-Bonnet), so on a closed mesh
// sum_v index(v) = n chi exactly (Poincare-Hopf), whatever the field, if no face is zero.
//
// Boundary vertices: their fan is open; the same sum over the fan's interior edges, with the
// boundary angle defect K_v = pi - (sum of the corner angles at v) (the boundary's geodesic
// turning at v), gives a real number b(v) = (sum +-omega_e + n K_v) / (2 pi) in units of 1/n
// turns, in general not an integer, and not a singularity. With it,
// sum_interior index(v) + sum_boundary b(v) = n chi on every mesh (Gauss-Bonnet with boundary):
// the boundary values sum to the integer n chi - (interior indices), e.g. 0 for a field normal or
// tangent to the boundary of a disk with one +1 singularity.
//
// Zero faces: a face whose DOF vector has norm <= zero_tolerance * (largest norm over all faces)
// has no direction; every vertex of such a face is undefined (reported, never given an index, no
// NaN anywhere). The zero faces hide whatever singularities they contain, so Poincare-Hopf then
// does not hold for the remaining vertices in general.
//
// Cost: O(#F) time and memory; the per-edge and per-corner angles are computed in parallel
// (oneTBB), the per-vertex sums in a fixed order, so the result does not depend on the thread
// count.

struct SingularityOptions {
  int32_t n = 1;  // symmetry order, 1..64 (1 for vector fields)
  // Faces with |u_f| <= zero_tolerance * max_f |u_f| count as zero. Finite, in [0, 1); 0: only
  // exact zeros (any nonzero vector has a direction).
  double zero_tolerance = 0.0;
};

enum class VertexIndexKind : uint8_t {
  kInterior = 0,   // closed fan: an integer index
  kBoundary = 1,   // open fan: a real boundary value b(v)
  kUndefined = 2,  // a face at v is zero: no index
};

// Per-vertex result (#V entries each, vertex order of the mesh).
struct VertexIndices {
  int32_t n = 1;
  std::vector<VertexIndexKind> kind;
  // Interior: the index in units of 1/n turns. Boundary and undefined: 0.
  std::vector<int32_t> index;
  // Interior: index as a double (units of 1/n turns). Boundary: b(v) (units of 1/n turns).
  // Undefined: 0.
  std::vector<double> value;
};

// A singular interior vertex.
struct Singularity {
  int32_t vertex = 0;
  int32_t index = 0;   // units of 1/n turns, nonzero
  double turns = 0.0;  // index / n
};

// A boundary vertex's open-fan value.
struct BoundaryIndex {
  int32_t vertex = 0;
  double value = 0.0;  // b(v), units of 1/n turns
  double turns = 0.0;  // b(v) / n
};

struct Singularities {
  int32_t n = 1;
  std::vector<Singularity> singularities;   // interior vertices with index != 0, ascending vertex
  std::vector<BoundaryIndex> boundary;      // every defined boundary vertex, ascending vertex
  std::vector<int32_t> undefined_vertices;  // ascending
  // Sum of all interior indices (units of 1/n turns): n chi on a closed mesh without zero faces.
  int64_t index_sum = 0;
};

// The index of every vertex (formula above). dofs: 2 #F entries, finite. InvalidArgument for a
// wrong size, a non-finite DOF (naming the face), n outside [1, 64] or a bad zero_tolerance.
// Internal if a vertex sum is not within 1e-6 of an integer (a broken mesh invariant).
absl::StatusOr<VertexIndices> ComputeVertexIndices(const TriangleMesh& mesh,
                                                   const Eigen::Ref<const Eigen::VectorXd>& dofs,
                                                   const SingularityOptions& options = {});

// The sparse summary of ComputeVertexIndices: singular interior vertices, boundary values,
// undefined vertices. Same errors.
absl::StatusOr<Singularities> ComputeSingularities(const TriangleMesh& mesh,
                                                   const Eigen::Ref<const Eigen::VectorXd>& dofs,
                                                   const SingularityOptions& options = {});

// A vertex whose index changed between two fields on the same mesh.
struct IndexChange {
  int32_t vertex = 0;
  VertexIndexKind kind_before = VertexIndexKind::kInterior;
  VertexIndexKind kind_after = VertexIndexKind::kInterior;
  int32_t index_before = 0;  // units of 1/n turns (0 unless interior)
  int32_t index_after = 0;
};

// The vertices whose kind or integer index differs between `before` and `after` (ascending vertex;
// boundary values b(v) are not compared): what a design session streams after an edit. O(#V).
// InvalidArgument if the two have different n or vertex counts.
absl::StatusOr<std::vector<IndexChange>> DiffVertexIndices(const VertexIndices& before,
                                                           const VertexIndices& after);

}  // namespace fieldspace

#endif  // FIELDSPACE_CORE_OPERATORS_SINGULARITIES_H_
