// Tests of LocalCholesky, the sequential supernodal Cholesky of the basis construction's local
// problems, against dense factorizations.
#include "core/linalg/local_cholesky.h"

#include <algorithm>
#include <atomic>
#include <cstdint>
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

// The same grid without the dense copy, for systems too large for one; and A x for it.
UpperCsc SparseGridMatrix(int nx, int ny, double shift) {
  UpperCsc A;
  A.n = nx * ny;
  A.outer.push_back(0);
  for (int j = 0; j < A.n; ++j) {
    if (j >= nx) {
      A.inner.push_back(j - nx);
      A.values.push_back(-1.0);
    }
    if (j % nx != 0) {
      A.inner.push_back(j - 1);
      A.values.push_back(-1.0);
    }
    A.inner.push_back(j);
    A.values.push_back(4.0 + shift + 0.01 * (j % 7));
    A.outer.push_back(static_cast<int32_t>(A.inner.size()));
  }
  return A;
}

Eigen::VectorXd Multiply(const UpperCsc& A, const Eigen::VectorXd& x) {
  Eigen::VectorXd y = Eigen::VectorXd::Zero(A.n);
  for (int32_t j = 0; j < A.n; ++j) {
    for (int32_t p = A.outer[j]; p < A.outer[j + 1]; ++p) {
      const int32_t i = A.inner[p];
      y[i] += A.values[p] * x[j];
      if (i != j) y[j] += A.values[p] * x[i];
    }
  }
  return y;
}

// Above kReleaseScratchRows the factorization gives its scratch back: the solves still read all
// they need, and the next factorizations (small and large) rebuild it.
TEST(LocalCholeskyTest, LargeSystemsSolveAfterTheirScratchIsGivenBack) {
  const UpperCsc large = SparseGridMatrix(520, 520, 0.01);
  ASSERT_GT(large.n, LocalCholesky::kReleaseScratchRows);
  const UpperCsc small = SparseGridMatrix(30, 20, 0.5);
  LocalCholesky chol;
  for (const UpperCsc* A : {&large, &small, &large}) {
    SCOPED_TRACE(A->n);
    ASSERT_TRUE(chol.Factorize(*A, nullptr).ok());
    const Eigen::VectorXd b = Eigen::VectorXd::Random(A->n);
    Eigen::VectorXd x = b;
    chol.SolveInPlace(x.data(), 1);
    EXPECT_LT((Multiply(*A, x) - b).norm() / b.norm(), 1e-10);
    // In the factor's order, two right-hand sides row-major.
    const std::vector<int32_t>& pinv = chol.inverse_permutation();
    Eigen::MatrixXd xr(2, A->n);
    for (int32_t i = 0; i < A->n; ++i) {
      xr(0, pinv[i]) = b[i];
      xr(1, pinv[i]) = 2.0 * b[i];
    }
    chol.SolvePermutedInPlace(xr.data(), 2);
    Eigen::VectorXd x0(A->n), x1(A->n);
    for (int32_t i = 0; i < A->n; ++i) {
      x0[i] = xr(0, pinv[i]);
      x1[i] = xr(1, pinv[i]);
    }
    EXPECT_LT((x0 - x).norm() / x.norm(), 1e-12);
    EXPECT_LT((x1 - 2.0 * x).norm() / x.norm(), 1e-12);
  }
}

TEST(LocalCholeskyTest, SolvesRightHandSidesKeptInTheFactorsOrder) {
  // A caller that numbers its unknowns by inverse_permutation() keeps its vectors row-major in
  // the factor's order and solves them in place.
  Eigen::MatrixXd dense;
  const UpperCsc A = GridMatrix(23, 31, 0.2, &dense);
  LocalCholesky chol;
  ASSERT_TRUE(chol.Factorize(A, nullptr).ok());
  const std::vector<int32_t>& perm = chol.permutation();
  const std::vector<int32_t>& order = chol.inverse_permutation();
  ASSERT_EQ(order.size(), static_cast<size_t>(A.n));
  for (int32_t k = 0; k < A.n; ++k) ASSERT_EQ(order[perm[k]], k);
  for (const int p : {1, 2, 3, 5}) {
    const Eigen::MatrixXd B = Eigen::MatrixXd::Random(A.n, p);
    std::vector<double> x(static_cast<size_t>(A.n) * p);
    for (int32_t i = 0; i < A.n; ++i) {
      for (int c = 0; c < p; ++c) x[static_cast<size_t>(order[i]) * p + c] = B(i, c);
    }
    chol.SolvePermutedInPlace(x.data(), p);
    Eigen::MatrixXd X(A.n, p);
    for (int32_t i = 0; i < A.n; ++i) {
      for (int c = 0; c < p; ++c) X(i, c) = x[static_cast<size_t>(order[i]) * p + c];
    }
    EXPECT_LT((dense * X - B).norm() / B.norm(), 1e-12) << "p = " << p;
  }
}

// The upper triangle of a dense symmetric matrix, the diagonal first in each column.
UpperCsc UpperFromDense(const Eigen::MatrixXd& dense) {
  const int n = static_cast<int>(dense.rows());
  UpperCsc A;
  A.n = n;
  A.outer.push_back(0);
  for (int j = 0; j < n; ++j) {
    A.inner.push_back(j);
    A.values.push_back(dense(j, j));
    for (int i = 0; i < j; ++i) {
      if (dense(i, j) != 0.0) {
        A.inner.push_back(i);
        A.values.push_back(dense(i, j));
      }
    }
    A.outer.push_back(static_cast<int32_t>(A.inner.size()));
  }
  return A;
}

// A random symmetric positive definite matrix: `components` blocks of random sparse graphs
// (about `degree` neighbours a row), one row per block coupled to a tenth of its block (AMD's
// dense-row handling), a few diagonal-only rows; strictly diagonally dominant.
UpperCsc RandomMatrix(int block, int components, int degree, uint32_t seed,
                      Eigen::MatrixXd* dense) {
  const int n = block * components + 5;
  dense->setZero(n, n);
  uint64_t state = seed;
  auto next = [&state](int bound) {
    state = state * 6364136223846793005ULL + 1442695040888963407ULL;
    return static_cast<int>((state >> 33) % static_cast<uint64_t>(bound));
  };
  auto couple = [&](int i, int j) {
    if (i == j) return;
    const double v = -0.1 - 0.9 * next(1000) / 1000.0;
    (*dense)(i, j) = (*dense)(j, i) = v;
  };
  for (int c = 0; c < components; ++c) {
    const int base = c * block;
    for (int i = 0; i < block; ++i) {
      for (int e = 0; e < degree / 2; ++e) {
        // Mostly near neighbours (a mesh-like band), sometimes far ones.
        const int j = next(8) == 0 ? next(block) : std::min(block - 1, i + 1 + next(6));
        couple(base + i, base + j);
      }
    }
    for (int t = 0; t < block / 10; ++t) couple(base + block / 2, base + next(block));
  }
  for (int i = 0; i < n; ++i) {
    (*dense)(i, i) = 0.0;
    (*dense)(i, i) = dense->row(i).cwiseAbs().sum() + 0.5;
  }
  return UpperFromDense(*dense);
}

// Checks the factorization's analysis against the dense Cholesky factor of the matrix permuted
// as the factorization says it is (permutation()): the column counts (through flops(), the sum
// of their squares) are the dense factor's and the supernodal storage holds its nonzeros plus at
// most the upper triangles of the diagonal blocks (`slack` times the nonzeros: a quarter for
// fill-reducing orders, whose supernodes are narrow). Returns the dense factor's nonzeros.
int64_t ExpectAnalysisMatchesDenseFactor(const LocalCholesky& chol, const Eigen::MatrixXd& dense,
                                         double slack = 0.25) {
  const int n = static_cast<int>(dense.rows());
  const std::vector<int32_t>& perm = chol.permutation();
  EXPECT_EQ(perm.size(), static_cast<size_t>(n));
  if (perm.size() != static_cast<size_t>(n)) return 0;
  std::vector<int> seen(n, 0);
  for (int32_t p : perm) {
    EXPECT_GE(p, 0);
    EXPECT_LT(p, n);
    if (p >= 0 && p < n) ++seen[p];
  }
  EXPECT_EQ(*std::min_element(seen.begin(), seen.end()), 1);
  Eigen::MatrixXd permuted(n, n);
  for (int i = 0; i < n; ++i) {
    for (int j = 0; j < n; ++j) permuted(i, j) = dense(perm[i], perm[j]);
  }
  const Eigen::MatrixXd L = permuted.llt().matrixL();
  int64_t nonzeros = 0;
  double squares = 0;
  for (int j = 0; j < n; ++j) {
    int64_t count = 0;
    for (int i = j; i < n; ++i) count += L(i, j) != 0.0;
    nonzeros += count;
    squares += static_cast<double>(count) * count;
  }
  EXPECT_EQ(chol.flops(), squares);
  EXPECT_GE(chol.factor_nonzeros(), nonzeros);
  EXPECT_LE(chol.factor_nonzeros(), nonzeros + slack * nonzeros);
  return nonzeros;
}

// The symbolic analysis (AMD order, elimination tree, column counts, fundamental supernodes and
// their row patterns) against the dense factor of the same permuted matrix: the column counts
// (through flops(), the sum of their squares) are the dense factor's, the supernodal storage
// holds its nonzeros plus at most the upper triangles of the diagonal blocks, and the solves
// are exact.
TEST(LocalCholeskyTest, AnalysisMatchesTheDenseFactor) {
  for (uint32_t seed : {1u, 2u, 3u}) {
    SCOPED_TRACE(seed);
    Eigen::MatrixXd dense;
    const UpperCsc A = RandomMatrix(150, 3, 6, seed, &dense);
    LocalCholesky chol;
    ASSERT_TRUE(chol.Factorize(A, nullptr).ok());
    const int64_t nonzeros = ExpectAnalysisMatchesDenseFactor(chol, dense);
    // Fill well below the dense triangle's (the order is fill-reducing).
    EXPECT_LT(nonzeros, int64_t{A.n} * A.n / 8);
    const Eigen::MatrixXd B = Eigen::MatrixXd::Random(A.n, 4);
    Eigen::MatrixXd X = B;
    chol.SolveInPlace(X.data(), 4);
    EXPECT_LT((dense * X - B).norm() / B.norm(), 1e-13);
  }
}

// A caller's order instead of AMD's: natural, reversed, shuffled and AMD's own (through
// MinimumDegreeOrder) all factor and solve exactly, each analyzed as its own permutation says
// (up to the postorder the analysis applies, which keeps the fill), and the natural order of a
// grid (a band) fills more than AMD's.
TEST(LocalCholeskyTest, FactorsAGivenOrder) {
  Eigen::MatrixXd dense;
  const UpperCsc A = GridMatrix(23, 17, 0.1, &dense);
  const int32_t n = A.n;
  std::vector<int32_t> natural(n), reversed(n), shuffled(n), amd;
  for (int32_t i = 0; i < n; ++i) natural[i] = reversed[n - 1 - i] = shuffled[i] = i;
  uint64_t state = 7;
  for (int32_t i = n - 1; i > 0; --i) {
    state = state * 6364136223846793005ULL + 1442695040888963407ULL;
    std::swap(shuffled[i], shuffled[static_cast<int32_t>((state >> 33) % (i + 1))]);
  }
  LocalCholesky chol;
  ASSERT_TRUE(chol.MinimumDegreeOrder(A, n, &amd).ok());
  std::vector<int64_t> fill;
  for (const std::vector<int32_t>* order : {&natural, &reversed, &shuffled, &amd}) {
    SCOPED_TRACE(fill.size());
    ASSERT_TRUE(chol.Factorize(A, nullptr, order).ok());
    // (A random order's supernodes near the root are wide: their upper triangles add more.)
    fill.push_back(ExpectAnalysisMatchesDenseFactor(chol, dense, order == &shuffled ? 1.0 : 0.25));
    const Eigen::MatrixXd B = Eigen::MatrixXd::Random(n, 2);
    Eigen::MatrixXd X = B;
    chol.SolveInPlace(X.data(), 2);
    EXPECT_LT((dense * X - B).norm() / B.norm(), 1e-12);
  }
  // A band of width 23: about 23 entries a column.
  EXPECT_GT(fill[0], 20 * n);
  EXPECT_LT(fill[3], fill[0] * 2 / 3);
  // AMD's order given is AMD's order taken.
  ASSERT_TRUE(chol.Factorize(A, nullptr).ok());
  EXPECT_EQ(chol.factor_nonzeros(), [&] {
    LocalCholesky given;
    EXPECT_TRUE(given.Factorize(A, nullptr, &amd).ok());
    return given.factor_nonzeros();
  }());
}

TEST(LocalCholeskyTest, RejectsOrdersThatAreNotPermutations) {
  Eigen::MatrixXd dense;
  const UpperCsc A = GridMatrix(6, 5, 0.1, &dense);
  std::vector<int32_t> order(A.n);
  for (int32_t i = 0; i < A.n; ++i) order[i] = i;
  std::vector<std::vector<int32_t>> bad(4, order);
  bad[0].pop_back();      // too short
  bad[1][3] = bad[1][4];  // a duplicate
  bad[2][0] = A.n;        // out of range
  bad[3][A.n - 1] = -1;   // negative
  LocalCholesky chol;
  for (const std::vector<int32_t>& b : bad) {
    EXPECT_EQ(chol.Factorize(A, nullptr, &b).code(), absl::StatusCode::kInvalidArgument);
  }
  // The instance is still good for the next system.
  ASSERT_TRUE(chol.Factorize(A, nullptr, &order).ok());
  Eigen::VectorXd x = Eigen::VectorXd::Ones(A.n);
  chol.SolveInPlace(x.data(), 1);
  EXPECT_LT((dense * x - Eigen::VectorXd::Ones(A.n)).norm(), 1e-12);
}

// AMD on the leading block of a matrix orders that block as AMD on the block alone does: the
// rows after it, coupled to it and to each other, do not enter.
TEST(LocalCholeskyTest, MinimumDegreeOrderOfTheLeadingBlock) {
  Eigen::MatrixXd grid;
  GridMatrix(12, 9, 0.1, &grid);
  // Through UpperFromDense as A below: AMD breaks ties by the order of the adjacency lists.
  const UpperCsc G = UpperFromDense(grid);
  const int n1 = G.n, n = n1 + 40;
  Eigen::MatrixXd dense = Eigen::MatrixXd::Zero(n, n);
  dense.topLeftCorner(n1, n1) = grid;
  for (int t = 0; t < 40; ++t) {
    const int i = n1 + t;
    dense(i, (7 * t) % n1) = dense((7 * t) % n1, i) = -0.5;
    if (t + 1 < 40) dense(i, i + 1) = dense(i + 1, i) = -0.5;
    dense(i, i) = 3.0;
  }
  for (int i = 0; i < n1; ++i) dense(i, i) += 1.0;
  const UpperCsc A = UpperFromDense(dense);
  LocalCholesky chol;
  std::vector<int32_t> of_block, of_grid;
  ASSERT_TRUE(chol.MinimumDegreeOrder(A, n1, &of_block).ok());
  ASSERT_TRUE(chol.MinimumDegreeOrder(G, n1, &of_grid).ok());
  EXPECT_EQ(of_block, of_grid);
  std::vector<int32_t> sorted = of_block;
  std::sort(sorted.begin(), sorted.end());
  for (int i = 0; i < n1; ++i) ASSERT_EQ(sorted[i], i);
  std::vector<int32_t> none = {1, 2};
  ASSERT_TRUE(chol.MinimumDegreeOrder(A, 0, &none).ok());
  EXPECT_TRUE(none.empty());
  EXPECT_EQ(chol.MinimumDegreeOrder(A, n + 1, &none).code(), absl::StatusCode::kInvalidArgument);
}

// Two unknowns per grid node (a full 2 x 2 block per coupling, as n-fields have per face): AMD on
// the graph of blocks keeps each node's rows together and fills as AMD on the rows does.
TEST(LocalCholeskyTest, BlockMinimumDegreeOrderKeepsBlocksTogether) {
  Eigen::MatrixXd grid;
  GridMatrix(19, 14, 0.1, &grid);
  const int nodes = static_cast<int>(grid.rows());
  Eigen::Matrix2d coupling, self;
  coupling << -0.6, 0.3, -0.2, -0.5;
  self << 1.0, 0.1, 0.1, 1.0;
  Eigen::MatrixXd dense = Eigen::MatrixXd::Zero(2 * nodes, 2 * nodes);
  for (int i = 0; i < nodes; ++i) {
    for (int j = 0; j < nodes; ++j) {
      if (i == j || grid(i, j) == 0.0) continue;
      dense.block<2, 2>(2 * i, 2 * j) = i < j ? coupling : Eigen::Matrix2d(coupling.transpose());
    }
  }
  for (int i = 0; i < nodes; ++i) {
    dense.block<2, 2>(2 * i, 2 * i) = self * (dense.middleRows(2 * i, 2).cwiseAbs().sum() + 0.5);
  }
  const UpperCsc A = UpperFromDense(dense);
  LocalCholesky chol;
  std::vector<int32_t> order;
  ASSERT_TRUE(chol.BlockMinimumDegreeOrder(A, 2, &order).ok());
  ASSERT_EQ(order.size(), static_cast<size_t>(A.n));
  std::vector<int> seen(A.n, 0);
  for (int k = 0; k < nodes; ++k) {
    EXPECT_EQ(order[2 * k] % 2, 0);
    EXPECT_EQ(order[2 * k + 1], order[2 * k] + 1);
    ++seen[order[2 * k]];
    ++seen[order[2 * k + 1]];
  }
  EXPECT_EQ(*std::min_element(seen.begin(), seen.end()), 1);
  ASSERT_TRUE(chol.Factorize(A, nullptr, &order).ok());
  const int64_t blocked = ExpectAnalysisMatchesDenseFactor(chol, dense);
  const Eigen::MatrixXd B = Eigen::MatrixXd::Random(A.n, 2);
  Eigen::MatrixXd X = B;
  chol.SolveInPlace(X.data(), 2);
  EXPECT_LT((dense * X - B).norm() / B.norm(), 1e-12);
  LocalCholesky rows;
  ASSERT_TRUE(rows.Factorize(A, nullptr).ok());
  EXPECT_LE(chol.factor_nonzeros(), rows.factor_nonzeros() * 21 / 20);
  EXPECT_GT(blocked, 0);
  // Blocks of one are AMD on the rows; a block size that does not divide is refused.
  std::vector<int32_t> ones, plain;
  ASSERT_TRUE(chol.BlockMinimumDegreeOrder(A, 1, &ones).ok());
  ASSERT_TRUE(chol.MinimumDegreeOrder(A, A.n, &plain).ok());
  EXPECT_EQ(ones, plain);
  EXPECT_EQ(chol.BlockMinimumDegreeOrder(A, 3, &order).code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(chol.BlockMinimumDegreeOrder(A, 0, &order).code(), absl::StatusCode::kInvalidArgument);
  // No rows: no order.
  UpperCsc empty;
  empty.outer = {0};
  ASSERT_TRUE(chol.BlockMinimumDegreeOrder(empty, 2, &order).ok());
  EXPECT_TRUE(order.empty());
}

// Systems without off-diagonal entries: one row, and a diagonal (every column its own
// supernode, the elimination tree a forest of single nodes).
TEST(LocalCholeskyTest, SolvesDiagonalSystems) {
  for (int32_t n : {1, 7}) {
    UpperCsc A;
    A.n = n;
    A.outer.push_back(0);
    for (int32_t j = 0; j < n; ++j) {
      A.inner.push_back(j);
      A.values.push_back(j + 2.0);
      A.outer.push_back(j + 1);
    }
    LocalCholesky chol;
    ASSERT_TRUE(chol.Factorize(A, nullptr).ok());
    EXPECT_EQ(chol.factor_nonzeros(), n);
    EXPECT_EQ(chol.flops(), n);
    std::vector<double> x(n, 1.0);
    chol.SolveInPlace(x.data(), 1);
    for (int32_t j = 0; j < n; ++j) EXPECT_NEAR(x[j], 1.0 / (j + 2.0), 1e-15);
  }
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
