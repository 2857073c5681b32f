#include "core/linalg/sparse_cholesky.h"

#include <cmath>
#include <random>
#include <thread>
#include <utility>
#include <vector>

#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tests/testing/fixtures.h"
#include "tests/testing/matchers.h"

namespace fieldspace {
namespace {

using ::fieldspace::testing::StatusIs;
using SpMat = Eigen::SparseMatrix<double>;
using ::fieldspace::testing::GridLaplacian;
using ::testing::HasSubstr;

Eigen::VectorXd Random(int n, uint32_t seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> g;
  Eigen::VectorXd v(n);
  for (int i = 0; i < n; ++i) v[i] = g(rng);
  return v;
}

struct MethodCase {
  CholeskyMethod method;
  CholeskyOrdering ordering;
};

class CholeskyMethodTest : public ::testing::TestWithParam<MethodCase> {
 protected:
  CholeskyOptions Options() const {
    CholeskyOptions o;
    o.method = GetParam().method;
    o.ordering = GetParam().ordering;
    return o;
  }
};

TEST_P(CholeskyMethodTest, SolvesToTinyResidual) {
  const SpMat A = GridLaplacian(60, 1e-3);  // 3600 rows, condition number ~ 1e4
  auto factor = SparseCholesky::Factorize(A, Options());
  ASSERT_TRUE(factor.ok()) << factor.status();
  EXPECT_EQ(factor->rows(), 3600);
  EXPECT_GE(factor->factor_nonzeros(), A.nonZeros() / 2);
  const Eigen::VectorXd b = Random(3600, 1);
  auto x = factor->Solve(b);
  ASSERT_TRUE(x.ok()) << x.status();
  EXPECT_LT((A * *x - b).norm(), 1e-10 * b.norm());
  Eigen::MatrixXd B(3600, 3);
  for (int c = 0; c < 3; ++c) B.col(c) = Random(3600, 10 + c);
  auto X = factor->SolveMatrix(B);
  ASSERT_TRUE(X.ok()) << X.status();
  EXPECT_LT((A * *X - B).norm(), 1e-10 * B.norm());
  // A strided view (rows of a taller matrix) gives the same solution.
  Eigen::MatrixXd taller = Eigen::MatrixXd::Zero(3700, 3);
  taller.topRows(3600) = B;
  auto Y = factor->SolveMatrix(taller.topRows(3600));
  ASSERT_TRUE(Y.ok()) << Y.status();
  EXPECT_EQ(*Y, *X);
}

TEST_P(CholeskyMethodTest, NotPositiveDefiniteIsFailedPrecondition) {
  const SpMat A = GridLaplacian(20, -0.5);  // eigenvalue -0.5 from the constant vector
  auto factor = SparseCholesky::Factorize(A, Options());
  EXPECT_THAT(factor, StatusIs(absl::StatusCode::kFailedPrecondition));
  EXPECT_THAT(factor.status().message(), HasSubstr("not positive definite"));
}

INSTANTIATE_TEST_SUITE_P(
    Methods, CholeskyMethodTest,
    ::testing::Values(MethodCase{CholeskyMethod::kSupernodal, CholeskyOrdering::kDefault},
                      MethodCase{CholeskyMethod::kSupernodal, CholeskyOrdering::kMetis},
                      MethodCase{CholeskyMethod::kSimplicial, CholeskyOrdering::kAmd},
                      MethodCase{CholeskyMethod::kAuto, CholeskyOrdering::kNatural}));

TEST(SparseCholeskyTest, SupernodalByDefault) {
  auto factor = SparseCholesky::Factorize(GridLaplacian(40, 1.0));
  ASSERT_TRUE(factor.ok());
  EXPECT_TRUE(factor->is_supernodal());
}

TEST(SparseCholeskyTest, UpperTriangleOnlyIsEnough) {
  const SpMat A = GridLaplacian(30, 0.5);
  const SpMat upper = A.triangularView<Eigen::Upper>();
  CholeskyOptions o;
  o.check_input = false;  // an upper triangle is not a symmetric matrix
  auto factor = SparseCholesky::Factorize(upper, o);
  ASSERT_TRUE(factor.ok()) << factor.status();
  const Eigen::VectorXd b = Random(900, 2);
  auto x = factor->Solve(b);
  ASSERT_TRUE(x.ok());
  EXPECT_LT((A * *x - b).norm(), 1e-10 * b.norm());
}

TEST(SparseCholeskyTest, ShiftedFactorizations) {
  // A + s B with the singular grid Laplacian A (kernel: constants) and B = diag(d) > 0.
  const SpMat A = GridLaplacian(30, 0.0);
  const int n = 900;
  Eigen::VectorXd d(n);
  for (int i = 0; i < n; ++i) d[i] = 1.0 + (i % 7) * 0.25;
  const Eigen::VectorXd b = Random(n, 3);
  auto diag = SparseCholesky::FactorizeShifted(A, 0.01, d);
  ASSERT_TRUE(diag.ok()) << diag.status();
  auto x = diag->Solve(b);
  ASSERT_TRUE(x.ok());
  EXPECT_LT((A * *x + 0.01 * d.cwiseProduct(*x) - b).norm(), 1e-10 * b.norm());
  const SpMat B = GridLaplacian(30, 1.0);
  auto sparse = SparseCholesky::FactorizeShifted(A, 2.0, B);
  ASSERT_TRUE(sparse.ok()) << sparse.status();
  x = sparse->Solve(b);
  ASSERT_TRUE(x.ok());
  EXPECT_LT((A * *x + 2.0 * (B * *x) - b).norm(), 1e-10 * b.norm());
  // A negative shift below the spectrum fails cleanly.
  EXPECT_THAT(SparseCholesky::FactorizeShifted(A, -0.01, d),
              StatusIs(absl::StatusCode::kFailedPrecondition));
  EXPECT_THAT(SparseCholesky::FactorizeShifted(A, 1.0, Eigen::VectorXd::Ones(5)),
              StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(SparseCholesky::FactorizeShifted(A, 1.0, GridLaplacian(5, 1.0)),
              StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(SparseCholesky::FactorizeShifted(A, std::nan(""), d),
              StatusIs(absl::StatusCode::kInvalidArgument));
}

TEST(SparseCholeskyTest, RefactorizeSamePattern) {
  const SpMat A = GridLaplacian(25, 1.0);
  auto factor = SparseCholesky::Factorize(A);
  ASSERT_TRUE(factor.ok());
  const SpMat A2 = 3.0 * A;
  ASSERT_TRUE(factor->Refactorize(A2).ok());
  const Eigen::VectorXd b = Random(625, 4);
  auto x = factor->Solve(b);
  ASSERT_TRUE(x.ok());
  EXPECT_LT((A2 * *x - b).norm(), 1e-10 * b.norm());
  // Different pattern or size: rejected, factor still usable.
  SpMat other = A;
  other.coeffRef(0, 624) = 0.1;
  other.coeffRef(624, 0) = 0.1;
  EXPECT_THAT(factor->Refactorize(other), StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(factor->Refactorize(GridLaplacian(5, 1.0)),
              StatusIs(absl::StatusCode::kInvalidArgument));
  // Indefinite values on the same pattern: FailedPrecondition, and solves refuse afterwards.
  EXPECT_THAT(factor->Refactorize(GridLaplacian(25, -1.0)),
              StatusIs(absl::StatusCode::kFailedPrecondition));
  EXPECT_THAT(factor->Solve(b), StatusIs(absl::StatusCode::kFailedPrecondition));
  ASSERT_TRUE(factor->Refactorize(A).ok());
  EXPECT_TRUE(factor->Solve(b).ok());
}

TEST(SparseCholeskyTest, InvalidInputs) {
  SpMat rect(3, 4);
  EXPECT_THAT(SparseCholesky::Factorize(rect), StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(SparseCholesky::Factorize(SpMat(0, 0)), StatusIs(absl::StatusCode::kInvalidArgument));
  SpMat asym = GridLaplacian(4, 1.0);
  asym.coeffRef(0, 1) = -0.5;
  auto a = SparseCholesky::Factorize(asym);
  EXPECT_THAT(a, StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(a.status().message(), HasSubstr("not symmetric"));
  SpMat nan = GridLaplacian(4, 1.0);
  nan.coeffRef(3, 3) = std::nan("");
  EXPECT_THAT(SparseCholesky::Factorize(nan), StatusIs(absl::StatusCode::kInvalidArgument));
  auto factor = SparseCholesky::Factorize(GridLaplacian(4, 1.0));
  ASSERT_TRUE(factor.ok());
  EXPECT_THAT(factor->Solve(Eigen::VectorXd::Ones(15)),
              StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(factor->SolveMatrix(Eigen::MatrixXd::Ones(16, 0)),
              StatusIs(absl::StatusCode::kInvalidArgument));
  // The zero matrix (no entries at all) is not positive definite.
  EXPECT_THAT(SparseCholesky::Factorize(SpMat(5, 5)),
              StatusIs(absl::StatusCode::kFailedPrecondition));
}

TEST(SparseCholeskyTest, ConcurrentSolvesAgree) {
  const SpMat A = GridLaplacian(50, 0.1);
  auto factor = SparseCholesky::Factorize(A);
  ASSERT_TRUE(factor.ok());
  const int threads = 8;
  std::vector<Eigen::VectorXd> b(threads), x(threads);
  std::vector<bool> ok(threads, false);
  for (int t = 0; t < threads; ++t) b[t] = Random(2500, 100 + t);
  std::vector<std::thread> pool;
  for (int t = 0; t < threads; ++t) {
    pool.emplace_back([&, t] {
      for (int rep = 0; rep < 20; ++rep) {
        auto r = factor->Solve(b[t]);
        ok[t] = r.ok();
        if (r.ok()) x[t] = *r;
      }
    });
  }
  for (std::thread& th : pool) th.join();
  for (int t = 0; t < threads; ++t) {
    ASSERT_TRUE(ok[t]);
    auto serial = factor->Solve(b[t]);
    ASSERT_TRUE(serial.ok());
    EXPECT_EQ(x[t], *serial);  // bitwise: no shared state between calls
    EXPECT_LT((A * x[t] - b[t]).norm(), 1e-10 * b[t].norm());
  }
}

TEST(SparseCholeskyTest, MoveKeepsTheFactor) {
  auto factor = SparseCholesky::Factorize(GridLaplacian(10, 1.0));
  ASSERT_TRUE(factor.ok());
  SparseCholesky moved = *std::move(factor);
  EXPECT_TRUE(moved.Solve(Eigen::VectorXd::Ones(100)).ok());
}

}  // namespace
}  // namespace fieldspace
