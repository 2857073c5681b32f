#ifndef FIELDSPACE_CORE_MESH_SHAPES_H_
#define FIELDSPACE_CORE_MESH_SHAPES_H_

#include <cstdint>

#include "absl/status/statusor.h"
#include "core/mesh/triangle_mesh.h"

namespace fieldspace {

// Procedural closed, consistently (outward) oriented triangle meshes for tests and the demo.
// Each returns InvalidArgument for parameters out of range (and never allocates absurdly).

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

}  // namespace fieldspace

#endif  // FIELDSPACE_CORE_MESH_SHAPES_H_
