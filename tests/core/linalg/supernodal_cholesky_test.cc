#include "core/linalg/supernodal_cholesky.h"

#include <atomic>
#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include "Eigen/Cholesky"
#include "Eigen/Dense"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tests/testing/matchers.h"

namespace fieldspace {
namespace {

using ::fieldspace::testing::StatusIs;

// A random SPD matrix with the sparsity of a geometric graph: `n` points on the unit sphere, 2x2
// blocks between points closer than `radius` (the structure of a reduced system), diagonally
// dominant.
Eigen::SparseMatrix<double> GeometricSpd(int n, double radius, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::vector<Eigen::Vector3d> p(n);
  for (int i = 0; i < n; ++i) {
    const double z = 1 - 2.0 * (i + 0.5) / n, r = std::sqrt(1 - z * z), t = i * 2.399963;
    p[i] = {r * std::cos(t), r * std::sin(t), z};
  }
  std::vector<Eigen::Triplet<double>> triplets;
  std::vector<double> row_sum(2 * n, 0.0);
  for (int i = 0; i < n; ++i) {
    for (int j = i; j < n; ++j) {
      if ((p[i] - p[j]).norm() >= radius) continue;
      for (int a = 0; a < 2; ++a) {
        for (int b = 0; b < 2; ++b) {
          if (i == j && a >= b) continue;
          const double v = u(rng);
          triplets.emplace_back(2 * i + a, 2 * j + b, v);
          triplets.emplace_back(2 * j + b, 2 * i + a, v);
          row_sum[2 * i + a] += std::abs(v);
          row_sum[2 * j + b] += std::abs(v);
        }
      }
    }
  }
  for (int i = 0; i < 2 * n; ++i) triplets.emplace_back(i, i, row_sum[i] + 1.0 + std::abs(u(rng)));
  Eigen::SparseMatrix<double> A(2 * n, 2 * n);
  A.setFromTriplets(triplets.begin(), triplets.end());
  A.makeCompressed();
  return A;
}

// 2D grid Laplacian + identity (n x n grid): a classic nested-dissection test.
Eigen::SparseMatrix<double> GridSpd(int n) {
  std::vector<Eigen::Triplet<double>> t;
  auto id = [n](int x, int y) { return x * n + y; };
  for (int x = 0; x < n; ++x) {
    for (int y = 0; y < n; ++y) {
      t.emplace_back(id(x, y), id(x, y), 4.5);
      if (x + 1 < n) {
        t.emplace_back(id(x, y), id(x + 1, y), -1.0);
        t.emplace_back(id(x + 1, y), id(x, y), -1.0);
      }
      if (y + 1 < n) {
        t.emplace_back(id(x, y), id(x, y + 1), -1.0);
        t.emplace_back(id(x, y + 1), id(x, y), -1.0);
      }
    }
  }
  Eigen::SparseMatrix<double> A(n * n, n * n);
  A.setFromTriplets(t.begin(), t.end());
  A.makeCompressed();
  return A;
}

double SolveError(const Eigen::SparseMatrix<double>& A, const SupernodalFactor& f, int nrhs) {
  const Eigen::MatrixXd B = Eigen::MatrixXd::Random(A.rows(), nrhs);
  Eigen::MatrixXd X = B;
  f.SolveInPlace(X);
  const Eigen::MatrixXd reference = Eigen::MatrixXd(A).llt().solve(B);
  return (X - reference).norm() / reference.norm();
}

TEST(SupernodalCholeskyTest, SolvesGeometricSystemsLikeDenseCholesky) {
  for (int n : {1, 7, 150, 900}) {
    const Eigen::SparseMatrix<double> A = GeometricSpd(n, n < 10 ? 2.0 : 0.25, n);
    auto sym = SupernodalSymbolic::Analyze(A);
    ASSERT_TRUE(sym.ok()) << sym.status();
    EXPECT_EQ((*sym)->rows(), A.rows());
    EXPECT_EQ((*sym)->pattern_nonzeros(), A.nonZeros());
    EXPECT_GE((*sym)->factor_nonzeros(), (A.nonZeros() + A.rows()) / 2);
    auto f = SupernodalFactor::Factorize(*sym, A);
    ASSERT_TRUE(f.ok()) << f.status();
    EXPECT_LT(SolveError(A, *f, 1), 1e-12) << "n = " << n;
    EXPECT_LT(SolveError(A, *f, 2), 1e-12) << "n = " << n;  // the per-column path
    EXPECT_LT(SolveError(A, *f, 5), 1e-12) << "n = " << n;
    const double logdet = Eigen::MatrixXd(A).llt().matrixLLT().diagonal().array().log().sum() * 2;
    EXPECT_NEAR(f->LogDeterminant(), logdet, 1e-9 * std::abs(logdet) + 1e-12);
  }
}

// A block-diagonal matrix (two independent blocks: a forest with several roots).
Eigen::SparseMatrix<double> TwoBlocks(const Eigen::SparseMatrix<double>& A1,
                                      const Eigen::SparseMatrix<double>& A2) {
  const int64_t n1 = A1.rows(), n = n1 + A2.rows();
  std::vector<Eigen::Triplet<double>> t;
  for (int j = 0; j < A1.outerSize(); ++j) {
    for (Eigen::SparseMatrix<double>::InnerIterator it(A1, j); it; ++it) {
      t.emplace_back(it.row(), it.col(), it.value());
    }
  }
  for (int j = 0; j < A2.outerSize(); ++j) {
    for (Eigen::SparseMatrix<double>::InnerIterator it(A2, j); it; ++it) {
      t.emplace_back(n1 + it.row(), n1 + it.col(), it.value());
    }
  }
  Eigen::SparseMatrix<double> A(n, n);
  A.setFromTriplets(t.begin(), t.end());
  A.makeCompressed();
  return A;
}

TEST(SupernodalCholeskyTest, HalfSolvesAndSparseForwardSubstitution) {
  const Eigen::SparseMatrix<double> A1 = GeometricSpd(900, 0.2, 5);
  const Eigen::SparseMatrix<double> A = TwoBlocks(A1, GridSpd(12));
  const int64_t n = A.rows(), n1 = A1.rows();
  auto sym = SupernodalSymbolic::Analyze(A);
  ASSERT_TRUE(sym.ok());
  auto f = SupernodalFactor::Factorize(*sym, A);
  ASSERT_TRUE(f.ok());
  const Eigen::LLT<Eigen::MatrixXd> dense{Eigen::MatrixXd(A)};
  // Forward then backward substitution, with the permutations, is a solve.
  const Eigen::VectorXd b = Eigen::VectorXd::Random(n);
  Eigen::VectorXd y = f->PermuteIn(b);
  f->ForwardInPlace(y);
  // |L^-1 P b|^2 = b^T A^-1 b, whatever the ordering.
  const double energy = b.dot(dense.solve(b));
  EXPECT_NEAR(y.squaredNorm(), energy, 1e-12 * energy);
  f->BackwardInPlace(y);
  const Eigen::VectorXd x = f->PermuteOut(y);
  EXPECT_LT((x - dense.solve(b)).norm() / x.norm(), 1e-12);
  EXPECT_EQ(f->PermuteIn(f->PermuteOut(b)), b);

  // A sparse right-hand side (a repeated row sums): the same forward substitution, visiting
  // only part of L, and W^T W = R A^-1 R^T for two such rows.
  const std::vector<int32_t> rows1 = {3, 400, 3, 17}, rows2 = {401, 1200, 5};
  const std::vector<double> vals1 = {0.5, -1.0, 0.25, 2.0}, vals2 = {1.0, 0.3, -0.7};
  Eigen::VectorXd dense1 = Eigen::VectorXd::Zero(n), dense2 = Eigen::VectorXd::Zero(n);
  for (size_t q = 0; q < rows1.size(); ++q) dense1[rows1[q]] += vals1[q];
  for (size_t q = 0; q < rows2.size(); ++q) dense2[rows2[q]] += vals2[q];
  Eigen::VectorXd w1(n), w2(n);
  const int64_t visited = f->ForwardSparse(rows1, vals1, w1);
  f->ForwardSparse(rows2, vals2, w2);
  Eigen::VectorXd reference = f->PermuteIn(dense1);
  f->ForwardInPlace(reference);
  EXPECT_LT((w1 - reference).norm(), 1e-14 * reference.norm());
  EXPECT_NEAR(w1.dot(w2), dense1.dot(dense.solve(dense2)), 1e-12 * w1.norm() * w2.norm());
  // Rows of the first block never reach the second block's supernodes.
  EXPECT_EQ(f->PermuteOut(w1).tail(n - n1).cwiseAbs().maxCoeff(), 0.0);
  int64_t all_rows = 0;
  {
    std::vector<int32_t> every(n);
    for (int64_t i = 0; i < n; ++i) every[i] = static_cast<int32_t>(i);
    Eigen::VectorXd w(n);
    all_rows = f->ForwardSparse(every, std::vector<double>(n, 1.0), w);
  }
  EXPECT_GT(visited, 0);
  EXPECT_LT(visited, all_rows);
}

TEST(SupernodalCholeskyTest, SupernodalMatrixMultipliesLikeTheSparseMatrix) {
  for (const Eigen::SparseMatrix<double>& A :
       {GeometricSpd(1, 2.0, 1), GeometricSpd(700, 0.25, 2), GridSpd(30),
        TwoBlocks(GeometricSpd(80, 0.5, 3), GridSpd(7))}) {
    auto sym = SupernodalSymbolic::Analyze(A);
    ASSERT_TRUE(sym.ok());
    auto M = SupernodalMatrix::Create(*sym, A);
    ASSERT_TRUE(M.ok()) << M.status();
    EXPECT_EQ(M->rows(), A.rows());
    // The largest splits its panels over the threads (above 2^16 entries).
    if (A.rows() == 700) EXPECT_GT((*sym)->factor_nonzeros(), int64_t{1} << 16);
    for (int rep = 0; rep < 3; ++rep) {
      const Eigen::VectorXd x = Eigen::VectorXd::Random(A.rows());
      const Eigen::VectorXd expected = A * x;
      EXPECT_LT((M->Multiply(x) - expected).norm(), 1e-14 * expected.norm() * std::sqrt(A.rows()));
    }
  }
  const Eigen::SparseMatrix<double> A = GridSpd(5);
  auto sym = SupernodalSymbolic::Analyze(A);
  ASSERT_TRUE(sym.ok());
  EXPECT_THAT(SupernodalMatrix::Create(*sym, std::vector<double>(3, 1.0)),
              StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(SupernodalMatrix::Create(*sym, GridSpd(4)),
              StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(SupernodalMatrix::Create(nullptr, A), StatusIs(absl::StatusCode::kInvalidArgument));
}

TEST(SupernodalCholeskyTest, GridAndThoroughOrderingAgree) {
  const Eigen::SparseMatrix<double> A = GridSpd(40);
  SupernodalAnalyzeOptions thorough;
  thorough.thorough = true;
  auto fast = SupernodalSymbolic::Analyze(A);
  auto best = SupernodalSymbolic::Analyze(A, thorough);
  ASSERT_TRUE(fast.ok() && best.ok());
  // The thorough search keeps the cheapest ordering it tries, which includes the default one.
  EXPECT_LE((*best)->flops(), (*fast)->flops() * 1.0001);
  for (const auto& sym : {*fast, *best}) {
    auto f = SupernodalFactor::Factorize(sym, A);
    ASSERT_TRUE(f.ok());
    EXPECT_LT(SolveError(A, *f, 3), 1e-12);
  }
}

TEST(SupernodalCholeskyTest, ParallelAndSequentialFactorsAgree) {
  const Eigen::SparseMatrix<double> A = GeometricSpd(1200, 0.22, 3);
  auto sym = SupernodalSymbolic::Analyze(A);
  ASSERT_TRUE(sym.ok());
  SupernodalFactorOptions seq;
  seq.parallel = false;
  auto f1 = SupernodalFactor::Factorize(*sym, A, seq);
  auto f2 = SupernodalFactor::Factorize(*sym, A);
  ASSERT_TRUE(f1.ok() && f2.ok());
  const Eigen::VectorXd b = Eigen::VectorXd::Random(A.rows());
  const Eigen::VectorXd x1 = f1->Solve(b), x2 = f2->Solve(b);
  EXPECT_LT((x1 - x2).norm() / x1.norm(), 1e-13);
  EXPECT_LT((A * x1 - b).norm() / b.norm(), 1e-13);
}

TEST(SupernodalCholeskyTest, BlockDiagonalMatrixHasSeveralRoots) {
  const Eigen::SparseMatrix<double> A = TwoBlocks(GeometricSpd(60, 0.5, 1), GridSpd(9));
  auto sym = SupernodalSymbolic::Analyze(A);
  ASSERT_TRUE(sym.ok());
  auto f = SupernodalFactor::Factorize(*sym, A);
  ASSERT_TRUE(f.ok());
  EXPECT_LT(SolveError(A, *f, 2), 1e-12);
}

TEST(SupernodalCholeskyTest, RefactorizeAndDiagonalShift) {
  Eigen::SparseMatrix<double> A = GeometricSpd(300, 0.3, 5);
  auto sym = SupernodalSymbolic::Analyze(A);
  ASSERT_TRUE(sym.ok());
  auto f = SupernodalFactor::Factorize(*sym, A);
  ASSERT_TRUE(f.ok());
  // New values, same pattern: the factorization follows.
  Eigen::SparseMatrix<double> A2 = A;
  for (int64_t q = 0; q < A2.nonZeros(); ++q) A2.valuePtr()[q] *= 1.5;
  ASSERT_TRUE(f->Refactorize(absl::MakeConstSpan(A2.valuePtr(), A2.nonZeros())).ok());
  EXPECT_LT(SolveError(A2, *f, 2), 1e-12);
  // diagonal_shift tau factorizes A + tau diag(A).
  SupernodalFactorOptions shifted;
  shifted.diagonal_shift = 0.25;
  ASSERT_TRUE(f->Refactorize(absl::MakeConstSpan(A.valuePtr(), A.nonZeros()), shifted).ok());
  Eigen::SparseMatrix<double> A3 = A;
  for (int64_t i = 0; i < A3.rows(); ++i) A3.coeffRef(i, i) *= 1.25;
  EXPECT_LT(SolveError(A3, *f, 1), 1e-12);
}

TEST(SupernodalCholeskyTest, IndefiniteMatrixIsFailedPrecondition) {
  Eigen::SparseMatrix<double> A = GeometricSpd(100, 0.4, 2);
  A.coeffRef(37, 37) = -5.0;
  auto sym = SupernodalSymbolic::Analyze(A);
  ASSERT_TRUE(sym.ok());
  auto f = SupernodalFactor::Factorize(*sym, A);
  EXPECT_THAT(f, StatusIs(absl::StatusCode::kFailedPrecondition)) << f.status();
  // A PSD-singular matrix fails too (zero pivot), and succeeds with a diagonal shift.
  Eigen::SparseMatrix<double> L = GridSpd(6);
  for (int i = 0; i < L.rows(); ++i) L.coeffRef(i, i) -= 0.5;  // 4-neighbor Laplacian
  for (int i = 0; i < L.rows(); ++i) {
    double s = 0;
    for (Eigen::SparseMatrix<double>::InnerIterator it(L, i); it; ++it) s += it.value();
    L.coeffRef(i, i) -= s;  // rows sum to zero: constants in the kernel
  }
  auto sym2 = SupernodalSymbolic::Analyze(L);
  ASSERT_TRUE(sym2.ok());
  SupernodalFactorOptions shifted;
  shifted.diagonal_shift = 1e-8;
  EXPECT_TRUE(SupernodalFactor::Factorize(*sym2, L, shifted).ok());
}

TEST(SupernodalCholeskyTest, InvalidInputs) {
  const Eigen::SparseMatrix<double> A = GeometricSpd(20, 0.8, 4);
  auto sym = SupernodalSymbolic::Analyze(A);
  ASSERT_TRUE(sym.ok());
  // Wrong number of values.
  std::vector<double> values(A.valuePtr(), A.valuePtr() + A.nonZeros());
  values.pop_back();
  EXPECT_THAT(SupernodalFactor::Factorize(*sym, values),
              StatusIs(absl::StatusCode::kInvalidArgument));
  // Non-finite value.
  std::vector<double> nan_values(A.valuePtr(), A.valuePtr() + A.nonZeros());
  nan_values[3] = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THAT(SupernodalFactor::Factorize(*sym, nan_values),
              StatusIs(absl::StatusCode::kInvalidArgument));
  // Negative shift.
  SupernodalFactorOptions bad;
  bad.diagonal_shift = -1;
  EXPECT_THAT(SupernodalFactor::Factorize(*sym, A, bad),
              StatusIs(absl::StatusCode::kInvalidArgument));
  // A matrix with another pattern.
  const Eigen::SparseMatrix<double> other = GridSpd(6);
  EXPECT_FALSE((*sym)->SamePattern(other));
  EXPECT_THAT(SupernodalFactor::Factorize(*sym, other),
              StatusIs(absl::StatusCode::kInvalidArgument));
  // Null analysis.
  EXPECT_THAT(SupernodalFactor::Factorize(nullptr, A),
              StatusIs(absl::StatusCode::kInvalidArgument));
  // Patterns the analysis rejects: non-square, empty, asymmetric, missing diagonal.
  EXPECT_THAT(SupernodalSymbolic::Analyze(Eigen::SparseMatrix<double>(3, 4)),
              StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(SupernodalSymbolic::Analyze(Eigen::SparseMatrix<double>(0, 0)),
              StatusIs(absl::StatusCode::kInvalidArgument));
  Eigen::SparseMatrix<double> asym(3, 3);
  asym.insert(0, 0) = 1;
  asym.insert(1, 1) = 1;
  asym.insert(2, 2) = 1;
  asym.insert(2, 0) = 1;
  asym.makeCompressed();
  EXPECT_THAT(SupernodalSymbolic::Analyze(asym), StatusIs(absl::StatusCode::kInvalidArgument));
  Eigen::SparseMatrix<double> no_diag(2, 2);
  no_diag.insert(0, 0) = 1;
  no_diag.insert(0, 1) = 1;
  no_diag.insert(1, 0) = 1;
  no_diag.makeCompressed();
  EXPECT_THAT(SupernodalSymbolic::Analyze(no_diag), StatusIs(absl::StatusCode::kInvalidArgument));
}

TEST(SupernodalCholeskyTest, CancelledFactorizationIsCancelledAndRefactorizeRecovers) {
  Eigen::SparseMatrix<double> A = GeometricSpd(400, 0.2, 5);
  auto sym = SupernodalSymbolic::Analyze(A);
  ASSERT_TRUE(sym.ok());
  std::atomic<bool> cancel{true};
  SupernodalFactorOptions options;
  options.cancel = &cancel;
  EXPECT_THAT(SupernodalFactor::Factorize(*sym, A, options),
              StatusIs(absl::StatusCode::kCancelled));
  auto f = SupernodalFactor::Factorize(*sym, A);
  ASSERT_TRUE(f.ok());
  EXPECT_THAT(f->Refactorize(absl::MakeConstSpan(A.valuePtr(), A.nonZeros()), options),
              StatusIs(absl::StatusCode::kCancelled));
  EXPECT_FALSE(f->is_valid());
  ASSERT_TRUE(f->Refactorize(absl::MakeConstSpan(A.valuePtr(), A.nonZeros())).ok());
  const Eigen::VectorXd b = Eigen::VectorXd::Random(A.rows());
  EXPECT_LT((A * f->Solve(b) - b).norm() / b.norm(), 1e-10);
}

}  // namespace
}  // namespace fieldspace
