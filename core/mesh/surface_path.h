#ifndef FIELDSPACE_CORE_MESH_SURFACE_PATH_H_
#define FIELDSPACE_CORE_MESH_SURFACE_PATH_H_

// Points and shortest paths on the surface of a triangle mesh (the designer's strokes,
// core/subspace/design_tools.h, are drawn along them), and the mesh walks they need.

#include <cstdint>
#include <vector>

#include "Eigen/Core"
#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "core/mesh/triangle_mesh.h"

namespace fieldspace {

// A point on the surface: face `face` and barycentric coordinates of its corners
// faces()(face, 0..2), each in [0, 1] (to 1e-9), summing to 1 (to 1e-9).
struct SurfacePoint {
  int32_t face = 0;
  Eigen::Vector3d barycentric = Eigen::Vector3d::Constant(1.0 / 3.0);
};

// InvalidArgument for a face out of range or barycentric coordinates that are not as above.
absl::Status ValidateSurfacePoint(const TriangleMesh& mesh, const SurfacePoint& point);

// The 3D position of a surface point.
Eigen::Vector3d SurfacePosition(const TriangleMesh& mesh, const SurfacePoint& point);

// The closest point of the surface to `p` (ties: the lowest face). Two parallel passes over the
// face barycenters, the exact point-triangle test only for faces whose barycenter is near enough
// (TriangleMesh::max_face_radius); callers that know the face (a picking client) send
// SurfacePoints.
// InvalidArgument for a non-finite p, or one so far away that its squared distances overflow.
absl::StatusOr<SurfacePoint> SnapToSurface(const TriangleMesh& mesh, const Eigen::Vector3d& p);

// One straight piece of a path on the surface, inside face `face` (from `a` to `b`, both in the
// face's closure).
struct PathSegment {
  int32_t face = 0;
  Eigen::Vector3d a, b;
};

// A shortest path on the surface from `from` to `to`: the faces of the shortest path between
// their faces in the dual graph (A*, edge lengths between barycenters), then the exact shortest
// polyline through that strip of faces (unfolded into the plane, funnel algorithm), with the
// strip rerouted the other way around any vertex the polyline touches while that shortens it
// (on convex parts of a surface this gives the geodesic). One segment per face, consecutive
// segments joined. InvalidArgument for invalid points or points on different connected
// components.
absl::StatusOr<std::vector<PathSegment>> ShortestSurfacePath(const TriangleMesh& mesh,
                                                             const SurfacePoint& from,
                                                             const SurfacePoint& to);

// The edge shared by faces f and g (neighbours), or -1.
int32_t SharedEdge(const TriangleMesh& mesh, int32_t f, int32_t g);

// The faces around interior vertex v, counter-clockwise from `start` (a face at v); empty for a
// boundary vertex.
std::vector<int32_t> VertexFan(const TriangleMesh& mesh, int32_t v, int32_t start);

}  // namespace fieldspace

#endif  // FIELDSPACE_CORE_MESH_SURFACE_PATH_H_
