#ifndef FIELDSPACE_CORE_SUBSPACE_SPECTRUM_H_
#define FIELDSPACE_CORE_SUBSPACE_SPECTRUM_H_

#include <cstdint>
#include <string>

#include "Eigen/Core"
#include "absl/status/statusor.h"
#include "core/basis/basis.h"
#include "core/common/cancel.h"
#include "core/operators/field_operator.h"
#include "core/subspace/reduced_system.h"

namespace fieldspace {

enum class ReducedEigenMethod : uint8_t {
  kAuto = 0,    // dense when d <= dense_max_dimension or K > d / 6, else sparse
  kDense = 1,   // generalized symmetric dense eigensolver on the d x d matrices (all pairs)
  kSparse = 2,  // Spectra shift-invert Lanczos on the sparse reduced matrices
};

struct ReducedEigenOptions {
  int32_t count = 10;  // K in [1, d]: the lowest K eigenpairs
  ReducedEigenMethod method = ReducedEigenMethod::kAuto;
  int64_t dense_max_dimension = 1500;
  bool compute_vectors = true;
  // Sparse method: Lanczos basis size (0: min(d, max(2K + 1, K + 32))), relative tolerance and
  // restarts (ResourceExhausted when not converged).
  int32_t subspace_size = 0;
  double tolerance = 1e-10;
  int32_t max_iterations = 1000;
  // Checked at every Lanczos step (sparse) and every column / QR step / block (dense): the solve
  // returns Cancelled within milliseconds of *cancel becoming true. Not owned; may be null.
  const CancelFlag* cancel = nullptr;
};

struct ReducedEigenResult {
  Eigen::VectorXd values;        // K, ascending
  Eigen::MatrixXd coefficients;  // d x K, (U^T M U)-orthonormal: the eigenfields are U y
  ReducedEigenMethod method = ReducedEigenMethod::kDense;  // the method that ran
};

// The reduced eigenproblem (paper section 8, "Laplace spectrum"): the lowest K solutions of
// (U^T S U) y = lambda (U^T M U) y, the Rayleigh-Ritz approximations from span(U) of the lowest
// eigenpairs of S x = lambda M x; each reduced eigenvalue is >= the corresponding full one.
// InvalidArgument for K outside [1, d] or bad options; ResourceExhausted when the sparse method
// does not converge; Cancelled (options.cancel); FailedPrecondition when a factorization fails;
// Internal for an unexpected solver failure.
absl::StatusOr<ReducedEigenResult> ReducedEigenpairs(const ReducedSystem& system,
                                                     const ReducedEigenOptions& options = {});
// An upper estimate of the bytes ReducedEigenpairs allocates with `options` (the method it would
// choose), for admission against a memory budget.
int64_t ReducedEigenWorkingBytes(const ReducedSystem& system, const ReducedEigenOptions& options);

// The global eigenbasis of paper section 7 (the alternative the local basis is compared with):
// U = the lowest `count` full-space eigenfields of op (S x = lambda M x), M-orthonormal, stored
// densely in the Basis format (nnz(U) = k * count). Expensive: a full-space eigensolve.
// Errors as ReferenceEigenpairs.
absl::StatusOr<Basis> BuildEigenBasis(const FieldOperator& op, int32_t count);

}  // namespace fieldspace

#endif  // FIELDSPACE_CORE_SUBSPACE_SPECTRUM_H_
