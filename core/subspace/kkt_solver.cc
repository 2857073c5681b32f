#include "core/subspace/kkt_solver.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <utility>

#include "absl/strings/str_cat.h"
#include "core/subspace/subspace_util.h"

namespace fieldspace {

std::vector<SparseRow> BasisRowsOfFace(const ReducedSystem& system, int32_t face) {
  const int32_t p = system.dofs_per_face();
  std::vector<SparseRow> rows(p);
  for (int32_t c = 0; c < p; ++c) {
    const BasisRow row = GetBasisRow(system.basis().U, static_cast<int64_t>(face) * p + c);
    rows[c].cols.assign(row.cols, row.cols + row.size);
    rows[c].vals.resize(row.size);
    for (int64_t q = 0; q < row.size; ++q) rows[c].vals[q] = static_cast<double>(row.vals[q]);
  }
  return rows;
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
  Z_.conservativeResize(d_, new_cap);
  K_.conservativeResize(new_cap, new_cap);
  t_.conservativeResize(new_cap);
  e_.conservativeResize(new_cap);
}

void KktSolver::ComputeGroup(int32_t g) {
  if (factor_ == nullptr) return;  // SetMatrix() computes every group later
  const int64_t r0 = static_cast<int64_t>(g) * p_;
  Eigen::MatrixXd Y = Eigen::MatrixXd::Zero(d_, p_);
  for (int32_t c = 0; c < p_; ++c) {
    const SparseRow& row = rows_[g][c];
    for (size_t q = 0; q < row.cols.size(); ++q) Y(row.cols[q], c) += row.vals[q];
  }
  factor_->SolveInPlace(Y);
  Z_.middleCols(r0, p_) = Y;
  const int64_t r = static_cast<int64_t>(num_groups_) * p_;
  for (int64_t i = 0; i < r; ++i) {
    const SparseRow& row = rows_[i / p_][i % p_];
    for (int32_t c = 0; c < p_; ++c) {
      const double v = row.Dot(Y.col(c).data());
      K_(i, r0 + c) = v;
      K_(r0 + c, i) = v;
    }
  }
  // The group's own block was written twice (both triangles from one side each): symmetrize.
  for (int32_t a = 0; a < p_; ++a) {
    for (int32_t c = a + 1; c < p_; ++c) {
      const double v = 0.5 * (rows_[g][a].Dot(Y.col(c).data()) + rows_[g][c].Dot(Y.col(a).data()));
      K_(r0 + a, r0 + c) = v;
      K_(r0 + c, r0 + a) = v;
    }
  }
}

void KktSolver::SetMatrix(const Eigen::SparseMatrix<double>* A, const SupernodalFactor* factor) {
  A_ = A;
  factor_ = factor;
  schur_valid_ = false;
  const int64_t r = static_cast<int64_t>(num_groups_) * p_;
  if (r == 0) return;
  Eigen::MatrixXd Y = Eigen::MatrixXd::Zero(d_, r);
  for (int64_t i = 0; i < r; ++i) {
    const SparseRow& row = rows_[i / p_][i % p_];
    for (size_t q = 0; q < row.cols.size(); ++q) Y(row.cols[q], i) += row.vals[q];
  }
  factor_->SolveInPlace(Y);
  Z_.leftCols(r) = Y;
  for (int64_t j = 0; j < r; ++j) {
    for (int64_t i = j; i < r; ++i) {
      const SparseRow& ri = rows_[i / p_][i % p_];
      const SparseRow& rj = rows_[j / p_][j % p_];
      const double v = 0.5 * (ri.Dot(Y.col(j).data()) + rj.Dot(Y.col(i).data()));
      K_(i, j) = v;
      K_(j, i) = v;
    }
  }
}

void KktSolver::Append(std::vector<SparseRow> rows, const Eigen::VectorXd& target, double e,
                       bool hard) {
  const int32_t g = num_groups_;
  EnsureCapacity(static_cast<int64_t>(g + 1) * p_);
  rows_.push_back(std::move(rows));
  hard_.push_back(hard ? 1 : 0);
  ++num_groups_;
  t_.segment(static_cast<int64_t>(g) * p_, p_) = target;
  e_.segment(static_cast<int64_t>(g) * p_, p_).setConstant(e);
  ComputeGroup(g);
  schur_valid_ = false;
}

void KktSolver::Replace(int32_t g, std::vector<SparseRow> rows, const Eigen::VectorXd& target,
                        double e) {
  rows_[g] = std::move(rows);
  t_.segment(static_cast<int64_t>(g) * p_, p_) = target;
  e_.segment(static_cast<int64_t>(g) * p_, p_).setConstant(e);
  ComputeGroup(g);
  schur_valid_ = false;
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
  if (g != last) {
    const int64_t a = static_cast<int64_t>(g) * p_;
    const int64_t b = static_cast<int64_t>(last) * p_;
    rows_[g] = std::move(rows_[last]);
    hard_[g] = hard_[last];
    t_.segment(a, p_) = t_.segment(b, p_);
    e_.segment(a, p_) = e_.segment(b, p_);
    Z_.middleCols(a, p_) = Z_.middleCols(b, p_);
    // Move row/column block b to a (K symmetric): first the columns, then the rows.
    K_.block(0, a, r, p_) = K_.block(0, b, r, p_);
    K_.block(a, 0, p_, r) = K_.block(b, 0, p_, r);
    // The diagonal block: K(a, a) must become the old K(b, b).
    K_.block(a, a, p_, p_) = K_.block(b, b, p_, p_);
  }
  rows_.pop_back();
  hard_.pop_back();
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

ReducedSolution KktSolver::Solve(const Eigen::VectorXd* b) const {
  const int64_t r = static_cast<int64_t>(num_groups_) * p_;
  ReducedSolution sol;
  Eigen::VectorXd x = Eigen::VectorXd::Zero(d_);
  if (b != nullptr) x = factor_->Solve(*b);
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
  const Eigen::VectorXd t = t_.head(r);
  const Eigen::VectorXd e = e_.head(r);
  Eigen::VectorXd nu = Eigen::VectorXd::Zero(r);
  if (r > 0) {
    nu = SolveSchur(apply_R(x) - t);
    x.noalias() -= Z_.leftCols(r) * nu;
  }
  const double tiny = std::numeric_limits<double>::min();
  for (int32_t step = 0;; ++step) {
    // Residuals of the true system and the normwise backward error.
    const Eigen::VectorXd Ax = (*A_) * x;
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
    Eigen::VectorXd y = factor_->Solve(r1);
    if (r > 0) {
      const Eigen::VectorXd dnu = SolveSchur(apply_R(y) - r2);
      y.noalias() -= Z_.leftCols(r) * dnu;
      nu += dnu;
    }
    x += y;
  }
  sol.coefficients = std::move(x);
  return sol;
}

}  // namespace fieldspace
