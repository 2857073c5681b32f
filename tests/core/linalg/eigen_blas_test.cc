// The Eigen replacements of the BLAS/LAPACK routines CHOLMOD calls, against naive loops written
// from the reference BLAS documentation, for every flag combination, leading dimensions larger
// than the matrices, and alpha / beta special cases.
#include "core/linalg/eigen_blas.h"

#include <algorithm>
#include <cmath>
#include <random>
#include <string>
#include <vector>

#include "Eigen/Core"
#include "gtest/gtest.h"

namespace {

using Eigen::MatrixXd;

std::mt19937 rng(42);

MatrixXd Random(int r, int c) {
  std::normal_distribution<double> g;
  MatrixXd m(r, c);
  for (int j = 0; j < c; ++j) {
    for (int i = 0; i < r; ++i) m(i, j) = g(rng);
  }
  return m;
}

// Column-major storage with leading dimension ld >= rows, padding filled with a sentinel.
std::vector<double> Store(const MatrixXd& m, int ld) {
  std::vector<double> s(static_cast<size_t>(ld) * std::max<int>(1, m.cols()), 777.0);
  for (int j = 0; j < m.cols(); ++j) {
    for (int i = 0; i < m.rows(); ++i) s[j * ld + i] = m(i, j);
  }
  return s;
}
MatrixXd Load(const std::vector<double>& s, int r, int c, int ld) {
  MatrixXd m(r, c);
  for (int j = 0; j < c; ++j) {
    for (int i = 0; i < r; ++i) m(i, j) = s[j * ld + i];
  }
  return m;
}
void ExpectPaddingUntouched(const std::vector<double>& s, int r, int c, int ld) {
  for (int j = 0; j < c; ++j) {
    for (int i = r; i < ld; ++i) ASSERT_EQ(s[j * ld + i], 777.0);
  }
}

MatrixXd Op(const MatrixXd& m, char t) { return t == 'N' ? m : MatrixXd(m.transpose()); }

TEST(EigenBlasTest, Dgemm) {
  for (char ta : {'N', 'T', 'C'}) {
    for (char tb : {'N', 't'}) {
      for (double beta : {0.0, 1.0, -0.5}) {
        const int m = 37, n = 23, k = 61, lda = 70, ldb = 80, ldc = 41;
        const MatrixXd A = Random(ta == 'N' ? m : k, ta == 'N' ? k : m);
        const MatrixXd B = Random(tb == 'N' ? k : n, tb == 'N' ? n : k);
        MatrixXd C = Random(m, n);
        if (beta == 0.0) C.setConstant(NAN);  // must not be read
        auto a = Store(A, lda), b = Store(B, ldb), c = Store(C, ldc);
        const double alpha = 1.7;
        dgemm_(&ta, &tb, &m, &n, &k, &alpha, a.data(), &lda, b.data(), &ldb, &beta, c.data(), &ldc);
        MatrixXd expected = alpha * Op(A, ta == 'N' ? 'N' : 'T') * Op(B, tb == 'N' ? 'N' : 'T');
        if (beta != 0.0) expected += beta * C;
        EXPECT_LT((Load(c, m, n, ldc) - expected).cwiseAbs().maxCoeff(), 1e-12);
        ExpectPaddingUntouched(c, m, n, ldc);
      }
    }
  }
}

TEST(EigenBlasTest, Dgemv) {
  for (char t : {'N', 'T'}) {
    for (int inc : {1, 2, -3}) {
      const int m = 29, n = 17, lda = 33;
      const MatrixXd A = Random(m, n);
      const int lx = t == 'N' ? n : m, ly = t == 'N' ? m : n;
      const Eigen::VectorXd X = Random(lx, 1), Y = Random(ly, 1);
      std::vector<double> x(lx * std::abs(inc), 5.0), y(ly * std::abs(inc), 5.0);
      for (int i = 0; i < lx; ++i) x[(inc > 0 ? i : lx - 1 - i) * std::abs(inc)] = X[i];
      for (int i = 0; i < ly; ++i) y[(inc > 0 ? i : ly - 1 - i) * std::abs(inc)] = Y[i];
      auto a = Store(A, lda);
      const double alpha = -0.3, beta = 2.0;
      dgemv_(&t, &m, &n, &alpha, a.data(), &lda, x.data(), &inc, &beta, y.data(), &inc);
      const Eigen::VectorXd expected = alpha * Op(A, t) * X + beta * Y;
      for (int i = 0; i < ly; ++i) {
        EXPECT_NEAR(y[(inc > 0 ? i : ly - 1 - i) * std::abs(inc)], expected[i], 1e-12);
      }
    }
  }
}

// A well-conditioned triangular matrix with the requested triangle (the other one is garbage that
// must not be read).
MatrixXd Triangular(int n) {
  MatrixXd A = Random(n, n);
  for (int i = 0; i < n; ++i) A(i, i) = 4.0 + std::abs(A(i, i));
  return A;
}
MatrixXd Effective(const MatrixXd& A, char uplo, char diag) {
  MatrixXd T = uplo == 'L' ? MatrixXd(A.triangularView<Eigen::Lower>())
                           : MatrixXd(A.triangularView<Eigen::Upper>());
  if (diag == 'U') T.diagonal().setOnes();
  return T;
}

TEST(EigenBlasTest, Dtrsv) {
  for (char uplo : {'L', 'U'}) {
    for (char t : {'N', 'T'}) {
      for (char diag : {'N', 'U'}) {
        const int n = 45, lda = 50, inc = 1;
        const MatrixXd A = Triangular(n);
        const Eigen::VectorXd b = Random(n, 1);
        auto a = Store(A, lda);
        std::vector<double> x(b.data(), b.data() + n);
        dtrsv_(&uplo, &t, &diag, &n, a.data(), &lda, x.data(), &inc);
        const Eigen::VectorXd xs = Eigen::Map<Eigen::VectorXd>(x.data(), n);
        EXPECT_LT((Op(Effective(A, uplo, diag), t) * xs - b).norm(), 1e-10 * b.norm());
      }
    }
  }
}

TEST(EigenBlasTest, Dtrsm) {
  for (char side : {'L', 'R'}) {
    for (char uplo : {'L', 'U'}) {
      for (char t : {'N', 'C'}) {
        for (char diag : {'N', 'U'}) {
          const int m = 31, n = 19, ldb = 40;
          const int na = side == 'L' ? m : n, lda = na + 3;
          const MatrixXd A = Triangular(na);
          const MatrixXd B = Random(m, n);
          auto a = Store(A, lda), b = Store(B, ldb);
          const double alpha = 0.75;
          dtrsm_(&side, &uplo, &t, &diag, &m, &n, &alpha, a.data(), &lda, b.data(), &ldb);
          const MatrixXd X = Load(b, m, n, ldb);
          const MatrixXd T = Op(Effective(A, uplo, diag), t == 'N' ? 'N' : 'T');
          const MatrixXd lhs = side == 'L' ? MatrixXd(T * X) : MatrixXd(X * T);
          EXPECT_LT((lhs - alpha * B).cwiseAbs().maxCoeff(), 1e-10);
          ExpectPaddingUntouched(b, m, n, ldb);
        }
      }
    }
  }
}

TEST(EigenBlasTest, Dsyrk) {
  for (char uplo : {'L', 'U'}) {
    for (char t : {'N', 'T'}) {
      for (double beta : {0.0, 1.0, 0.25}) {
        const int n = 27, k = 14, ldc = 30;
        const int lda = (t == 'N' ? n : k) + 2;
        const MatrixXd A = Random(t == 'N' ? n : k, t == 'N' ? k : n);
        MatrixXd C = Random(n, n);
        auto a = Store(A, lda), c = Store(C, ldc);
        const double alpha = -1.25;
        dsyrk_(&uplo, &t, &n, &k, &alpha, a.data(), &lda, &beta, c.data(), &ldc);
        const MatrixXd AAt = t == 'N' ? MatrixXd(A * A.transpose()) : MatrixXd(A.transpose() * A);
        const MatrixXd expected = alpha * AAt + beta * C;
        const MatrixXd got = Load(c, n, n, ldc);
        for (int j = 0; j < n; ++j) {
          for (int i = 0; i < n; ++i) {
            const bool in_triangle = uplo == 'L' ? i >= j : i <= j;
            // The other triangle is not touched.
            EXPECT_NEAR(got(i, j), in_triangle ? expected(i, j) : C(i, j), 1e-12);
          }
        }
      }
    }
  }
}

TEST(EigenBlasTest, Dpotrf) {
  for (char uplo : {'L', 'U'}) {
    const int n = 150, lda = 160;  // beyond Eigen's blocking size
    const MatrixXd R = Random(n, n);
    const MatrixXd A = R * R.transpose() + n * MatrixXd::Identity(n, n);
    auto a = Store(A, lda);
    int info = -1;
    dpotrf_(&uplo, &n, a.data(), &lda, &info);
    EXPECT_EQ(info, 0);
    const MatrixXd F = Load(a, n, n, lda);
    const MatrixXd L = uplo == 'L' ? MatrixXd(F.triangularView<Eigen::Lower>())
                                   : MatrixXd(F.triangularView<Eigen::Upper>().transpose());
    EXPECT_LT((L * L.transpose() - A).cwiseAbs().maxCoeff(), 1e-9 * A.cwiseAbs().maxCoeff());
    // Not positive definite at the leading minor of order 91.
    MatrixXd B = A;
    B(90, 90) = -1.0;
    auto b = Store(B, lda);
    dpotrf_(&uplo, &n, b.data(), &lda, &info);
    EXPECT_EQ(info, 91);
  }
}

}  // namespace
