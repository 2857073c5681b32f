#ifndef FIELDSPACE_CORE_BASIS_LOCAL_PROBLEM_H_
#define FIELDSPACE_CORE_BASIS_LOCAL_PROBLEM_H_

#include <cstdint>
#include <vector>

#include "Eigen/Core"
#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "core/basis/local_eigensolver.h"
#include "core/common/cancel.h"
#include "core/linalg/local_cholesky.h"
#include "core/mesh/triangle_mesh.h"
#include "core/operators/field_operator.h"

namespace fieldspace::basis_internal {

using RowBlock = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

// Estimate of the lowest Dirichlet eigenvalue of a region of area `area`: a flat disk's
// j_{0,1}^2 pi / area. Sets the scale of the shift tau; accuracy is irrelevant.
inline double DiskEigenvalueEstimate(double area) {
  return 5.783185962946784 * 3.141592653589793 / area;
}

// How far ahead (in faces) the per-face loops over a region prefetch the rows they will read: a
// region's faces are ascending but scattered over the mesh's arrays (on a subdivided mesh, nearly
// one cache line per face; bench/RESULTS.md, Session 32).
inline constexpr int32_t kPrefetchFaces = 8;

// Per-thread scratch reused from region to region: index maps that are -1 everywhere except
// while a region is being built (reset through touched lists, O(region) per region), and the
// sparse Cholesky workspace.
struct RegionWorkspace {
  std::vector<int32_t> dof_map;     // k, global DOF -> local DOF
  std::vector<int32_t> vertex_map;  // #V
  std::vector<int32_t> edge_map;    // #E
  LocalCholesky cholesky;
  std::vector<int32_t> touched;
  std::vector<int32_t> cursor;     // assembly scratch
  std::vector<int32_t> outer_map;  // k, global DOF -> row of S~ V outside the region (clamped)
  // The order the local system is factored in (InducedNodeOrder for the Hodge factor's K,
  // LocalCholesky::BlockMinimumDegreeOrder otherwise) and its scratch.
  std::vector<int32_t> order, vertex_order, rank, edge_low, edge_high, bucket;
};

// The generic local problem (any field type): S_bar = V^T S V extracted from the global S by a
// global -> local DOF map in O(nnz of the region's columns), and (S_bar + tau I)^-1 by a sparse
// Cholesky factorization of S_bar + tau I.
class RestrictedLocalOperator final : public LocalOperator {
 public:
  // `faces`: the region, ascending. `inv_sqrt_mass`: k entries 1 / sqrt(M_ii). `tau` > 0.
  // `clamped` (BasisOptions::clamped_local_fields): the local operator is the biharmonic energy
  // of fields that vanish outside the region, B_bar = (S~ V)^T (S~ V) with S~ = M^-1/2 S M^-1/2
  // and all of S~ V's rows (also those of the faces around the region), instead of V^T S~ V:
  // its eigenfields' values and slopes vanish at the region's edge, so they carry no kink there.
  RestrictedLocalOperator(const FieldOperator& op, const Eigen::VectorXd& inv_sqrt_mass,
                          const std::vector<int32_t>& faces, double tau, RegionWorkspace& ws,
                          bool clamped = false);

  int32_t size() const override { return n_; }
  void ApplyStiffness(const Eigen::MatrixXd& X, Eigen::MatrixXd* Y) override;
  absl::Status PrepareShiftInverse(const CancelToken& cancel) override;
  void ApplyShiftInverse(const Eigen::MatrixXd& X, Eigen::MatrixXd* Y) override;
  // (S_bar + tau I) Y = X, so S_bar Y = X - tau Y without a product with S_bar: its rounding is
  // the factorization's, of the order of the product's own (|S_bar| eps |Y|).
  void ApplyShiftInverseAndStiffness(const Eigen::MatrixXd& X, Eigen::MatrixXd* Y,
                                     Eigen::MatrixXd* SY) override;
  double shift() const override { return tau_; }

 private:
  int32_t n_ = 0;
  int32_t dofs_per_face_ = 1;  // the factorization orders the faces, each face's DOFs together
  double tau_ = 0;
  RegionWorkspace& ws_;
  std::vector<int32_t> outer_, inner_;  // S_bar, both triangles, CSC, sorted rows
  std::vector<double> values_;
};

// The order HodgeLocalOperator factors its K = tau I + B_D^T B_D in, into ws.order. K's nodes
// are numbered vertices first (0 .. num_vertices - 1), then edges; `face_nodes` holds each face's
// three vertices and then the three edges opposite them (6 per face). AMD orders K's vertex block
// alone, and each edge is eliminated right before the earlier of its two endpoints (edges with
// the same earlier endpoint in the order of their later one). On a triangle mesh the edges
// between the vertices of a separator of the vertex graph separate the edge graph (two edges are
// coupled only through a face, and a face with edges on both sides would have vertices on both
// sides), and the two blocks are coupled only at the region's boundary, so the induced order
// keeps the fill of AMD on the whole of K (a little less: bench/RESULTS.md, Session 31) for the
// cost of AMD on a quarter of its nodes and a third of its couplings.
absl::Status InducedNodeOrder(const UpperCsc& K, int32_t num_vertices,
                              const std::vector<int32_t>& face_nodes, RegionWorkspace& ws);

// Global data for the vector Hodge Laplacian's factored form S = B B^T (docs/conventions.md,
// Vector Hodge Laplacian): B has one column per vertex (M J-rotated hat gradients, scaled by
// Mv^-1/2) and one per edge (M J CR gradients, scaled by Me^-1/2); on face f both columns of
// corner k are built from the frame coordinates t_fk of the edge vector opposite k
// (area_f grad phi_k = J t_fk / 2 and area_f J grad psi_e = t_fk). The scales are the square
// roots of S's own inverse masses (BuildHodgeInverseMasses, core/operators/vector_laplacian.h).
struct HodgeFactorData {
  std::vector<double> inv_sqrt_vertex_mass;  // #V
  std::vector<double> inv_sqrt_edge_mass;    // #E
};
HodgeFactorData BuildHodgeFactorData(const TriangleMesh& mesh);

// The error of a build that reads S (BuildReadsStiffness) given an operator without it.
absl::Status MissingStiffnessError(const FieldType& type);

// Whether op.stiffness equals B B^T (to rounding): tested on a random vector, entrywise
// relative to |S| |x|. Only then may the Woodbury operator below stand in for S_bar.
absl::StatusOr<bool> HodgeFactorMatches(const TriangleMesh& mesh, const FieldOperator& op,
                                        const HodgeFactorData& data, const CancelToken& cancel);

// The vector local problem through the factor: S_bar = B_D B_D^T, B_D = V^T B restricted to the
// region's rows (n x N, N the region's vertices plus edges). Its shift-inverse by Woodbury,
//   (B_D B_D^T + tau I)^-1 x = (x - B_D (tau I + B_D^T B_D)^-1 B_D^T x) / tau,
// factors the N x N matrix K = tau I + B_D^T B_D, whose graph has vertex-vertex and edge-edge
// couplings only (the discrete Hodge decomposition makes the vertex-edge blocks vanish except at
// the region's boundary edges): ~6x fewer flops than factoring S_bar itself, whose face graph
// couples every face with the 12 faces around its vertices.
class HodgeLocalOperator final : public LocalOperator {
 public:
  HodgeLocalOperator(const TriangleMesh& mesh, const HodgeFactorData& data,
                     const std::vector<int32_t>& faces, double tau, RegionWorkspace& ws);

  int32_t size() const override { return n_; }
  void ApplyStiffness(const Eigen::MatrixXd& X, Eigen::MatrixXd* Y) override;
  absl::Status PrepareShiftInverse(const CancelToken& cancel) override;
  void ApplyShiftInverse(const Eigen::MatrixXd& X, Eigen::MatrixXd* Y) override;
  // With z = K^-1 B_D^T x: (S_bar + tau I)^-1 x = (x - B_D z) / tau and, since
  // B_D^T (x - B_D z) / tau = z, S_bar (S_bar + tau I)^-1 x = B_D z: one pass over B_D each way.
  void ApplyShiftInverseAndStiffness(const Eigen::MatrixXd& X, Eigen::MatrixXd* Y,
                                     Eigen::MatrixXd* SY) override;
  double shift() const override { return tau_; }

 private:
  // K = tau I + B_D^T B_D (upper triangle, nodes numbered vertices first, then edges).
  UpperCsc AssembleK();
  // zr_ = B_D^T X (N x p).
  void ApplyBt(const Eigen::MatrixXd& X);
  // Y = B_D zr_ (n x p), or Y -= B_D zr_.
  void ApplyB(Eigen::MatrixXd* Y, bool subtract);

  int32_t n_ = 0;          // 2 * faces
  int32_t num_nodes_ = 0;  // N: vertices then edges
  int32_t num_vertices_ = 0;
  double tau_ = 0;
  RegionWorkspace& ws_;
  // Face i's columns of B_D (3 vertices, 3 edges), and its 2 x 6 block. The nodes are numbered
  // vertices first, then edges, until K is factored; from then on in the factor's order
  // (LocalCholesky::inverse_permutation), so that zr_ is solved in place, without a permuted copy.
  std::vector<int32_t> b_cols_;
  std::vector<double> b_vals_;
  std::vector<uint8_t> boundary_edge_;  // per local edge: exactly one of its faces in the region
  RowBlock zr_;                         // B_D^T X, row-major: the solves' layout
};

}  // namespace fieldspace::basis_internal

#endif  // FIELDSPACE_CORE_BASIS_LOCAL_PROBLEM_H_
