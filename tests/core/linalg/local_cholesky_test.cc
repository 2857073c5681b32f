// Tests of LocalCholesky, the sequential supernodal Cholesky of the basis construction's local
// problems, against dense factorizations.
#include "core/linalg/local_cholesky.h"

#include <atomic>
#include <vector>

#include "Eigen/Cholesky"
#include "Eigen/Core"
#include "core/common/cancel.h"
#include "gtest/gtest.h"

namespace fieldspace {
namespace {

// A flag that is already set: Factorize returns at its first check.
const CancelFlag kCancelled{true};

// A 2D grid Laplacian plus a diagonal: SPD, sparse, with fill.
UpperCsc GridMatrix(int nx, int ny, double shift, Eigen::MatrixXd* dense) {
  const int n = nx * ny;
  dense->setZero(n, n);
  for (int y = 0; y < ny; ++y) {
    for (int x = 0; x < nx; ++x) {
      const int i = y * nx + x;
      (*dense)(i, i) = 4.0 + shift + 0.01 * (i % 7);
      if (x + 1 < nx) (*dense)(i, i + 1) = (*dense)(i + 1, i) = -1.0;
      if (y + 1 < ny) (*dense)(i, i + nx) = (*dense)(i + nx, i) = -1.0;
    }
  }
  UpperCsc A;
  A.n = n;
  A.outer.push_back(0);
  for (int j = 0; j < n; ++j) {
    // Upper triangle, unsorted rows on purpose: descending, the diagonal last.
    for (int i = j - 1; i >= 0; --i) {
      if ((*dense)(i, j) != 0.0) {
        A.inner.push_back(i);
        A.values.push_back((*dense)(i, j));
      }
    }
    A.inner.push_back(j);
    A.values.push_back((*dense)(j, j));
    A.outer.push_back(static_cast<int32_t>(A.inner.size()));
  }
  return A;
}

TEST(LocalCholeskyTest, SolvesLikeDense) {
  Eigen::MatrixXd dense;
  const UpperCsc A = GridMatrix(37, 29, 0.05, &dense);
  LocalCholesky chol;
  ASSERT_TRUE(chol.Factorize(A, nullptr).ok());
  EXPECT_GT(chol.flops(), 0);
  const Eigen::MatrixXd B = Eigen::MatrixXd::Random(A.n, 3);
  Eigen::MatrixXd X = B;
  chol.SolveInPlace(X.data(), 3);
  const Eigen::MatrixXd ref = dense.llt().solve(B);
  EXPECT_LT((X - ref).norm() / ref.norm(), 1e-12);
  // Reuse for another matrix of another size.
  Eigen::MatrixXd dense2;
  const UpperCsc A2 = GridMatrix(10, 50, 1.0, &dense2);
  ASSERT_TRUE(chol.Factorize(A2, nullptr).ok());
  Eigen::VectorXd b = Eigen::VectorXd::Random(A2.n);
  Eigen::VectorXd x = b;
  chol.SolveInPlace(x.data(), 1);
  EXPECT_LT((dense2 * x - b).norm() / b.norm(), 1e-12);
}

TEST(LocalCholeskyTest, RejectsIndefinite) {
  Eigen::MatrixXd dense;
  UpperCsc A = GridMatrix(8, 8, -5.0, &dense);  // diagonal ~ -1: indefinite
  LocalCholesky chol;
  EXPECT_EQ(chol.Factorize(A, nullptr).code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_EQ(GridMatrix(8, 8, 0.1, &dense).n, 64);
  EXPECT_EQ(chol.Factorize(GridMatrix(30, 30, 0.1, &dense), &kCancelled).code(),
            absl::StatusCode::kCancelled);
}

}  // namespace
}  // namespace fieldspace
