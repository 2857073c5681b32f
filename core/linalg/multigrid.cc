#include "core/linalg/multigrid.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "Eigen/Dense"
#include "absl/strings/str_format.h"
#include "core/common/random.h"
#include "tbb/blocked_range.h"
#include "tbb/enumerable_thread_specific.h"
#include "tbb/parallel_for.h"
#include "tbb/parallel_reduce.h"

namespace fieldspace {
namespace {

constexpr int32_t kMaxLevels = 25;
// Right-hand sides go through the solver in panels of at most this many columns (the width of
// the cycle's single-precision rows: one AVX register).
constexpr int kPanel = 8;

// A compressed sparse row matrix; the finest level's points into the caller's matrix.
template <typename V>
struct Csr {
  int32_t rows = 0;
  int32_t cols = 0;
  const int32_t* outer = nullptr;
  const int32_t* index = nullptr;
  const V* value = nullptr;
  // Storage when owned (coarse levels, prolongations).
  std::vector<int32_t> outer_store, index_store;
  std::vector<V> value_store;

  int64_t nonzeros() const { return rows == 0 ? 0 : outer[rows]; }
  void Own() {
    outer = outer_store.data();
    index = index_store.data();
    value = value_store.data();
  }
};

// The caller's matrix as a Csr (no copy): a symmetric compressed column-major matrix's columns
// are its rows.
Csr<double> View(const Eigen::SparseMatrix<double>& A) {
  Csr<double> v;
  v.rows = static_cast<int32_t>(A.rows());
  v.cols = static_cast<int32_t>(A.cols());
  v.outer = A.outerIndexPtr();
  v.index = A.innerIndexPtr();
  v.value = A.valuePtr();
  return v;
}

// The single-precision copy the cycle runs on (it halves the memory traffic of its sweeps; the
// conjugate gradient recurrence and its products with A stay in double). Takes over `x`'s index
// storage when it owns it.
Csr<float> ToFloat(Csr<double>&& x) {
  Csr<float> f;
  f.rows = x.rows;
  f.cols = x.cols;
  const int64_t nnz = x.nonzeros();
  f.value_store.assign(x.value, x.value + nnz);
  if (x.outer_store.empty()) {
    f.outer = x.outer;
    f.index = x.index;
    f.value = f.value_store.data();
  } else {
    f.outer_store = std::move(x.outer_store);
    f.index_store = std::move(x.index_store);
    f.Own();
  }
  x = Csr<double>();
  return f;
}

// X Y for CSR X (r x m) and Y (m x c), by rows in parallel (Gustavson: a dense accumulator and
// a marker per thread). Column indices within a row come out unsorted.
Csr<double> Multiply(const Csr<double>& X, const Csr<double>& Y) {
  Csr<double> Z;
  Z.rows = X.rows;
  Z.cols = Y.cols;
  Z.outer_store.assign(static_cast<size_t>(X.rows) + 1, 0);
  struct Scratch {
    std::vector<int32_t> marker;
    std::vector<double> acc;
  };
  tbb::enumerable_thread_specific<Scratch> scratch([&] {
    return Scratch{std::vector<int32_t>(Y.cols, -1), std::vector<double>(Y.cols, 0.0)};
  });
  const int32_t grain = 2048;
  // Symbolic pass: the row lengths.
  tbb::parallel_for(tbb::blocked_range<int32_t>(0, X.rows, grain),
                    [&](const tbb::blocked_range<int32_t>& range) {
                      std::vector<int32_t>& marker = scratch.local().marker;
                      for (int32_t i = range.begin(); i != range.end(); ++i) {
                        int32_t count = 0;
                        for (int32_t p = X.outer[i]; p < X.outer[i + 1]; ++p) {
                          const int32_t j = X.index[p];
                          for (int32_t s = Y.outer[j]; s < Y.outer[j + 1]; ++s) {
                            const int32_t c = Y.index[s];
                            if (marker[c] != i) {
                              marker[c] = i;
                              ++count;
                            }
                          }
                        }
                        Z.outer_store[i + 1] = count;
                      }
                    });
  for (int32_t i = 0; i < X.rows; ++i) Z.outer_store[i + 1] += Z.outer_store[i];
  Z.index_store.resize(Z.outer_store[X.rows]);
  Z.value_store.resize(Z.outer_store[X.rows]);
  for (Scratch& s : scratch) std::fill(s.marker.begin(), s.marker.end(), -1);
  // Numeric pass.
  tbb::parallel_for(tbb::blocked_range<int32_t>(0, X.rows, grain),
                    [&](const tbb::blocked_range<int32_t>& range) {
                      Scratch& s = scratch.local();
                      for (int32_t i = range.begin(); i != range.end(); ++i) {
                        int32_t* cols = Z.index_store.data() + Z.outer_store[i];
                        int32_t n = 0;
                        for (int32_t p = X.outer[i]; p < X.outer[i + 1]; ++p) {
                          const int32_t j = X.index[p];
                          const double x = X.value[p];
                          for (int32_t q = Y.outer[j]; q < Y.outer[j + 1]; ++q) {
                            const int32_t c = Y.index[q];
                            if (s.marker[c] != i) {
                              s.marker[c] = i;
                              s.acc[c] = 0.0;
                              cols[n++] = c;
                            }
                            s.acc[c] += x * Y.value[q];
                          }
                        }
                        double* vals = Z.value_store.data() + Z.outer_store[i];
                        for (int32_t t = 0; t < n; ++t) vals[t] = s.acc[cols[t]];
                      }
                    });
  Z.Own();
  return Z;
}

// X^T (c x r) for CSR X (r x c).
Csr<double> Transpose(const Csr<double>& X) {
  Csr<double> T;
  T.rows = X.cols;
  T.cols = X.rows;
  T.outer_store.assign(static_cast<size_t>(X.cols) + 1, 0);
  const int64_t nnz = X.nonzeros();
  for (int64_t p = 0; p < nnz; ++p) ++T.outer_store[X.index[p] + 1];
  for (int32_t c = 0; c < X.cols; ++c) T.outer_store[c + 1] += T.outer_store[c];
  T.index_store.resize(nnz);
  T.value_store.resize(nnz);
  std::vector<int32_t> cursor(T.outer_store.begin(), T.outer_store.end() - 1);
  for (int32_t i = 0; i < X.rows; ++i) {
    for (int32_t p = X.outer[i]; p < X.outer[i + 1]; ++p) {
      const int32_t q = cursor[X.index[p]]++;
      T.index_store[q] = i;
      T.value_store[q] = X.value[p];
    }
  }
  T.Own();
  return T;
}

// Y = X V (or Y += X V) for CSR X (r x c) and row-major V (c x W), in parallel over rows.
template <int W, typename M, typename T>
void MultiplyDense(const Csr<M>& X, const T* v, T* y, bool add) {
  tbb::parallel_for(tbb::blocked_range<int32_t>(0, X.rows, 4096),
                    [&](const tbb::blocked_range<int32_t>& range) {
                      for (int32_t i = range.begin(); i != range.end(); ++i) {
                        T s[W] = {};
                        for (int32_t p = X.outer[i]; p < X.outer[i + 1]; ++p) {
                          const T a = static_cast<T>(X.value[p]);
                          const T* vj = v + static_cast<int64_t>(X.index[p]) * W;
                          for (int c = 0; c < W; ++c) s[c] += a * vj[c];
                        }
                        T* yi = y + static_cast<int64_t>(i) * W;
                        for (int c = 0; c < W; ++c) yi[c] = add ? yi[c] + s[c] : s[c];
                      }
                    });
}

// A product with a single column (the spectral radius estimate).
void MultiplyVector(const Csr<double>& X, const double* v, double* y) {
  MultiplyDense<1>(X, v, y, /*add=*/false);
}

struct Level {
  Csr<float> A;
  std::vector<float> inv_diag;
  Csr<float> P;                      // n x (next level's n); empty on the coarsest
  Csr<float> R;                      // P^T
  std::vector<float> x, b, r, save;  // n x kPanel work arrays of the cycle
};

// Aggregates of the strength graph of A (Vanek, Mandel, Brezina 1996, section 5): first, every
// node whose strong neighbours are all free becomes a root with them; then each free node joins
// the aggregate of a strong neighbour from the first pass; what is left forms aggregates with
// its free strong neighbours (or alone). Returns the aggregate of each row and their number.
int32_t Aggregate(const Csr<double>& A, const std::vector<double>& diag, double theta,
                  std::vector<int32_t>* agg) {
  const int32_t n = A.rows;
  agg->assign(n, -1);
  std::vector<int32_t>& a = *agg;
  auto strong = [&](int32_t i, int32_t p) {
    const int32_t j = A.index[p];
    return j != i && std::abs(A.value[p]) >= theta * std::sqrt(diag[i] * diag[j]);
  };
  int32_t count = 0;
  for (int32_t i = 0; i < n; ++i) {
    if (a[i] >= 0) continue;
    bool free = true;
    bool any = false;
    for (int32_t p = A.outer[i]; p < A.outer[i + 1] && free; ++p) {
      if (!strong(i, p)) continue;
      any = true;
      free = a[A.index[p]] < 0;
    }
    if (!free || !any) continue;
    a[i] = count;
    for (int32_t p = A.outer[i]; p < A.outer[i + 1]; ++p) {
      if (strong(i, p)) a[A.index[p]] = count;
    }
    ++count;
  }
  const std::vector<int32_t> first = a;
  for (int32_t i = 0; i < n; ++i) {
    if (a[i] >= 0) continue;
    double best = -1.0;
    for (int32_t p = A.outer[i]; p < A.outer[i + 1]; ++p) {
      const int32_t j = A.index[p];
      if (!strong(i, p) || first[j] < 0) continue;
      const double w = std::abs(A.value[p]);
      if (w > best) {
        best = w;
        a[i] = first[j];
      }
    }
  }
  for (int32_t i = 0; i < n; ++i) {
    if (a[i] >= 0) continue;
    a[i] = count;
    for (int32_t p = A.outer[i]; p < A.outer[i + 1]; ++p) {
      if (strong(i, p) && a[A.index[p]] < 0) a[A.index[p]] = count;
    }
    ++count;
  }
  return count;
}

// An upper estimate of the spectral radius of D^-1 A (power iteration, then 10% margin).
double SpectralRadiusEstimate(const Csr<double>& A, const std::vector<double>& inv_diag) {
  const int32_t n = A.rows;
  std::vector<double> v(n), w(n);
  SplitMix64 random(0x9e3779b97f4a7c15ull);
  for (int32_t i = 0; i < n; ++i) v[i] = 0.5 * random.NextSigned();
  double rho = 0.0;
  for (int it = 0; it < 12; ++it) {
    MultiplyVector(A, v.data(), w.data());
    double norm = 0.0;
    for (int32_t i = 0; i < n; ++i) {
      w[i] *= inv_diag[i];
      norm += w[i] * w[i];
    }
    double vnorm = 0.0;
    for (int32_t i = 0; i < n; ++i) vnorm += v[i] * v[i];
    norm = std::sqrt(norm);
    rho = norm / std::sqrt(vnorm);
    if (!(norm > 0)) break;
    for (int32_t i = 0; i < n; ++i) v[i] = w[i] / norm;
  }
  return 1.1 * rho;
}

// The smoothed prolongation P = (I - omega D^-1 A) P_tent, P_tent the normalized constant on
// each aggregate, omega = 4 / (3 rho(D^-1 A)).
Csr<double> SmoothedProlongation(const Csr<double>& A, const std::vector<double>& inv_diag,
                                 const std::vector<int32_t>& agg, int32_t num_agg) {
  const int32_t n = A.rows;
  std::vector<int32_t> size(num_agg, 0);
  for (int32_t i = 0; i < n; ++i) ++size[agg[i]];
  std::vector<double> t(n);
  for (int32_t i = 0; i < n; ++i) t[i] = 1.0 / std::sqrt(static_cast<double>(size[agg[i]]));
  const double omega = 4.0 / (3.0 * SpectralRadiusEstimate(A, inv_diag));
  Csr<double> P;
  P.rows = n;
  P.cols = num_agg;
  P.outer_store.assign(static_cast<size_t>(n) + 1, 0);
  std::vector<std::pair<int32_t, double>> row;
  for (int32_t i = 0; i < n; ++i) {
    row.clear();
    row.emplace_back(agg[i], t[i]);
    const double s = -omega * inv_diag[i];
    for (int32_t p = A.outer[i]; p < A.outer[i + 1]; ++p) {
      const int32_t j = A.index[p];
      const int32_t c = agg[j];
      const double v = s * A.value[p] * t[j];
      bool found = false;
      for (auto& e : row) {
        if (e.first == c) {
          e.second += v;
          found = true;
          break;
        }
      }
      if (!found) row.emplace_back(c, v);
    }
    for (const auto& [c, v] : row) {
      if (v == 0.0) continue;
      P.index_store.push_back(c);
      P.value_store.push_back(v);
    }
    P.outer_store[i + 1] = static_cast<int32_t>(P.index_store.size());
  }
  P.Own();
  return P;
}

// One Gauss-Seidel sweep on A x = b (n x W row-major), forward or backward.
template <int W>
void GaussSeidel(const Level& l, bool forward, float* x, const float* b) {
  const int32_t n = l.A.rows;
  for (int32_t k = 0; k < n; ++k) {
    const int32_t i = forward ? k : n - 1 - k;
    float s[W];
    const float* bi = b + static_cast<int64_t>(i) * W;
    for (int c = 0; c < W; ++c) s[c] = bi[c];
    for (int32_t p = l.A.outer[i]; p < l.A.outer[i + 1]; ++p) {
      const float a = l.A.value[p];
      const float* xj = x + static_cast<int64_t>(l.A.index[p]) * W;
      for (int c = 0; c < W; ++c) s[c] -= a * xj[c];
    }
    float* xi = x + static_cast<int64_t>(i) * W;
    const float d = l.inv_diag[i];
    for (int c = 0; c < W; ++c) xi[c] += d * s[c];
  }
}

class Hierarchy {
 public:
  absl::Status Build(const Eigen::SparseMatrix<double>& A, const MultigridOptions& options) {
    Csr<double> current = View(A);  // the level being coarsened, in double
    fine_nonzeros_ = current.nonzeros();
    while (true) {
      auto level = std::make_unique<Level>();
      Level& l = *level;
      const int32_t n = current.rows;
      total_nonzeros_ += current.nonzeros();
      std::vector<double> diag(n, 0.0);
      for (int32_t i = 0; i < n; ++i) {
        for (int32_t p = current.outer[i]; p < current.outer[i + 1]; ++p) {
          if (current.index[p] == i) diag[i] += current.value[p];
        }
        if (!(diag[i] > 0) || !std::isfinite(diag[i])) {
          // The caller's matrix is wrong; a coarse one is the hierarchy's failure (a caller
          // may fall back to a factorization).
          const std::string message =
              absl::StrFormat("multigrid: diagonal entry %d of level %d is %g, not positive", i,
                              levels_.size(), diag[i]);
          return levels_.empty() ? absl::InvalidArgumentError(message)
                                 : absl::FailedPreconditionError(message);
        }
      }
      std::vector<double> inv_diag(n);
      for (int32_t i = 0; i < n; ++i) inv_diag[i] = 1.0 / diag[i];
      l.inv_diag.assign(inv_diag.begin(), inv_diag.end());
      for (std::vector<float>* v : {&l.x, &l.b, &l.r, &l.save}) {
        v->resize(static_cast<size_t>(n) * kPanel);
      }
      bool coarsest = n <= options.coarsest_rows || levels_.size() + 1 == kMaxLevels;
      std::vector<int32_t> agg;
      int32_t nc = 0;
      if (!coarsest) {
        if (IsCancelled(options.cancel)) return absl::CancelledError("multigrid setup cancelled");
        nc = Aggregate(current, diag, options.strength_threshold, &agg);
        coarsest = nc >= n - n / 10;  // coarsening stalls
      }
      if (coarsest) {
        if (n > 4 * options.coarsest_rows) {
          return absl::FailedPreconditionError(absl::StrFormat(
              "multigrid: coarsening stalled at %d rows (level %d)", n, levels_.size()));
        }
        Eigen::MatrixXd dense = Eigen::MatrixXd::Zero(n, n);
        for (int32_t i = 0; i < n; ++i) {
          for (int32_t p = current.outer[i]; p < current.outer[i + 1]; ++p) {
            dense(i, current.index[p]) += current.value[p];
          }
        }
        coarse_.compute(0.5 * (dense + dense.transpose()));
        if (coarse_.info() != Eigen::Success) {
          return absl::FailedPreconditionError(absl::StrFormat(
              "multigrid: the coarsest matrix (%d rows) is not positive definite", n));
        }
        l.A = ToFloat(std::move(current));
        levels_.push_back(std::move(level));
        return absl::OkStatus();
      }
      Csr<double> P = SmoothedProlongation(current, inv_diag, agg, nc);
      Csr<double> R = Transpose(P);
      Csr<double> next;
      {
        Csr<double> AP = Multiply(current, P);
        next = Multiply(R, AP);
      }
      l.A = ToFloat(std::move(current));
      l.P = ToFloat(std::move(P));
      l.R = ToFloat(std::move(R));
      levels_.push_back(std::move(level));
      current = std::move(next);
      current.Own();  // (moving the vectors kept their buffers; refresh the pointers anyway)
    }
  }

  int32_t levels() const { return static_cast<int32_t>(levels_.size()); }
  int32_t coarsest_rows() const { return levels_.back()->A.rows; }
  double operator_complexity() const {
    return static_cast<double>(total_nonzeros_) /
           static_cast<double>(std::max<int64_t>(1, fine_nonzeros_));
  }

  // The preconditioner z = C r, symmetric positive definite (up to single-precision rounding):
  // write r (n x W row-major) to input(), Run<W>(), read z from output().
  float* input() { return levels_.front()->b.data(); }
  const float* output() const { return levels_.front()->x.data(); }
  template <int W>
  void Run() {
    Cycle<W>(0);
  }

 private:
  // Level k's x from its b: one Gauss-Seidel sweep, the coarse correction (two cycles of the next
  // level, a W-cycle: 17 iterations against a V-cycle's 23 on fertility_loop3_1789k at tolerance
  // 1e-10, for the coarse levels' small share of the work), one sweep in the opposite order.
  template <int W>
  void Cycle(size_t k) {
    Level& l = *levels_[k];
    const int32_t n = l.A.rows;
    using Block =
        Eigen::Matrix<float, Eigen::Dynamic, W, W == 1 ? Eigen::ColMajor : Eigen::RowMajor>;
    if (k + 1 == levels_.size()) {
      const Eigen::MatrixXd b = Eigen::Map<const Block>(l.b.data(), n, W).template cast<double>();
      Eigen::Map<Block>(l.x.data(), n, W) = coarse_.solve(b).template cast<float>();
      return;
    }
    Level& next = *levels_[k + 1];
    const size_t size = static_cast<size_t>(n) * W;
    const size_t next_size = static_cast<size_t>(next.A.rows) * W;
    std::fill(l.x.begin(), l.x.begin() + size, 0.0f);
    GaussSeidel<W>(l, /*forward=*/true, l.x.data(), l.b.data());
    MultiplyDense<W>(l.A, l.x.data(), l.r.data(), /*add=*/false);
    for (size_t i = 0; i < size; ++i) l.r[i] = l.b[i] - l.r[i];
    MultiplyDense<W>(l.R, l.r.data(), next.b.data(), /*add=*/false);
    Cycle<W>(k + 1);
    if (k + 2 < levels_.size()) {
      std::copy(next.x.begin(), next.x.begin() + next_size, next.save.begin());
      MultiplyDense<W>(next.A, next.x.data(), next.r.data(), /*add=*/false);
      for (size_t i = 0; i < next_size; ++i) next.b[i] -= next.r[i];
      Cycle<W>(k + 1);
      for (size_t i = 0; i < next_size; ++i) next.x[i] += next.save[i];
    }
    MultiplyDense<W>(l.P, next.x.data(), l.x.data(), /*add=*/true);
    GaussSeidel<W>(l, /*forward=*/false, l.x.data(), l.b.data());
  }

  int64_t fine_nonzeros_ = 0;
  int64_t total_nonzeros_ = 0;
  std::vector<std::unique_ptr<Level>> levels_;
  Eigen::LLT<Eigen::MatrixXd> coarse_;
};

// Y = A P and the column-wise dots P . Y, in one pass (deterministic in the threads).
template <int W>
void MultiplyAndDot(const Csr<double>& A, const double* p, double* y, double* dots) {
  struct Sums {
    double v[W] = {};
  };
  const Sums sums = tbb::parallel_deterministic_reduce(
      tbb::blocked_range<int32_t>(0, A.rows, 4096), Sums(),
      [&](const tbb::blocked_range<int32_t>& range, Sums acc) {
        for (int32_t i = range.begin(); i != range.end(); ++i) {
          double s[W] = {};
          for (int32_t q = A.outer[i]; q < A.outer[i + 1]; ++q) {
            const double a = A.value[q];
            const double* pj = p + static_cast<int64_t>(A.index[q]) * W;
            for (int c = 0; c < W; ++c) s[c] += a * pj[c];
          }
          double* yi = y + static_cast<int64_t>(i) * W;
          const double* pi = p + static_cast<int64_t>(i) * W;
          for (int c = 0; c < W; ++c) {
            yi[c] = s[c];
            acc.v[c] += pi[c] * s[c];
          }
        }
        return acc;
      },
      [](Sums a, const Sums& b) {
        for (int c = 0; c < W; ++c) a.v[c] += b.v[c];
        return a;
      });
  for (int c = 0; c < W; ++c) dots[c] = sums.v[c];
}

// Preconditioned conjugate gradients on a panel of W columns: B and X n x W row-major, X
// starting at zero. One recurrence per column, all columns through each product; a column
// stops (its step sizes become 0) once its relative residual is below the tolerance. The
// vector updates are fused into as few passes as the recurrence allows (it is memory bound),
// and the preconditioned residual is read straight from the cycle's single-precision output.
// Returns the iterations taken; FailedPrecondition past max_iterations; Cancelled.
template <int W>
absl::StatusOr<int32_t> SolvePanel(const Csr<double>& A, Hierarchy& h, const double* B, double* X,
                                   const MultigridOptions& options, double* max_residual) {
  const int32_t n = A.rows;
  const size_t size = static_cast<size_t>(n) * W;
  std::vector<double> R(B, B + size), P(size), AP(size);
  float* cycle_in = h.input();
  const float* z = h.output();
  double b_norm[W] = {}, r_norm[W] = {}, rz[W] = {};
  bool active[W];
  for (size_t i = 0; i < size; i += W) {
    for (int c = 0; c < W; ++c) {
      b_norm[c] += B[i + c] * B[i + c];
      cycle_in[i + c] = static_cast<float>(B[i + c]);
    }
  }
  for (int c = 0; c < W; ++c) {
    r_norm[c] = b_norm[c];
    b_norm[c] = std::sqrt(b_norm[c]);
    active[c] = b_norm[c] > 0;
  }
  h.Run<W>();
  for (size_t i = 0; i < size; i += W) {
    for (int c = 0; c < W; ++c) {
      P[i + c] = z[i + c];
      rz[c] += R[i + c] * P[i + c];
    }
  }
  for (int32_t it = 0;; ++it) {
    bool any = false;
    *max_residual = 0;
    for (int c = 0; c < W; ++c) {
      if (b_norm[c] == 0) continue;
      const double rel = std::sqrt(r_norm[c]) / b_norm[c];
      *max_residual = std::max(*max_residual, rel);
      if (rel <= options.tolerance) active[c] = false;
      any = any || active[c];
    }
    if (!any) return it;
    if (it == options.max_iterations) {
      return absl::FailedPreconditionError(
          absl::StrFormat("multigrid: relative residual %g after %d iterations (tolerance %g)",
                          *max_residual, it, options.tolerance));
    }
    if (IsCancelled(options.cancel)) return absl::CancelledError("multigrid solve cancelled");
    double pap[W], alpha[W];
    MultiplyAndDot<W>(A, P.data(), AP.data(), pap);
    for (int c = 0; c < W; ++c) {
      alpha[c] = active[c] && pap[c] > 0 ? rz[c] / pap[c] : 0.0;
      r_norm[c] = 0;
    }
    // X += alpha P, R -= alpha AP, the cycle's input and ||R||^2 in one pass.
    for (size_t i = 0; i < size; i += W) {
      for (int c = 0; c < W; ++c) {
        X[i + c] += alpha[c] * P[i + c];
        const double r = R[i + c] - alpha[c] * AP[i + c];
        R[i + c] = r;
        r_norm[c] += r * r;
        cycle_in[i + c] = static_cast<float>(r);
      }
    }
    h.Run<W>();
    double rz_new[W] = {}, beta[W];
    for (size_t i = 0; i < size; i += W) {
      for (int c = 0; c < W; ++c) rz_new[c] += R[i + c] * static_cast<double>(z[i + c]);
    }
    for (int c = 0; c < W; ++c) {
      beta[c] = active[c] && rz[c] > 0 ? rz_new[c] / rz[c] : 0.0;
      rz[c] = rz_new[c];
    }
    for (size_t i = 0; i < size; i += W) {
      for (int c = 0; c < W; ++c) P[i + c] = static_cast<double>(z[i + c]) + beta[c] * P[i + c];
    }
  }
}

}  // namespace

absl::StatusOr<MultigridRowMatrix> SolveMultigridCg(const Eigen::SparseMatrix<double>& A,
                                                    const MultigridRowMatrix& B,
                                                    const MultigridOptions& options,
                                                    MultigridStats* stats) {
  const auto t0 = std::chrono::steady_clock::now();
  if (A.rows() != A.cols() || B.rows() != A.rows()) {
    return absl::InvalidArgumentError(
        absl::StrFormat("multigrid: A is %d x %d and B has %d rows", A.rows(), A.cols(), B.rows()));
  }
  if (!A.isCompressed()) {
    return absl::InvalidArgumentError("multigrid: A must be compressed");
  }
  if (!(options.tolerance > 0) || options.max_iterations < 1 || options.coarsest_rows < 1) {
    return absl::InvalidArgumentError(
        "multigrid: tolerance must be > 0, max_iterations and coarsest_rows >= 1");
  }
  for (Eigen::Index p = 0; p < A.nonZeros(); ++p) {
    if (!std::isfinite(A.valuePtr()[p])) {
      return absl::InvalidArgumentError("multigrid: A has a non-finite entry");
    }
  }
  if (!B.allFinite()) return absl::InvalidArgumentError("multigrid: B has a non-finite entry");
  MultigridStats local;
  MultigridStats& st = stats != nullptr ? *stats : local;
  st = MultigridStats();
  const int32_t n = static_cast<int32_t>(A.rows());
  const int32_t q = static_cast<int32_t>(B.cols());
  MultigridRowMatrix X = MultigridRowMatrix::Zero(n, q);
  if (n == 0 || q == 0) return X;

  Hierarchy h;
  if (absl::Status s = h.Build(A, options); !s.ok()) return s;
  st.levels = h.levels();
  st.coarsest_rows = h.coarsest_rows();
  st.operator_complexity = h.operator_complexity();
  const auto t1 = std::chrono::steady_clock::now();
  st.setup_seconds = std::chrono::duration<double>(t1 - t0).count();

  const Csr<double> Ac = View(A);
  for (int32_t first = 0; first < q; first += kPanel) {
    const int32_t cols = std::min(kPanel, q - first);
    const int width = cols == 1 ? 1 : cols == 2 ? 2 : cols <= 4 ? 4 : 8;
    // The panel, padded with zero columns to its width; B and X themselves when they are one
    // panel of a width (no copies of the usual 2 g = 2, 4, 8 columns).
    const bool in_place = q == width;
    std::vector<double> b, x;
    if (!in_place) {
      b.assign(static_cast<size_t>(n) * width, 0.0);
      x.assign(b.size(), 0.0);
      for (int32_t i = 0; i < n; ++i) {
        for (int32_t c = 0; c < cols; ++c) b[static_cast<size_t>(i) * width + c] = B(i, first + c);
      }
    }
    const double* bp = in_place ? B.data() : b.data();
    double* xp = in_place ? X.data() : x.data();
    double residual = 0;
    absl::StatusOr<int32_t> it;
    switch (width) {
      case 1:
        it = SolvePanel<1>(Ac, h, bp, xp, options, &residual);
        break;
      case 2:
        it = SolvePanel<2>(Ac, h, bp, xp, options, &residual);
        break;
      case 4:
        it = SolvePanel<4>(Ac, h, bp, xp, options, &residual);
        break;
      default:
        it = SolvePanel<8>(Ac, h, bp, xp, options, &residual);
        break;
    }
    st.relative_residual = std::max(st.relative_residual, residual);
    if (!it.ok()) return it.status();
    st.iterations += *it;
    if (in_place) continue;
    for (int32_t i = 0; i < n; ++i) {
      for (int32_t c = 0; c < cols; ++c) X(i, first + c) = x[static_cast<size_t>(i) * width + c];
    }
  }
  st.solve_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t1).count();
  return X;
}

}  // namespace fieldspace
