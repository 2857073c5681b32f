#include "core/subspace/model_problem.h"

#include <algorithm>
#include <cmath>
#include <optional>
#include <utility>
#include <vector>

#include "absl/strings/str_cat.h"
#include "core/common/cancel.h"
#include "core/common/index_check.h"
#include "core/common/status_macros.h"
#include "core/subspace/kkt_solver.h"
#include "oneapi/tbb/blocked_range.h"
#include "oneapi/tbb/enumerable_thread_specific.h"
#include "oneapi/tbb/parallel_for.h"

namespace fieldspace {

EnergyWeights EffectiveEnergyWeights(const ReducedSystem& system, const EnergyWeights& weights,
                                     bool scale_free) {
  EnergyWeights w = weights;
  if (scale_free) w.mu_b *= system.mass().sum() / system.dofs_per_face();
  return w;
}

absl::Status ValidateSolveOptions(const ReducedSolveOptions& o) {
  if (!(o.regularization >= 0) || !(o.max_regularization >= o.regularization) ||
      !std::isfinite(o.max_regularization) || !(o.tolerance >= 0) || o.max_refinement_steps < 0 ||
      o.max_iterations < 1 || !(o.dependence_tolerance > 0) || !(o.dependence_tolerance < 1)) {
    return absl::InvalidArgumentError(
        "ReducedSolveOptions: need 0 <= regularization <= max_regularization < inf, "
        "tolerance >= 0, max_refinement_steps >= 0, max_iterations >= 1 and "
        "0 < dependence_tolerance < 1");
  }
  return absl::OkStatus();
}

absl::StatusOr<ReducedSolution> SolveReducedModelProblem(const ReducedSystem& system,
                                                         const ModelProblem& problem,
                                                         const ReducedSolveOptions& options) {
  RETURN_IF_ERROR(ValidateSolveOptions(options));
  RETURN_IF_ERROR(ValidateWeightsWithoutDataTerm(problem.weights));
  const EnergyWeights w = EffectiveEnergyWeights(system, problem.weights, problem.scale_free);
  for (const FieldConstraint& c : problem.constraints) {
    RETURN_IF_ERROR(ValidateConstraint(c, system.num_faces(), system.type()));
  }
  const absl::Status cancelled_error = absl::CancelledError("reduced model solve cancelled");
  if (IsCancelled(options.cancel)) return cancelled_error;
  const int64_t d = system.dimension();
  // A_s = U^T (mu_S S + mu_B B) U + mu_C sum_soft w_i U_i^T U_i, b = mu_C sum_soft w_i U_i^T c_i.
  Eigen::SparseMatrix<double> A = system.stiffness();
  {
    double* a = A.valuePtr();
    const double* s = system.stiffness().valuePtr();
    const double* bl = system.bilaplacian().valuePtr();
    for (int64_t p = 0; p < A.nonZeros(); ++p) a[p] = w.mu_s * s[p] + w.mu_b * bl[p];
  }
  Eigen::VectorXd b = Eigen::VectorXd::Zero(d);
  const bool any_soft = std::any_of(problem.constraints.begin(), problem.constraints.end(),
                                    [](const FieldConstraint& c) { return !c.hard(); });
  if (any_soft && w.mu_c > 0) {
    const size_t n = problem.constraints.size();
    // Scale-free: each soft weight is divided by its face's stiffness under the energy alone.
    std::optional<SupernodalFactor> energy;
    if (problem.scale_free) {
      double tau0 = 0;
      ASSIGN_OR_RETURN(energy, FactorizeRegularized(system.pattern_symbolic(),
                                                    ShiftKernelColumns(system, A), options, &tau0));
      if (IsCancelled(options.cancel)) return cancelled_error;
    }
    // The soft terms mu U_f^T U_f go straight into A's values: every pair of columns nonzero at a
    // common face is an entry of U^T M U, so of the shared pattern. Per thread one value array and
    // one right-hand side (O(nnz(A) + d) memory, whatever the number of constraints), summed at
    // the end; cancellation is checked per block of constraints.
    struct Partial {
      std::vector<double> values;
      Eigen::VectorXd b;
      bool outside = false;  // an entry outside the pattern (cannot happen; checked anyway)
      absl::Status error;    // the first FaceStiffness failure of this thread
    };
    const int64_t nnz = A.nonZeros();
    tbb::enumerable_thread_specific<Partial> partials([&] {
      return Partial{std::vector<double>(nnz, 0.0), Eigen::VectorXd::Zero(d), false, {}};
    });
    const int32_t* outer = A.outerIndexPtr();
    const int32_t* inner = A.innerIndexPtr();
    tbb::parallel_for(
        tbb::blocked_range<size_t>(0, n, 256), [&](const tbb::blocked_range<size_t>& range) {
          if (IsCancelled(options.cancel)) return;
          Partial& part = partials.local();
          for (size_t i = range.begin(); i != range.end() && part.error.ok(); ++i) {
            const FieldConstraint& c = problem.constraints[i];
            if (c.hard()) continue;
            const std::vector<SparseRow> rows = BasisRowsOfFace(system, c.face);
            double stiffness = 1.0;
            if (energy.has_value()) {
              absl::StatusOr<double> g = FaceStiffness(system, *energy, rows);
              if (!g.ok()) {
                part.error = absl::Status(
                    g.status().code(),
                    absl::StrCat("constraint on face ", c.face, ": ", g.status().message()));
                break;
              }
              stiffness = *g;
            }
            const double mu = w.mu_c * c.weight / stiffness;
            for (size_t comp = 0; comp < rows.size(); ++comp) {
              const SparseRow& row = rows[comp];
              for (size_t q = 0; q < row.cols.size(); ++q) {
                const int32_t col = row.cols[q];
                part.b[col] += mu * row.vals[q] * c.value[comp];
                const int32_t* begin = inner + outer[col];
                const int32_t* end = inner + outer[col + 1];
                for (size_t t = 0; t < row.cols.size(); ++t) {
                  const int32_t* at = std::lower_bound(begin, end, row.cols[t]);
                  if (at == end || *at != row.cols[t]) {
                    part.outside = true;
                    continue;
                  }
                  part.values[at - inner] += mu * row.vals[t] * row.vals[q];
                }
              }
            }
          }
        });
    for (const Partial& part : partials) RETURN_IF_ERROR(part.error);
    if (IsCancelled(options.cancel)) return cancelled_error;
    double* a = A.valuePtr();
    for (const Partial& part : partials) {
      if (part.outside) {
        return absl::InternalError(
            "a soft constraint's entries fall outside the reduced system's pattern");
      }
      for (int64_t q = 0; q < nnz; ++q) a[q] += part.values[q];
      b += part.b;
    }
  }
  std::shared_ptr<const SupernodalSymbolic> symbolic = system.pattern_symbolic();
  if (!symbolic->SamePattern(A)) {
    ASSIGN_OR_RETURN(symbolic, SupernodalSymbolic::Analyze(A));
  }
  double tau = 0;
  if (IsCancelled(options.cancel)) return cancelled_error;
  ASSIGN_OR_RETURN(SupernodalFactor factor,
                   FactorizeRegularized(symbolic, ShiftKernelColumns(system, A), options, &tau));
  ASSIGN_OR_RETURN(SupernodalMatrix A_panels, SupernodalMatrix::Create(symbolic, A));

  KktSolver kkt(d, system.dofs_per_face(), options);
  for (const FieldConstraint& c : problem.constraints) {
    if (!c.hard()) continue;
    kkt.Append(BasisRowsOfFace(system, c.face), c.value, 0.0, /*hard=*/true);
  }
  if (IsCancelled(options.cancel)) return cancelled_error;
  RETURN_IF_ERROR(kkt.SetMatrix(&A_panels, &factor));
  if (problem.biharmonic == BiharmonicForm::kMixed) kkt.SetMixedBiharmonic(&system, w.mu_b);
  if (IsCancelled(options.cancel)) return cancelled_error;
  RETURN_IF_ERROR(kkt.FactorizeSchur());
  if (IsCancelled(options.cancel)) return cancelled_error;
  ReducedSolution solution = kkt.Solve(&b);
  if (IsCancelled(options.cancel)) return cancelled_error;  // the mixed form's iterations stop
  solution.regularization = tau;
  return solution;
}

int64_t SolveWorkingBytes(const ReducedSystem& system, int64_t soft, int64_t hard, bool scale_free,
                          int32_t threads) {
  const int64_t d = system.dimension();
  const int64_t p = system.dofs_per_face();
  const int64_t nnz = system.stats().pattern_nonzeros;
  const int64_t factor = system.stats().factor_nonzeros;
  // A, its kernel-shifted copy and the supernodal panels of A; the factor (twice when scale-free:
  // the energy's own factorization for the stiffnesses).
  int64_t bytes = 2 * nnz * 12 + factor * 8 + factor * 8 * (scale_free ? 2 : 1);
  if (soft > 0) bytes += std::max<int64_t>(threads, 1) * (nnz + d) * 8;  // per-thread sums
  // Hard constraint rows: A^-1 G^T (d x h) and the h x h Schur complement, with its factor.
  const int64_t h = hard * p;
  bytes += h * d * 8 + 2 * h * h * 8;
  // Each FieldConstraint: face, kind, weight and a heap vector of p doubles (with its header).
  bytes += (soft + hard) * (static_cast<int64_t>(sizeof(FieldConstraint)) + 8 * p + 16);
  // Working vectors (about 16 with the mixed biharmonic's conjugate gradients).
  return bytes + 16 * d * 8;
}

}  // namespace fieldspace
