#include "core/linalg/local_cholesky.h"

#include <amd.h>

#include <algorithm>
#include <cmath>
#include <limits>

#include "Eigen/Cholesky"
#include "Eigen/Core"
#include "absl/status/status.h"

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
                  const int64_t* lpx, const int32_t* ls, const double* lx, double* x) {
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
                   const int64_t* lpx, const int32_t* ls, const double* lx, double* x) {
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

// L L^T x = b on p row-major right-hand sides (as ForwardSolve and BackwardSolve).
template <int P>
void Substitute(int32_t p, int32_t nsuper, const int32_t* super, const int32_t* lpi,
                const int64_t* lpx, const int32_t* ls, const double* lx, double* x) {
  ForwardSolve<P>(p, nsuper, super, lpi, lpx, ls, lx, x);
  BackwardSolve<P>(p, nsuper, super, lpi, lpx, ls, lx, x);
}

// Substitute<p> for the common small p (one to four fields per region solve), Substitute<0>
// (p at run time) otherwise.
constexpr int32_t kNumSubstitute = 5;
constexpr decltype(&Substitute<0>) kSubstitute[kNumSubstitute] = {
    Substitute<0>, Substitute<1>, Substitute<2>, Substitute<3>, Substitute<4>};

}  // namespace

LocalCholesky::LocalCholesky() = default;
LocalCholesky::~LocalCholesky() = default;

absl::Status LocalCholesky::BuildAdjacency(const UpperCsc& A, int32_t n) {
  // Counts first, then positions: AMD's elbow room below must fit 32-bit indices too.
  adj_outer_.assign(static_cast<size_t>(n) + 1, 0);
  int64_t nz = 0;
  for (int32_t j = 0; j < n; ++j) {
    for (int32_t p = A.outer[j]; p < A.outer[j + 1]; ++p) {
      const int32_t i = A.inner[p];
      if (i == j) continue;
      ++adj_outer_[i + 1];
      ++adj_outer_[j + 1];
      nz += 2;
    }
  }
  if (nz + nz / 5 + n > std::numeric_limits<int32_t>::max() - 1) {
    return absl::ResourceExhaustedError("local system too large for 32-bit indices");
  }
  for (int32_t i = 0; i < n; ++i) adj_outer_[i + 1] += adj_outer_[i];
  adj_.resize(adj_outer_[n]);
  std::vector<int32_t>& cursor = len_;
  cursor.assign(adj_outer_.begin(), adj_outer_.end() - 1);
  for (int32_t j = 0; j < n; ++j) {
    for (int32_t p = A.outer[j]; p < A.outer[j + 1]; ++p) {
      const int32_t i = A.inner[p];
      if (i == j) continue;
      adj_[cursor[i]++] = j;
      adj_[cursor[j]++] = i;
    }
  }
  return absl::OkStatus();
}

void LocalCholesky::Amd(int32_t n, std::vector<int32_t>* order) {
  // amd_2 directly: the adjacency with elbow room (amd_2 overwrites it), AMD's default dense-row
  // threshold and aggressive absorption.
  const int64_t nz = adj_outer_[n];
  const int64_t iwlen = nz + nz / 5 + n;  // within 32 bits: BuildAdjacency checked
  amd_work_.resize(8 * static_cast<size_t>(n));
  int32_t* pe = amd_work_.data();
  int32_t* nv = pe + n;
  int32_t* amd_next = nv + n;        // AMD's inverse permutation
  int32_t* amd_last = amd_next + n;  // AMD's permutation
  int32_t* head = amd_last + n;
  int32_t* elen = head + n;
  int32_t* degree = elen + n;
  int32_t* w = degree + n;
  iw_.resize(iwlen);
  std::copy(adj_.begin(), adj_.begin() + nz, iw_.begin());
  len_.resize(n);
  for (int32_t i = 0; i < n; ++i) {
    pe[i] = adj_outer_[i];
    len_[i] = adj_outer_[i + 1] - adj_outer_[i];
  }
  double control[AMD_CONTROL], info[AMD_INFO];
  amd_defaults(control);
  amd_2(n, pe, iw_.data(), len_.data(), static_cast<int32_t>(iwlen), static_cast<int32_t>(nz), nv,
        amd_next, amd_last, head, elen, degree, w, control, info);
  order->assign(amd_last, amd_last + n);
}

absl::Status LocalCholesky::MinimumDegreeOrder(const UpperCsc& A, int32_t n,
                                               std::vector<int32_t>* order) {
  if (n < 0 || n > A.n) {
    return absl::InvalidArgumentError("leading block larger than the matrix");
  }
  if (n == 0) {
    order->clear();
    return absl::OkStatus();
  }
  if (absl::Status built = BuildAdjacency(A, n); !built.ok()) return built;
  Amd(n, order);
  return absl::OkStatus();
}

absl::Status LocalCholesky::BlockMinimumDegreeOrder(const UpperCsc& A, int32_t block,
                                                    std::vector<int32_t>* order) {
  if (block < 1 || A.n % block != 0) {
    return absl::InvalidArgumentError("the block size does not divide the matrix");
  }
  if (block == 1 || A.n == 0) return MinimumDegreeOrder(A, A.n, order);
  // The blocks' upper pattern (each coupling once, by a marker per block column), then AMD on it.
  const int32_t nb = A.n / block;
  UpperCsc& quotient = quotient_;
  quotient.n = nb;
  quotient.outer.assign(1, 0);
  quotient.inner.clear();
  std::vector<int32_t>& marker = head_;
  marker.assign(nb, -1);
  for (int32_t jb = 0; jb < nb; ++jb) {
    for (int32_t j = jb * block; j < (jb + 1) * block; ++j) {
      for (int32_t p = A.outer[j]; p < A.outer[j + 1]; ++p) {
        const int32_t ib = A.inner[p] / block;
        if (ib >= jb || marker[ib] == jb) continue;
        marker[ib] = jb;
        quotient.inner.push_back(ib);
      }
    }
    quotient.outer.push_back(static_cast<int32_t>(quotient.inner.size()));
  }
  std::vector<int32_t>& block_order = next_;
  if (absl::Status built = BuildAdjacency(quotient, nb); !built.ok()) return built;
  Amd(nb, &block_order);
  order->resize(A.n);
  for (int32_t k = 0; k < nb; ++k) {
    for (int32_t c = 0; c < block; ++c) (*order)[k * block + c] = block_order[k] * block + c;
  }
  return absl::OkStatus();
}

absl::Status LocalCholesky::Analyze(const UpperCsc& A, const std::vector<int32_t>* order) {
  const int32_t n = A.n;
  // The adjacency of A + A^T as CSC: the elimination tree below walks it in the permuted order.
  if (absl::Status built = BuildAdjacency(A, n); !built.ok()) return built;
  if (order == nullptr) {
    Amd(n, &perm_);
  } else {
    if (static_cast<int32_t>(order->size()) != n) {
      return absl::InvalidArgumentError("the given order is not a permutation of the rows");
    }
    std::vector<int32_t>& seen = len_;
    seen.assign(n, 0);
    for (int32_t i : *order) {
      if (i < 0 || i >= n || seen[i]++ != 0) {
        return absl::InvalidArgumentError("the given order is not a permutation of the rows");
      }
    }
    perm_ = *order;
  }

  // The elimination tree of P A P^T (Liu's algorithm: for each row k, the entries left of the
  // diagonal, each followed to the root of its current subtree, path-compressed), a postorder of
  // it (AMD's order is a postorder of its own assembly tree, mostly not of the elimination tree),
  // and the matrix permuted once by both.
  pinv_.resize(n);
  for (int32_t k = 0; k < n; ++k) pinv_[perm_[k]] = k;
  parent_.resize(n);
  {
    std::vector<int32_t>& ancestor = next_;
    ancestor.assign(n, -1);
    for (int32_t k = 0; k < n; ++k) {
      parent_[k] = -1;
      const int32_t j = perm_[k];
      for (int32_t p = adj_outer_[j]; p < adj_outer_[j + 1]; ++p) {
        for (int32_t i = pinv_[adj_[p]]; i != -1 && i < k;) {
          const int32_t up = ancestor[i];
          ancestor[i] = k;
          if (up == -1) parent_[i] = k;
          i = up;
        }
      }
    }
  }
  {
    // Postorder: children in ascending order, by a depth-first search with an explicit stack.
    std::vector<int32_t>& child_head = head_;
    std::vector<int32_t>& sibling = next_;
    child_head.assign(n, -1);
    sibling.assign(n, -1);
    for (int32_t j = n - 1; j >= 0; --j) {
      if (parent_[j] != -1) {
        sibling[j] = child_head[parent_[j]];
        child_head[parent_[j]] = j;
      }
    }
    std::vector<int32_t>& post = map_;
    std::vector<int32_t>& stack = super_map_;
    post.resize(n);
    stack.resize(n);
    int32_t k = 0;
    for (int32_t root = 0; root < n; ++root) {
      if (parent_[root] != -1) continue;
      int32_t top = 0;
      stack[0] = root;
      while (top >= 0) {
        const int32_t j = stack[top];
        const int32_t c = child_head[j];
        if (c == -1) {
          --top;
          post[k++] = j;
        } else {
          child_head[j] = sibling[c];
          stack[++top] = c;
        }
      }
    }
    // Relabel: new column k is old column post[k].
    std::vector<int32_t>& post_inv = head_;
    for (int32_t i = 0; i < n; ++i) post_inv[post[i]] = i;
    std::vector<int32_t>& relabeled = next_;
    for (int32_t i = 0; i < n; ++i) {
      const int32_t up = parent_[post[i]];
      relabeled[i] = up == -1 ? -1 : post_inv[up];
    }
    parent_.swap(relabeled);
    for (int32_t i = 0; i < n; ++i) post[i] = perm_[post[i]];
    perm_.swap(post);
  }
  PermuteLower(A);

  // Column counts of L (Gilbert, Ng and Peyton 1994): each column's count is the number of
  // row subtrees it lies in, found from the skeleton matrix by least common ancestors in the
  // postordered tree (here the identity order).
  std::vector<int32_t>& count = colcount_;
  count.assign(n, 0);
  std::vector<int32_t>& first = head_;
  std::vector<int32_t>& max_first = next_;
  std::vector<int32_t>& prev_leaf = map_;
  std::vector<int32_t>& ancestor = super_map_;
  first.assign(n, -1);
  max_first.assign(n, -1);
  prev_leaf.assign(n, -1);
  ancestor.resize(n);
  for (int32_t k = 0; k < n; ++k) {
    count[k] = first[k] == -1 ? 1 : 0;  // a leaf
    for (int32_t j = k; j != -1 && first[j] == -1; j = parent_[j]) first[j] = k;
    ancestor[k] = k;
  }
  for (int32_t j = 0; j < n; ++j) {
    if (parent_[j] != -1) --count[parent_[j]];
    for (int32_t p = c_outer_[j]; p < c_outer_[j + 1]; ++p) {
      const int32_t i = c_inner_[p];
      if (i <= j || first[j] <= max_first[i]) continue;  // not a leaf of row i's subtree
      max_first[i] = first[j];
      const int32_t jprev = prev_leaf[i];
      prev_leaf[i] = j;
      ++count[j];
      if (jprev == -1) continue;  // the first leaf of row i's subtree
      int32_t q = jprev;          // the least common ancestor of jprev and j
      while (q != ancestor[q]) q = ancestor[q];
      for (int32_t s = jprev; s != q;) {
        const int32_t up = ancestor[s];
        ancestor[s] = q;
        s = up;
      }
      --count[q];
    }
    if (parent_[j] != -1) ancestor[j] = parent_[j];
  }
  for (int32_t j = 0; j < n; ++j) {
    if (parent_[j] != -1) count[parent_[j]] += count[j];
  }

  // Fundamental supernodes: column j joins j - 1's supernode when j is its parent, j - 1 is its
  // only child, and their columns share the pattern below.
  std::vector<int32_t>& children = head_;
  children.assign(n, 0);
  for (int32_t j = 0; j < n; ++j) {
    if (parent_[j] != -1) ++children[parent_[j]];
  }
  super_.clear();
  super_.push_back(0);
  for (int32_t j = 1; j < n; ++j) {
    if (parent_[j - 1] == j && children[j] == 1 && count[j - 1] == count[j] + 1) continue;
    super_.push_back(j);
  }
  super_.push_back(n);
  nsuper_ = static_cast<int32_t>(super_.size()) - 1;
  const int32_t nsuper = nsuper_;
  super_map_.resize(n);
  lpi_.resize(static_cast<size_t>(nsuper) + 1);
  lpx_.resize(static_cast<size_t>(nsuper) + 1);
  lpi_[0] = 0;
  lpx_[0] = 0;
  flops_ = 0;
  for (int32_t s = 0; s < nsuper; ++s) {
    const int32_t nscol = super_[s + 1] - super_[s];
    const int32_t nsrow = count[super_[s]];
    for (int32_t k = super_[s]; k < super_[s + 1]; ++k) {
      super_map_[k] = s;
      flops_ += static_cast<double>(count[k]) * count[k];
    }
    lpi_[s + 1] = lpi_[s] + nsrow;
    lpx_[s + 1] = lpx_[s] + static_cast<int64_t>(nsrow) * nscol;
  }
  // Row patterns, ascending without a sort: each supernode's own columns, then the rows i below
  // them in the order of i, where row i of L reaches a supernode iff the supernode lies on the
  // tree path from a column j < i with C(i, j) != 0 up to i's own supernode.
  ls_.resize(lpi_[nsuper]);
  std::vector<int32_t>& super_parent = head_;
  std::vector<int32_t>& fill = next_;
  std::vector<int32_t>& marker = map_;
  super_parent.resize(nsuper);
  fill.resize(nsuper);
  marker.assign(nsuper, -1);
  for (int32_t s = 0; s < nsuper; ++s) {
    const int32_t up = parent_[super_[s + 1] - 1];
    super_parent[s] = up == -1 ? -1 : super_map_[up];
    int32_t p = lpi_[s];
    for (int32_t k = super_[s]; k < super_[s + 1]; ++k) ls_[p++] = k;
    fill[s] = p;
  }
  for (int32_t i = 0; i < n; ++i) {
    marker[super_map_[i]] = i;
    const int32_t j = perm_[i];
    for (int32_t p = adj_outer_[j]; p < adj_outer_[j + 1]; ++p) {
      const int32_t col = pinv_[adj_[p]];
      if (col >= i) continue;
      for (int32_t s = super_map_[col]; marker[s] != i; s = super_parent[s]) {
        marker[s] = i;
        if (fill[s] == lpi_[s + 1]) {
          return absl::InternalError("local system: supernode pattern exceeds its column count");
        }
        ls_[fill[s]++] = i;
      }
    }
  }
  for (int32_t s = 0; s < nsuper; ++s) {
    if (fill[s] != lpi_[s + 1]) {
      return absl::InternalError("local system: supernode pattern short of its column count");
    }
  }
  return absl::OkStatus();
}

void LocalCholesky::PermuteLower(const UpperCsc& A) {
  // C = P A P^T, lower triangle, by counting sort on the permuted column.
  const int32_t n = A.n;
  pinv_.resize(n);
  for (int32_t k = 0; k < n; ++k) pinv_[perm_[k]] = k;
  c_outer_.assign(static_cast<size_t>(n) + 1, 0);
  for (int32_t j = 0; j < n; ++j) {
    for (int32_t p = A.outer[j]; p < A.outer[j + 1]; ++p) {
      ++c_outer_[std::min(pinv_[A.inner[p]], pinv_[j]) + 1];
    }
  }
  for (int32_t j = 0; j < n; ++j) c_outer_[j + 1] += c_outer_[j];
  c_inner_.resize(A.inner.size());
  c_values_.resize(A.inner.size());
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

absl::Status LocalCholesky::Factorize(const UpperCsc& A, const CancelToken& cancel,
                                      const std::vector<int32_t>* order) {
  n_ = A.n;
  nsuper_ = 0;
  lx_.clear();
  const int32_t n = A.n;
  if (n == 0) return absl::OkStatus();
  if (absl::Status analyzed = Analyze(A, order); !analyzed.ok()) {
    nsuper_ = 0;
    return analyzed;
  }
  const int32_t* super = super_.data();
  const int32_t* lpi = lpi_.data();
  const int64_t* lpx = lpx_.data();
  const int32_t* ls = ls_.data();
  const int32_t nsuper = nsuper_;

  // Left-looking supernodal numeric factorization (CHOLMOD's t_cholmod_super_numeric scheme);
  // super_map_ (column -> supernode) comes from Analyze.
  map_.assign(n, 0);
  head_.assign(nsuper, -1);
  next_.assign(nsuper, -1);
  lpos_.assign(nsuper, 0);
  lx_.resize(lpx_[nsuper]);
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
      nsuper_ = 0;
      return absl::FailedPreconditionError("local system is not numerically positive definite");
    }
    if (nsrow > nscol) {
      lpos_[s] = nscol;
      const int32_t s2 = super_map_[ls[psi + nscol]];
      next_[s] = head_[s2];
      head_[s2] = s;
    }
    if ((s & 255) == 0 && cancel.Check()) {
      nsuper_ = 0;
      return absl::CancelledError("basis construction cancelled");
    }
  }
  if (n > kReleaseScratchRows) ReleaseScratch();
  return absl::OkStatus();
}

void LocalCholesky::ReleaseScratch() {
  for (std::vector<int32_t>* v :
       {&parent_, &colcount_, &c_outer_, &c_inner_, &super_map_, &map_, &head_, &next_, &lpos_,
        &len_, &amd_work_, &iw_, &adj_outer_, &adj_}) {
    std::vector<int32_t>().swap(*v);
  }
  std::vector<double>().swap(c_values_);
  std::vector<double>().swap(update_);
  std::vector<int32_t>().swap(quotient_.outer);
  std::vector<int32_t>().swap(quotient_.inner);
}

void LocalCholesky::SolveInPlace(double* X, int32_t p) {
  const int32_t n = n_;
  if (n == 0 || p == 0) return;
  const int32_t* perm = perm_.data();
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
    SolvePermutedInPlace(xp, pc);
    for (int32_t k = 0; k < n; ++k) {
      for (int32_t c = 0; c < pc; ++c)
        X[static_cast<int64_t>(c0 + c) * n + perm[k]] = xp[static_cast<int64_t>(k) * pc + c];
    }
  }
}

void LocalCholesky::SolvePermutedInPlace(double* x, int32_t p) const {
  if (n_ == 0 || p == 0) return;
  kSubstitute[p < kNumSubstitute ? p : 0](p, nsuper_, super_.data(), lpi_.data(), lpx_.data(),
                                          ls_.data(), lx_.data(), x);
}

}  // namespace fieldspace
