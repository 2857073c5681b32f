#include "core/linalg/supernodal_cholesky.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstring>
#include <functional>
#include <limits>
#include <mutex>
#include <utility>

#include "Eigen/Cholesky"
#include "absl/strings/str_cat.h"
#include "core/common/cancel.h"
#include "core/common/status_macros.h"
#include "core/linalg/cholmod_util.h"
#include "oneapi/tbb/blocked_range.h"
#include "oneapi/tbb/parallel_for.h"

namespace fieldspace {
namespace {

using ColMajorMap = Eigen::Map<Eigen::MatrixXd, 0, Eigen::OuterStride<>>;
using RowMajorMatrix = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

// Block size of the right-looking dense factorization: large enough for Eigen's GEMM kernels to
// run near peak, small enough that the diagonal-block factorizations stay a minor cost.
constexpr int64_t kBlock = 96;
// Fronts whose partial factorization costs fewer flops run their dense kernels on one thread.
constexpr double kParallelFrontFlops = 4e6;
// Subtrees below this many flops are processed by one task.
constexpr double kParallelSubtreeFlops = 2e6;

// Flops of factoring the first nc columns of an nr x nr front (rank-1 updates of the lower part).
double FrontFlops(int64_t nr, int64_t nc) {
  double f = 0;
  for (int64_t k = 0; k < nc; ++k) {
    const double r = static_cast<double>(nr - k - 1);
    f += r * (r + 1) + r + 1;
  }
  return f;
}

// Factors the first nc columns of the symmetric nr x nr front F (column-major, leading dimension
// nr, lower triangle significant): F11 = L11 L11^T, L21 = F21 L11^-T, F22 -= L21 L21^T. Blocked
// right-looking; the upper triangle of the diagonal blocks is overwritten with junk, never read.
// Returns -1 on success, else the local column whose pivot was not positive.
int64_t PartialCholesky(double* F, int64_t nr, int64_t nc, bool parallel) {
  const bool par = parallel && FrontFlops(nr, nc) > kParallelFrontFlops;
  for (int64_t k0 = 0; k0 < nc; k0 += kBlock) {
    const int64_t kb = std::min(kBlock, nc - k0);
    ColMajorMap D(F + k0 + k0 * nr, kb, kb, Eigen::OuterStride<>(nr));
    {
      Eigen::Ref<Eigen::MatrixXd> Dref(D);
      Eigen::LLT<Eigen::Ref<Eigen::MatrixXd>, Eigen::Lower> llt(Dref);
      if (llt.info() != Eigen::Success) {
        for (int64_t j = 0; j < kb; ++j) {
          if (!(D(j, j) > 0) || !std::isfinite(D(j, j))) return k0 + j;
        }
        return k0;
      }
    }
    const int64_t r0 = k0 + kb;
    const int64_t m = nr - r0;
    if (m == 0) continue;
    // Panel below the diagonal block: P <- P L_D^-T.
    auto trsm = [&](int64_t row_begin, int64_t row_end) {
      ColMajorMap P(F + r0 + row_begin + k0 * nr, row_end - row_begin, kb,
                    Eigen::OuterStride<>(nr));
      D.transpose().triangularView<Eigen::Upper>().solveInPlace<Eigen::OnTheRight>(P);
    };
    // Trailing lower triangle: T(j0:, j0:j0+jb) -= P(j0:, :) P(j0:j0+jb, :)^T per column block.
    auto update = [&](int64_t j0, int64_t jb) {
      ColMajorMap T(F + (r0 + j0) + (r0 + j0) * nr, m - j0, jb, Eigen::OuterStride<>(nr));
      ColMajorMap Pa(F + (r0 + j0) + k0 * nr, m - j0, kb, Eigen::OuterStride<>(nr));
      ColMajorMap Pb(F + (r0 + j0) + k0 * nr, jb, kb, Eigen::OuterStride<>(nr));
      T.noalias() -= Pa * Pb.transpose();
    };
    const int64_t num_col_blocks = (m + kBlock - 1) / kBlock;
    if (par && m > kBlock) {
      tbb::parallel_for(tbb::blocked_range<int64_t>(0, num_col_blocks, 1),
                        [&](const tbb::blocked_range<int64_t>& r) {
                          for (int64_t b = r.begin(); b < r.end(); ++b) {
                            const int64_t lo = b * kBlock;
                            trsm(lo, std::min(m, lo + kBlock));
                          }
                        });
      tbb::parallel_for(tbb::blocked_range<int64_t>(0, num_col_blocks, 1),
                        [&](const tbb::blocked_range<int64_t>& r) {
                          for (int64_t b = r.begin(); b < r.end(); ++b) {
                            const int64_t j0 = b * kBlock;
                            update(j0, std::min(kBlock, m - j0));
                          }
                        });
    } else {
      trsm(0, m);
      for (int64_t b = 0; b < num_col_blocks; ++b) {
        const int64_t j0 = b * kBlock;
        update(j0, std::min(kBlock, m - j0));
      }
    }
  }
  return -1;
}

}  // namespace

absl::StatusOr<std::shared_ptr<const SupernodalSymbolic>> SupernodalSymbolic::Analyze(
    const Eigen::SparseMatrix<double>& pattern, const SupernodalAnalyzeOptions& options) {
  const int64_t n = pattern.rows();
  if (n < 1 || pattern.cols() != n) {
    return absl::InvalidArgumentError(
        absl::StrCat("SupernodalSymbolic: pattern must be square and non-empty, got ", n, " x ",
                     pattern.cols()));
  }
  if (!pattern.isCompressed()) {
    return absl::InvalidArgumentError("SupernodalSymbolic: pattern must be compressed");
  }
  if (pattern.nonZeros() >= std::numeric_limits<int32_t>::max()) {
    return absl::ResourceExhaustedError("SupernodalSymbolic: pattern has too many nonzeros");
  }
  const int* outer = pattern.outerIndexPtr();
  const int* inner = pattern.innerIndexPtr();
  // Sorted rows, a stored diagonal, structural symmetry (count of (i, j) equals count of (j, i)
  // per column pair is checked by a transpose count).
  std::vector<int32_t> transpose_count(n, 0);
  for (int64_t j = 0; j < n; ++j) {
    bool has_diagonal = false;
    for (int p = outer[j]; p < outer[j + 1]; ++p) {
      if (inner[p] < 0 || inner[p] >= n || (p > outer[j] && inner[p] <= inner[p - 1])) {
        return absl::InvalidArgumentError(absl::StrCat("SupernodalSymbolic: row indices of column ",
                                                       j, " are not sorted and unique"));
      }
      has_diagonal |= inner[p] == j;
      ++transpose_count[inner[p]];
    }
    if (!has_diagonal) {
      return absl::InvalidArgumentError(
          absl::StrCat("SupernodalSymbolic: diagonal entry ", j, " is not stored"));
    }
  }
  for (int64_t j = 0; j < n; ++j) {
    if (transpose_count[j] != outer[j + 1] - outer[j]) {
      return absl::InvalidArgumentError(absl::StrCat(
          "SupernodalSymbolic: pattern is not structurally symmetric (row/column ", j, ")"));
    }
  }
  // Structural symmetry proper: every (i, j) has its (j, i) (binary search in column i).
  for (int64_t j = 0; j < n; ++j) {
    for (int p = outer[j]; p < outer[j + 1]; ++p) {
      const int i = inner[p];
      if (!std::binary_search(inner + outer[i], inner + outer[i + 1], static_cast<int>(j))) {
        return absl::InvalidArgumentError(
            absl::StrCat("SupernodalSymbolic: pattern is not structurally symmetric: (", i, ", ", j,
                         ") is stored but its transpose is not"));
      }
    }
  }

  // Upper triangle as a CHOLMOD pattern matrix (stype = 1: only the upper part is read).
  std::vector<int> up_p(n + 1, 0);
  std::vector<int> up_i;
  up_i.reserve((pattern.nonZeros() + n) / 2);
  for (int64_t j = 0; j < n; ++j) {
    for (int p = outer[j]; p < outer[j + 1] && inner[p] <= j; ++p) up_i.push_back(inner[p]);
    up_p[j + 1] = static_cast<int>(up_i.size());
  }
  cholmod_sparse A = linalg_internal::UpperView(n, up_p.data(), up_i.data(), /*values=*/nullptr,
                                                /*sorted=*/true);
  linalg_internal::CholmodCommon common;
  common->supernodal = CHOLMOD_SUPERNODAL;
  common->postorder = 1;
  if (options.thorough) common->nmethods = 9;
  ASSIGN_OR_RETURN(cholmod_factor * L,
                   linalg_internal::Analyze(&A, common.get(), "SupernodalSymbolic"));
  struct FactorGuard {
    cholmod_factor** L;
    cholmod_common* c;
    ~FactorGuard() { cholmod_free_factor(L, c); }
  } guard{&L, common.get()};
  if (!L->is_super) {
    return absl::InternalError("SupernodalSymbolic: CHOLMOD returned a simplicial analysis");
  }

  auto sym = std::shared_ptr<SupernodalSymbolic>(new SupernodalSymbolic());
  sym->n_ = n;
  sym->pattern_outer_.assign(outer, outer + n + 1);
  sym->pattern_inner_.assign(inner, inner + pattern.nonZeros());
  const int* Lperm = static_cast<const int*>(L->Perm);
  sym->perm_.assign(Lperm, Lperm + n);
  sym->iperm_.resize(n);
  for (int64_t k = 0; k < n; ++k) sym->iperm_[sym->perm_[k]] = static_cast<int32_t>(k);
  const std::vector<int32_t>& iperm = sym->iperm_;

  const int64_t nsuper = static_cast<int64_t>(L->nsuper);
  const int* Lsuper = static_cast<const int*>(L->super);
  const int* Lpi = static_cast<const int*>(L->pi);
  const int* Ls = static_cast<const int*>(L->s);
  sym->super_begin_.assign(Lsuper, Lsuper + nsuper + 1);
  sym->rows_begin_.resize(nsuper + 1);
  for (int64_t s = 0; s <= nsuper; ++s) sym->rows_begin_[s] = Lpi[s];
  sym->rows_.assign(Ls, Ls + Lpi[nsuper]);

  sym->col_super_.resize(n);
  for (int64_t s = 0; s < nsuper; ++s) {
    for (int c = Lsuper[s]; c < Lsuper[s + 1]; ++c) sym->col_super_[c] = static_cast<int32_t>(s);
  }
  const std::vector<int32_t>& col_to_super = sym->col_super_;
  // Structure checks (the multifrontal assembly relies on them) and the elimination tree.
  sym->parent_.assign(nsuper, -1);
  for (int64_t s = 0; s < nsuper; ++s) {
    const int64_t nc = Lsuper[s + 1] - Lsuper[s];
    int32_t* rows = sym->rows_.data() + sym->rows_begin_[s];
    const int64_t nr = sym->rows_begin_[s + 1] - sym->rows_begin_[s];
    if (nr < nc) return absl::InternalError("SupernodalSymbolic: malformed supernode");
    for (int64_t k = 0; k < nc; ++k) {
      if (rows[k] != Lsuper[s] + k) {
        return absl::InternalError("SupernodalSymbolic: supernode rows do not start diagonal");
      }
    }
    std::sort(rows + nc, rows + nr);
    if (nr > nc) {
      if (rows[nc] < Lsuper[s + 1]) {
        return absl::InternalError("SupernodalSymbolic: off-diagonal row inside its supernode");
      }
      sym->parent_[s] = col_to_super[rows[nc]];
    }
  }
  sym->relative_map_.assign(sym->rows_.size(), -1);
  for (int64_t s = 0; s < nsuper; ++s) {
    const int32_t p = sym->parent_[s];
    if (p < 0) continue;
    const int64_t nc = Lsuper[s + 1] - Lsuper[s];
    const int32_t* prow_begin = sym->rows_.data() + sym->rows_begin_[p];
    const int32_t* prow_end = sym->rows_.data() + sym->rows_begin_[p + 1];
    for (int64_t k = sym->rows_begin_[s] + nc; k < sym->rows_begin_[s + 1]; ++k) {
      const int32_t* it = std::lower_bound(prow_begin, prow_end, sym->rows_[k]);
      if (it == prow_end || *it != sym->rows_[k]) {
        return absl::InternalError(
            "SupernodalSymbolic: a child's rows are not contained in its parent's");
      }
      sym->relative_map_[k] = static_cast<int32_t>(it - prow_begin);
    }
  }
  sym->children_begin_.assign(nsuper + 1, 0);
  for (int64_t s = 0; s < nsuper; ++s) {
    if (sym->parent_[s] >= 0) ++sym->children_begin_[sym->parent_[s] + 1];
  }
  for (int64_t s = 0; s < nsuper; ++s) sym->children_begin_[s + 1] += sym->children_begin_[s];
  sym->children_.resize(sym->children_begin_[nsuper]);
  {
    std::vector<int32_t> fill(sym->children_begin_.begin(), sym->children_begin_.end() - 1);
    for (int64_t s = 0; s < nsuper; ++s) {
      if (sym->parent_[s] >= 0) {
        sym->children_[fill[sym->parent_[s]]++] = static_cast<int32_t>(s);
      } else {
        sym->roots_.push_back(static_cast<int32_t>(s));
      }
    }
  }
  // Subtree extents and costs; postorder means each subtree is a contiguous index range.
  sym->first_descendant_.resize(nsuper);
  sym->subtree_flops_.assign(nsuper, 0.0);
  std::vector<int64_t> subtree_size(nsuper, 1);
  for (int64_t s = 0; s < nsuper; ++s) sym->first_descendant_[s] = static_cast<int32_t>(s);
  sym->panel_begin_.assign(nsuper + 1, 0);
  sym->factor_nonzeros_ = 0;
  sym->flops_ = 0;
  for (int64_t s = 0; s < nsuper; ++s) {  // children precede parents
    const int64_t nc = Lsuper[s + 1] - Lsuper[s];
    const int64_t nr = sym->rows_begin_[s + 1] - sym->rows_begin_[s];
    const double f = FrontFlops(nr, nc);
    sym->flops_ += f;
    sym->subtree_flops_[s] += f;
    sym->panel_begin_[s + 1] = sym->panel_begin_[s] + nr * nc;
    sym->factor_nonzeros_ += nr * nc - nc * (nc - 1) / 2;
    const int32_t p = sym->parent_[s];
    if (p >= 0) {
      sym->subtree_flops_[p] += sym->subtree_flops_[s];
      subtree_size[p] += subtree_size[s];
      sym->first_descendant_[p] = std::min(sym->first_descendant_[p], sym->first_descendant_[s]);
    }
  }
  sym->postordered_ = true;
  for (int64_t s = 0; s < nsuper; ++s) {
    if (s - sym->first_descendant_[s] + 1 != subtree_size[s]) sym->postordered_ = false;
  }

  // Assembly map: each stored entry (i, j) whose permuted position is in the lower triangle goes
  // to the front of the supernode owning its permuted column.
  std::vector<int64_t> count(nsuper + 1, 0);
  for (int64_t j = 0; j < n; ++j) {
    const int32_t pj = iperm[j];
    for (int p = outer[j]; p < outer[j + 1]; ++p) {
      if (iperm[inner[p]] >= pj) ++count[col_to_super[pj] + 1];
    }
  }
  for (int64_t s = 0; s < nsuper; ++s) count[s + 1] += count[s];
  sym->assembly_begin_ = count;
  sym->assembly_value_.resize(count[nsuper]);
  sym->assembly_offset_.resize(count[nsuper]);
  for (int64_t j = 0; j < n; ++j) {
    const int32_t pj = iperm[j];
    const int32_t s = col_to_super[pj];
    const int32_t* rows = sym->rows_.data() + sym->rows_begin_[s];
    const int64_t nr = sym->rows_begin_[s + 1] - sym->rows_begin_[s];
    const int64_t cj = pj - Lsuper[s];
    for (int p = outer[j]; p < outer[j + 1]; ++p) {
      const int32_t pi = iperm[inner[p]];
      if (pi < pj) continue;
      const int32_t* it = std::lower_bound(rows, rows + nr, pi);
      if (it == rows + nr || *it != pi) {
        return absl::InternalError("SupernodalSymbolic: entry of A outside the structure of L");
      }
      const int64_t slot = count[s]++;
      sym->assembly_value_[slot] = p;
      sym->assembly_offset_[slot] = (it - rows) + cj * nr;
    }
  }
  return std::shared_ptr<const SupernodalSymbolic>(std::move(sym));
}

SupernodalSymbolic::Supernode SupernodalSymbolic::supernode(int64_t s) const {
  Supernode out;
  out.c0 = super_begin_[s];
  out.nc = super_begin_[s + 1] - out.c0;
  out.nr = rows_begin_[s + 1] - rows_begin_[s];
  out.m = out.nr - out.nc;
  out.below = rows_.data() + rows_begin_[s] + out.nc;
  out.panel = panel_begin_[s];
  return out;
}

Eigen::VectorXd SupernodalSymbolic::ToPermuted(const Eigen::VectorXd& b) const {
  Eigen::VectorXd y(n_);
  for (int64_t k = 0; k < n_; ++k) y[k] = b[perm_[k]];
  return y;
}

Eigen::VectorXd SupernodalSymbolic::FromPermuted(const Eigen::VectorXd& y) const {
  Eigen::VectorXd b(n_);
  for (int64_t k = 0; k < n_; ++k) b[perm_[k]] = y[k];
  return b;
}

int64_t SupernodalSymbolic::memory_bytes() const {
  return static_cast<int64_t>(
      4 * (pattern_outer_.size() + pattern_inner_.size() + perm_.size() + iperm_.size() +
           col_super_.size() + super_begin_.size() + rows_.size() + relative_map_.size() +
           parent_.size() + children_begin_.size() + children_.size() + roots_.size() +
           first_descendant_.size()) +
      8 * (rows_begin_.size() + subtree_flops_.size() + panel_begin_.size() +
           assembly_begin_.size() + assembly_value_.size() + assembly_offset_.size()));
}

bool SupernodalSymbolic::SamePattern(const Eigen::SparseMatrix<double>& A) const {
  if (A.rows() != n_ || A.cols() != n_ || !A.isCompressed()) return false;
  if (A.nonZeros() != static_cast<int64_t>(pattern_inner_.size())) return false;
  return std::equal(pattern_outer_.begin(), pattern_outer_.end(), A.outerIndexPtr()) &&
         std::equal(pattern_inner_.begin(), pattern_inner_.end(), A.innerIndexPtr());
}

absl::StatusOr<SupernodalFactor> SupernodalFactor::Factorize(
    std::shared_ptr<const SupernodalSymbolic> symbolic, absl::Span<const double> values,
    const SupernodalFactorOptions& options) {
  if (symbolic == nullptr) {
    return absl::InvalidArgumentError("SupernodalFactor: no symbolic analysis");
  }
  SupernodalFactor f;
  f.symbolic_ = std::move(symbolic);
  RETURN_IF_ERROR(f.Refactorize(values, options));
  return f;
}

absl::StatusOr<SupernodalFactor> SupernodalFactor::Factorize(
    std::shared_ptr<const SupernodalSymbolic> symbolic, const Eigen::SparseMatrix<double>& A,
    const SupernodalFactorOptions& options) {
  if (symbolic == nullptr) {
    return absl::InvalidArgumentError("SupernodalFactor: no symbolic analysis");
  }
  if (!symbolic->SamePattern(A)) {
    return absl::InvalidArgumentError(
        "SupernodalFactor: the matrix does not have the analyzed sparsity pattern");
  }
  return Factorize(std::move(symbolic), absl::MakeConstSpan(A.valuePtr(), A.nonZeros()), options);
}

absl::Status SupernodalFactor::Refactorize(absl::Span<const double> values,
                                           const SupernodalFactorOptions& options) {
  valid_ = false;
  const SupernodalSymbolic& sym = *symbolic_;
  if (static_cast<int64_t>(values.size()) != sym.pattern_nonzeros()) {
    return absl::InvalidArgumentError(absl::StrCat(
        "SupernodalFactor: expected ", sym.pattern_nonzeros(), " values, got ", values.size()));
  }
  if (!(options.diagonal_shift >= 0) || !std::isfinite(options.diagonal_shift)) {
    return absl::InvalidArgumentError("SupernodalFactor: diagonal_shift must be finite and >= 0");
  }
  for (double v : values) {
    if (!std::isfinite(v)) {
      return absl::InvalidArgumentError("SupernodalFactor: matrix has a non-finite value");
    }
  }
  const int64_t nsuper = sym.num_supernodes();
  panels_.resize(sym.panel_begin_[nsuper]);
  std::vector<std::vector<double>> updates(nsuper);
  std::atomic<bool> failed{false};
  std::mutex failure_mutex;
  int64_t failed_column = -1;
  const double diag_scale = 1.0 + options.diagonal_shift;

  std::atomic<bool> cancelled{false};
  auto factor_front = [&](int32_t s) {
    if (failed.load(std::memory_order_relaxed) || cancelled.load(std::memory_order_relaxed)) {
      return;
    }
    if (IsCancelled(options.cancel)) {
      cancelled.store(true);
      return;
    }
    const auto [c0, nc, nr, m, below, panel] = sym.supernode(s);
    // The front is allocated per call (not thread-local): a thread waiting inside a nested
    // parallel loop may run another front's task meanwhile.
    std::vector<double> front(static_cast<size_t>(nr * nr), 0.0);
    for (int64_t k = sym.assembly_begin_[s]; k < sym.assembly_begin_[s + 1]; ++k) {
      front[sym.assembly_offset_[k]] += values[sym.assembly_value_[k]];
    }
    if (diag_scale != 1.0) {
      for (int64_t j = 0; j < nc; ++j) front[j + j * nr] *= diag_scale;
    }
    for (int32_t ci = sym.children_begin_[s]; ci < sym.children_begin_[s + 1]; ++ci) {
      const int32_t c = sym.children_[ci];
      const int64_t cnc = sym.super_begin_[c + 1] - sym.super_begin_[c];
      const int64_t cm = sym.rows_begin_[c + 1] - sym.rows_begin_[c] - cnc;
      const int32_t* map = sym.relative_map_.data() + sym.rows_begin_[c] + cnc;
      const double* U = updates[c].data();
      for (int64_t q = 0; q < cm; ++q) {
        double* col = front.data() + static_cast<int64_t>(map[q]) * nr;
        const double* ucol = U + q * cm;
        for (int64_t p = q; p < cm; ++p) col[map[p]] += ucol[p];
      }
      std::vector<double>().swap(updates[c]);
    }
    const int64_t bad = PartialCholesky(front.data(), nr, nc, options.parallel);
    if (bad >= 0) {
      std::lock_guard<std::mutex> lock(failure_mutex);
      if (!failed.exchange(true)) failed_column = c0 + bad;
      return;
    }
    std::memcpy(panels_.data() + panel, front.data(),
                sizeof(double) * static_cast<size_t>(nr * nc));
    if (m > 0) {
      std::vector<double>& U = updates[s];
      U.resize(static_cast<size_t>(m * m));
      for (int64_t q = 0; q < m; ++q) {
        std::memcpy(U.data() + q * m, front.data() + nc + (nc + q) * nr,
                    sizeof(double) * static_cast<size_t>(m));
      }
    }
  };

  if (!sym.postordered_ || !options.parallel) {
    for (int32_t s = 0; s < nsuper; ++s) factor_front(s);
  } else {
    // Parallel over independent subtrees; a subtree too small to split runs as one loop over
    // its contiguous (postordered) index range.
    std::function<void(int32_t)> process = [&](int32_t s) {
      if (sym.subtree_flops_[s] < kParallelSubtreeFlops) {
        for (int32_t t = sym.first_descendant_[s]; t <= s; ++t) factor_front(t);
        return;
      }
      const int32_t cb = sym.children_begin_[s];
      const int32_t ce = sym.children_begin_[s + 1];
      if (ce - cb == 1) {
        process(sym.children_[cb]);
      } else if (ce - cb > 1) {
        tbb::parallel_for(cb, ce, [&](int32_t ci) { process(sym.children_[ci]); });
      }
      factor_front(s);
    };
    tbb::parallel_for(static_cast<size_t>(0), sym.roots_.size(),
                      [&](size_t r) { process(sym.roots_[r]); });
  }
  if (cancelled.load()) return absl::CancelledError("SupernodalFactor: cancelled");
  if (failed.load()) {
    return absl::FailedPreconditionError(
        absl::StrCat("SupernodalFactor: matrix is not positive definite (pivot of permuted column ",
                     failed_column, " of ", sym.n_, " is not positive)"));
  }
  valid_ = true;
  return absl::OkStatus();
}

template <typename Block>
void SupernodalFactor::ForwardSupernode(int64_t s, Block& X, Block& tmp) const {
  const auto [c0, nc, nr, m, below, panel] = symbolic_->supernode(s);
  Eigen::Map<const Eigen::MatrixXd> P(panels_.data() + panel, nr, nc);
  auto Xs = X.middleRows(c0, nc);
  P.topRows(nc).template triangularView<Eigen::Lower>().solveInPlace(Xs);
  if (m > 0) {
    tmp.noalias() = P.bottomRows(m) * Xs;
    for (int64_t k = 0; k < m; ++k) X.row(below[k]) -= tmp.row(k);
  }
}

template <typename Block>
void SupernodalFactor::Forward(Block& X) const {
  Block tmp;
  for (int64_t s = 0; s < symbolic_->num_supernodes(); ++s) ForwardSupernode(s, X, tmp);
}

template <typename Block>
void SupernodalFactor::Backward(Block& X) const {
  Block tmp;
  for (int64_t s = symbolic_->num_supernodes() - 1; s >= 0; --s) {
    const auto [c0, nc, nr, m, below, panel] = symbolic_->supernode(s);
    Eigen::Map<const Eigen::MatrixXd> P(panels_.data() + panel, nr, nc);
    auto Xs = X.middleRows(c0, nc);
    if (m > 0) {
      tmp.resize(m, X.cols());
      for (int64_t k = 0; k < m; ++k) tmp.row(k) = X.row(below[k]);
      Xs.noalias() -= P.bottomRows(m).transpose() * tmp;
    }
    P.topRows(nc).transpose().template triangularView<Eigen::Upper>().solveInPlace(Xs);
  }
}

template <typename Block>
void SupernodalFactor::Substitute(Block& X) const {
  Forward(X);
  Backward(X);
}

void SupernodalFactor::ForwardInPlace(Eigen::Ref<Eigen::VectorXd> y) const {
  Eigen::VectorXd x = y;
  Forward(x);
  y = x;
}

void SupernodalFactor::BackwardInPlace(Eigen::Ref<Eigen::VectorXd> y) const {
  Eigen::VectorXd x = y;
  Backward(x);
  y = x;
}

Eigen::VectorXd SupernodalFactor::PermuteIn(const Eigen::VectorXd& b) const {
  return symbolic_->ToPermuted(b);
}

Eigen::VectorXd SupernodalFactor::PermuteOut(const Eigen::VectorXd& y) const {
  return symbolic_->FromPermuted(y);
}

int64_t SupernodalFactor::ForwardSparse(absl::Span<const int32_t> rows,
                                        absl::Span<const double> vals,
                                        Eigen::Ref<Eigen::VectorXd> y) const {
  const SupernodalSymbolic& sym = *symbolic_;
  const int64_t nsuper = sym.num_supernodes();
  // The reach of the nonzeros: the supernodes on their paths to the roots of the supernodal
  // elimination tree. A parent's index exceeds its children's, so ascending order is a
  // topological order for the forward substitution.
  std::vector<int32_t> reach;
  std::vector<char> marked(nsuper, 0);
  Eigen::VectorXd x = Eigen::VectorXd::Zero(sym.n_);
  for (size_t q = 0; q < rows.size(); ++q) {
    const int32_t k = sym.iperm_[rows[q]];
    x[k] += vals[q];
    for (int32_t s = sym.col_super_[k]; s >= 0 && !marked[s]; s = sym.parent_[s]) {
      marked[s] = 1;
      reach.push_back(s);
    }
  }
  std::sort(reach.begin(), reach.end());
  Eigen::VectorXd tmp;
  int64_t visited_rows = 0;
  for (const int32_t s : reach) {
    ForwardSupernode(s, x, tmp);
    visited_rows += sym.rows_begin_[s + 1] - sym.rows_begin_[s];
  }
  y = x;
  return visited_rows;
}

void SupernodalFactor::ForwardSparseColumns(
    absl::Span<const absl::Span<const int32_t>> rows,
    absl::Span<const absl::Span<const double>> vals, Eigen::Ref<Eigen::MatrixXd> Y,
    std::vector<std::pair<int64_t, int64_t>>* reach_rows) const {
  const SupernodalSymbolic& sym = *symbolic_;
  const int64_t k = static_cast<int64_t>(rows.size());
  std::vector<int32_t> reach;
  std::vector<char> marked(sym.num_supernodes(), 0);
  for (size_t j = 0; j < rows.size(); ++j) {
    for (const int32_t row : rows[j]) {
      for (int32_t s = sym.col_super_[sym.iperm_[row]]; s >= 0 && !marked[s]; s = sym.parent_[s]) {
        marked[s] = 1;
        reach.push_back(s);
      }
    }
  }
  std::sort(reach.begin(), reach.end());  // children before parents
  // Only the reach's rows of X are read or written (a supernode's panel rows are its ancestors'
  // columns), so only they are zeroed and copied out.
  std::vector<std::pair<int64_t, int64_t>> ranges;
  for (const int32_t s : reach) {
    const int64_t begin = sym.super_begin_[s], end = sym.super_begin_[s + 1];
    if (!ranges.empty() && ranges.back().second == begin) {
      ranges.back().second = end;
    } else {
      ranges.emplace_back(begin, end);
    }
  }
  RowMajorMatrix X(sym.n_, k);
  for (const auto& [a, b] : ranges) X.middleRows(a, b - a).setZero();
  for (size_t j = 0; j < rows.size(); ++j) {
    for (size_t q = 0; q < rows[j].size(); ++q) {
      X(sym.iperm_[rows[j][q]], static_cast<int64_t>(j)) += vals[j][q];
    }
  }
  RowMajorMatrix tmp;
  for (const int32_t s : reach) ForwardSupernode(s, X, tmp);
  if (reach_rows == nullptr) {
    Y.setZero();
    for (const auto& [a, b] : ranges) Y.middleRows(a, b - a) = X.middleRows(a, b - a);
    return;
  }
  for (const auto& [a, b] : ranges) Y.middleRows(a, b - a) = X.middleRows(a, b - a);
  *reach_rows = std::move(ranges);
}

void SupernodalFactor::SolveInPlace(Eigen::Ref<Eigen::MatrixXd> B) const {
  const SupernodalSymbolic& sym = *symbolic_;
  const int64_t n = sym.n_;
  const int64_t nrhs = B.cols();
  if (nrhs == 0) return;
  if (nrhs <= 2) {
    // One or two right-hand sides (every constraint edit of a design session): one column at a
    // time, with matrix-vector kernels. Eigen's matrix-matrix path would pack each panel for a
    // 1-2 column product, which costs more than the product itself.
    Eigen::VectorXd x(n);
    for (int64_t c = 0; c < nrhs; ++c) {
      for (int64_t k = 0; k < n; ++k) x[k] = B(sym.perm_[k], c);
      Substitute(x);
      for (int64_t k = 0; k < n; ++k) B(sym.perm_[k], c) = x[k];
    }
    return;
  }
  RowMajorMatrix X(n, nrhs);
  for (int64_t k = 0; k < n; ++k) X.row(k) = B.row(sym.perm_[k]);
  Substitute(X);
  for (int64_t k = 0; k < n; ++k) B.row(sym.perm_[k]) = X.row(k);
}

Eigen::VectorXd SupernodalFactor::Solve(const Eigen::VectorXd& b) const {
  Eigen::VectorXd x = b;
  SolveInPlace(x);
  return x;
}

double SupernodalFactor::LogDeterminant() const {
  const SupernodalSymbolic& sym = *symbolic_;
  double sum = 0;
  for (int64_t s = 0; s < sym.num_supernodes(); ++s) {
    const int64_t nc = sym.super_begin_[s + 1] - sym.super_begin_[s];
    const int64_t nr = sym.rows_begin_[s + 1] - sym.rows_begin_[s];
    const double* P = panels_.data() + sym.panel_begin_[s];
    for (int64_t j = 0; j < nc; ++j) sum += std::log(P[j + j * nr]);
  }
  return 2 * sum;
}

}  // namespace fieldspace
