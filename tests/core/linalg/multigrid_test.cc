// SolveMultigridCg: solutions to the tolerance that agree with a sparse Cholesky, iteration counts
// that do not grow with the grid (what a multigrid preconditioner is for; by the usual bound,
// plain or diagonally preconditioned CG needs iterations proportional to the square root of the
// condition number, i.e. to the grid width), any number of right-hand sides, and the error
// paths.

#include "core/linalg/multigrid.h"

#include <atomic>
#include <cmath>
#include <random>

#include "core/linalg/sparse_cholesky.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tests/testing/fixtures.h"
#include "tests/testing/matchers.h"

namespace fieldspace {
namespace {

using ::fieldspace::testing::GridLaplacian;
using ::fieldspace::testing::StatusIs;
using ::testing::HasSubstr;
using SpMat = Eigen::SparseMatrix<double>;

MultigridRowMatrix Random(int64_t rows, int64_t cols, uint32_t seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> g;
  MultigridRowMatrix B(rows, cols);
  for (int64_t i = 0; i < rows; ++i) {
    for (int64_t j = 0; j < cols; ++j) B(i, j) = g(rng);
  }
  return B;
}

// The n x n grid's graph Laplacian with node 0 pinned (its row and column removed): symmetric
// positive definite, condition number ~ n^2 log n, constants as its near-kernel, as the
// kernel fields' vertex Laplacian with one pinned vertex.
SpMat PinnedGridLaplacian(int n) {
  const SpMat A = GridLaplacian(n, 0.0);
  const int m = n * n - 1;
  SpMat P = A.bottomRightCorner(m, m);
  P.makeCompressed();
  return P;
}

double MaxColumnResidual(const SpMat& A, const MultigridRowMatrix& X, const MultigridRowMatrix& B) {
  double worst = 0;
  const MultigridRowMatrix R = B - A * X;
  for (Eigen::Index j = 0; j < B.cols(); ++j) {
    if (B.col(j).norm() == 0) continue;
    worst = std::max(worst, R.col(j).norm() / B.col(j).norm());
  }
  return worst;
}

TEST(MultigridTest, SolvesToTheToleranceAndAgreesWithCholesky) {
  const SpMat A = PinnedGridLaplacian(60);
  const MultigridRowMatrix B = Random(A.rows(), 3, 1);
  MultigridOptions options;
  options.tolerance = 1e-11;
  MultigridStats stats;
  absl::StatusOr<MultigridRowMatrix> X = SolveMultigridCg(A, B, options, &stats);
  ASSERT_TRUE(X.ok()) << X.status();
  EXPECT_LE(MaxColumnResidual(A, *X, B), 1e-11);
  EXPECT_LE(stats.relative_residual, 1e-11);
  EXPECT_GE(stats.levels, 2);
  EXPECT_LE(stats.coarsest_rows, options.coarsest_rows);
  EXPECT_GT(stats.operator_complexity, 1.0);
  EXPECT_LT(stats.operator_complexity, 2.0);
  auto factor = SparseCholesky::Factorize(A);
  ASSERT_TRUE(factor.ok()) << factor.status();
  auto reference = factor->SolveMatrix(Eigen::MatrixXd(B));
  ASSERT_TRUE(reference.ok()) << reference.status();
  // Error <= condition number x residual: ~1e4 x 1e-11.
  EXPECT_LT((Eigen::MatrixXd(*X) - *reference).norm(), 1e-6 * reference->norm());
}

TEST(MultigridTest, IterationsDoNotGrowWithTheGrid) {
  int iterations[2] = {0, 0};
  const int widths[2] = {32, 128};
  for (int k = 0; k < 2; ++k) {
    const SpMat A = PinnedGridLaplacian(widths[k]);
    MultigridStats stats;
    absl::StatusOr<MultigridRowMatrix> X = SolveMultigridCg(A, Random(A.rows(), 1, 7), {}, &stats);
    ASSERT_TRUE(X.ok()) << X.status();
    iterations[k] = stats.iterations;
    std::printf("grid %d^2: %d levels, %d iterations, operator complexity %.2f\n", widths[k],
                stats.levels, stats.iterations, stats.operator_complexity);
  }
  EXPECT_LE(iterations[1], iterations[0] + 6);
  EXPECT_LE(iterations[1], 40);
}

TEST(MultigridTest, AnyNumberOfColumnsGoesThroughPanels) {
  const SpMat A = GridLaplacian(40, 1e-2);
  for (int q : {1, 2, 3, 8, 11}) {
    MultigridRowMatrix B = Random(A.rows(), q, 10 + q);
    if (q == 11) B.col(9).setZero();  // a zero column solves to zero
    MultigridStats stats;
    absl::StatusOr<MultigridRowMatrix> X = SolveMultigridCg(A, B, {}, &stats);
    ASSERT_TRUE(X.ok()) << q << ": " << X.status();
    ASSERT_EQ(X->cols(), q);
    EXPECT_LE(MaxColumnResidual(A, *X, B), 1e-10) << q;
    // Each column alone gives the same solution as in the panel.
    const int j = q - 1;
    absl::StatusOr<MultigridRowMatrix> single = SolveMultigridCg(A, B.col(j));
    ASSERT_TRUE(single.ok()) << single.status();
    EXPECT_LT((single->col(0) - X->col(j)).norm(), 1e-7 * (1 + X->col(j).norm())) << q;
    if (q == 11) {
      EXPECT_EQ(X->col(9).norm(), 0.0);
    }
  }
}

TEST(MultigridTest, SmallSystemsAreSolvedByTheCoarsestLevelAlone) {
  const SpMat A = GridLaplacian(10, 1.0);
  const MultigridRowMatrix B = Random(A.rows(), 2, 3);
  MultigridStats stats;
  absl::StatusOr<MultigridRowMatrix> X = SolveMultigridCg(A, B, {}, &stats);
  ASSERT_TRUE(X.ok()) << X.status();
  EXPECT_EQ(stats.levels, 1);
  EXPECT_LE(stats.iterations, 2);
  EXPECT_LE(MaxColumnResidual(A, *X, B), 1e-10);
}

TEST(MultigridTest, RejectsBadInput) {
  const SpMat A = PinnedGridLaplacian(20);
  const MultigridRowMatrix B = Random(A.rows(), 2, 5);
  EXPECT_THAT(SolveMultigridCg(A, B.topRows(10)).status(),
              StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr("rows")));
  MultigridRowMatrix nan_b = B;
  nan_b(3, 1) = std::nan("");
  EXPECT_THAT(SolveMultigridCg(A, nan_b).status(),
              StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr("non-finite")));
  SpMat bad = A;
  bad.coeffRef(5, 5) = -1.0;
  EXPECT_THAT(SolveMultigridCg(bad, B).status(),
              StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr("not positive")));
  SpMat inf = A;
  inf.coeffRef(7, 8) = std::numeric_limits<double>::infinity();
  EXPECT_THAT(SolveMultigridCg(inf, B).status(),
              StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr("non-finite")));
  MultigridOptions zero_tolerance;
  zero_tolerance.tolerance = 0;
  EXPECT_THAT(SolveMultigridCg(A, B, zero_tolerance).status(),
              StatusIs(absl::StatusCode::kInvalidArgument));
}

// A positive diagonal but an indefinite matrix: the coarsest level's dense Cholesky fails, which
// is FailedPrecondition (the kernel step then falls back to CHOLMOD), not a crash or garbage.
TEST(MultigridTest, IndefiniteCoarsestMatrixIsFailedPrecondition) {
  SpMat A = GridLaplacian(10, 0.0);  // 100 rows: the coarsest level alone; eigenvalues 0..8
  for (int i = 0; i < A.rows(); ++i) A.coeffRef(i, i) -= 0.5 * A.coeff(i, i);
  const MultigridRowMatrix B = Random(A.rows(), 2, 4);
  EXPECT_THAT(SolveMultigridCg(A, B).status(),
              StatusIs(absl::StatusCode::kFailedPrecondition, HasSubstr("not positive definite")));
}

TEST(MultigridTest, ReportsNonConvergenceAndCancellation) {
  const SpMat A = PinnedGridLaplacian(50);
  const MultigridRowMatrix B = Random(A.rows(), 2, 9);
  MultigridOptions few;
  few.max_iterations = 2;
  few.tolerance = 1e-14;
  EXPECT_THAT(SolveMultigridCg(A, B, few).status(),
              StatusIs(absl::StatusCode::kFailedPrecondition, HasSubstr("after 2 iterations")));
  std::atomic<bool> cancel{true};
  MultigridOptions cancelled;
  cancelled.cancel = &cancel;
  EXPECT_THAT(SolveMultigridCg(A, B, cancelled).status(), StatusIs(absl::StatusCode::kCancelled));
}

}  // namespace
}  // namespace fieldspace
