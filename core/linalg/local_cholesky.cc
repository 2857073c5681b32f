#include "core/linalg/local_cholesky.h"

#include <cholmod.h>

#include <algorithm>
#include <cmath>

#include "Eigen/Cholesky"
#include "Eigen/Core"
#include "absl/status/statusor.h"
#include "core/linalg/cholmod_util.h"

namespace fieldspace {
namespace {

using MatrixMap = Eigen::Map<Eigen::MatrixXd, 0, Eigen::OuterStride<>>;

// Below these sizes plain loops beat Eigen's blocked kernels (whose packing and dispatch
// overheads dominate for the many tiny supernodes near the leaves of the elimination tree).
constexpr int64_t kSmallUpdate = 4096;  // ndcol * ndrow1 * ndrow2 of a descendant update
constexpr int32_t kSmallPanel = 24;     // columns of a supernode

// Triangular solves with the supernodal factor on p right-hand sides stored row-major (row k of
// the permuted system at x + k * p). P > 0 fixes p at compile time.
template <int P>
void ForwardSolve(int32_t p_runtime, int32_t nsuper, const int32_t* super, const int32_t* lpi,
                  const int32_t* lpx, const int32_t* ls, const double* lx, double* x) {
  const int32_t p = P > 0 ? P : p_runtime;
  for (int32_t s = 0; s < nsuper; ++s) {
    const int32_t k1 = super[s];
    const int32_t nscol = super[s + 1] - k1;
    const int32_t psi = lpi[s];
    const int32_t nsrow = lpi[s + 1] - psi;
    const int32_t* rows = ls + psi;
    const double* l = lx + lpx[s];
    for (int32_t j = 0; j < nscol; ++j) {
      const double* lj = l + static_cast<int64_t>(j) * nsrow;
      double* xj = x + static_cast<int64_t>(k1 + j) * p;
      const double inv = 1.0 / lj[j];
      for (int32_t c = 0; c < p; ++c) xj[c] *= inv;
      for (int32_t i = j + 1; i < nsrow; ++i) {
        double* xi = x + static_cast<int64_t>(rows[i]) * p;
        const double a = lj[i];
        for (int32_t c = 0; c < p; ++c) xi[c] -= a * xj[c];
      }
    }
  }
}

template <int P>
void BackwardSolve(int32_t p_runtime, int32_t nsuper, const int32_t* super, const int32_t* lpi,
                   const int32_t* lpx, const int32_t* ls, const double* lx, double* x) {
  const int32_t p = P > 0 ? P : p_runtime;
  double acc[64];
  for (int32_t s = nsuper - 1; s >= 0; --s) {
    const int32_t k1 = super[s];
    const int32_t nscol = super[s + 1] - k1;
    const int32_t psi = lpi[s];
    const int32_t nsrow = lpi[s + 1] - psi;
    const int32_t* rows = ls + psi;
    const double* l = lx + lpx[s];
    for (int32_t j = nscol - 1; j >= 0; --j) {
      const double* lj = l + static_cast<int64_t>(j) * nsrow;
      double* xj = x + static_cast<int64_t>(k1 + j) * p;
      for (int32_t c = 0; c < p; ++c) acc[c] = xj[c];
      for (int32_t i = j + 1; i < nsrow; ++i) {
        const double* xi = x + static_cast<int64_t>(rows[i]) * p;
        const double a = lj[i];
        for (int32_t c = 0; c < p; ++c) acc[c] -= a * xi[c];
      }
      const double inv = 1.0 / lj[j];
      for (int32_t c = 0; c < p; ++c) xj[c] = acc[c] * inv;
    }
  }
}
using ConstMatrixMap = Eigen::Map<const Eigen::MatrixXd, 0, Eigen::OuterStride<>>;

// The supernodal structure of a CHOLMOD symbolic factor (CHOLMOD_INT indices): the fill-reducing
// permutation, the first column of each supernode, the offsets of its row indices (in ls) and of
// its values (in lx), and the number of supernodes.
struct Layout {
  const int32_t* perm;
  const int32_t* super;
  const int32_t* lpi;
  const int32_t* lpx;
  const int32_t* ls;
  int32_t nsuper;
};

Layout LayoutOf(const cholmod_factor* L) {
  return {static_cast<const int32_t*>(L->Perm), static_cast<const int32_t*>(L->super),
          static_cast<const int32_t*>(L->pi),   static_cast<const int32_t*>(L->px),
          static_cast<const int32_t*>(L->s),    static_cast<int32_t>(L->nsuper)};
}

// L L^T x = b on p row-major right-hand sides (as ForwardSolve and BackwardSolve).
template <int P>
void Substitute(int32_t p, int32_t nsuper, const int32_t* super, const int32_t* lpi,
                const int32_t* lpx, const int32_t* ls, const double* lx, double* x) {
  ForwardSolve<P>(p, nsuper, super, lpi, lpx, ls, lx, x);
  BackwardSolve<P>(p, nsuper, super, lpi, lpx, ls, lx, x);
}

// Substitute<p> for the common small p (one to four fields per region solve), Substitute<0>
// (p at run time) otherwise.
constexpr int32_t kNumSubstitute = 5;
constexpr decltype(&Substitute<0>) kSubstitute[kNumSubstitute] = {
    Substitute<0>, Substitute<1>, Substitute<2>, Substitute<3>, Substitute<4>};

}  // namespace

LocalCholesky::LocalCholesky() : common_(std::make_unique<linalg_internal::CholmodCommon>()) {
  cholmod_common& c = **common_;
  // AMD only (METIS gives ~40% fewer flops here but its ordering costs more than it saves),
  // postordered, supernodal structure with CHOLMOD's default relaxed amalgamation.
  c.nmethods = 1;
  c.method[0].ordering = CHOLMOD_AMD;
  c.postorder = 1;
  c.supernodal = CHOLMOD_SUPERNODAL;
  c.final_ll = 1;
  // Fundamental supernodes only (no relaxed amalgamation): the kernels below are efficient on
  // small supernodes, and the explicit zeros that amalgamation adds cost more in the many solves
  // than they save in the factorization (measured: ~12% faster per region overall).
  for (int i = 0; i < 3; ++i) {
    c.nrelax[i] = 0;
    c.zrelax[i] = 0.0;
  }
}

LocalCholesky::~LocalCholesky() { FreeSymbolic(); }

void LocalCholesky::FreeSymbolic() {
  if (symbolic_ != nullptr) cholmod_free_factor(&symbolic_, common_->get());
  symbolic_ = nullptr;
}

absl::Status LocalCholesky::Factorize(const UpperCsc& A, const CancelToken& cancel) {
  FreeSymbolic();
  n_ = A.n;
  const int32_t n = A.n;
  if (n == 0) return absl::OkStatus();
  cholmod_sparse a = linalg_internal::UpperView(n, A.outer.data(), A.inner.data(), A.values.data(),
                                                /*sorted=*/false);
  absl::StatusOr<cholmod_factor*> symbolic =
      linalg_internal::Analyze(&a, common_->get(), "local system");
  if (!symbolic.ok()) return symbolic.status();
  symbolic_ = *symbolic;
  flops_ = (*common_)->fl;
  const auto [perm, super, lpi, lpx, ls, nsuper] = LayoutOf(symbolic_);

  // C = P A P^T, lower triangle, by counting sort on the permuted column.
  pinv_.resize(n);
  for (int32_t k = 0; k < n; ++k) pinv_[perm[k]] = k;
  c_outer_.assign(static_cast<size_t>(n) + 1, 0);
  for (int32_t j = 0; j < n; ++j) {
    for (int32_t p = A.outer[j]; p < A.outer[j + 1]; ++p) {
      ++c_outer_[std::min(pinv_[A.inner[p]], pinv_[j]) + 1];
    }
  }
  for (int32_t j = 0; j < n; ++j) c_outer_[j + 1] += c_outer_[j];
  c_inner_.resize(A.inner.size());
  c_values_.resize(A.inner.size());
  {
    map_.assign(c_outer_.begin(), c_outer_.end() - 1);  // cursors
    for (int32_t j = 0; j < n; ++j) {
      for (int32_t p = A.outer[j]; p < A.outer[j + 1]; ++p) {
        const int32_t pi = pinv_[A.inner[p]];
        const int32_t pj = pinv_[j];
        const int32_t q = map_[std::min(pi, pj)]++;
        c_inner_[q] = std::max(pi, pj);
        c_values_[q] = A.values[p];
      }
    }
  }

  // Left-looking supernodal numeric factorization (CHOLMOD's t_cholmod_super_numeric scheme).
  super_map_.resize(n);
  for (int32_t s = 0; s < nsuper; ++s) {
    for (int32_t k = super[s]; k < super[s + 1]; ++k) super_map_[k] = s;
  }
  map_.assign(n, 0);
  head_.assign(nsuper, -1);
  next_.assign(nsuper, -1);
  lpos_.assign(nsuper, 0);
  lx_.resize(symbolic_->xsize);
  for (int32_t s = 0; s < nsuper; ++s) {
    const int32_t k1 = super[s];
    const int32_t k2 = super[s + 1];
    const int32_t nscol = k2 - k1;
    const int32_t psi = lpi[s];
    const int32_t nsrow = lpi[s + 1] - psi;
    double* lsx = lx_.data() + lpx[s];
    for (int32_t i = 0; i < nsrow; ++i) map_[ls[psi + i]] = i;
    // Assemble the columns of C into the zeroed block.
    std::fill(lsx, lsx + static_cast<int64_t>(nsrow) * nscol, 0.0);
    for (int32_t j = k1; j < k2; ++j) {
      double* col = lsx + static_cast<int64_t>(j - k1) * nsrow;
      for (int32_t p = c_outer_[j]; p < c_outer_[j + 1]; ++p)
        col[map_[c_inner_[p]]] += c_values_[p];
    }
    // Updates from every descendant d whose row pattern meets columns [k1, k2).
    for (int32_t d = head_[s]; d != -1;) {
      const int32_t dnext = next_[d];
      const int32_t pdi = lpi[d];
      const int32_t ndrow = lpi[d + 1] - pdi;
      const int32_t ndcol = super[d + 1] - super[d];
      const int32_t p = lpos_[d];
      int32_t q = p;
      while (q < ndrow && ls[pdi + q] < k2) ++q;
      const int32_t ndrow1 = q - p;      // rows of d inside [k1, k2)
      const int32_t ndrow2 = ndrow - p;  // rows of d from k1 on
      const int32_t* rows = ls + pdi + p;
      const double* ldx = lx_.data() + lpx[d];
      if (static_cast<int64_t>(ndcol) * ndrow1 * ndrow2 <= kSmallUpdate) {
        // Small: rank-1 updates scattered directly (no temporary, no GEMM call overhead).
        for (int32_t k = 0; k < ndcol; ++k) {
          const double* lk = ldx + static_cast<int64_t>(k) * ndrow + p;
          for (int32_t jj = 0; jj < ndrow1; ++jj) {
            const double a = lk[jj];
            if (a == 0.0) continue;
            double* col = lsx + static_cast<int64_t>(rows[jj] - k1) * nsrow;
            for (int32_t ii = jj; ii < ndrow2; ++ii) col[map_[rows[ii]]] -= a * lk[ii];
          }
        }
      } else {
        ConstMatrixMap ld(ldx, ndrow, ndcol, Eigen::OuterStride<>(ndrow));
        if (update_.size() < static_cast<size_t>(ndrow2) * ndrow1) {
          update_.resize(static_cast<size_t>(ndrow2) * ndrow1);
        }
        Eigen::Map<Eigen::MatrixXd> c(update_.data(), ndrow2, ndrow1);
        c.noalias() = ld.middleRows(p, ndrow2) * ld.middleRows(p, ndrow1).transpose();
        for (int32_t jj = 0; jj < ndrow1; ++jj) {
          double* col = lsx + static_cast<int64_t>(rows[jj] - k1) * nsrow;
          const double* cj = update_.data() + static_cast<int64_t>(jj) * ndrow2;
          for (int32_t ii = jj; ii < ndrow2; ++ii) col[map_[rows[ii]]] -= cj[ii];
        }
      }
      lpos_[d] = q;
      if (q < ndrow) {
        const int32_t s2 = super_map_[ls[pdi + q]];
        next_[d] = head_[s2];
        head_[s2] = d;
      }
      d = dnext;
    }
    head_[s] = -1;
    bool positive = true;
    if (nscol <= kSmallPanel) {
      // Right-looking Cholesky of the whole nsrow x nscol panel (diagonal block and the rows
      // below it at once).
      for (int32_t j = 0; j < nscol && positive; ++j) {
        double* cj = lsx + static_cast<int64_t>(j) * nsrow;
        const double djj = cj[j];
        if (!(djj > 0.0) || !std::isfinite(djj)) {
          positive = false;
          break;
        }
        const double ljj = std::sqrt(djj);
        cj[j] = ljj;
        const double inv = 1.0 / ljj;
        for (int32_t i = j + 1; i < nsrow; ++i) cj[i] *= inv;
        for (int32_t k = j + 1; k < nscol; ++k) {
          double* ck = lsx + static_cast<int64_t>(k) * nsrow;
          const double a = cj[k];
          for (int32_t i = k; i < nsrow; ++i) ck[i] -= a * cj[i];
        }
      }
    } else {
      MatrixMap block(lsx, nsrow, nscol, Eigen::OuterStride<>(nsrow));
      Eigen::Ref<Eigen::MatrixXd> diag = block.topRows(nscol);
      Eigen::LLT<Eigen::Ref<Eigen::MatrixXd>> llt(diag);
      positive = llt.info() == Eigen::Success;
      if (positive && nsrow > nscol) {
        auto below = block.bottomRows(nsrow - nscol);
        block.topRows(nscol)
            .triangularView<Eigen::Lower>()
            .transpose()
            .solveInPlace<Eigen::OnTheRight>(below);
      }
    }
    if (!positive) {
      FreeSymbolic();
      return absl::FailedPreconditionError("local system is not numerically positive definite");
    }
    if (nsrow > nscol) {
      lpos_[s] = nscol;
      const int32_t s2 = super_map_[ls[psi + nscol]];
      next_[s] = head_[s2];
      head_[s2] = s;
    }
    if ((s & 255) == 0 && cancel.Check()) {
      FreeSymbolic();
      return absl::CancelledError("basis construction cancelled");
    }
  }
  return absl::OkStatus();
}

void LocalCholesky::SolveInPlace(double* X, int32_t p) {
  const int32_t n = n_;
  if (n == 0 || p == 0) return;
  const auto [perm, super, lpi, lpx, ls, nsuper] = LayoutOf(symbolic_);
  // Permuted right-hand sides, row-major (row k at xp + k p): the updates of a supernode touch
  // whole rows, one cache line each for small p.
  for (int32_t c0 = 0; c0 < p; c0 += 64) {
    const int32_t pc = std::min<int32_t>(64, p - c0);
    xp_.resize(static_cast<size_t>(n) * pc);
    double* xp = xp_.data();
    for (int32_t k = 0; k < n; ++k) {
      for (int32_t c = 0; c < pc; ++c)
        xp[static_cast<int64_t>(k) * pc + c] = X[static_cast<int64_t>(c0 + c) * n + perm[k]];
    }
    kSubstitute[pc < kNumSubstitute ? pc : 0](pc, nsuper, super, lpi, lpx, ls, lx_.data(), xp);
    for (int32_t k = 0; k < n; ++k) {
      for (int32_t c = 0; c < pc; ++c)
        X[static_cast<int64_t>(c0 + c) * n + perm[k]] = xp[static_cast<int64_t>(k) * pc + c];
    }
  }
}

}  // namespace fieldspace
