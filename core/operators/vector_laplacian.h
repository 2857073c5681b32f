#ifndef FIELDSPACE_CORE_OPERATORS_VECTOR_LAPLACIAN_H_
#define FIELDSPACE_CORE_OPERATORS_VECTOR_LAPLACIAN_H_

#include <cstddef>
#include <cstdint>
#include <new>
#include <vector>

#include "Eigen/SparseCore"
#include "absl/functional/function_ref.h"
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

// The inverses of S's lumped masses above: Mv_v^-1 = 3 / (sum of the areas of the faces around
// vertex v) and Me_e^-1 = 3 / (the areas of e's one or two faces), each sum in ascending face
// order. The one definition: S's assembly (VectorHodgeRows) and the basis build's factored form
// S = B B^T (core/basis/local_problem.h, HodgeFactorData) both read them here, so that B B^T
// reproduces S to the last bits.
struct HodgeInverseMasses {
  std::vector<double> vertex;  // #V
  std::vector<double> edge;    // #E
};
HodgeInverseMasses BuildHodgeInverseMasses(const TriangleMesh& mesh);

namespace vector_laplacian_internal {

// 64-byte aligned storage for the per-face tables.
template <typename T>
struct CacheAlignedAllocator {
  using value_type = T;
  CacheAlignedAllocator() = default;
  template <typename U>
  CacheAlignedAllocator(const CacheAlignedAllocator<U>&) {}
  T* allocate(size_t n) {
    return static_cast<T*>(::operator new (n * sizeof(T), std::align_val_t{64}));
  }
  void deallocate(T* p, size_t) { ::operator delete (p, std::align_val_t{64}); }
  friend bool operator==(const CacheAlignedAllocator&, const CacheAlignedAllocator&) {
    return true;
  }
};

// Faces around each vertex as packed corners 4 f + k (face f, corner k at the vertex; shifts
// instead of divisions in the hot loop), ascending in f (counting sort over faces in order), so
// the stars of a face's three vertices can be merged.
struct VertexStars {
  std::vector<int64_t> offset;   // #V + 1
  std::vector<int32_t> corners;  // 3F
};

}  // namespace vector_laplacian_internal

// The rows of BuildVectorHodgeStiffness(mesh) one face at a time, computed from small per-face
// tables instead of read from the assembled S: for steps that go over S's rows once or twice
// (the assembly itself, the reduced system's products) without holding S (~96 bytes a face here:
// the edge vectors' 64, the vertex stars and the inverse masses; S takes ~630). The mesh must
// outlive it.
class VectorHodgeRows {
 public:
  // ResourceExhausted beyond 2^29 faces (corners are packed in 32 bits).
  static absl::StatusOr<VectorHodgeRows> Create(const TriangleMesh& mesh);

  int32_t num_faces() const { return mesh_->num_faces(); }
  // The number of faces sharing a vertex with f, f included: the blocks ForEachBlock visits.
  int32_t CountBlocks(int32_t f) const;
  // visit(g, block) for each face g sharing a vertex with f, ascending g (f included), with
  // block[2 c + d] = S(2 f + c, 2 g + d): bitwise the values the assembled S holds.
  void ForEachBlock(int32_t f, absl::FunctionRef<void(int32_t g, const double* block)> visit) const;
  // trace(S): the sum of the diagonal blocks' diagonals.
  double Trace() const;

 private:
  explicit VectorHodgeRows(const TriangleMesh& mesh) : mesh_(&mesh) {}

  const TriangleMesh* mesh_;
  vector_laplacian_internal::VertexStars stars_;
  // Edge vectors t_fk (counter-clockwise, opposite corner k) in face f's frame, 8 doubles a face
  // (6 used, one 64-byte cache line).
  std::vector<double, vector_laplacian_internal::CacheAlignedAllocator<double>> t_;
  HodgeInverseMasses inv_mass_;
};

}  // namespace fieldspace

#endif  // FIELDSPACE_CORE_OPERATORS_VECTOR_LAPLACIAN_H_
