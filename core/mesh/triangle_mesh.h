#ifndef FIELDSPACE_CORE_MESH_TRIANGLE_MESH_H_
#define FIELDSPACE_CORE_MESH_TRIANGLE_MESH_H_

#include <cstdint>
#include <vector>

#include "Eigen/Core"
#include "absl/status/statusor.h"

namespace fieldspace {

// #V x 3 vertex positions, row-major (one vertex per row).
using VertexMatrix = Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor>;
// #F x 3 zero-based vertex indices, row-major (one face per row).
using FaceMatrix = Eigen::Matrix<int32_t, Eigen::Dynamic, 3, Eigen::RowMajor>;
// #E x 2 pairs (vertex pairs for edges, face pairs for edge-face incidence).
using PairMatrix = Eigen::Matrix<int32_t, Eigen::Dynamic, 2, Eigen::RowMajor>;

// Marks "no face" in adjacency tables (across a boundary edge).
inline constexpr int32_t kNoFace = -1;

// Raw triangle soup as read from a file: nothing is validated yet.
struct MeshArrays {
  VertexMatrix vertices;  // #V x 3
  FaceMatrix faces;       // #F x 3, zero-based
};

// One connected component (faces connected across shared edges).
struct MeshComponent {
  int32_t num_faces = 0;
  int32_t num_vertices = 0;
  int32_t num_edges = 0;
  int32_t num_boundary_loops = 0;
  int32_t euler_characteristic = 0;  // V - E + F
  int32_t genus = 0;                 // (2 - boundary_loops - chi) / 2
  double area = 0.0;
};

// An immutable, validated, manifold, consistently oriented triangle mesh with its topology and
// per-face geometry (docs/conventions.md, Meshes and Frames). Created only through Create();
// thread-safe to share (all state is computed eagerly, nothing is cached lazily).
class TriangleMesh {
 public:
  // Validates `arrays` and builds topology and geometry. Unreferenced vertices are dropped (and
  // counted), everything else that is wrong is an InvalidArgument error naming the face, edge or
  // vertex: out-of-range indices, non-finite coordinates, repeated indices in a face, zero-area
  // faces, non-manifold edges or vertices, inconsistent orientation, an empty mesh.
  static absl::StatusOr<TriangleMesh> Create(MeshArrays arrays);

  int32_t num_vertices() const { return static_cast<int32_t>(vertices_.rows()); }
  int32_t num_faces() const { return static_cast<int32_t>(faces_.rows()); }
  int32_t num_edges() const { return static_cast<int32_t>(edges_.rows()); }

  // #V x 3 positions (unreferenced input vertices removed, order otherwise kept).
  const VertexMatrix& vertices() const { return vertices_; }
  // #F x 3 vertex indices in file order (the order defines the face frame).
  const FaceMatrix& faces() const { return faces_; }
  // #E x 2 vertex pairs (a, b) with a < b.
  const PairMatrix& edges() const { return edges_; }
  // #F x 3: face_edges()(f, k) is the edge opposite corner k, i.e. between vertices
  // faces()(f, (k+1)%3) and faces()(f, (k+2)%3).
  const FaceMatrix& face_edges() const { return face_edges_; }
  // #F x 3: face_neighbors()(f, k) is the face across face_edges()(f, k), or kNoFace.
  const FaceMatrix& face_neighbors() const { return face_neighbors_; }
  // #E x 2: the faces incident to edge e; (f0, f1) with f0 < f1, or (f0, kNoFace) on a boundary.
  const PairMatrix& edge_faces() const { return edge_faces_; }

  // Per face (#F rows): area, unit normal, barycenter, and the frame (docs/conventions.md, Frames)
  // x_f = normalize(p1 - p0), n_f = normalize((p1 - p0) x (p2 - p0)), y_f = n_f x x_f.
  const Eigen::VectorXd& face_areas() const { return face_areas_; }
  const VertexMatrix& face_normals() const { return face_normals_; }
  const VertexMatrix& face_barycenters() const { return face_barycenters_; }
  const VertexMatrix& frame_x() const { return frame_x_; }
  const VertexMatrix& frame_y() const { return frame_y_; }
  // The largest distance from a face's barycenter to one of its corners: every point of face f
  // lies within it of face_barycenters().row(f) (SnapToSurface prunes with it).
  double max_face_radius() const { return max_face_radius_; }
  // The edge vector t_k = p_{k+2} - p_{k+1} of face f (opposite corner k, counter-clockwise) in
  // f's frame: (t_k . x_f, t_k . y_f). The one definition every operator assembly uses, so that
  // operators built from it agree to the last bit (the factored Hodge form B B^T reproduces S).
  Eigen::Vector2d EdgeVectorInFrame(int32_t f, int k) const {
    const Eigen::Vector3d x = frame_x_.row(f).transpose();
    const Eigen::Vector3d y = frame_y_.row(f).transpose();
    const Eigen::Vector3d t =
        (vertices_.row(faces_(f, (k + 2) % 3)) - vertices_.row(faces_(f, (k + 1) % 3))).transpose();
    return {t.dot(x), t.dot(y)};
  }

  // Connected components: face_component()(f) in [0, num_components()).
  const Eigen::VectorXi& face_component() const { return face_component_; }
  int32_t num_components() const { return static_cast<int32_t>(components_.size()); }
  const std::vector<MeshComponent>& components() const { return components_; }
  // Boundary loops as ordered vertex cycles.
  const std::vector<std::vector<int32_t>>& boundary_loops() const { return boundary_loops_; }

  // Whole-mesh summaries (sums over components).
  int32_t euler_characteristic() const;
  int32_t genus() const;
  double total_area() const { return total_area_; }
  // Bytes held by the arrays above (for memory budgets).
  int64_t MemoryBytes() const;
  int32_t dropped_unreferenced_vertices() const { return dropped_unreferenced_vertices_; }

 private:
  TriangleMesh() = default;

  VertexMatrix vertices_;
  FaceMatrix faces_;
  PairMatrix edges_;
  FaceMatrix face_edges_;
  FaceMatrix face_neighbors_;
  PairMatrix edge_faces_;
  Eigen::VectorXd face_areas_;
  VertexMatrix face_normals_;
  VertexMatrix face_barycenters_;
  VertexMatrix frame_x_;
  VertexMatrix frame_y_;
  Eigen::VectorXi face_component_;
  std::vector<MeshComponent> components_;
  std::vector<std::vector<int32_t>> boundary_loops_;
  double total_area_ = 0.0;
  double max_face_radius_ = 0.0;
  int32_t dropped_unreferenced_vertices_ = 0;
};

}  // namespace fieldspace

#endif  // FIELDSPACE_CORE_MESH_TRIANGLE_MESH_H_
