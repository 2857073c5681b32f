#ifndef FIELDSPACE_CORE_MESH_SHAPES_H_
#define FIELDSPACE_CORE_MESH_SHAPES_H_

#include <cstdint>

#include "absl/status/statusor.h"
#include "core/mesh/triangle_mesh.h"

namespace fieldspace {

// Procedural, consistently oriented triangle meshes for tests and the demo: closed surfaces
// (sphere, torus, knot, genus g), meshes with irregular, obtuse or noisy triangles, and open
// surfaces with borders. Each returns InvalidArgument for parameters out of range (and never
// allocates absurdly).

// Icosahedron subdivided `subdivisions` times (0..9), vertices on the sphere of `radius`:
// 20 * 4^s faces, 10 * 4^s + 2 vertices, genus 0.
absl::StatusOr<MeshArrays> MakeIcosphere(int32_t subdivisions, double radius = 1.0);

// Torus of revolution around z: major radius R, tube radius r (0 < r < R), `major_segments` x
// `minor_segments` quads split in two: 2 * major * minor faces, genus 1.
absl::StatusOr<MeshArrays> MakeTorus(double major_radius, double minor_radius,
                                     int32_t major_segments, int32_t minor_segments);

// A tube of radius `tube_radius` around the (p, q) torus knot on a torus of radii (R, r):
// 2 * segments * tube_segments faces, genus 1. p and q coprime, >= 1.
struct TorusKnotOptions {
  int32_t p = 2;
  int32_t q = 3;
  double major_radius = 1.0;
  double minor_radius = 0.4;
  double tube_radius = 0.15;
  int32_t segments = 512;      // along the knot
  int32_t tube_segments = 48;  // around the tube
};
absl::StatusOr<MeshArrays> MakeTorusKnot(const TorusKnotOptions& options);

// A closed surface of genus g: the boundary of a thick plate with g square holes in a row.
// `resolution` cells per unit length of the plate (>= 1); faces grow with resolution^2.
absl::StatusOr<MeshArrays> MakeGenusSurface(int32_t genus, int32_t resolution);

// ---- Irregular, obtuse and noisy ----------------------------------------------------------------

// A sphere of non-uniform density: the icosphere's vertices p moved to the unit sphere along
// p + pull * e_z, so faces shrink towards +z and grow towards -z (linear sizes change by about
// (1 + pull) / (1 - pull) from pole to pole). pull in [0, 0.9]; counts as MakeIcosphere.
absl::StatusOr<MeshArrays> MakeNonUniformSphere(int32_t subdivisions, double pull);

// A torus of revolution of obtuse triangles: odd rings of the tube (constant minor angle) are
// turned by half a major step and the quads split along the alternating diagonal, so every
// triangle has one side along a ring and its apex on the next ring, halfway along. The apex angle
// is obtuse everywhere once minor_segments > 2 major_segments r / (R - r), and near 180 degrees
// (slivers) well above that. minor_segments even, >= 4; 2 * major * minor faces, genus 1.
absl::StatusOr<MeshArrays> MakeStaggeredTorus(double major_radius, double minor_radius,
                                              int32_t major_segments, int32_t minor_segments);

// `mesh` with every vertex moved by a pseudo-random offset, uniform in the ball of radius
// `amplitude` times the shortest edge at that vertex (so no edge collapses): noise in 3D on a
// surface, irregular sizes and angles on a plane. Deterministic in `seed` on every platform;
// faces and topology unchanged. amplitude in [0, 0.4].
absl::StatusOr<MeshArrays> PerturbVertices(const MeshArrays& mesh, double amplitude, uint64_t seed);

// ---- Open surfaces (with borders) --------------------------------------------------------------

// An open cylinder of `radius` around z, from z = 0 to `height`: `around` (>= 3) x `along` (>= 1)
// quads split in two, 2 * around * along faces, genus 0, two boundary loops, chi = 0. Normals
// point outward.
absl::StatusOr<MeshArrays> MakeCylinder(double radius, double height, int32_t around,
                                        int32_t along);

// The unit disk in z = 0 as a polar grid: a centre vertex and `rings` (>= 1) rings of `segments`
// (>= 3) vertices each, so the triangles are thin near the centre and wide at the rim (non-uniform,
// with one vertex of valence `segments`). segments * (2 rings - 1) faces, 1 + rings * segments
// vertices, genus 0, one boundary loop, normals +z.
absl::StatusOr<MeshArrays> MakePolarDisk(int32_t rings, int32_t segments);

// A flat plate with `holes` square holes in a row: the top of MakeGenusSurface's plate,
// (2 holes + 1) x 3 unit squares in z = 0, `resolution` cells per unit. Genus 0, holes + 1
// boundary loops, chi = 1 - holes, normals +z.
absl::StatusOr<MeshArrays> MakePerforatedPlate(int32_t holes, int32_t resolution);

}  // namespace fieldspace

#endif  // FIELDSPACE_CORE_MESH_SHAPES_H_
