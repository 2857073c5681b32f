#include "core/linalg/eigensolver.h"

#include <algorithm>
#include <cmath>
#include <numbers>
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

// Path graph Laplacian with free ends: eigenvalues 2 - 2 cos(pi k / n), k = 0..n-1.
SpMat PathLaplacian(int n) {
  std::vector<Eigen::Triplet<double>> t;
  for (int i = 0; i + 1 < n; ++i) {
    t.emplace_back(i, i, 1.0);
    t.emplace_back(i + 1, i + 1, 1.0);
    t.emplace_back(i, i + 1, -1.0);
    t.emplace_back(i + 1, i, -1.0);
  }
  SpMat L(n, n);
  L.setFromTriplets(t.begin(), t.end());
  return L;
}

double PathEigenvalue(int n, int k) { return 2.0 - 2.0 * std::cos(std::numbers::pi * k / n); }

TEST(EigensolverTest, PathLaplacianSparseAndDense) {
  for (int n : {100, 5000}) {  // dense path, shift-invert Lanczos path
    const SpMat L = PathLaplacian(n);
    EigenOptions o;
    o.count = 8;
    auto r = LowestEigenpairs(L, Eigen::VectorXd::Ones(n), o);
    ASSERT_TRUE(r.ok()) << r.status();
    ASSERT_EQ(r->values.size(), 8);
    for (int k = 0; k < 8; ++k) {
      EXPECT_NEAR(r->values[k], PathEigenvalue(n, k), 1e-12) << "n = " << n << " k = " << k;
    }
    EXPECT_LT(r->shift, 0.0);
    if (n > o.dense_max_size) {
      EXPECT_GT(r->operations, 0);
    }
  }
}

TEST(EigensolverTest, GeneralizedProblemWithDiagonalMass) {
  // S x = lambda M x with S = diag(s), M = diag(m): eigenvalues s_i / m_i, eigenvectors
  // M-normalized unit vectors.
  const int n = 2000;
  std::vector<Eigen::Triplet<double>> t;
  Eigen::VectorXd m(n);
  std::vector<double> ratios;
  for (int i = 0; i < n; ++i) {
    const double s = 1.0 + ((i * 7919) % n);
    m[i] = 0.5 + (i % 5);
    t.emplace_back(i, i, s);
    ratios.push_back(s / m[i]);
  }
  SpMat S(n, n);
  S.setFromTriplets(t.begin(), t.end());
  std::sort(ratios.begin(), ratios.end());
  EigenOptions o;
  o.count = 5;
  auto r = LowestEigenpairs(S, m, o);
  ASSERT_TRUE(r.ok()) << r.status();
  for (int k = 0; k < 5; ++k) EXPECT_NEAR(r->values[k], ratios[k], 1e-10 * ratios[k]);
  const Eigen::MatrixXd gram = r->vectors.transpose() * m.asDiagonal() * r->vectors;
  EXPECT_LT((gram - Eigen::MatrixXd::Identity(5, 5)).cwiseAbs().maxCoeff(), 1e-10);
}

TEST(EigensolverTest, KernelOfSingularMatrixAndResiduals) {
  // The grid Laplacian has a one-dimensional kernel; the default negative shift handles it.
  const SpMat L = GridLaplacian(40, 0.0);
  Eigen::VectorXd m(1600);
  for (int i = 0; i < 1600; ++i) m[i] = 1.0 + 0.5 * std::sin(i);
  EigenOptions o;
  o.count = 6;
  auto r = LowestEigenpairs(L, m, o);
  ASSERT_TRUE(r.ok()) << r.status();
  EXPECT_LT(std::abs(r->values[0]), 1e-12);
  EXPECT_GT(r->values[1], 1e-3);
  for (int k = 0; k < 6; ++k) {
    const Eigen::VectorXd res =
        L * r->vectors.col(k) - r->values[k] * m.cwiseProduct(r->vectors.col(k));
    EXPECT_LT(res.norm(), 1e-8) << k;
  }
  EXPECT_TRUE(std::is_sorted(r->values.data(), r->values.data() + 6));
  // Without vectors: same values.
  o.compute_vectors = false;
  auto v = LowestEigenpairs(L, m, o);
  ASSERT_TRUE(v.ok());
  EXPECT_EQ(v->vectors.size(), 0);
  EXPECT_LT((v->values - r->values).cwiseAbs().maxCoeff(), 1e-10);
}

TEST(EigensolverTest, FindsEveryCopyOfRepeatedEigenvalues) {
  // Four uncoupled copies of a path: every eigenvalue has multiplicity exactly 4. A single
  // Krylov sequence sees each eigenspace as one direction, so the copies must come from the
  // deflated multiplicity check.
  const int n = 800;
  const SpMat L = PathLaplacian(n);
  std::vector<Eigen::Triplet<double>> t;
  for (int b = 0; b < 4; ++b) {
    for (int j = 0; j < n; ++j) {
      for (SpMat::InnerIterator it(L, j); it; ++it) {
        t.emplace_back(b * n + it.row(), b * n + j, it.value());
      }
    }
  }
  SpMat S(4 * n, 4 * n);
  S.setFromTriplets(t.begin(), t.end());
  EigenOptions o;
  o.count = 12;
  auto r = LowestEigenpairs(S, Eigen::VectorXd::Ones(4 * n), o);
  ASSERT_TRUE(r.ok()) << r.status();
  for (int i = 0; i < 12; ++i) {
    EXPECT_NEAR(r->values[i], PathEigenvalue(n, i / 4), 1e-10) << i;
  }
  const Eigen::MatrixXd gram = r->vectors.transpose() * r->vectors;
  EXPECT_LT((gram - Eigen::MatrixXd::Identity(12, 12)).cwiseAbs().maxCoeff(), 1e-8);
  for (int i = 0; i < 12; ++i) {
    EXPECT_LT((S * r->vectors.col(i) - r->values[i] * r->vectors.col(i)).norm(), 1e-7) << i;
  }
}

TEST(EigensolverTest, InvalidArguments) {
  const SpMat L = PathLaplacian(500);
  const Eigen::VectorXd m = Eigen::VectorXd::Ones(500);
  auto status_of = [&](const SpMat& S, const Eigen::VectorXd& mass, const EigenOptions& o) {
    return LowestEigenpairs(S, mass, o).status();
  };
  EigenOptions o;
  o.count = 0;
  EXPECT_THAT(status_of(L, m, o), StatusIs(absl::StatusCode::kInvalidArgument));
  o.count = 501;
  EXPECT_THAT(status_of(L, m, o), StatusIs(absl::StatusCode::kInvalidArgument));
  o = {};
  EXPECT_THAT(status_of(L, Eigen::VectorXd::Ones(499), o),
              StatusIs(absl::StatusCode::kInvalidArgument));
  Eigen::VectorXd bad_mass = m;
  bad_mass[17] = 0.0;
  EXPECT_THAT(status_of(L, bad_mass, o), StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(status_of(SpMat(3, 4), Eigen::VectorXd::Ones(3), o),
              StatusIs(absl::StatusCode::kInvalidArgument));
  SpMat asym = L;
  asym.coeffRef(0, 1) = 5.0;
  EXPECT_THAT(status_of(asym, m, o), StatusIs(absl::StatusCode::kInvalidArgument));
  o.tolerance = 0;
  EXPECT_THAT(status_of(L, m, o), StatusIs(absl::StatusCode::kInvalidArgument));
  o = {};
  o.max_iterations = 0;
  EXPECT_THAT(status_of(L, m, o), StatusIs(absl::StatusCode::kInvalidArgument));
  o = {};
  o.subspace_size = 5;  // must exceed count = 10
  EXPECT_THAT(status_of(L, m, o), StatusIs(absl::StatusCode::kInvalidArgument));
  o = {};
  o.shift = std::nan("");
  EXPECT_THAT(status_of(L, m, o), StatusIs(absl::StatusCode::kInvalidArgument));
  o = {};
  o.relative_shift = -1;
  EXPECT_THAT(status_of(L, m, o), StatusIs(absl::StatusCode::kInvalidArgument));
}

TEST(EigensolverTest, IndefiniteOrShiftAboveSpectrumIsFailedPrecondition) {
  for (int grid : {10, 40}) {  // dense and sparse paths
    const int n = grid * grid;
    const Eigen::VectorXd m = Eigen::VectorXd::Ones(n);
    auto r = LowestEigenpairs(GridLaplacian(grid, -0.5), m);
    EXPECT_THAT(r, StatusIs(absl::StatusCode::kFailedPrecondition)) << grid;
    EXPECT_THAT(r.status().message(), HasSubstr("not positive definite"));
    EigenOptions o;
    o.shift = 0.5;  // above the zero eigenvalue of the Laplacian
    EXPECT_THAT(LowestEigenpairs(GridLaplacian(grid, 0.0), m, o),
                StatusIs(absl::StatusCode::kFailedPrecondition))
        << grid;
  }
}

TEST(EigensolverTest, IterationLimitIsResourceExhausted) {
  // Tightly clustered spectrum, tiny Krylov space, one restart: cannot converge.
  const SpMat L = GridLaplacian(60, 0.0);
  EigenOptions o;
  o.count = 20;
  o.subspace_size = 21;
  o.max_iterations = 1;
  o.tolerance = 1e-14;
  auto r = LowestEigenpairs(L, Eigen::VectorXd::Ones(3600), o);
  EXPECT_THAT(r, StatusIs(absl::StatusCode::kResourceExhausted));
  EXPECT_THAT(r.status().message(), HasSubstr("not converged"));
}

}  // namespace
}  // namespace fieldspace
