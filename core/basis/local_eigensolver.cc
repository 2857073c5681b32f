#include "core/basis/local_eigensolver.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <utility>
#include <vector>

#include "Eigen/Cholesky"
#include "Eigen/Eigenvalues"
#include "Eigen/QR"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/string_view.h"
#include "core/common/random.h"
#include "core/linalg/lanczos.h"

namespace fieldspace::basis_internal {
namespace {

// Deterministic start vectors, uniform in [-1, 1).
Eigen::MatrixXd RandomBlock(int32_t n, int32_t p, uint64_t seed) {
  Eigen::MatrixXd X(n, p);
  SplitMix64 random(seed);
  for (int32_t j = 0; j < p; ++j) {
    for (int32_t i = 0; i < n; ++i) X(i, j) = random.NextSigned();
  }
  return X;
}

// Orthonormal basis of the column span of B (n x q, q <= n): Householder QR, so the result is
// orthonormal even when columns of B are nearly dependent.
Eigen::MatrixXd Orthonormalize(const Eigen::MatrixXd& B) {
  Eigen::HouseholderQR<Eigen::MatrixXd> qr(B);
  return qr.householderQ() * Eigen::MatrixXd::Identity(B.rows(), B.cols());
}

// Rows per chunk of the tall-block products below: a chunk of each of the (at most a dozen)
// n x 1 columns involved stays in L1 / L2 while all pairs of them are multiplied, instead of
// every product streaming two whole columns from memory (a region's blocks are 0.3-1 MB each).
constexpr Eigen::Index kRowChunk = 512;

// f(first, length) for consecutive chunks of kRowChunk rows covering [0, n).
template <typename F>
void ForRowChunks(Eigen::Index n, F&& f) {
  for (Eigen::Index r0 = 0; r0 < n; r0 += kRowChunk) f(r0, std::min(kRowChunk, n - r0));
}

// out = A^T B for tall blocks A, B (n x p each, p small), chunk by chunk of rows, one vectorized
// dot product per entry and chunk. (Eigen's matrix product packs both operands for such shapes
// and was twice as slow here.)
template <typename Out>
void InnerProducts(const Eigen::MatrixXd& A, const Eigen::MatrixXd& B, Out&& out) {
  out.setZero();
  ForRowChunks(A.rows(), [&](Eigen::Index r0, Eigen::Index len) {
    for (Eigen::Index r = 0; r < A.cols(); ++r) {
      const auto a = A.col(r).segment(r0, len);
      for (Eigen::Index c = 0; c < B.cols(); ++c) out(r, c) += a.dot(B.col(c).segment(r0, len));
    }
  });
}

// The Gram matrices of LOBPCG's trial basis V = [X, W, P] (the first nb of `blocks`, n x p
// each) without forming V: G = V^T V (q x q, q = nb p) and H = V^T (S V) from the carried
// products, in one pass over the rows.
void TrialGram(const std::array<const Eigen::MatrixXd*, 3>& blocks,
               const std::array<const Eigen::MatrixXd*, 3>& products, int32_t nb, int32_t p,
               Eigen::MatrixXd& G, Eigen::MatrixXd& H) {
  const int32_t q = nb * p;
  G.setZero(q, q);
  H.setZero(q, q);
  std::vector<const double*> v(q), sv(q);
  for (int32_t b = 0; b < nb; ++b) {
    for (int32_t c = 0; c < p; ++c) {
      v[b * p + c] = blocks[b]->col(c).data();
      sv[b * p + c] = products[b]->col(c).data();
    }
  }
  using ConstSegment = Eigen::Map<const Eigen::VectorXd>;
  ForRowChunks(blocks[0]->rows(), [&](Eigen::Index r0, Eigen::Index len) {
    for (int32_t i = 0; i < q; ++i) {
      const ConstSegment vi(v[i] + r0, len);
      for (int32_t j = i; j < q; ++j) G(i, j) += vi.dot(ConstSegment(v[j] + r0, len));
      for (int32_t j = 0; j < q; ++j) H(i, j) += vi.dot(ConstSegment(sv[j] + r0, len));
    }
  });
  G.triangularView<Eigen::StrictlyLower>() = G.transpose();
}

// W <- W - X (X^T W) and SW <- SW - SX (X^T W): W made orthogonal to X's columns (orthonormal),
// with its product carried along; chunk by chunk of rows as InnerProducts.
void ProjectOut(const Eigen::MatrixXd& X, const Eigen::MatrixXd& SX, Eigen::MatrixXd& W,
                Eigen::MatrixXd& SW) {
  const Eigen::Index p = X.cols();
  Eigen::MatrixXd a(p, W.cols());
  InnerProducts(X, W, a);
  ForRowChunks(X.rows(), [&](Eigen::Index r0, Eigen::Index len) {
    for (Eigen::Index c = 0; c < W.cols(); ++c) {
      auto w = W.col(c).segment(r0, len);
      auto sw = SW.col(c).segment(r0, len);
      for (Eigen::Index k = 0; k < p; ++k) {
        w -= a(k, c) * X.col(k).segment(r0, len);
        sw -= a(k, c) * SX.col(k).segment(r0, len);
      }
    }
  });
}

// LOBPCG's update of its blocks from the Ritz coefficients C = [C_X; C_W; C_P] (q x p, C_P only
// `with_p`): p <- w C_W + p C_P, then x <- x C_X + p, row by row in place (a row's new values
// depend on that row alone), so no block is copied or allocated. P > 0 fixes p at compile time.
template <int P>
void RitzUpdateRows(int64_t n, int32_t p_runtime, const double* C, int64_t q, bool with_p,
                    double* x, const double* w, double* pb) {
  constexpr int kMax = P > 0 ? P : 1;
  const int32_t p = P > 0 ? P : p_runtime;
  for (int64_t i = 0; i < n; ++i) {
    double xi[kMax], wi[kMax], pi[kMax];
    for (int32_t k = 0; k < p; ++k) {
      xi[k] = x[i + k * n];
      wi[k] = w[i + k * n];
      if (with_p) pi[k] = pb[i + k * n];
    }
    for (int32_t c = 0; c < p; ++c) {
      const double* col = C + c * q;
      double sp = 0.0;
      for (int32_t k = 0; k < p; ++k) sp += wi[k] * col[p + k];
      if (with_p) {
        for (int32_t k = 0; k < p; ++k) sp += pi[k] * col[2 * p + k];
      }
      double sx = sp;
      for (int32_t k = 0; k < p; ++k) sx += xi[k] * col[k];
      x[i + c * n] = sx;
      pb[i + c * n] = sp;
    }
  }
}

void RitzUpdate(const Eigen::MatrixXd& C, bool with_p, Eigen::MatrixXd& x, const Eigen::MatrixXd& w,
                Eigen::MatrixXd& pb) {
  const int64_t n = x.rows();
  const int32_t p = static_cast<int32_t>(x.cols());
  if (pb.rows() != n || pb.cols() != p) pb.resize(n, p);  // the first P: nothing to read
  const double* c = C.data();
  const int64_t q = C.rows();
  switch (p) {
    case 1:
      return RitzUpdateRows<1>(n, p, c, q, with_p, x.data(), w.data(), pb.data());
    case 2:
      return RitzUpdateRows<2>(n, p, c, q, with_p, x.data(), w.data(), pb.data());
    case 3:
      return RitzUpdateRows<3>(n, p, c, q, with_p, x.data(), w.data(), pb.data());
    case 4:
      return RitzUpdateRows<4>(n, p, c, q, with_p, x.data(), w.data(), pb.data());
    default: {
      // Larger blocks (many fields per region): Eigen's products, whose temporaries are fine
      // at this size.
      Eigen::MatrixXd np = w * C.middleRows(p, p);
      if (with_p) np += pb * C.bottomRows(p);
      x = x * C.topRows(p) + np;
      pb = std::move(np);
    }
  }
}

absl::StatusOr<LocalEigenResult> SolveDense(LocalOperator& op, int32_t m) {
  const int32_t n = op.size();
  Eigen::MatrixXd S;
  op.ApplyStiffness(Eigen::MatrixXd::Identity(n, n), &S);
  const Eigen::MatrixXd Ssym = 0.5 * (S + S.transpose());
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(Ssym);
  if (es.info() != Eigen::Success) {
    return absl::InternalError("dense local eigensolver failed");
  }
  LocalEigenResult result;
  result.values = es.eigenvalues().head(m);
  result.vectors = es.eigenvectors().leftCols(m);
  result.dense = true;
  return result;
}

absl::StatusOr<LocalEigenResult> SolveLanczos(LocalOperator& op, int32_t m, double tolerance) {
  const int32_t n = op.size();
  Eigen::MatrixXd x(n, 1), y;
  // The factorization is of S_bar + tau I, i.e. sigma = -tau.
  auto inverse = [&](const double* x_in, double* y_out) {
    x = Eigen::Map<const Eigen::VectorXd>(x_in, n);
    op.ApplyShiftInverse(x, &y);
    Eigen::Map<Eigen::VectorXd>(y_out, n) = y.col(0);
    return absl::OkStatus();
  };
  LanczosOptions lanczos;
  lanczos.count = m;
  lanczos.subspace_size = std::min(n, std::max(2 * m + 1, 20));
  lanczos.max_iterations = 1000;
  lanczos.tolerance = std::min(1e-10, tolerance * tolerance);
  lanczos.context = "local eigenproblem";
  absl::StatusOr<LanczosResult> run = ShiftInvertEigenpairs(n, inverse, -op.shift(), lanczos);
  // This is the fallback: when it does not converge either, nothing did. Not a server fault: the
  // parameters ask for more than this region's eigenproblem gives (seen: n = 64 at d = 10, where
  // each region is a large part of the mesh and its spectrum is dense).
  const auto not_converged = [n](absl::string_view why) {
    return absl::FailedPreconditionError(
        absl::StrCat("local eigenproblem of a region of ", n,
                     " DOFs did not converge (LOBPCG, then Spectra's Lanczos): ", why,
                     "; a larger dimension d (smaller regions) helps"));
  };
  if (absl::IsResourceExhausted(run.status())) return not_converged(run.status().message());
  if (!run.ok()) return run.status();
  LocalEigenResult result;
  const Eigen::MatrixXd X = Orthonormalize(run->vectors);
  Eigen::MatrixXd SX;
  op.ApplyStiffness(X, &SX);
  Eigen::MatrixXd H = X.transpose() * SX;
  H = 0.5 * (H + H.transpose()).eval();
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(H);
  result.values = es.eigenvalues();
  result.vectors = X * es.eigenvectors();
  // Lanczos judges convergence through the inverse alone; an inaccurate inverse (a factorization
  // of a nearly singular region) can pass it with wrong pairs. The residual with S_bar itself
  // is the test LOBPCG passes too.
  const Eigen::MatrixXd R = SX * es.eigenvectors() - result.vectors * result.values.asDiagonal();
  for (int32_t i = 0; i < m; ++i) {
    const double bound = tolerance * (std::abs(result.values[i]) + op.shift());
    if (!(R.col(i).norm() <= bound)) {
      return not_converged(absl::StrFormat("eigenpair %d has residual %.3g against S, above %.3g",
                                           i, R.col(i).norm(), bound));
    }
  }
  result.lanczos_fallback = true;
  return result;
}

}  // namespace

absl::StatusOr<LocalEigenResult> SolveLocalEigenproblem(LocalOperator& op,
                                                        const LocalEigenOptions& options,
                                                        const CancelToken& cancel) {
  const int32_t n = op.size();
  const int32_t m = options.count;
  if (m < 1 || m > n) {
    return absl::InvalidArgumentError(
        absl::StrFormat("local eigenproblem: %d eigenpairs of a %d x %d problem", m, n, n));
  }
  const int32_t p = m + std::max(0, options.guard);
  if (n <= std::max(options.dense_max_size, 3 * p)) return SolveDense(op, m);

  absl::Status prepared = op.PrepareShiftInverse(cancel);
  if (!prepared.ok()) return prepared;
  const double tau = op.shift();

  // LOBPCG (Knyazev 2001) on the trial basis B = [X, W, P] with the products S B carried along
  // (only S W is computed per iteration; S X and S P follow from the Rayleigh-Ritz coefficients),
  // Rayleigh-Ritz through the Cholesky factor of the Gram matrix B^T B. When that Gram matrix is
  // too ill-conditioned, P is dropped for the iteration (a restart). Convergence is confirmed with
  // an exactly recomputed S X before returning.
  Eigen::MatrixXd X;
  {
    Eigen::MatrixXd X0 = RandomBlock(n, p, options.seed);
    if (options.initial != nullptr && options.initial->rows() == n) {
      const Eigen::Index k = std::min<Eigen::Index>(p, options.initial->cols());
      X0.leftCols(k) = options.initial->leftCols(k);
    }
    X = Orthonormalize(X0);
  }
  Eigen::MatrixXd SX, W, SW, P, SP, R;
  op.ApplyStiffness(X, &SX);
  Eigen::VectorXd theta;
  {
    Eigen::MatrixXd H(p, p);
    InnerProducts(X, SX, H);
    Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(0.5 * (H + H.transpose()));
    X = X * es.eigenvectors();
    SX = SX * es.eigenvectors();
    theta = es.eigenvalues();
  }
  LocalEigenResult result;
  bool verified = false;  // SX recomputed exactly since the last update
  // The trial basis [X, W, P] is never copied into one matrix: its Gram matrices are taken block
  // by block, and the Ritz vectors are summed from the blocks in place (RitzUpdate). A copy
  // [X, W, P] and its products took six more n x p blocks per thread (144 MB on a coarse
  // level's region of ~1.5M DOFs), and Session 21 found that blocks of that size allocated per
  // iteration paid their page faults every time (bench/RESULTS.md).
  const std::array<const Eigen::MatrixXd*, 3> blocks = {&X, &W, &P};
  const std::array<const Eigen::MatrixXd*, 3> products = {&SX, &SW, &SP};
  for (int32_t it = 1; it <= options.max_iterations; ++it) {
    if (cancel.Check()) return absl::CancelledError("basis construction cancelled");
    R = SX - X * theta.asDiagonal();
    auto converged = [&] {
      for (int32_t i = 0; i < m; ++i) {
        if (R.col(i).norm() > options.tolerance * (std::abs(theta[i]) + tau)) return false;
      }
      return true;
    };
    if (converged()) {
      if (!verified) {
        op.ApplyStiffness(X, &SX);
        verified = true;
        R = SX - X * theta.asDiagonal();
      }
      if (converged()) {
        result.values = theta.head(m);
        result.vectors = X.leftCols(m);
        result.iterations = it - 1;
        return result;
      }
    }
    op.ApplyShiftInverseAndStiffness(R, &W, &SW);
    ProjectOut(X, SX, W, SW);
    for (int32_t c = 0; c < p; ++c) {
      const double norm = W.col(c).norm();
      if (norm > 0) {
        W.col(c) /= norm;
        SW.col(c) /= norm;
      }
    }
    if (P.cols() > 0) {
      for (int32_t c = 0; c < p; ++c) {
        const double norm = P.col(c).norm();
        if (norm > 0) {
          P.col(c) /= norm;
          SP.col(c) /= norm;
        }
      }
    }
    bool solved = false;
    for (int attempt = 0; attempt < 2 && !solved; ++attempt) {
      const bool with_p = attempt == 0 && P.cols() > 0;
      if (attempt == 1 && P.cols() == 0) break;
      const int32_t nb = with_p ? 3 : 2;  // blocks in the trial basis
      Eigen::MatrixXd G, H;
      TrialGram(blocks, products, nb, p, G, H);
      H = 0.5 * (H + H.transpose()).eval();
      Eigen::LLT<Eigen::MatrixXd> llt(G);
      if (llt.info() != Eigen::Success) continue;
      const Eigen::MatrixXd L = llt.matrixL();
      if (L.diagonal().minCoeff() < 1e-7) continue;  // nearly dependent columns
      // Standard symmetric problem L^-1 H L^-T y = theta y, c = L^-T y.
      Eigen::MatrixXd A = llt.matrixL().solve(H);
      A = llt.matrixL().solve(A.transpose().eval());
      Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(0.5 * (A + A.transpose()));
      if (es.info() != Eigen::Success) continue;
      const Eigen::MatrixXd C = llt.matrixU().solve(Eigen::MatrixXd(es.eigenvectors().leftCols(p)));
      RitzUpdate(C, with_p, X, W, P);
      RitzUpdate(C, with_p, SX, SW, SP);
      theta = es.eigenvalues().head(p);
      solved = true;
    }
    if (!solved) break;  // hand over to Lanczos
    verified = false;
  }
  if (cancel.Check()) return absl::CancelledError("basis construction cancelled");
  return SolveLanczos(op, m, options.tolerance);
}

}  // namespace fieldspace::basis_internal
