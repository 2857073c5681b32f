#include "core/linalg/matrix_market.h"

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tests/testing/matchers.h"

namespace fieldspace {
namespace {

using ::fieldspace::testing::StatusIs;
using SpMat = Eigen::SparseMatrix<double>;
using ::testing::HasSubstr;
using ::testing::StartsWith;

std::string TempPath(const std::string& name) {
  return (std::filesystem::path(::testing::TempDir()) / name).string();
}

std::string ReadAll(const std::string& path) {
  std::ifstream in(path);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

void WriteAll(const std::string& path, const std::string& text) {
  std::ofstream out(path);
  out << text;
}

TEST(MatrixMarketTest, ExactFormat) {
  SpMat A(3, 2);
  A.insert(0, 0) = 0.1;
  A.insert(2, 0) = -3.0;
  A.insert(1, 1) = 1e-300;
  A.makeCompressed();
  const std::string path = TempPath("format.mtx");
  ASSERT_TRUE(WriteMatrixMarket(path, A).ok());
  // 1-based, column-major, %.17g.
  EXPECT_EQ(ReadAll(path),
            "%%MatrixMarket matrix coordinate real general\n"
            "3 2 3\n"
            "1 1 0.10000000000000001\n"
            "3 1 -3\n"
            "2 2 1e-300\n");
  ASSERT_TRUE(WriteMatrixMarketDiagonal(path, Eigen::Vector3d(2.5, 1.0 / 3.0, 7.0)).ok());
  EXPECT_EQ(ReadAll(path),
            "%%MatrixMarket matrix coordinate real general\n"
            "3 3 3\n"
            "1 1 2.5\n"
            "2 2 0.33333333333333331\n"
            "3 3 7\n");
}

TEST(MatrixMarketTest, RoundTripIsBitExactAcrossBatches) {
  // Enough entries for several formatting chunks.
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(-1e3, 1e3);
  std::uniform_int_distribution<int> idx(0, 999);
  std::vector<Eigen::Triplet<double>> t;
  for (int i = 0; i < 200000; ++i)
    t.emplace_back(idx(rng), idx(rng), u(rng) * std::pow(10.0, idx(rng) % 40 - 20));
  SpMat A(1000, 1000);
  A.setFromTriplets(t.begin(), t.end());
  const std::string path = TempPath("roundtrip.mtx");
  ASSERT_TRUE(WriteMatrixMarket(path, A).ok());
  auto B = ReadMatrixMarket(path);
  ASSERT_TRUE(B.ok()) << B.status();
  ASSERT_EQ(B->nonZeros(), A.nonZeros());
  EXPECT_EQ(SpMat(*B - A).norm(), 0.0);
  for (int j = 0; j < A.outerSize(); ++j) {
    SpMat::InnerIterator a(A, j), b(*B, j);
    for (; a && b; ++a, ++b) {
      ASSERT_EQ(a.row(), b.row());
      ASSERT_EQ(a.value(), b.value());
    }
  }
}

TEST(MatrixMarketTest, ReadsSymmetricAndInteger) {
  const std::string path = TempPath("sym.mtx");
  WriteAll(path,
           "%%MatrixMarket matrix coordinate integer symmetric\n% comment\n\n3 3 3\n1 1 4\n3 1 "
           "-2\n2 2 5\n");
  auto A = ReadMatrixMarket(path);
  ASSERT_TRUE(A.ok()) << A.status();
  EXPECT_EQ(A->coeff(0, 2), -2.0);
  EXPECT_EQ(A->coeff(2, 0), -2.0);
  EXPECT_EQ(A->coeff(1, 1), 5.0);
  EXPECT_EQ(A->nonZeros(), 4);
}

TEST(MatrixMarketTest, ReadErrors) {
  EXPECT_THAT(ReadMatrixMarket(TempPath("does_not_exist.mtx")),
              StatusIs(absl::StatusCode::kNotFound));
  const std::string path = TempPath("bad.mtx");
  struct Case {
    const char* text;
    const char* message;
  };
  for (const Case& c : {
           Case{"", "expected '%%MatrixMarket"},
           Case{"%%MatrixMarket matrix array real general\n2 2\n1\n2\n3\n4\n", "expected"},
           Case{"%%MatrixMarket matrix coordinate complex general\n1 1 1\n1 1 1 0\n", "field"},
           Case{"%%MatrixMarket matrix coordinate real hermitian\n1 1 1\n1 1 1\n", "symmetry"},
           Case{"%%MatrixMarket matrix coordinate real general\n2 2\n", "rows cols entries"},
           Case{"%%MatrixMarket matrix coordinate real general\n2 2 1\n3 1 1.0\n", "outside"},
           Case{"%%MatrixMarket matrix coordinate real general\n2 2 2\n1 1 1.0\n", "ends after"},
           Case{"%%MatrixMarket matrix coordinate real general\n2 2 1\n1 1 x\n", ":3:"},
           Case{"%%MatrixMarket matrix coordinate real general\n2 2 1\n1 1 1\n2 2 2\n", "more"},
       }) {
    WriteAll(path, c.text);
    auto r = ReadMatrixMarket(path);
    EXPECT_THAT(r, StatusIs(absl::StatusCode::kInvalidArgument)) << c.text;
    EXPECT_THAT(r.status().message(), HasSubstr(c.message)) << c.text;
  }
}

TEST(MatrixMarketTest, WriteIntoMissingDirectoryIsNotFound) {
  SpMat A(1, 1);
  A.insert(0, 0) = 1;
  const std::string path = TempPath("no_such_dir/x.mtx");
  EXPECT_THAT(WriteMatrixMarket(path, A), StatusIs(absl::StatusCode::kNotFound));
  EXPECT_THAT(WriteMatrixMarketDiagonal(path, Eigen::VectorXd::Ones(2)),
              StatusIs(absl::StatusCode::kNotFound));
}

}  // namespace
}  // namespace fieldspace
