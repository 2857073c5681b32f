#include "core/subspace/kkt_solver.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <utility>

#include "Eigen/Eigenvalues"
#include "absl/strings/str_cat.h"
#include "core/common/cancel.h"
#include "core/subspace/subspace_util.h"
#include "oneapi/tbb/parallel_for.h"

namespace fieldspace {

std::vector<SparseRow> BasisRowsOfFace(const ReducedSystem& system, int32_t face) {
  const int32_t p = system.dofs_per_face();
  std::vector<SparseRow> rows(p);
  BasisRowScratch scratch;
  for (int32_t c = 0; c < p; ++c) {
    const BasisRow row = system.BasisRowOf(static_cast<int64_t>(face) * p + c, &scratch);
    rows[c].cols.assign(row.cols, row.cols + row.size);
    rows[c].vals.resize(row.size);
    for (int64_t q = 0; q < row.size; ++q) rows[c].vals[q] = static_cast<double>(row.vals[q]);
  }
  return rows;
}

absl::StatusOr<double> FaceStiffness(const ReducedSystem& system, const SupernodalFactor& factor,
                                     const std::vector<SparseRow>& rows, bool skip_kernel_columns) {
  const int64_t d = system.dimension();
  const int64_t first_kernel =
      skip_kernel_columns ? d - std::max<int32_t>(0, system.basis().kernel_columns) : d;
  const int32_t p = static_cast<int32_t>(rows.size());
  Eigen::MatrixXd W(d, p);
  std::vector<int32_t> cols;
  std::vector<double> vals;
  for (int32_t c = 0; c < p; ++c) {
    cols.clear();
    vals.clear();
    for (size_t q = 0; q < rows[c].cols.size(); ++q) {
      if (rows[c].cols[q] >= first_kernel) continue;
      cols.push_back(rows[c].cols[q]);
      vals.push_back(rows[c].vals[q]);
    }
    factor.ForwardSparse(cols, vals, W.col(c));
  }
  return StiffnessOfSubstitutions(W);
}

absl::StatusOr<double> StiffnessOfSubstitutions(const Eigen::Ref<const Eigen::MatrixXd>& W) {
  const Eigen::MatrixXd G = W.transpose() * W;
  const double g = Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(G, Eigen::EigenvaluesOnly)
                       .eigenvalues()
                       .minCoeff();
  // Relative to the largest: a face where one DOF direction has no support.
  if (!(g > 1e-12 * G.trace()) || !std::isfinite(g)) {
    return absl::FailedPreconditionError(
        "a scale-free soft constraint's face has (almost) no support in the subspace: no basis "
        "field controls one of its DOF directions, so its weight cannot be normalized; use raw "
        "weights or another face");
  }
  return g;
}

Eigen::SparseMatrix<double> ShiftKernelColumns(const ReducedSystem& system,
                                               const Eigen::SparseMatrix<double>& A) {
  Eigen::SparseMatrix<double> shifted = A;
  const int32_t q = system.basis().kernel_columns;
  const int64_t d = A.cols();
  if (q <= 0 || q >= d) return shifted;
  const Eigen::VectorXd mass = system.mass_matrix().diagonal();
  const Eigen::VectorXd energy = A.diagonal();
  double scale = std::numeric_limits<double>::infinity();
  for (int64_t i = 0; i < d - q; ++i) {
    if (energy[i] > 0 && mass[i] > 0) scale = std::min(scale, energy[i] / mass[i]);
  }
  if (!std::isfinite(scale)) return shifted;
  for (int64_t j = d - q; j < d; ++j) {
    shifted.coeffRef(j, j) += kKernelColumnShift * scale * mass[j];
  }
  return shifted;
}

absl::StatusOr<SupernodalFactor> FactorizeRegularized(
    std::shared_ptr<const SupernodalSymbolic> symbolic, const Eigen::SparseMatrix<double>& A,
    const ReducedSolveOptions& options, double* tau) {
  if (!(options.regularization >= 0) || !(options.max_regularization >= options.regularization) ||
      !std::isfinite(options.max_regularization)) {
    return absl::InvalidArgumentError(
        "ReducedSolveOptions: need 0 <= regularization <= max_regularization < inf");
  }
  SupernodalFactorOptions factor_options;
  factor_options.parallel = options.parallel;
  factor_options.cancel = options.cancel;
  double shift = options.regularization;
  absl::Status last;
  while (true) {
    factor_options.diagonal_shift = shift;
    auto factor = SupernodalFactor::Factorize(symbolic, A, factor_options);
    if (factor.ok()) {
      *tau = shift;
      return factor;
    }
    last = factor.status();
    if (!absl::IsFailedPrecondition(last) || shift >= options.max_regularization) break;
    shift = std::min(options.max_regularization, std::max(shift * 1e3, 1e-15));
  }
  if (absl::IsFailedPrecondition(last)) {
    return absl::FailedPreconditionError(absl::StrCat(
        "reduced system matrix cannot be factorized even with a relative diagonal shift of ",
        options.max_regularization, " (is it positive semi-definite?): ", last.message()));
  }
  return last;
}

KktSolver::KktSolver(int64_t dim, int32_t rows_per_group, const ReducedSolveOptions& options)
    : d_(dim), p_(rows_per_group), options_(options) {}

void KktSolver::EnsureCapacity(int64_t rows) {
  const int64_t cap = K_.rows();
  if (rows <= cap) return;
  const int64_t new_cap = std::max<int64_t>(rows, std::max<int64_t>(2 * cap, 16 * p_));
  K_.conservativeResize(new_cap, new_cap);
  t_.conservativeResize(new_cap);
  e_.conservativeResize(new_cap);
}

void KktSolver::EnsureSourceCapacity(int64_t cols) {
  for (Eigen::MatrixXd& V : V_) {
    if (cols <= V.cols()) continue;
    V.conservativeResize(d_, std::max<int64_t>(cols, std::max<int64_t>(2 * V.cols(), 16 * p_)));
  }
}

void KktSolver::ReleaseSource(int32_t g) {
  const int32_t i = source_of_[g];
  if (i < 0) return;
  source_of_[g] = -1;
  if (--sources_[i].members > 0) return;
  const int64_t v0 = sources_[i].v0;
  const int64_t width = sources_[i].width;
  sources_.erase(sources_.begin() + i);
  for (int32_t& s : source_of_) s -= s > i ? 1 : 0;
  if (v0 + width == v_cols_) {
    v_cols_ -= width;
  } else {
    // A hole: zero (no source's S reads or writes it, and 0 times its entries stays 0), moved
    // out once the holes are a quarter of V.
    for (Eigen::MatrixXd& V : V_) V.middleCols(v0, width).setZero();
    hole_cols_ += width;
  }
  if (4 * hole_cols_ > v_cols_) CompactSources();
}

void KktSolver::CompactSources() {
  std::vector<Source*> by_column;
  for (Source& src : sources_) by_column.push_back(&src);
  std::sort(by_column.begin(), by_column.end(),
            [](const Source* a, const Source* b) { return a->v0 < b->v0; });
  int64_t next = 0;
  for (Source* src : by_column) {
    if (src->v0 != next) {
      for (Eigen::MatrixXd& V : V_) {
        for (int64_t j = 0; j < src->width; ++j) V.col(next + j) = V.col(src->v0 + j);
      }
      src->v0 = next;
    }
    next += src->width;
  }
  v_cols_ = next;
  hole_cols_ = 0;
}

Eigen::MatrixXd KktSolver::ApplySt(const Eigen::Ref<const Eigen::MatrixXd>& X) const {
  // A combined source's block C^T X_src once for all its groups, then its groups' rows of it.
  std::vector<Eigen::MatrixXd> combined(sources_.size());
  for (size_t i = 0; i < sources_.size(); ++i) {
    const Source& src = sources_[i];
    if (src.C.size() != 0) {
      combined[i].noalias() = src.C.transpose() * X.middleRows(src.v0, src.width);
    }
  }
  Eigen::MatrixXd out(static_cast<int64_t>(num_groups_) * p_, X.cols());
  for (int32_t g = 0; g < num_groups_; ++g) {
    const Source& src = sources_[source_of_[g]];
    if (src.C.size() == 0) {
      out.middleRows(static_cast<int64_t>(g) * p_, p_) = X.middleRows(src.v0, p_);
    } else {
      out.middleRows(static_cast<int64_t>(g) * p_, p_) =
          combined[source_of_[g]].middleRows(source_col_[g], p_);
    }
  }
  return out;
}

Eigen::VectorXd KktSolver::ApplyS(const Eigen::VectorXd& nu) const {
  Eigen::VectorXd out = Eigen::VectorXd::Zero(v_cols_);
  for (int32_t g = 0; g < num_groups_; ++g) {
    const Source& src = sources_[source_of_[g]];
    const auto nu_g = nu.segment(static_cast<int64_t>(g) * p_, p_);
    if (src.C.size() == 0) {
      out.segment(src.v0, p_) += nu_g;
    } else {
      out.segment(src.v0, src.width).noalias() += src.C.middleCols(source_col_[g], p_) * nu_g;
    }
  }
  return out;
}

Eigen::MatrixXd KktSolver::GroupColumns(size_t k, int32_t g0, int32_t n) const {
  Eigen::MatrixXd W(d_, static_cast<int64_t>(n) * p_);
  for (int32_t i = 0; i < n; ++i) {
    const Source& src = sources_[source_of_[g0 + i]];
    if (src.C.size() == 0) {
      W.middleCols(static_cast<int64_t>(i) * p_, p_) = V_[k].middleCols(src.v0, p_);
    } else {
      W.middleCols(static_cast<int64_t>(i) * p_, p_).noalias() =
          V_[k].middleCols(src.v0, src.width) * src.C.middleCols(source_col_[g0 + i], p_);
    }
  }
  return W;
}

template <typename F>
void KktSolver::ForEachTerm(const F& f) const {
  const size_t n = terms_.size();
  if (n > 1 && options_.parallel) {
    tbb::parallel_for(size_t{0}, n, [&](size_t k) { f(k); });
  } else {
    for (size_t k = 0; k < n; ++k) f(k);
  }
}

KktSolver::RightHandSides KktSolver::GroupRightHandSides(absl::Span<const int32_t> groups) const {
  std::vector<const SparseRow*> rows;
  for (int32_t g : groups) {
    for (const SparseRow& row : rows_[g]) rows.push_back(&row);
  }
  const int64_t m = static_cast<int64_t>(rows.size());
  // The basis columns the rows touch: a stroke's faces share most of theirs (a 58-face stroke's
  // ~117 rows touch 12-48 columns on a 1.4M-face mesh at d = 2000), and then substituting those
  // columns' unit vectors and combining them (C = the rows restricted to them) costs a fraction of
  // substituting every row.
  RightHandSides out;
  for (const SparseRow* row : rows) {
    out.touched.insert(out.touched.end(), row->cols.begin(), row->cols.end());
  }
  std::sort(out.touched.begin(), out.touched.end());
  out.touched.erase(std::unique(out.touched.begin(), out.touched.end()), out.touched.end());
  const int64_t q = static_cast<int64_t>(out.touched.size());
  if (q < m) {
    out.combined = true;
    out.C = Eigen::MatrixXd::Zero(q, m);
    for (int64_t j = 0; j < m; ++j) {
      for (size_t k = 0; k < rows[j]->cols.size(); ++k) {
        const auto at = std::lower_bound(out.touched.begin(), out.touched.end(), rows[j]->cols[k]);
        out.C(at - out.touched.begin(), j) += rows[j]->vals[k];
      }
    }
    out.cols.reserve(q);
    out.vals.reserve(q);
    for (const int32_t& c : out.touched) {
      out.cols.emplace_back(&c, 1);
      out.vals.emplace_back(&kOne, 1);
    }
  } else {
    for (const SparseRow* row : rows) {
      out.cols.emplace_back(row->cols);
      out.vals.emplace_back(row->vals);
    }
  }
  return out;
}

Eigen::MatrixXd KktSolver::RecomputeGroups(absl::Span<const int32_t> groups, bool cross) {
  for (int32_t g : groups) ReleaseSource(g);
  RightHandSides rhs = GroupRightHandSides(groups);
  const int64_t q = static_cast<int64_t>(rhs.cols.size());
  const int64_t v0 = v_cols_;
  EnsureSourceCapacity(v0 + q);
  v_cols_ += q;
  if (rhs.combined) {
    for (size_t i = 0; i < groups.size(); ++i) {
      source_of_[groups[i]] = static_cast<int32_t>(sources_.size());
      source_col_[groups[i]] = static_cast<int64_t>(i) * p_;
    }
    sources_.push_back({v0, q, static_cast<int32_t>(groups.size()), std::move(rhs.C)});
  } else {
    for (size_t i = 0; i < groups.size(); ++i) {
      source_of_[groups[i]] = static_cast<int32_t>(sources_.size());
      source_col_[groups[i]] = 0;
      sources_.push_back({v0 + static_cast<int64_t>(i) * p_, p_, 1, {}});
    }
  }
  const int64_t s = v_cols_;
  std::vector<Eigen::MatrixXd> parts(terms_.size());
  // Per term on its own thread: the new sources' columns Y = L_k^-1 P B over the reach (zero
  // elsewhere), then V_k^T Y over the reach (after Y is stored, so that it holds their entries
  // against each other too).
  ForEachTerm([&](size_t k) {
    auto Y = V_[k].middleCols(v0, q);
    std::vector<std::pair<int64_t, int64_t>> reach;
    terms_[k].factor->ForwardSparseColumns(rhs.cols, rhs.vals, Y, &reach);
    int64_t next = 0;
    for (const auto& [a, b] : reach) {
      Y.middleRows(next, a - next).setZero();
      next = b;
    }
    Y.bottomRows(d_ - next).setZero();
    if (!cross) return;
    parts[k] = Eigen::MatrixXd::Zero(s, q);
    for (const auto& [a, b] : reach) {
      parts[k].noalias() += V_[k].block(a, 0, b - a, s).transpose() * Y.middleRows(a, b - a);
    }
  });
  if (!cross) return {};
  Eigen::MatrixXd G = terms_[0].weight * parts[0];
  for (size_t k = 1; k < terms_.size(); ++k) G.noalias() += terms_[k].weight * parts[k];
  if (rhs.combined) G = G * sources_.back().C;  // s x m: the groups' own W columns
  return ApplySt(G);
}

void KktSolver::ComputeGroup(int32_t g) {
  // SetMatrix() or SetMixed() computes every group later.
  if (terms_.empty()) return;
  const int64_t r0 = static_cast<int64_t>(g) * p_;
  const int64_t r = static_cast<int64_t>(num_groups_) * p_;
  // K = R A^-1 R^T: the group's rows and columns against all groups (its own block included).
  K_.block(0, r0, r, p_) = RecomputeGroups({&g, 1});
  K_.block(r0, 0, p_, r) = K_.block(0, r0, r, p_).transpose();
}

absl::Status KktSolver::SetMatrix(const SupernodalMatrix* A, const SupernodalFactor* factor) {
  A_ = A;
  mixed_.reset();
  return SetTerms({InverseTerm{factor, 1.0}});
}

absl::Status KktSolver::SetMixed(std::unique_ptr<const MixedEnergyInverse> inverse) {
  const auto terms = inverse->terms();
  if (&terms[0].factor->symbolic() != &terms[1].factor->symbolic()) {
    return absl::InternalError("mixed biharmonic: the two factorizations have different patterns");
  }
  A_ = nullptr;
  mixed_system_ = nullptr;
  mixed_mu_b_ = 0;
  mixed_ = std::move(inverse);
  return SetTerms({terms.begin(), terms.end()});
}

absl::Status KktSolver::SetTerms(std::vector<InverseTerm> terms) {
  terms_ = std::move(terms);
  V_.resize(terms_.size());
  return ComputeAllGroups();
}

absl::Status KktSolver::ComputeAllGroups() {
  schur_valid_ = false;
  const int64_t r = static_cast<int64_t>(num_groups_) * p_;
  const absl::Status cancelled = absl::CancelledError("hard constraint system: cancelled");
  // Thousands of constraints take seconds here (r forward substitutions, then O(r^2 d) for K):
  // cancellation is checked per block of groups and per block of K's columns.
  constexpr int64_t kColumns = 64;
  const int32_t groups_per_block = std::max<int32_t>(1, static_cast<int32_t>(kColumns / p_));
  // New sources for every group, by blocks of consecutive groups (a stroke's faces, appended as
  // one run, share one again).
  sources_.clear();
  v_cols_ = 0;
  hole_cols_ = 0;
  std::fill(source_of_.begin(), source_of_.end(), -1);
  std::vector<int32_t> block;
  for (int32_t g0 = 0; g0 < num_groups_; g0 += groups_per_block) {
    if (IsCancelled(options_.cancel)) return cancelled;
    const int32_t k = std::min(groups_per_block, num_groups_ - g0);
    block.resize(k);
    for (int32_t i = 0; i < k; ++i) block[i] = g0 + i;
    RecomputeGroups(block, /*cross=*/false);
  }
  // K = S^T sum_k c_k V_k^T W_k by blocks of its columns (groups g0 .. g0 + n - 1).
  const int64_t s = v_cols_;
  for (int32_t g0 = 0; g0 < num_groups_; g0 += groups_per_block) {
    if (IsCancelled(options_.cancel)) return cancelled;
    const int32_t n = std::min(groups_per_block, num_groups_ - g0);
    Eigen::MatrixXd G = Eigen::MatrixXd::Zero(s, static_cast<int64_t>(n) * p_);
    for (size_t k = 0; k < terms_.size(); ++k) {
      G.noalias() += terms_[k].weight * (V_[k].leftCols(s).transpose() * GroupColumns(k, g0, n));
    }
    K_.block(0, static_cast<int64_t>(g0) * p_, r, G.cols()) = ApplySt(G);
  }
  return absl::OkStatus();
}

void KktSolver::SetMixedBiharmonic(const ReducedSystem* system, double mu_b) {
  const bool on = system != nullptr && mu_b > 0;
  mixed_system_ = on ? system : nullptr;
  mixed_mu_b_ = on ? mu_b : 0.0;
}

void KktSolver::Append(std::vector<SparseRow> rows, const Eigen::VectorXd& target, double e,
                       bool hard) {
  const int32_t g = num_groups_;
  EnsureCapacity(static_cast<int64_t>(g + 1) * p_);
  rows_.push_back(std::move(rows));
  hard_.push_back(hard ? 1 : 0);
  source_of_.push_back(-1);
  source_col_.push_back(0);
  ++num_groups_;
  t_.segment(static_cast<int64_t>(g) * p_, p_) = target;
  e_.segment(static_cast<int64_t>(g) * p_, p_).setConstant(e);
  ComputeGroup(g);
  schur_valid_ = false;
}

void KktSolver::AppendGroups(std::vector<NewGroup> groups) {
  const int32_t g0 = num_groups_;
  const int32_t k = static_cast<int32_t>(groups.size());
  if (k == 0) return;
  EnsureCapacity(static_cast<int64_t>(g0 + k) * p_);
  for (NewGroup& group : groups) {
    const int64_t r0 = static_cast<int64_t>(num_groups_) * p_;
    t_.segment(r0, p_) = group.target;
    e_.segment(r0, p_).setConstant(group.e);
    rows_.push_back(std::move(group.rows));
    hard_.push_back(group.hard ? 1 : 0);
    source_of_.push_back(-1);
    source_col_.push_back(0);
    ++num_groups_;
  }
  schur_valid_ = false;
  // SetMatrix() or SetMixed() computes every group later.
  if (terms_.empty()) return;
  std::vector<int32_t> added(k);
  for (int32_t i = 0; i < k; ++i) added[i] = g0 + i;
  const int64_t r0 = static_cast<int64_t>(g0) * p_;
  const int64_t r = static_cast<int64_t>(num_groups_) * p_;
  const int64_t nc = r - r0;
  // K = R A^-1 R^T: the new columns against all groups, then the new rows by symmetry.
  K_.block(0, r0, r, nc) = RecomputeGroups(added);
  K_.block(r0, 0, nc, r0) = K_.block(0, r0, r0, nc).transpose();
}

void KktSolver::ReplaceGroups(const std::vector<int32_t>& slots, std::vector<NewGroup> groups) {
  const int64_t k = static_cast<int64_t>(slots.size());
  if (k == 0) return;
  for (int64_t i = 0; i < k; ++i) {
    const int64_t r0 = static_cast<int64_t>(slots[i]) * p_;
    t_.segment(r0, p_) = groups[i].target;
    e_.segment(r0, p_).setConstant(groups[i].e);
    rows_[slots[i]] = std::move(groups[i].rows);
    hard_[slots[i]] = groups[i].hard ? 1 : 0;
  }
  schur_valid_ = false;
  if (terms_.empty()) return;
  const int64_t r = static_cast<int64_t>(num_groups_) * p_;
  // r x k p: R A^-1 R^T's columns of the replaced rows (their new rows included).
  const Eigen::MatrixXd G = RecomputeGroups(slots);
  for (int64_t i = 0; i < k; ++i) {
    const int64_t c0 = static_cast<int64_t>(slots[i]) * p_;
    K_.block(0, c0, r, p_) = G.middleCols(i * p_, p_);
    K_.block(c0, 0, p_, r) = G.middleCols(i * p_, p_).transpose();
  }
}

void KktSolver::SetTarget(int32_t g, const Eigen::VectorXd& target) {
  t_.segment(static_cast<int64_t>(g) * p_, p_) = target;
}

void KktSolver::SetE(int32_t g, double e) {
  e_.segment(static_cast<int64_t>(g) * p_, p_).setConstant(e);
  schur_valid_ = false;
}

void KktSolver::RemoveSwapLast(int32_t g) {
  const int32_t last = num_groups_ - 1;
  const int64_t r = static_cast<int64_t>(num_groups_) * p_;
  ReleaseSource(g);
  if (g != last) {
    const int64_t a = static_cast<int64_t>(g) * p_;
    const int64_t b = static_cast<int64_t>(last) * p_;
    rows_[g] = std::move(rows_[last]);
    hard_[g] = hard_[last];
    t_.segment(a, p_) = t_.segment(b, p_);
    e_.segment(a, p_) = e_.segment(b, p_);
    source_of_[g] = source_of_[last];
    source_col_[g] = source_col_[last];
    // Move row/column block b to a (K symmetric): first the columns, then the rows.
    K_.block(0, a, r, p_) = K_.block(0, b, r, p_);
    K_.block(a, 0, p_, r) = K_.block(b, 0, p_, r);
    // The diagonal block: K(a, a) must become the old K(b, b).
    K_.block(a, a, p_, p_) = K_.block(b, b, p_, p_);
  }
  rows_.pop_back();
  hard_.pop_back();
  source_of_.pop_back();
  source_col_.pop_back();
  --num_groups_;
  schur_valid_ = false;
}

absl::Status KktSolver::FactorizeSchur() {
  const int64_t r = static_cast<int64_t>(num_groups_) * p_;
  std::vector<int64_t> order;
  order.reserve(r);
  int64_t num_hard_rows = 0;
  for (int32_t g = 0; g < num_groups_; ++g) {
    if (!hard_[g]) continue;
    for (int32_t c = 0; c < p_; ++c) order.push_back(static_cast<int64_t>(g) * p_ + c);
    num_hard_rows += p_;
  }
  for (int32_t g = 0; g < num_groups_; ++g) {
    if (hard_[g]) continue;
    for (int32_t c = 0; c < p_; ++c) order.push_back(static_cast<int64_t>(g) * p_ + c);
  }
  Eigen::VectorXd scale(r);
  for (int64_t i = 0; i < r; ++i) {
    const int64_t row = order[i];
    const double h = K_(row, row) + e_[row];
    if (!(h > 0) || !std::isfinite(h)) {
      return absl::FailedPreconditionError(
          absl::StrCat("constraint ", row / p_, " (component ", row % p_,
                       ") has no support in the subspace: every basis field vanishes at its face"));
    }
    scale[i] = 1.0 / std::sqrt(h);
  }
  Eigen::MatrixXd H(r, r);
  for (int64_t j = 0; j < r; ++j) {
    for (int64_t i = 0; i < r; ++i) {
      H(i, j) = K_(order[i], order[j]) * scale[i] * scale[j];
    }
    H(j, j) += e_[order[j]] * scale[j] * scale[j];
  }
  if (IsCancelled(options_.cancel))
    return absl::CancelledError("hard constraint system: cancelled");
  Eigen::LLT<Eigen::MatrixXd> llt(H);
  const auto dependent = [&](int64_t i) {
    return absl::FailedPreconditionError(absl::StrCat(
        "hard constraints are linearly dependent in the subspace: constraint ", order[i] / p_,
        " (component ", order[i] % p_,
        ") is (numerically) determined by the others; remove one, or use a soft constraint"));
  };
  if (llt.info() != Eigen::Success) {
    // Locate the failing pivot for the message: the first hard row whose pivot is not positive.
    return dependent(std::max<int64_t>(0, std::min<int64_t>(num_hard_rows, r) - 1));
  }
  const Eigen::MatrixXd& L = llt.matrixLLT();
  for (int64_t i = 0; i < num_hard_rows; ++i) {
    if (L(i, i) * L(i, i) < options_.dependence_tolerance) return dependent(i);
  }
  schur_min_pivot_ = 1.0;
  for (int64_t i = 0; i < r; ++i) schur_min_pivot_ = std::min(schur_min_pivot_, L(i, i) * L(i, i));
  order_ = std::move(order);
  scale_ = std::move(scale);
  schur_ = std::move(llt);
  schur_valid_ = true;
  return absl::OkStatus();
}

Eigen::VectorXd KktSolver::SolveSchur(const Eigen::VectorXd& v) const {
  const int64_t r = static_cast<int64_t>(order_.size());
  Eigen::VectorXd w(r);
  for (int64_t i = 0; i < r; ++i) w[i] = v[order_[i]] * scale_[i];
  schur_.solveInPlace(w);
  Eigen::VectorXd out(r);
  for (int64_t i = 0; i < r; ++i) out[order_[i]] = w[i] * scale_[i];
  return out;
}

ReducedSolution KktSolver::Solve(const Eigen::VectorXd* b, bool verify) const {
  // With P A_hat P^T = L L^T and W = L^-1 P R^T: A_hat^-1 v = P^T L^-T u for u = L^-1 P v,
  // R A_hat^-1 v = W^T u, and the solution of the saddle-point system is
  //   nu = H^-1 (W^T u - t),   x = P^T L^-T (u - W nu),   u = L^-1 P b:
  // one forward and one backward substitution (per term of A_hat^-1, side by side), whatever the
  // number of constraints.
  const int64_t r = static_cast<int64_t>(num_groups_) * p_;
  ReducedSolution sol;
  const auto apply_R = [&](const Eigen::VectorXd& v) {
    Eigen::VectorXd out(r);
    for (int64_t i = 0; i < r; ++i) out[i] = rows_[i / p_][i % p_].Dot(v.data());
    return out;
  };
  const auto apply_Rt = [&](const Eigen::VectorXd& nu) {
    Eigen::VectorXd out = Eigen::VectorXd::Zero(d_);
    for (int64_t i = 0; i < r; ++i) {
      const SparseRow& row = rows_[i / p_][i % p_];
      for (size_t q = 0; q < row.cols.size(); ++q) out[row.cols[q]] += row.vals[q] * nu[i];
    }
    return out;
  };
  // [dx; dnu] for right-hand sides (f, g) of the saddle-point system with A replaced by A_hat,
  // A_hat^-1 = sum_k c_k P^T L_k^-T L_k^-1 P (one term, or the mixed form's two on one pattern):
  //   u_k = L_k^-1 P f,  H nu = sum_k c_k W_k^T u_k - g,  x = P^T sum_k c_k L_k^-T (u_k - W_k nu).
  const auto solve_kkt = [&](const Eigen::VectorXd* f, const Eigen::VectorXd& g,
                             Eigen::VectorXd* dx, Eigen::VectorXd* dnu) {
    const SupernodalFactor& first = *terms_[0].factor;
    std::vector<Eigen::VectorXd> u(terms_.size());
    const Eigen::VectorXd pf = f != nullptr ? first.PermuteIn(*f) : Eigen::VectorXd();
    std::vector<Eigen::VectorXd> wu(terms_.size());
    ForEachTerm([&](size_t k) {
      if (f == nullptr) {
        u[k] = Eigen::VectorXd::Zero(d_);
        return;
      }
      u[k] = pf;
      terms_[k].factor->ForwardInPlace(u[k]);
      if (r > 0) wu[k].noalias() = V_[k].leftCols(v_cols_).transpose() * u[k];
    });
    if (r > 0) {
      Eigen::VectorXd h = -g;
      if (f != nullptr) {
        Eigen::VectorXd vu = terms_[0].weight * wu[0];
        for (size_t k = 1; k < terms_.size(); ++k) vu.noalias() += terms_[k].weight * wu[k];
        h.noalias() += ApplySt(vu).col(0);
      }
      *dnu = SolveSchur(h);
    } else {
      dnu->resize(0);
    }
    const Eigen::VectorXd s_nu = r > 0 ? ApplyS(*dnu) : Eigen::VectorXd();
    ForEachTerm([&](size_t k) {
      if (r > 0) u[k].noalias() -= V_[k].leftCols(v_cols_) * s_nu;
      terms_[k].factor->BackwardInPlace(u[k]);
    });
    Eigen::VectorXd sum = terms_[0].weight * u[0];
    for (size_t k = 1; k < terms_.size(); ++k) sum.noalias() += terms_[k].weight * u[k];
    *dx = first.PermuteOut(sum);
  };
  // The true matrix times v: A, or with the mixed biharmonic A - mu_b U^T B U + mu_b K Mr^-1 K.
  const auto apply_A = [&](const Eigen::VectorXd& v) {
    if (mixed_ != nullptr) return mixed_->Multiply(v);
    Eigen::VectorXd out = A_->Multiply(v);
    if (mixed_system_ != nullptr) {
      const ReducedSystem& system = *mixed_system_;
      const Eigen::VectorXd mr_kv = system.mass_factor().Solve(system.stiffness() * v);
      out.noalias() += mixed_mu_b_ * (system.stiffness() * mr_kv);
      out.noalias() -= mixed_mu_b_ * (system.bilaplacian() * v);
    }
    return out;
  };
  const double tiny = std::numeric_limits<double>::min();
  const Eigen::VectorXd t = t_.head(r);
  const Eigen::VectorXd e = e_.head(r);
  Eigen::VectorXd x, nu;
  solve_kkt(b, t, &x, &nu);
  if (mixed_system_ != nullptr) {
    // Conjugate gradients on A_s = A + R_s^T E_s^-1 R_s (soft rows eliminated) restricted to the
    // null space of the hard rows R_h, preconditioned by the KKT solve with F (which returns a
    // correction z with R_h z = 0 and a hard multiplier w: F_s z + R_h^T w = res), starting from
    // the preconditioner's own solution. The residual res = b_s - A_s x - R_h^T y is kept free of
    // the hard rows' range by moving each w into the multipliers y (Gould, Hribar and Nocedal's
    // residual update), so that at the end res is the first block residual of the saddle-point
    // system at (x, nu) with nu_soft = E_s^-1 (R_s x - t_s), nu_hard = y.
    Eigen::VectorXd inv_e = Eigen::VectorXd::Zero(r);
    Eigen::VectorXd hard_rows = Eigen::VectorXd::Zero(r);
    for (int64_t i = 0; i < r; ++i) {
      if (hard_[i / p_]) {
        hard_rows[i] = 1;
      } else {
        inv_e[i] = 1.0 / e[i];
      }
    }
    const Eigen::VectorXd zero_rows = Eigen::VectorXd::Zero(r);
    const auto apply_soft = [&](const Eigen::VectorXd& v) {
      return apply_Rt(inv_e.cwiseProduct(apply_R(v)));
    };
    Eigen::VectorXd bs = apply_Rt(inv_e.cwiseProduct(t));
    if (b != nullptr) bs += *b;
    Eigen::VectorXd y = hard_rows.cwiseProduct(nu);
    Eigen::VectorXd Ax, res;
    // The backward error at (x, y) for the true products Ax and the residual res (either the
    // recursively updated one or recomputed).
    const auto backward_error = [&]() {
      const Eigen::VectorXd Rx = apply_R(x);
      const Eigen::VectorXd full_nu = y + inv_e.cwiseProduct(Rx - t);
      const Eigen::VectorXd Enu = e.cwiseProduct(full_nu);
      const double scale1 = Ax.norm() + apply_Rt(full_nu).norm() + (b != nullptr ? b->norm() : 0.0);
      const double scale2 = t.norm() + Rx.norm() + Enu.norm();
      const double eta1 = res.norm() / (scale1 + tiny);
      const double eta2 = (t - Rx + Enu).norm() / (scale2 + tiny);
      return std::max(eta1, eta2);
    };
    const auto recompute = [&]() {
      Ax = apply_A(x);
      res = bs - Ax - apply_soft(x) - apply_Rt(y);
    };
    const auto precondition = [&](Eigen::VectorXd* z) {
      Eigen::VectorXd w;
      solve_kkt(&res, zero_rows, z, &w);
      w = hard_rows.cwiseProduct(w);
      y += w;
      res -= apply_Rt(w);
    };
    recompute();
    double eta = backward_error();
    int32_t iterations = 0;
    // Restarts from the recomputed residual when the recursive one has drifted; stops when a
    // cycle no longer halves the backward error (rounding level).
    while (eta > options_.tolerance && iterations < options_.max_iterations &&
           !IsCancelled(options_.cancel)) {
      // The corrections keep R_h x fixed, so its rounding error (large when F is nearly singular,
      // e.g. regularized in a kernel direction) is removed by a refinement step first.
      const Eigen::VectorXd hard_residual = hard_rows.cwiseProduct(t - apply_R(x));
      if (hard_residual.norm() > options_.tolerance * (t.norm() + tiny)) {
        Eigen::VectorXd dx, dnu;
        solve_kkt(&res, hard_residual, &dx, &dnu);
        x += dx;
        y += hard_rows.cwiseProduct(dnu);
        recompute();
      }
      Eigen::VectorXd z;
      precondition(&z);
      Eigen::VectorXd p = z;
      double rz = res.dot(z);
      while (iterations < options_.max_iterations && !IsCancelled(options_.cancel)) {
        const Eigen::VectorXd Ap = apply_A(p);
        const Eigen::VectorXd q = Ap + apply_soft(p);
        const double pq = p.dot(q);
        if (!(rz > 0) || !(pq > 0)) break;  // converged to rounding
        const double alpha = rz / pq;
        x.noalias() += alpha * p;
        Ax.noalias() += alpha * Ap;
        res.noalias() -= alpha * q;
        ++iterations;
        if (backward_error() <= options_.tolerance) break;
        precondition(&z);
        const double rz_next = res.dot(z);
        p = z + (rz_next / rz) * p;
        rz = rz_next;
      }
      recompute();
      const double next = backward_error();
      const bool progress = next < 0.5 * eta;
      eta = next;
      if (!progress) break;
    }
    sol.backward_error = eta;
    sol.refinement_steps = iterations;
    sol.coefficients = std::move(x);
    return sol;
  }
  if (!verify) {
    sol.backward_error = std::numeric_limits<double>::quiet_NaN();
    sol.coefficients = std::move(x);
    return sol;
  }
  for (int32_t step = 0;; ++step) {
    // Residuals of the true system and the normwise backward error.
    const Eigen::VectorXd Ax = apply_A(x);
    const Eigen::VectorXd Rtnu = apply_Rt(nu);
    const Eigen::VectorXd Rx = apply_R(x);
    Eigen::VectorXd r1 = -Ax - Rtnu;
    double scale1 = Ax.norm() + Rtnu.norm();
    if (b != nullptr) {
      r1 += *b;
      scale1 += b->norm();
    }
    const Eigen::VectorXd Enu = e.cwiseProduct(nu);
    const Eigen::VectorXd r2 = t - Rx + Enu;
    const double scale2 = t.norm() + Rx.norm() + Enu.norm();
    const double eta = std::max(r1.norm() / (scale1 + tiny), r2.norm() / (scale2 + tiny));
    sol.backward_error = eta;
    sol.refinement_steps = step;
    if (eta <= options_.tolerance || step >= options_.max_refinement_steps) break;
    Eigen::VectorXd dx, dnu;
    solve_kkt(&r1, r2, &dx, &dnu);
    x += dx;
    nu += dnu;
  }
  sol.coefficients = std::move(x);
  return sol;
}

}  // namespace fieldspace
