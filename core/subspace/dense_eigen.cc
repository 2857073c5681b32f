#include "core/subspace/dense_eigen.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <vector>

#include "Eigen/Cholesky"
#include "Eigen/Eigenvalues"
#include "Eigen/Householder"
#include "absl/strings/str_cat.h"
#include "core/common/cancel.h"

namespace fieldspace {
namespace {

absl::Status CancelledStatus() { return absl::CancelledError("dense eigensolve cancelled"); }

constexpr Eigen::Index kBlock = 64;  // columns per cancellable block of a BLAS-3 step

// The Cholesky factor L of `a` (symmetric positive definite; its lower triangle is read and
// overwritten with L), a block of kBlock columns at a time so that cancellation is checked every
// O(n^2 kBlock) operations (Eigen's LLT takes seconds at n = 3000 and cannot be interrupted).
// FailedPrecondition if `a` is not positive definite.
absl::Status CancellableCholesky(Eigen::MatrixXd& a, const CancelFlag* cancel) {
  const Eigen::Index n = a.rows();
  for (Eigen::Index k = 0; k < n; k += kBlock) {
    if (IsCancelled(cancel)) return CancelledStatus();
    const Eigen::Index b = std::min(kBlock, n - k);
    const Eigen::Index r = n - k - b;
    Eigen::Ref<Eigen::MatrixXd> a11 = a.block(k, k, b, b);
    Eigen::LLT<Eigen::Ref<Eigen::MatrixXd>> llt(a11);  // in place
    if (llt.info() != Eigen::Success) return absl::FailedPreconditionError("not positive definite");
    if (r == 0) break;
    auto a21 = a.block(k + b, k, r, b);
    a11.triangularView<Eigen::Lower>().adjoint().solveInPlace<Eigen::OnTheRight>(a21);
    a.block(k + b, k + b, r, r).selfadjointView<Eigen::Lower>().rankUpdate(a21, -1.0);
  }
  return absl::OkStatus();
}

}  // namespace

absl::StatusOr<DenseEigenResult> LowestSymmetricEigenpairs(Eigen::MatrixXd& a, int64_t count,
                                                           bool vectors, const CancelFlag* cancel) {
  const Eigen::Index n = a.rows();
  if (a.cols() != n || n < 1) {
    return absl::InvalidArgumentError(absl::StrCat(
        "dense eigensolve: need a non-empty square matrix, got ", a.rows(), " x ", a.cols()));
  }
  if (count < 1 || count > n) {
    return absl::InvalidArgumentError(
        absl::StrCat("dense eigensolve: count ", count, " is outside [1, ", n, "]"));
  }
  double scale = 0;
  for (Eigen::Index j = 0; j < n; ++j) {
    for (Eigen::Index i = j; i < n; ++i) {
      if (!std::isfinite(a(i, j))) {
        return absl::InvalidArgumentError("dense eigensolve: the matrix has non-finite entries");
      }
      scale = std::max(scale, std::abs(a(i, j)));
    }
  }
  DenseEigenResult result;
  if (scale == 0) {
    result.values = Eigen::VectorXd::Zero(count);
    if (vectors) result.vectors = Eigen::MatrixXd::Identity(n, count);
    return result;
  }
  a.triangularView<Eigen::Lower>() /= scale;  // as Eigen: avoids over- and underflow

  // Householder tridiagonalization Q^T A Q = T, one column at a time: H_i = I - tau_i v_i v_i^T
  // with v_i = [1; a(i+2:n, i)] and the subdiagonal entry left in a(i+1, i).
  Eigen::VectorXd tau(std::max<Eigen::Index>(n - 1, 1));
  Eigen::VectorXd w(n);
  for (Eigen::Index i = 0; i + 1 < n; ++i) {
    if (IsCancelled(cancel)) return CancelledStatus();
    const Eigen::Index r = n - i - 1;
    auto v = a.col(i).tail(r);
    double beta = 0;
    v.makeHouseholderInPlace(tau[i], beta);
    v[0] = 1;
    auto A22 = a.bottomRightCorner(r, r);
    auto p = w.head(r);
    p.noalias() = tau[i] * (A22.selfadjointView<Eigen::Lower>() * v);
    p -= (0.5 * tau[i] * p.dot(v)) * v;
    A22.selfadjointView<Eigen::Lower>().rankUpdate(v, p, -1.0);
    v[0] = beta;
  }
  Eigen::VectorXd diag = a.diagonal();
  Eigen::VectorXd sub = n > 1 ? Eigen::VectorXd(a.diagonal(-1)) : Eigen::VectorXd::Zero(1);

  // Implicit symmetric QR with Wilkinson shifts (Eigen's step and deflation criterion), the
  // rotations accumulated into Z.
  Eigen::MatrixXd Z;
  if (vectors) Z.setIdentity(n, n);
  const double tiny = std::numeric_limits<double>::min();
  const double precision_inv = 1.0 / std::numeric_limits<double>::epsilon();
  const int64_t max_steps = int64_t{30} * n;
  int64_t steps = 0;
  Eigen::Index end = n - 1, start = 0;
  while (end > 0) {
    for (Eigen::Index i = start; i < end; ++i) {
      if (std::abs(sub[i]) < tiny) {
        sub[i] = 0;
      } else {
        const double scaled = precision_inv * sub[i];
        if (scaled * scaled <= std::abs(diag[i]) + std::abs(diag[i + 1])) sub[i] = 0;
      }
    }
    while (end > 0 && sub[end - 1] == 0) --end;
    if (end <= 0) break;
    if (++steps > max_steps) {
      return absl::InternalError("dense eigensolve: the QR iteration did not converge");
    }
    if (IsCancelled(cancel)) return CancelledStatus();
    start = end - 1;
    while (start > 0 && sub[start - 1] != 0) --start;
    Eigen::internal::tridiagonal_qr_step<Eigen::ColMajor>(
        diag.data(), sub.data(), start, end, vectors ? Z.data() : static_cast<double*>(nullptr), n);
  }

  std::vector<Eigen::Index> order(n);
  std::iota(order.begin(), order.end(), Eigen::Index{0});
  std::partial_sort(order.begin(), order.begin() + count, order.end(),
                    [&](Eigen::Index x, Eigen::Index y) { return diag[x] < diag[y]; });
  result.values.resize(count);
  for (int64_t k = 0; k < count; ++k) result.values[k] = diag[order[k]] * scale;
  if (!vectors) return result;

  // Eigenvectors of A: Q z, Q applied to the selected columns only, a block at a time.
  result.vectors.resize(n, count);
  for (int64_t k = 0; k < count; ++k) result.vectors.col(k) = Z.col(order[k]);
  Z.resize(0, 0);
  if (n > 1) {
    // tau has exactly n - 1 entries; the sequence keeps references to a and tau.
    const auto Q = Eigen::HouseholderSequence<Eigen::MatrixXd, Eigen::VectorXd>(a, tau)
                       .setLength(n - 1)
                       .setShift(1);
    for (Eigen::Index j = 0; j < count; j += kBlock) {
      if (IsCancelled(cancel)) return CancelledStatus();
      auto block = result.vectors.middleCols(j, std::min<Eigen::Index>(kBlock, count - j));
      Q.applyThisOnTheLeft(block);
    }
  }
  return result;
}

absl::StatusOr<DenseEigenResult> LowestGeneralizedEigenpairs(const Eigen::MatrixXd& S,
                                                             const Eigen::MatrixXd& M,
                                                             int64_t count, bool vectors,
                                                             const CancelFlag* cancel) {
  const Eigen::Index n = S.rows();
  if (S.cols() != n || M.rows() != n || M.cols() != n) {
    return absl::InvalidArgumentError("dense eigensolve: S and M must be square of equal size");
  }
  if (!M.allFinite()) {
    return absl::InvalidArgumentError("dense eigensolve: M has non-finite entries");
  }
  Eigen::MatrixXd L = M;
  if (absl::Status st = CancellableCholesky(L, cancel); !st.ok()) {
    if (absl::IsCancelled(st)) return st;
    return absl::FailedPreconditionError("dense eigensolve: M is not positive definite");
  }
  const auto lower = L.triangularView<Eigen::Lower>();
  // C = L^-1 S L^-T as L^-1 (L^-1 S)^T (S symmetric), each triangular solve a block of columns
  // at a time.
  Eigen::MatrixXd C = S.selfadjointView<Eigen::Lower>();
  for (int pass = 0; pass < 2; ++pass) {
    for (Eigen::Index j = 0; j < n; j += kBlock) {
      if (IsCancelled(cancel)) return CancelledStatus();
      auto block = C.middleCols(j, std::min<Eigen::Index>(kBlock, n - j));
      lower.solveInPlace(block);
    }
    if (pass == 0) C.transposeInPlace();
  }
  auto result = LowestSymmetricEigenpairs(C, count, vectors, cancel);
  if (!result.ok() || !vectors) return result;
  // y = L^-T z, a block of columns at a time (O(n^2) per column: seconds for a thousand).
  for (Eigen::Index j = 0; j < count; j += kBlock) {
    if (IsCancelled(cancel)) return CancelledStatus();
    auto block = result->vectors.middleCols(j, std::min<Eigen::Index>(kBlock, count - j));
    lower.adjoint().solveInPlace(block);
  }
  return result;
}

}  // namespace fieldspace
