#ifndef FIELDSPACE_CORE_LINALG_EIGENSOLVER_H_
#define FIELDSPACE_CORE_LINALG_EIGENSOLVER_H_

#include <cstdint>
#include <optional>

#include "Eigen/Core"
#include "Eigen/SparseCore"
#include "absl/status/statusor.h"
#include "core/linalg/sparse_cholesky.h"

namespace fieldspace {

struct EigenOptions {
  int32_t count = 10;  // K >= 1 lowest eigenpairs wanted
  // Relative accuracy of the Ritz values of the shift-inverted operator (Spectra's tol).
  double tolerance = 1e-10;
  int32_t max_iterations = 1000;  // implicit restarts of the Lanczos process
  // The shift sigma of the shift-invert transformation; must be below the whole spectrum so that
  // S - sigma M is positive definite (true for any sigma < 0 when S is PSD, even with a kernel).
  // Unset: sigma = -relative_shift * max_i S_ii / M_ii, a small negative number on the scale of
  // the largest eigenvalue, which keeps S - sigma M well conditioned (cond <~ 1 / relative_shift).
  std::optional<double> shift;
  double relative_shift = 1e-8;
  // Lanczos basis size ncv; 0: min(k, max(2 K + 1, K + 20)).
  int32_t subspace_size = 0;
  bool compute_vectors = true;
  // Single-vector Lanczos can miss copies of (numerically) repeated eigenvalues: symmetric meshes,
  // harmonic kernels, the degenerate lowest pair of a region. When true, a small Lanczos run on
  // the operator deflated by the pairs found looks for anything missed below the K-th value and
  // merges it (Rayleigh-Ritz), repeating until nothing is found. Best effort: it catches copies
  // separated from the K-th value (the failure seen in practice), not ones that differ from it by
  // less than ~1e-6 relative. Costs a few dozen extra solves.
  bool verify_multiplicities = true;
  // Problems with at most this many rows are solved densely (Spectra needs K < k and ncv <= k,
  // and a dense solve is faster for small k anyway).
  int64_t dense_max_size = 300;
  CholeskyOptions cholesky;
};

struct EigenResult {
  // K eigenvalues, ascending.
  Eigen::VectorXd values;
  // k x K, column i the eigenvector of values[i], M-orthonormal (X^T M X = I). Empty when
  // compute_vectors is false.
  Eigen::MatrixXd vectors;
  double shift = 0.0;      // sigma actually used
  int64_t iterations = 0;  // Lanczos restarts (0 for the dense path)
  int64_t operations = 0;  // applications of (S - sigma M)^-1 (0 for the dense path)
  int32_t recovered = 0;   // eigenpairs found only by the multiplicity verification
};

// The K lowest eigenpairs of the generalized problem S x = lambda M x.
// S: k x k sparse symmetric (both triangles stored), all eigenvalues > sigma (PSD suffices for the
// default shift). mass: k, the diagonal of M, finite and > 0.
// Method: with y = M^1/2 x the problem is the standard symmetric one A y = lambda y with
// A = M^-1/2 S M^-1/2; Spectra's shift-invert Lanczos runs on (A - sigma I)^-1 =
// M^1/2 (S - sigma M)^-1 M^1/2, applied with one CHOLMOD factorization of S - sigma M.
// Errors: InvalidArgument for bad sizes, non-finite or asymmetric input, count outside [1, k] or
// bad options; FailedPrecondition when S - sigma M is not positive definite (S not PSD, or the
// given shift is not below the spectrum); ResourceExhausted when the Lanczos iteration does not
// converge within max_iterations; Internal for an unexpected Spectra failure.
absl::StatusOr<EigenResult> LowestEigenpairs(const Eigen::SparseMatrix<double>& S,
                                             const Eigen::VectorXd& mass,
                                             const EigenOptions& options = {});

}  // namespace fieldspace

#endif  // FIELDSPACE_CORE_LINALG_EIGENSOLVER_H_
