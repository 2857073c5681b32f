#ifndef FIELDSPACE_CORE_LINALG_LANCZOS_H_
#define FIELDSPACE_CORE_LINALG_LANCZOS_H_

#include <cstdint>

#include "Eigen/Core"
#include "absl/functional/function_ref.h"
#include "absl/status/status.h"
#include "absl/status/statusor.h"

namespace fieldspace {

// The one adapter to Spectra's implicitly restarted Lanczos solvers. Spectra throws (from its own
// checks, or to stop an iteration) and reports convergence through info(); both become an
// absl::Status here, so no caller includes Spectra or catches anything.

// y = T x for a symmetric n x n operator T; x and y point to n values each (never aliased). A
// non-OK status (a failed solve, a cancellation) stops the iteration and is returned unchanged.
using LanczosOperator = absl::FunctionRef<absl::Status(const double* x, double* y)>;

struct LanczosOptions {
  int64_t count = 1;              // K >= 1 eigenpairs wanted, K < n
  int64_t subspace_size = 0;      // ncv, the Lanczos basis size: K < ncv <= n
  int32_t max_iterations = 1000;  // implicit restarts
  double tolerance = 1e-10;       // relative accuracy of the Ritz values of T (Spectra's tol)
  // Prefix of every error message, e.g. "eigensolver".
  const char* context = "Lanczos";
};

struct LanczosResult {
  Eigen::VectorXd values;   // K, ordered as the function says
  Eigen::MatrixXd vectors;  // n x K, column i the eigenvector of values[i]
  int64_t iterations = 0;   // restarts
  int64_t operations = 0;   // applications of T
};

// Errors of all three functions: the operator's status unchanged; ResourceExhausted "... not
// converged ..." when fewer than K pairs converged within max_iterations; Internal for a
// numerical failure or an exception of Spectra (which includes options outside the ranges above).

// The K largest (algebraic) eigenvalues of the symmetric n x n operator T, descending, with
// orthonormal eigenvectors.
absl::StatusOr<LanczosResult> LargestEigenpairs(int64_t n, LanczosOperator T,
                                                const LanczosOptions& options);

// The K eigenvalues nearest above sigma of a symmetric n x n matrix A (all of whose eigenvalues
// exceed sigma), ascending, with orthonormal eigenvectors. `inverse` applies (A - sigma I)^-1;
// Lanczos runs on it and maps its Ritz values nu back to lambda = sigma + 1 / nu.
absl::StatusOr<LanczosResult> ShiftInvertEigenpairs(int64_t n, LanczosOperator inverse,
                                                    double sigma, const LanczosOptions& options);

// The generalized problem A x = lambda B x (A symmetric, B symmetric positive definite, both
// n x n): the K eigenvalues nearest above sigma, ascending, with B-orthonormal eigenvectors
// (X^T B X = I). `inverse` applies (A - sigma B)^-1 and `B` applies B.
absl::StatusOr<LanczosResult> GeneralizedShiftInvertEigenpairs(int64_t n, LanczosOperator inverse,
                                                               LanczosOperator B, double sigma,
                                                               const LanczosOptions& options);

}  // namespace fieldspace

#endif  // FIELDSPACE_CORE_LINALG_LANCZOS_H_
