#ifndef FIELDSPACE_CORE_SUBSPACE_REDUCED_SYSTEM_H_
#define FIELDSPACE_CORE_SUBSPACE_REDUCED_SYSTEM_H_

#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <string_view>

#include "Eigen/Core"
#include "Eigen/SparseCore"
#include "absl/status/statusor.h"
#include "core/basis/basis.h"
#include "core/common/cancel.h"
#include "core/linalg/supernodal_cholesky.h"
#include "core/mesh/triangle_mesh.h"
#include "core/operators/field_operator.h"
#include "core/operators/field_type.h"
#include "core/subspace/lift_plan.h"
#include "core/subspace/subspace_util.h"

namespace fieldspace {

class VectorHodgeRows;  // core/operators/vector_laplacian.h

struct ReducedSystemOptions {
  // Worker threads for the precomputation (0: all available cores).
  int32_t threads = 0;
  // Memory for the per-thread dense accumulators of the reduced matrices. When d x d accumulators
  // for all threads do not fit, the output columns are processed in bands (more passes over U).
  int64_t accumulator_budget_bytes = int64_t{768} << 20;
  // Try several fill-reducing orderings (AMD, METIS, ...) for the shared symbolic analysis and
  // keep the cheapest: costs ~10x the analysis time once per basis, saves ~25% of every
  // refactorization in interactive sessions.
  bool thorough_ordering = true;
  // Checked while the reduced matrices are computed; when it becomes true Build returns
  // Cancelled.
  const CancelFlag* cancel = nullptr;
  // Called from any thread with the fraction of the product pass done (about 100 calls).
  std::function<void(double fraction)> progress;
  // Keep only the LiftPlan, a face-major copy of U (see lift_plan.h), and serve every row of U
  // from it: basis() then has U's dimensions but none of its nonzeros, and the caller's Basis may
  // be dropped. A daemon's served basis saves U's 8 bytes a nonzero (595 MB on 1.38M faces at
  // d = 2000: bench/RESULTS.md, Session 23). Results are those of U up to the summation order.
  bool release_basis_rows = false;
};

struct ReducedSystemStats {
  int64_t stiffness_nonzeros = 0;    // numerically nonzero entries of U^T S U (both triangles)
  int64_t bilaplacian_nonzeros = 0;  // of U^T B U
  int64_t mass_nonzeros = 0;         // of U^T M U
  int64_t pattern_nonzeros = 0;      // of the shared pattern (union of the three)
  int64_t factor_nonzeros = 0;       // of the Cholesky factor of a matrix on that pattern
  double factor_flops = 0;           // of one numeric factorization on that pattern
  double products_seconds = 0;       // computing the three reduced matrices (0 when given)
  bool products_given = false;       // built from ReducedMatrices computed earlier
  double analysis_seconds = 0;       // ordering + symbolic analysis
  double mass_factor_seconds = 0;    // factorizing U^T M U
  double total_seconds = 0;
  int64_t memory_bytes = 0;  // held by the ReducedSystem itself (not counting the Basis)
};

// The three reduced matrices of a ReducedSystem on their shared pattern: d x d, both triangles,
// compressed, one symmetric pattern with every diagonal entry (ReducedSystem::stiffness() etc.).
// What the product pass over U computes, and what a store keeps so that a basis loaded again
// skips that pass (EncodeReducedMatrices).
struct ReducedMatrices {
  Eigen::SparseMatrix<double> stiffness;    // U^T S U
  Eigen::SparseMatrix<double> bilaplacian;  // U^T B U
  Eigen::SparseMatrix<double> mass_matrix;  // U^T M U
};

// The per-basis precomputation of the subspace methods (paper section 5; docs/conventions.md,
// Reduced quantities): the reduced matrices U^T S U, U^T B U (B = S M^-1 S) and U^T M U, the
// symbolic analysis shared by every factorization of a weighted combination of them, and the
// factorization of U^T M U used by projections. Immutable after Build(): share one instance between
// any number of threads and sessions (all accessors are const, nothing is computed lazily).
class ReducedSystem {
 public:
  // basis->U: k x d (k = op.dofs(), d >= 1), finite; op: the operator the basis was built for
  // (same field type), S k x k symmetric PSD, mass k positive. B is never formed in the full
  // space: U^T B U = (S U)^T M^-1 (S U). Products accumulate in double (U is stored in float; the
  // reduced matrices are exact for the float-valued basis up to double rounding).
  // InvalidArgument for mismatched or non-finite input; FailedPrecondition when U^T M U is not
  // positive definite (linearly dependent or zero columns of U); Cancelled (options.cancel).
  static absl::StatusOr<std::shared_ptr<const ReducedSystem>> Build(
      std::shared_ptr<const Basis> basis, const FieldOperator& op,
      const ReducedSystemOptions& options = {});
  // The same for the operator of basis->type on `mesh` (BuildFieldOperator's), bit for bit: for
  // vector fields S's rows are computed from the mesh as the pass reads them (VectorHodgeRows)
  // and S is never assembled (867 MB less on 1.38M faces); other fields assemble S for the pass.
  // InvalidArgument also when U's rows are not the mesh's DOFs.
  static absl::StatusOr<std::shared_ptr<const ReducedSystem>> Build(
      std::shared_ptr<const Basis> basis, const TriangleMesh& mesh,
      const ReducedSystemOptions& options = {});
  // The same from the reduced matrices computed earlier for this basis and operator (e.g. by
  // DecodeReducedMatrices from a store) and the operator's mass alone (`mass`: k positive values,
  // BuildFaceMass): no product pass and no stiffness, the rest as above. The caller vouches that
  // they belong to `basis` (a store ties them to the basis file's checksum). InvalidArgument also
  // when they are not d x d on one symmetric pattern with every diagonal entry, or not finite.
  static absl::StatusOr<std::shared_ptr<const ReducedSystem>> Build(
      std::shared_ptr<const Basis> basis, Eigen::VectorXd mass, ReducedMatrices matrices,
      const ReducedSystemOptions& options = {});

  // The same for a basis read as a LiftPlan (LiftPlan::StreamBuilder from the basis file, what a
  // daemon loads): `basis` has U's k x d dimensions and no nonzeros, `plan` is U. The system is
  // one built with release_basis_rows. InvalidArgument also when `basis` has nonzeros or `plan`
  // is not k x d with the basis's DOFs per face.
  static absl::StatusOr<std::shared_ptr<const ReducedSystem>> Build(
      std::shared_ptr<const Basis> basis, LiftPlan plan, Eigen::VectorXd mass,
      ReducedMatrices matrices, const ReducedSystemOptions& options = {});

  // The basis; without its rows (U has no nonzeros) when built with release_basis_rows: read them
  // through BasisRowOf.
  const Basis& basis() const { return *basis_; }
  bool basis_rows_released() const { return rows_released_; }
  // Row i of U (i < k), from U or, once released, copied from the LiftPlan into `scratch`.
  BasisRow BasisRowOf(int64_t i, BasisRowScratch* scratch) const {
    if (!rows_released_) return GetBasisRow(basis_->U, i);
    scratch->cols.clear();
    scratch->vals.clear();
    const int32_t p = dofs_per_face();
    lift_plan_.AppendRow(i / p, static_cast<int32_t>(i % p), &scratch->cols, &scratch->vals);
    return {scratch->cols.data(), scratch->vals.data(), static_cast<int64_t>(scratch->cols.size())};
  }
  const std::shared_ptr<const Basis>& shared_basis() const { return basis_; }
  const FieldType& type() const { return basis_->type; }
  int32_t dofs_per_face() const { return basis_->type.dofs_per_face(); }
  int64_t dofs() const { return basis_->U.rows(); }  // k
  int32_t num_faces() const { return static_cast<int32_t>(dofs() / dofs_per_face()); }
  int32_t dimension() const { return static_cast<int32_t>(basis_->U.cols()); }  // d

  // k: the diagonal of the full-space mass M (face areas, repeated per DOF).
  const Eigen::VectorXd& mass() const { return mass_; }
  // d x d, symmetric, both triangles stored, all three on the same sparsity pattern (so that
  // weighted sums can be formed value by value: see pattern_symbolic()).
  const Eigen::SparseMatrix<double>& stiffness() const { return stiffness_; }      // U^T S U, PSD
  const Eigen::SparseMatrix<double>& bilaplacian() const { return bilaplacian_; }  // U^T B U, PSD
  const Eigen::SparseMatrix<double>& mass_matrix() const { return mass_matrix_; }  // U^T M U, SPD
  // Symbolic analysis of that pattern, for SupernodalFactor.
  const std::shared_ptr<const SupernodalSymbolic>& pattern_symbolic() const { return symbolic_; }
  // Cholesky factorization of U^T M U.
  const SupernodalFactor& mass_factor() const { return *mass_factor_; }
  // U laid out for fast lifting (see lift_plan.h); used by the Lift overloads taking a system.
  const LiftPlan& lift_plan() const { return lift_plan_; }
  const ReducedSystemStats& stats() const { return stats_; }

 private:
  ReducedSystem() = default;
  // Both Builds from given matrices: `plan` is U when given (the basis then without rows).
  static absl::StatusOr<std::shared_ptr<const ReducedSystem>> FromMatrices(
      std::shared_ptr<const Basis> basis, std::optional<LiftPlan> plan, Eigen::VectorXd mass,
      ReducedMatrices matrices, const ReducedSystemOptions& options);
  // Both Builds by the product pass over U, with S's rows from `S` or from `hodge_rows`.
  static absl::StatusOr<std::shared_ptr<const ReducedSystem>> FromProducts(
      std::shared_ptr<const Basis> basis, const Eigen::SparseMatrix<double>* S,
      const VectorHodgeRows* hodge_rows, Eigen::VectorXd mass, const ReducedSystemOptions& options,
      std::chrono::steady_clock::time_point t_start);
  // The part of the Builds after the matrices: counts, analysis, U^T M U's factorization, the
  // lift plan (`plan`, or built from U when it has none).
  static absl::StatusOr<std::shared_ptr<const ReducedSystem>> Complete(
      std::shared_ptr<ReducedSystem> sys, std::shared_ptr<const Basis> basis, Eigen::VectorXd mass,
      const ReducedSystemOptions& options, std::chrono::steady_clock::time_point t_start,
      std::optional<LiftPlan> plan = std::nullopt);

  std::shared_ptr<const Basis> basis_;
  bool rows_released_ = false;
  Eigen::VectorXd mass_;
  Eigen::SparseMatrix<double> stiffness_;
  Eigen::SparseMatrix<double> bilaplacian_;
  Eigen::SparseMatrix<double> mass_matrix_;
  std::shared_ptr<const SupernodalSymbolic> symbolic_;
  std::unique_ptr<SupernodalFactor> mass_factor_;
  LiftPlan lift_plan_;
  ReducedSystemStats stats_;
};

// The reduced matrices of `system` as bytes, format version 1 (little-endian): magic
// "FSREDUC" 0x01, u32 version, u32 0, i64 d, i64 nnz, the shared pattern's column pointers
// (int32 x (d + 1)) and row indices (int32 x nnz), then the values of U^T S U, U^T B U and U^T M U
// (float64 x nnz each). No checksum of its own: the store's container has one.
std::string EncodeReducedMatrices(const ReducedSystem& system);
// The matrices of those bytes: DataLoss when the magic, version or sizes do not match (the bytes
// must be exactly as long as the header implies). The pattern itself is checked by Build.
absl::StatusOr<ReducedMatrices> DecodeReducedMatrices(std::string_view bytes);

struct WeightedMassOptions {
  // As ReducedSystemOptions::accumulator_budget_bytes; used only in the degenerate case below
  // (the regular pass keeps one array of the pattern's values per thread).
  int64_t accumulator_budget_bytes = int64_t{768} << 20;
  // Checked for every group of rows of U: Cancelled once true. Not owned; may be null.
  const CancelFlag* cancel = nullptr;
};

// U^T W M U (d x d, symmetric PSD, both triangles stored) for per-DOF weights W = diag(w)
// (`dof_weights`: k values, finite, >= 0): the mass matrix of a data term weighted per face or
// per DOF. Computed by the same parallel product pass over U as ReducedSystem::Build (only the
// mass product, accumulated straight onto the shared pattern): O(nnz(U) * nonzeros per row of U)
// work, O(nnz of the pattern) memory per thread. The result has the pattern of
// system.mass_matrix() (so that
// SupernodalSymbolic::SamePattern holds and weighted sums with the other reduced matrices are
// formed value by value), except in the degenerate case that it has a nonzero where all three
// precomputed matrices vanish exactly (cancellation): then it is returned on the union of both
// patterns. With w = 1 it equals mass_matrix() up to rounding. InvalidArgument for a wrong size or
// a negative or non-finite weight; Cancelled.
absl::StatusOr<Eigen::SparseMatrix<double>> WeightedMassMatrix(
    const ReducedSystem& system, const Eigen::Ref<const Eigen::VectorXd>& dof_weights,
    const WeightedMassOptions& options = {});

}  // namespace fieldspace

#endif  // FIELDSPACE_CORE_SUBSPACE_REDUCED_SYSTEM_H_
