// SupernodalMatrix (supernodal_cholesky.h): a symmetric matrix stored in the panels of its
// supernodal analysis, so that the true matrix of a factorization can multiply without a second
// sparse copy.

#include <algorithm>
#include <utility>
#include <vector>

#include "absl/strings/str_cat.h"
#include "core/linalg/supernodal_cholesky.h"
#include "oneapi/tbb/parallel_for.h"
#include "oneapi/tbb/task_arena.h"

namespace fieldspace {

absl::StatusOr<SupernodalMatrix> SupernodalMatrix::Create(
    std::shared_ptr<const SupernodalSymbolic> symbolic, absl::Span<const double> values) {
  if (symbolic == nullptr) return absl::InvalidArgumentError("SupernodalMatrix: no analysis");
  const SupernodalSymbolic& sym = *symbolic;
  if (static_cast<int64_t>(values.size()) != sym.pattern_nonzeros()) {
    return absl::InvalidArgumentError(absl::StrCat("SupernodalMatrix: ", values.size(),
                                                   " values for a pattern with ",
                                                   sym.pattern_nonzeros(), " entries"));
  }
  SupernodalMatrix out;
  out.panels_.assign(static_cast<size_t>(sym.panel_begin_.back()), 0.0);
  // The factorization's assembly map: offsets in the first nc columns of an nr x nr front are
  // offsets in the nr x nc panel.
  for (int64_t s = 0; s < sym.num_supernodes(); ++s) {
    double* panel = out.panels_.data() + sym.panel_begin_[s];
    for (int64_t k = sym.assembly_begin_[s]; k < sym.assembly_begin_[s + 1]; ++k) {
      panel[sym.assembly_offset_[k]] += values[sym.assembly_value_[k]];
    }
  }
  out.symbolic_ = std::move(symbolic);
  return out;
}

absl::StatusOr<SupernodalMatrix> SupernodalMatrix::Create(
    std::shared_ptr<const SupernodalSymbolic> symbolic, const Eigen::SparseMatrix<double>& A) {
  if (symbolic == nullptr) return absl::InvalidArgumentError("SupernodalMatrix: no analysis");
  if (!symbolic->SamePattern(A)) {
    return absl::InvalidArgumentError(
        "SupernodalMatrix: matrix does not have the analyzed pattern");
  }
  return Create(std::move(symbolic), absl::MakeConstSpan(A.valuePtr(), A.nonZeros()));
}

Eigen::VectorXd SupernodalMatrix::Multiply(const Eigen::VectorXd& x) const {
  const SupernodalSymbolic& sym = *symbolic_;
  const Eigen::VectorXd xp = sym.ToPermuted(x);
  const int64_t nsuper = sym.num_supernodes();
  // Supernodes [s0, s1) into y (permuted numbering).
  const auto product = [&](int64_t s0, int64_t s1, Eigen::VectorXd& yp) {
    Eigen::VectorXd xr, yr;
    for (int64_t s = s0; s < s1; ++s) {
      const auto [c0, nc, nr, m, rows, panel] = sym.supernode(s);
      Eigen::Map<const Eigen::MatrixXd> P(panels_.data() + panel, nr, nc);
      yp.segment(c0, nc).noalias() +=
          P.topRows(nc).selfadjointView<Eigen::Lower>() * xp.segment(c0, nc);
      if (m == 0) continue;
      // The off-diagonal block B (m x nc) contributes B^T x_rows to this supernode's rows and
      // B x_cols to the rows below.
      xr.resize(m);
      for (int64_t k = 0; k < m; ++k) xr[k] = xp[rows[k]];
      const auto B = P.bottomRows(m);
      yp.segment(c0, nc).noalias() += B.transpose() * xr;
      yr.noalias() = B * xp.segment(c0, nc);
      for (int64_t k = 0; k < m; ++k) yp[rows[k]] += yr[k];
    }
  };
  // The panels split into equal parts, one per thread, each with its own accumulator: a product
  // reads every panel once from memory, and a design edit's check runs three of them in a row.
  constexpr int64_t kParallelEntries = int64_t{1} << 16;
  const int64_t total = sym.panel_begin_[nsuper];
  const int64_t parts =
      total < kParallelEntries
          ? 1
          : std::min<int64_t>(std::max(1, tbb::this_task_arena::max_concurrency()), 8);
  if (parts == 1) {
    Eigen::VectorXd yp = Eigen::VectorXd::Zero(sym.n_);
    product(0, nsuper, yp);
    return sym.FromPermuted(yp);
  }
  std::vector<int64_t> bounds(parts + 1, nsuper);
  bounds[0] = 0;
  for (int64_t t = 1; t < parts; ++t) {
    bounds[t] =
        std::upper_bound(sym.panel_begin_.begin(), sym.panel_begin_.end() - 1, total * t / parts) -
        sym.panel_begin_.begin();
  }
  std::vector<Eigen::VectorXd> y(parts, Eigen::VectorXd::Zero(sym.n_));
  tbb::parallel_for(int64_t{0}, parts, [&](int64_t t) {
    product(bounds[t], std::max(bounds[t], bounds[t + 1]), y[t]);
  });
  for (int64_t t = 1; t < parts; ++t) y[0] += y[t];
  return sym.FromPermuted(y[0]);
}

}  // namespace fieldspace
