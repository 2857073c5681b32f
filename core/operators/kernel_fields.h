#ifndef FIELDSPACE_CORE_OPERATORS_KERNEL_FIELDS_H_
#define FIELDSPACE_CORE_OPERATORS_KERNEL_FIELDS_H_

#include <cstdint>

#include "Eigen/Core"
#include "absl/status/statusor.h"
#include "core/common/cancel.h"
#include "core/linalg/multigrid.h"
#include "core/mesh/triangle_mesh.h"
#include "core/operators/field_operator.h"
#include "core/operators/field_type.h"

namespace fieldspace {

// How the vector kernel's Poisson problem (step 3 below) is solved.
enum class PoissonSolver {
  // Conjugate gradients with a smoothed-aggregation multigrid preconditioner
  // (core/linalg/multigrid.h), falling back to kCholesky should it not converge.
  kMultigrid,
  // One sparse Cholesky factorization (CHOLMOD): exact, but its ordering and factorization take
  // about twice the multigrid's time on large meshes (15 against 9 s on 1.8M faces).
  kCholesky,
};

struct KernelFieldOptions {
  // A candidate field x (unit M-norm) is accepted into the kernel when its Rayleigh quotient
  // x^T S x is at most this times lambda_ref = trace(S) / trace(M) (the mass-weighted mean of the
  // diagonal of M^-1 S). Exact kernel fields come out at rounding level (1e-19..1e-16: x^T S x
  // sums products of size lambda_max); the lowest nonzero eigenvalues of the shared meshes are
  // 1e-5..1e-4 lambda_ref, and shrink like 1 / #F.
  double accept_tolerance = 1e-12;
  PoissonSolver poisson_solver = PoissonSolver::kMultigrid;
  // Multigrid iterations before CHOLMOD takes over (the shared meshes need 14-23; >= 1).
  int32_t poisson_max_iterations = 100;
  const CancelFlag* cancel = nullptr;
};

// Statistics of one ComputeKernelFields call (diagnostics and tests).
struct KernelFieldStats {
  int32_t candidates = 0;          // fields built before the Rayleigh-Ritz selection
  int32_t expected_harmonic = 0;   // vector fields: 2 g summed over the closed components
  double lambda_ref = 0;           // trace(S) / trace(M) (0 without S where no kernel can be)
  double max_rayleigh = 0;         // largest x^T S x / lambda_ref of the accepted columns
  double min_rejected = 0;         // smallest x^T S x / lambda_ref of the rejected ones (0: none)
  int32_t poisson_iterations = 0;  // multigrid conjugate gradient iterations (vector fields)
  bool poisson_fallback = false;   // the multigrid did not converge and CHOLMOD solved instead
  // Wall-clock seconds: candidates = trees and cocycles (vector) or transport (others);
  // poisson = assembling and solving the cotan Laplacian (vector); ritz = the
  // M-orthonormalization and Rayleigh-Ritz step; seconds = the whole call.
  double candidate_seconds = 0;
  double poisson_seconds = 0;
  double ritz_seconds = 0;
  double seconds = 0;
};

// The kernel of S (docs/conventions.md, Kernel fields): a k x q matrix (k = p #F, DOF order of
// docs/conventions.md) whose columns span { x : S x = 0 } of `op` on `mesh`, M-orthonormal
// (X^T M X = I to rounding), each with x^T S x <= accept_tolerance * lambda_ref; q may be 0.
//
// Vector fields (Hodge Laplacian): the discrete harmonic fields of Polthier and Preuss, found by
// a tree-cotree decomposition (Eppstein 2003) and a Hodge projection:
//  1. a spanning tree of the primal edges and a spanning tree of the dual graph across the
//     remaining edges (rooted at a virtual face outside every boundary) leave 1 - chi generator
//     edges per component (2 g on a closed component);
//  2. for each generator, the closed 1-form (cocycle) that is 1 on it, 0 on the other generators
//     and the tree, and closed on every face, read as a piecewise constant field (tangentially
//     continuous: no edge circulation);
//  3. its exact part G_V u removed by one P1 vertex Poisson solve (cotan Laplacian
//     G_V^T M G_V u = G_V^T M X, all generators at once: multigrid-preconditioned conjugate
//     gradients to a relative residual of 1e-10, or CHOLMOD), which leaves it divergence free at
//     every vertex;
//  4. Rayleigh-Ritz with S (through its factored form, the vertex divergences and edge
//     circulations) on the M-orthonormalized candidates (rank-revealed by the M-Gram
//     matrix). On a closed component all 2 g candidates are harmonic (an error otherwise); with a
//     boundary a field in the kernel must also have no tangential component along boundary
//     edges, and the Ritz step keeps exactly the combinations that meet that (usually none).
// n-fields and tensors (connection Laplacians, sum_e w_e |a_f0 - P_e a_f1|^2): the parallel
// fields. Per component, p fields transported from one face along a spanning tree of the dual
// graph (P_e read off the off-diagonal blocks of S), then the same Rayleigh-Ritz step: it keeps
// the directions fixed by every loop's holonomy. Tensors: always the isotropic fields c I (one
// per component), plus trace-free parallel fields on flat components; n-fields: none unless the
// component is flat for the n-fold transport.
// O(#F) plus one Poisson solve on the #V x #V cotan Laplacian (vector fields): O(#V) per
// multigrid iteration, about 10-20 iterations on the shared meshes.
// For vector fields `op` may be without S (FieldOperator::has_stiffness): everything is computed
// from the mesh then.
// InvalidArgument when `op` does not match the mesh or, for n-fields and tensors, has no S;
// Cancelled; Internal when a closed component's harmonic fields do not pass the acceptance
// (solver trouble).
absl::StatusOr<Eigen::MatrixXd> ComputeKernelFields(const TriangleMesh& mesh,
                                                    const FieldOperator& op,
                                                    const KernelFieldOptions& options = {},
                                                    KernelFieldStats* stats = nullptr);

// The same, building the operator of `type` first.
absl::StatusOr<Eigen::MatrixXd> ComputeKernelFields(const TriangleMesh& mesh, const FieldType& type,
                                                    const KernelFieldOptions& options = {});

// An upper bound of the nonzeros ComputeKernelFields' columns have (each is nonzero only on its
// component's faces, and a component has at most as many kernel fields as candidates: 2 g closed,
// 1 - chi with a boundary, for vector fields; p parallel fields otherwise), so that a basis can
// leave room for them when it lays out U (BuildBasis).
int64_t KernelEntriesBound(const TriangleMesh& mesh, const FieldType& type);

// Z^T S Z (q x q) for the vector Hodge Laplacian S of `mesh` and a k x q matrix Z in its DOF order,
// without S: the Rayleigh-Ritz step of ComputeKernelFields. Internal; exposed for its test.
Eigen::MatrixXd HodgeGram(const TriangleMesh& mesh, const MultigridRowMatrix& Z);

}  // namespace fieldspace

#endif  // FIELDSPACE_CORE_OPERATORS_KERNEL_FIELDS_H_
