#ifndef FIELDSPACE_CORE_SUBSPACE_KKT_SOLVER_H_
#define FIELDSPACE_CORE_SUBSPACE_KKT_SOLVER_H_

// Internal to core/subspace: the constrained-solve engine behind DesignSession and
// SolveReducedModelProblem. Not a public API.

#include <cstdint>
#include <memory>
#include <utility>
#include <vector>

#include "Eigen/Cholesky"
#include "Eigen/Core"
#include "Eigen/SparseCore"
#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/types/span.h"
#include "core/linalg/supernodal_cholesky.h"
#include "core/subspace/mixed_energy.h"
#include "core/subspace/model_problem.h"

namespace fieldspace {

// A sparse row of length d (a row of U, in double).
struct SparseRow {
  std::vector<int32_t> cols;
  std::vector<double> vals;
  double Dot(const double* x) const {
    double v = 0;
    for (size_t q = 0; q < cols.size(); ++q) v += vals[q] * x[cols[q]];
    return v;
  }
};

// Rows dofs_per_face * face + c (c < dofs_per_face) of the basis: the constraint rows U_f.
std::vector<SparseRow> BasisRowsOfFace(const ReducedSystem& system, int32_t face);

// The matrix to factorize for an energy matrix A (d x d, on the system's pattern) of a basis with
// kernel columns (Basis::kernel_columns): those columns have zero energy, so A is singular in
// their directions (to rounding, which can make a pivot negative) and a Schur complement through
// it would call any hard constraint on a face where a kernel field is nonzero dependent. Their
// diagonal entries get kKernelColumnShift * min_i (A_ii / (U^T M U)_ii) (i over the local
// columns) times their (U^T M U)_ii; solves refine against the true A, so well-posed problems
// get the exact solution, and a kernel direction no constraint controls gets 0. A copy of A
// unchanged when the basis has no kernel columns.
inline constexpr double kKernelColumnShift = 1e-6;
Eigen::SparseMatrix<double> ShiftKernelColumns(const ReducedSystem& system,
                                               const Eigen::SparseMatrix<double>& A);

// The stiffness of a face in the subspace, which scale-free soft constraints divide their weight
// by (ModelProblem::scale_free): the smallest eigenvalue of G = R F^-1 R^T (p x p) for the face's
// rows R of U (BasisRowsOfFace) and the factorization F of the energy matrix, with the entries of
// the basis's kernel columns left out of R when `skip_kernel_columns` (when the energy is the
// Laplacians' alone, whose kernel columns have zero energy: their diagonal shift,
// ShiftKernelColumns, must not enter, and a kernel direction only makes a constraint pull harder;
// with a data term they have energy like any other column and stay in). A soft constraint
// alone with weight mu / g pulls its face's DOFs G (G + (g / mu) I)^-1 of the way to its value:
// at least mu / (1 + mu) in every direction. Dimensionless (S is scale invariant). p sparse
// forward substitutions. FailedPrecondition when no (non-kernel) basis field is nonzero at the
// face.
absl::StatusOr<double> FaceStiffness(const ReducedSystem& system, const SupernodalFactor& factor,
                                     const std::vector<SparseRow>& rows,
                                     bool skip_kernel_columns = true);

// FaceStiffness from the face's forward substitutions W = L^-1 P U_f^T (d x p): the smallest
// eigenvalue of W^T W, FailedPrecondition when it vanishes against the largest (batched callers
// compute W for several faces at once).
absl::StatusOr<double> StiffnessOfSubstitutions(const Eigen::Ref<const Eigen::MatrixXd>& W);

// Factorizes `A` (on the system's shared pattern or any pattern with its own analysis) with the
// regularization policy of ReducedSolveOptions: diagonal scaled by (1 + tau), tau raised 1000x
// on failure up to max_regularization. Returns the tau used through `tau`.
absl::StatusOr<SupernodalFactor> FactorizeRegularized(
    std::shared_ptr<const SupernodalSymbolic> symbolic, const Eigen::SparseMatrix<double>& A,
    const ReducedSolveOptions& options, double* tau);

// Solves the saddle-point system
//   A x + R^T nu = b,    R x - E nu = t
// given a factorization F of A (possibly regularized: A_hat). R stacks the constraints' rows
// (p = rows_per_group rows per constraint, the rows of U at its face), E = diag(e) with
// e = 1 / (mu_C w) on a soft constraint's rows and 0 on a hard one's. For soft rows, nu = the
// scaled residual; this is exactly the minimizer of x^T A x - 2 b^T x + sum_soft (R_i x -
// t_i)^2 / e_i subject to R_h x = t_h. With F = P^T L L^T P, W = L^-1 P R^T (d x r, kept as V S
// below; R's rows are sparse, so each column costs a forward substitution over the
// elimination-tree paths of its nonzeros only) and H = R F^-1 R^T + E = W^T W + E (r x r):
//   u = L^-1 P b,  H nu = W^T u - t,  x = P^T L^-T (u - W nu),
// followed by iterative refinement against the true A (residuals are cheap sparse products, each
// correction one forward and one backward substitution). Adding a constraint costs p sparse
// forward substitutions plus O(d r p) for H's new entries; every solve one backward substitution
// (and a forward one when b != 0); every change refactorizes H (O(r^3), r = p * #constraints).
// W is kept as W = V S: V = L^-1 P B (d x s) for the constraints' sources B, S (s x r)
// block-sparse. A constraint's source is its own p rows (S's block the identity); a group edit
// whose rows touch fewer basis columns than it has rows (a stroke's faces share most of theirs)
// gets one source for all its groups, the unit vectors of the touched columns, and S's blocks are
// its rows restricted to them. So a stroke of m rows over q < m columns costs q forward
// substitutions, q columns of V and products with q columns per solve instead of m. With the
// mixed energy (SetMixed) A_hat^-1 is a signed sum of two factorizations' inverses, each with its
// own V (S is shared): H = sum_k c_k W_k^T W_k + E and x = P^T sum_k c_k L_k^-T (u_k - W_k nu).
class KktSolver {
 public:
  KktSolver(int64_t dim, int32_t rows_per_group, const ReducedSolveOptions& options);

  // The true matrix (for residuals) and the factorization used for solves; both must stay alive
  // and unchanged until the next call. Recomputes W and K for all constraints. Cancelled (W and K
  // then incomplete: call again before solving) when the options' cancel flag is set meanwhile.
  absl::Status SetMatrix(const SupernodalMatrix* A, const SupernodalFactor* factor);

  // The mixed energy mu_s K + mu_b K Mr^-1 K through its partial fractions MixedEnergyInverse
  // instead: A_s^-1 = c_1 K_s^-1 + c_2 N_s^-1, two factorizations on one pattern, so each
  // constraint keeps W_k = L_k^-1 P R^T for both (sparse forward substitutions over the rows'
  // elimination-tree reach, as in the exact form), H = sum_k c_k W_k^T W_k + E, and a solve runs
  // one backward substitution per factorization. Verified solves refine against the true matrix
  // like the exact form's. Replaces SetMatrix's matrix and factorization (and
  // SetMixedBiharmonic's conjugate gradients) until the next SetMatrix. Recomputes W and K for
  // all constraints.
  absl::Status SetMixed(std::unique_ptr<const MixedEnergyInverse> inverse);

  // The mixed biharmonic (BiharmonicForm::kMixed) with weight mu_b (> 0; 0 turns it off): the
  // true matrix becomes A - mu_b U^T B U + mu_b K Mr^-1 K (K = U^T S U, Mr = U^T M U of
  // `system`, which must stay alive), with A the matrix of SetMatrix (holding mu_b U^T B U).
  // Since the mixed term never exceeds the exact one, the factorization of A bounds the true
  // matrix from above and preconditions Solve's conjugate gradients (see Solve). Survives
  // SetMatrix.
  void SetMixedBiharmonic(const ReducedSystem* system, double mu_b);

  int32_t num_groups() const { return num_groups_; }
  // Appends a constraint (rows: p sparse rows; target: p values; e >= 0, 0 for hard). Before the
  // first SetMatrix() this only records it (SetMatrix solves for all groups at once).
  void Append(std::vector<SparseRow> rows, const Eigen::VectorXd& target, double e, bool hard);
  // Appends several constraints (as Append each) in one step: their W columns by independent
  // sparse forward substitutions (in parallel with options.parallel), then their rows and
  // columns of K in one matrix product, which a group edit (a stroke's faces) needs instead of
  // one matrix-vector product per row.
  struct NewGroup {
    std::vector<SparseRow> rows;
    Eigen::VectorXd target;
    double e = 0;
    bool hard = false;
  };
  void AppendGroups(std::vector<NewGroup> groups);
  // Replace for several groups at once (slots[i] gets groups[i], whose `hard` is set too), the
  // same way: parallel W columns, one matrix product for K.
  void ReplaceGroups(const std::vector<int32_t>& slots, std::vector<NewGroup> groups);
  void SetTarget(int32_t g, const Eigen::VectorXd& target);
  void SetE(int32_t g, double e);
  // Removes group g; the last group moves into slot g (callers track ids by slot).
  void RemoveSwapLast(int32_t g);
  const std::vector<SparseRow>& GroupRows(int32_t g) const { return rows_[g]; }
  Eigen::VectorXd GroupTarget(int32_t g) const { return t_.segment(g * p_, p_); }
  double GroupE(int32_t g) const { return e_[g * p_]; }
  bool GroupHard(int32_t g) const { return hard_[g] != 0; }

  // Factorizes H = R Z + E with the hard rows first. FailedPrecondition when the hard rows are
  // linearly dependent in the A^-1 inner product (pivot ratio below dependence_tolerance), e.g.
  // the same face constrained twice. On error the previous factorization of H is kept.
  absl::Status FactorizeSchur();

  // The solution x (d) for right-hand side b (nullptr: b = 0). Precondition: FactorizeSchur()
  // succeeded since the last change. verify = false skips the residual of the true system (and
  // with it any refinement): backward_error is then NaN. With the mixed biharmonic the solve is
  // always verified: the soft rows eliminated (A_s = A + R_s^T E_s^-1 R_s), conjugate gradients
  // on A_s in the null space of the hard rows, each step preconditioned by the KKT solve with F
  // (a constraint preconditioner, which keeps every iterate on the hard constraints), until the
  // saddle-point system's backward error is below the tolerance or max_iterations.
  ReducedSolution Solve(const Eigen::VectorXd* b, bool verify = true) const;
  // The smallest pivot of the last factorization of the scaled H (unit diagonal, so in (0, 1]):
  // near 0 when constraints are nearly dependent in the subspace. 1 without constraints.
  double schur_min_pivot() const { return schur_min_pivot_; }

 private:
  // The right-hand sides whose forward substitutions give some groups' columns of W: the rows
  // themselves (m of them), or, when they touch fewer than m basis columns (a stroke's faces),
  // those columns' unit vectors, whose substitutions Y give the columns as Y C (C: q x m, the
  // rows restricted to them).
  struct RightHandSides {
    std::vector<int32_t> touched;
    std::vector<absl::Span<const int32_t>> cols;
    std::vector<absl::Span<const double>> vals;
    bool combined = false;
    Eigen::MatrixXd C;
  };
  static constexpr double kOne = 1.0;
  void EnsureCapacity(int64_t rows);
  // Sets the terms of A_hat^-1 and recomputes every group.
  absl::Status SetTerms(std::vector<InverseTerm> terms);
  // f(k) for every term k (side by side with options.parallel).
  template <typename F>
  void ForEachTerm(const F& f) const;
  RightHandSides GroupRightHandSides(absl::Span<const int32_t> groups) const;
  // For groups whose rows changed: releases their sources and gives them new ones (one combined
  // source, or one per group; see the class comment) with their columns of every V_k (forward
  // substitutions over the rows' elimination-tree reach, the terms side by side), and with
  // `cross` R A_hat^-1 R^T's columns of their rows against all r current rows (r x p k:
  // S^T sum_k c_k V_k^T V_k S over the reach, their entries against each other included).
  Eigen::MatrixXd RecomputeGroups(absl::Span<const int32_t> groups, bool cross = true);
  void ComputeGroup(int32_t g);
  // V and K for every group (after SetMatrix / SetMixed).
  absl::Status ComputeAllGroups();
  // S^T X for X with s rows (indexed like V's columns): r rows.
  Eigen::MatrixXd ApplySt(const Eigen::Ref<const Eigen::MatrixXd>& X) const;
  // S nu (nu: r values): s values.
  Eigen::VectorXd ApplyS(const Eigen::VectorXd& nu) const;
  // Groups g0 .. g0 + n - 1's columns of W_k = V_k S (d x n p).
  Eigen::MatrixXd GroupColumns(size_t k, int32_t g0, int32_t n) const;
  // Group g no longer uses its source; a source without groups leaves V: its columns become a
  // hole (zero), and once holes are a quarter of V's columns in use the sources move down
  // (CompactSources), so that a remove costs O(d p) amortized whatever the number of sources.
  void ReleaseSource(int32_t g);
  void CompactSources();
  void EnsureSourceCapacity(int64_t cols);
  // H^-1 v (v: r values).
  Eigen::VectorXd SolveSchur(const Eigen::VectorXd& v) const;

  int64_t d_;
  int32_t p_;
  ReducedSolveOptions options_;
  const SupernodalMatrix* A_ = nullptr;              // the exact form's true matrix
  std::vector<InverseTerm> terms_;                   // A_hat^-1 = sum_k c_k F_k^-1; empty: unset
  std::unique_ptr<const MixedEnergyInverse> mixed_;  // see SetMixed
  const ReducedSystem* mixed_system_ = nullptr;      // with mixed_mu_b_ > 0: see SetMixedBiharmonic
  double mixed_mu_b_ = 0;
  int32_t num_groups_ = 0;
  std::vector<std::vector<SparseRow>> rows_;  // per group, p rows
  std::vector<char> hard_;                    // per group
  Eigen::VectorXd t_;                         // per row (capacity)
  Eigen::VectorXd e_;                         // per row (capacity)
  // The sources (class comment), in V's first v_cols_ columns in any order, with holes. A
  // group's W columns are V_k.middleCols(v0, width) C_g with C_g = C.middleCols(source_col_[g],
  // p), or V_k.middleCols(v0, p) when C is empty (the source is that group's alone).
  struct Source {
    int64_t v0 = 0;
    int64_t width = 0;
    int32_t members = 0;  // groups that use it
    Eigen::MatrixXd C;    // width x (p * groups at creation), or empty
  };
  std::vector<Source> sources_;
  std::vector<int32_t> source_of_;   // per group; -1: none yet (before SetMatrix / SetMixed)
  std::vector<int64_t> source_col_;  // per group: its first column of the source's C
  int64_t v_cols_ = 0;               // s: V's columns in use, holes included
  int64_t hole_cols_ = 0;            // columns of V no source uses (zero)
  // Per term, d x capacity: L_k^-1 P B for the sources B (permuted numbering), zero outside
  // each source's reach.
  std::vector<Eigen::MatrixXd> V_;
  Eigen::MatrixXd K_;  // capacity x capacity: R A_hat^-1 R^T = sum_k c_k W_k^T W_k
  // Factorization of the scaled, permuted H: order_[i] = row of H at position i (hard first),
  // scale_ = 1 / sqrt(diag(H)).
  std::vector<int64_t> order_;
  Eigen::VectorXd scale_;
  Eigen::LLT<Eigen::MatrixXd> schur_;
  bool schur_valid_ = false;
  double schur_min_pivot_ = 1.0;
};

}  // namespace fieldspace

#endif  // FIELDSPACE_CORE_SUBSPACE_KKT_SOLVER_H_
