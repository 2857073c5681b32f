#include "core/subspace/dense_eigen.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <thread>

#include "Eigen/Eigenvalues"
#include "Eigen/QR"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tests/testing/matchers.h"

namespace fieldspace {
namespace {

using ::fieldspace::testing::StatusIs;
using ::testing::HasSubstr;

// Q diag(values) Q^T with a random orthogonal Q: a symmetric matrix with a known spectrum.
Eigen::MatrixXd WithSpectrum(const Eigen::VectorXd& values, unsigned seed) {
  std::srand(seed);
  const Eigen::Index n = values.size();
  Eigen::HouseholderQR<Eigen::MatrixXd> qr(Eigen::MatrixXd::Random(n, n));
  const Eigen::MatrixXd Q = qr.householderQ();
  return Q * values.asDiagonal() * Q.transpose();
}

TEST(DenseEigenTest, KnownSpectrumWithMultipleEigenvaluesAndOrthonormalVectors) {
  // Multiplicities 1, 3, 2, 5, ... as on a sphere; negative and zero eigenvalues included.
  const int n = 120;
  Eigen::VectorXd values(n);
  for (int i = 0; i < n; ++i) values[i] = -2.0 + (i < 1 ? 0 : i < 4 ? 1 : i < 6 ? 2 : i);
  Eigen::MatrixXd A = WithSpectrum(values, 7);
  const Eigen::MatrixXd original = A;
  const int K = 20;
  auto r = LowestSymmetricEigenpairs(A, K, true, nullptr);
  ASSERT_TRUE(r.ok()) << r.status();
  std::sort(values.data(), values.data() + n);
  for (int k = 0; k < K; ++k) EXPECT_NEAR(r->values[k], values[k], 1e-11 * n) << k;
  EXPECT_LT((r->vectors.transpose() * r->vectors - Eigen::MatrixXd::Identity(K, K)).norm(), 1e-12);
  EXPECT_LT((original * r->vectors - r->vectors * r->values.asDiagonal()).norm(), 1e-10 * n);
}

TEST(DenseEigenTest, MatchesEigensSolverOnARandomMatrixReadingOnlyTheLowerTriangle) {
  const int n = 300;
  std::srand(3);
  Eigen::MatrixXd B = Eigen::MatrixXd::Random(n, n);
  const Eigen::MatrixXd A = 0.5 * (B + B.transpose());
  Eigen::MatrixXd lower_only = A;
  lower_only.triangularView<Eigen::StrictlyUpper>().setConstant(1e300);  // must be ignored
  auto r = LowestSymmetricEigenpairs(lower_only, n, true, nullptr);
  ASSERT_TRUE(r.ok()) << r.status();
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> reference(A);
  EXPECT_LT((r->values - reference.eigenvalues()).cwiseAbs().maxCoeff(), 1e-12 * n);
  EXPECT_LT((A * r->vectors - r->vectors * r->values.asDiagonal()).norm(), 1e-11 * n);
  // Values only: same numbers, no vectors.
  Eigen::MatrixXd again = A;
  auto v = LowestSymmetricEigenpairs(again, 5, false, nullptr);
  ASSERT_TRUE(v.ok());
  EXPECT_EQ(v->vectors.size(), 0);
  EXPECT_LT((v->values - reference.eigenvalues().head(5)).cwiseAbs().maxCoeff(), 1e-12 * n);
}

TEST(DenseEigenTest, GeneralizedProblemGivesMOrthonormalVectors) {
  const int n = 200;
  std::srand(11);
  Eigen::MatrixXd B = Eigen::MatrixXd::Random(n, n);
  const Eigen::MatrixXd S = B * B.transpose();  // semi-definite-ish, with small eigenvalues
  const Eigen::VectorXd m = Eigen::VectorXd::Random(n).cwiseAbs().array() + 0.1;
  Eigen::MatrixXd M = m.asDiagonal();
  M.diagonal(1).setConstant(0.01);
  M.diagonal(-1).setConstant(0.01);
  const int K = 15;
  auto r = LowestGeneralizedEigenpairs(S, M, K, true, nullptr);
  ASSERT_TRUE(r.ok()) << r.status();
  Eigen::GeneralizedSelfAdjointEigenSolver<Eigen::MatrixXd> reference(S, M);
  for (int k = 0; k < K; ++k) {
    EXPECT_NEAR(r->values[k], reference.eigenvalues()[k],
                1e-10 * std::abs(reference.eigenvalues()[n - 1]));
  }
  const Eigen::MatrixXd& Y = r->vectors;
  EXPECT_LT((Y.transpose() * M * Y - Eigen::MatrixXd::Identity(K, K)).norm(), 1e-10);
  EXPECT_LT((S * Y - M * Y * r->values.asDiagonal()).norm() / S.norm(), 1e-11);
}

TEST(DenseEigenTest, SmallAndDegenerateInputs) {
  Eigen::MatrixXd one(1, 1);
  one << -4.5;
  auto r = LowestSymmetricEigenpairs(one, 1, true, nullptr);
  ASSERT_TRUE(r.ok());
  EXPECT_EQ(r->values[0], -4.5);
  EXPECT_EQ(std::abs(r->vectors(0, 0)), 1.0);
  Eigen::MatrixXd zero = Eigen::MatrixXd::Zero(4, 4);
  r = LowestSymmetricEigenpairs(zero, 2, true, nullptr);
  ASSERT_TRUE(r.ok());
  EXPECT_EQ(r->values, Eigen::VectorXd::Zero(2));
  Eigen::MatrixXd diag = Eigen::Vector3d(3, 1, 2).asDiagonal();
  r = LowestSymmetricEigenpairs(diag, 3, false, nullptr);
  ASSERT_TRUE(r.ok());
  EXPECT_EQ(r->values, Eigen::Vector3d(1, 2, 3));
}

TEST(DenseEigenTest, BadInputIsRejected) {
  Eigen::MatrixXd rect(3, 4);
  rect.setZero();
  EXPECT_THAT(LowestSymmetricEigenpairs(rect, 1, true, nullptr),
              StatusIs(absl::StatusCode::kInvalidArgument));
  Eigen::MatrixXd a = Eigen::MatrixXd::Identity(3, 3);
  EXPECT_THAT(LowestSymmetricEigenpairs(a, 0, true, nullptr),
              StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(LowestSymmetricEigenpairs(a, 4, true, nullptr),
              StatusIs(absl::StatusCode::kInvalidArgument));
  a(2, 0) = std::nan("");
  auto s = LowestSymmetricEigenpairs(a, 1, true, nullptr);
  EXPECT_THAT(s, StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(s.status().message(), HasSubstr("non-finite"));
  const Eigen::MatrixXd I = Eigen::MatrixXd::Identity(3, 3);
  Eigen::MatrixXd indefinite = I;
  indefinite(1, 1) = -1;
  EXPECT_THAT(LowestGeneralizedEigenpairs(I, indefinite, 1, true, nullptr),
              StatusIs(absl::StatusCode::kFailedPrecondition));
}

TEST(DenseEigenTest, CancellationStopsALargeSolveQuickly) {
  const int n = 1200;  // several seconds of work uncancelled
  std::srand(5);
  Eigen::MatrixXd B = Eigen::MatrixXd::Random(n, n);
  const Eigen::MatrixXd S = B + B.transpose();
  const Eigen::MatrixXd M = Eigen::MatrixXd::Identity(n, n);
  std::atomic<bool> cancel{true};
  EXPECT_THAT(LowestGeneralizedEigenpairs(S, M, 10, true, &cancel),
              StatusIs(absl::StatusCode::kCancelled));
  // Cancelled while running: after 50 ms, in whichever phase the solve is, it returns quickly.
  for (int delay_ms : {50, 400}) {
    cancel = false;
    std::chrono::steady_clock::time_point cancelled_at;
    std::thread canceller([&] {
      std::this_thread::sleep_for(std::chrono::milliseconds(delay_ms));
      cancelled_at = std::chrono::steady_clock::now();
      cancel = true;
    });
    auto r = LowestGeneralizedEigenpairs(S, M, n, true, &cancel);
    const auto returned_at = std::chrono::steady_clock::now();
    canceller.join();
    EXPECT_THAT(r, StatusIs(absl::StatusCode::kCancelled)) << delay_ms;
    // Generous for a loaded CI machine; the phases between checks take about a millisecond.
    EXPECT_LT(returned_at - cancelled_at, std::chrono::milliseconds(500)) << delay_ms;
  }
}

}  // namespace
}  // namespace fieldspace
