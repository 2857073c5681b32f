#include "tests/testing/fixtures.h"

#include <algorithm>
#include <random>
#include <utility>
#include <vector>

#include "gtest/gtest.h"

namespace fieldspace::testing {

FieldOperator MustBuildOperator(const TriangleMesh& mesh, const FieldType& type) {
  absl::StatusOr<FieldOperator> op = BuildFieldOperator(mesh, type);
  EXPECT_TRUE(op.ok()) << op.status();
  return *std::move(op);
}

Eigen::VectorXd RandomVector(int64_t n, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  Eigen::VectorXd v(n);
  for (int64_t i = 0; i < n; ++i) v[i] = u(rng);
  return v;
}

std::shared_ptr<Basis> RandomBasis(const FieldType& type, int64_t k, int64_t d,
                                   int64_t rows_per_column, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<float> value(-1.0f, 1.0f);
  std::vector<Eigen::Triplet<float>> triplets;
  for (int64_t j = 0; j < d; ++j) {
    for (int64_t t = 0; t < rows_per_column; ++t) {
      triplets.emplace_back(static_cast<int>(rng() % k), static_cast<int>(j), value(rng));
    }
  }
  for (int64_t i = 0; i < k; ++i) {
    triplets.emplace_back(static_cast<int>(i), static_cast<int>(rng() % d), value(rng));
  }
  auto basis = std::make_shared<Basis>();
  basis->type = type;
  basis->params.dimension = static_cast<int32_t>(d);
  basis->U.resize(k, d);
  basis->U.setFromTriplets(triplets.begin(), triplets.end());
  basis->U.makeCompressed();
  return basis;
}

std::shared_ptr<Basis> IdentityBasis(const FieldType& type, int64_t k) {
  auto basis = std::make_shared<Basis>();
  basis->type = type;
  basis->params.dimension = static_cast<int32_t>(k);
  basis->U.resize(k, k);
  basis->U.setIdentity();
  basis->U.makeCompressed();
  return basis;
}

Eigen::MatrixXd DenseU(const Basis& basis) { return Eigen::MatrixXd(basis.U.cast<double>()); }

Eigen::SparseMatrix<double> ColumnMajor(const Basis& basis) {
  Eigen::SparseMatrix<double> U = basis.U.cast<double>();
  U.makeCompressed();
  return U;
}

Eigen::VectorXd DenseColumn(const Eigen::SparseMatrix<double>& U, int32_t j) {
  return Eigen::VectorXd(U.col(j));
}

double MaxAbs(const Eigen::SparseMatrix<double>& A) {
  double m = 0.0;
  for (int j = 0; j < A.outerSize(); ++j) {
    for (Eigen::SparseMatrix<double>::InnerIterator it(A, j); it; ++it) {
      m = std::max(m, std::abs(it.value()));
    }
  }
  return m;
}

double MaxAbsDiff(const Eigen::SparseMatrix<double>& A, const Eigen::SparseMatrix<double>& B) {
  return MaxAbs(A - B);
}

double RelativeDifference(const Eigen::MatrixXd& a, const Eigen::MatrixXd& b) {
  const double scale = std::max(a.norm(), b.norm());
  return scale == 0 ? 0.0 : (a - b).norm() / scale;
}

Eigen::SparseMatrix<double> GridLaplacian(int n, double diagonal) {
  std::vector<Eigen::Triplet<double>> t;
  auto id = [n](int i, int j) { return j * n + i; };
  for (int j = 0; j < n; ++j) {
    for (int i = 0; i < n; ++i) {
      t.emplace_back(id(i, j), id(i, j), diagonal);
      auto link = [&](int a, int b) {
        t.emplace_back(a, a, 1.0);
        t.emplace_back(b, b, 1.0);
        t.emplace_back(a, b, -1.0);
        t.emplace_back(b, a, -1.0);
      };
      if (i + 1 < n) link(id(i, j), id(i + 1, j));
      if (j + 1 < n) link(id(i, j), id(i, j + 1));
    }
  }
  Eigen::SparseMatrix<double> A(n * n, n * n);
  A.setFromTriplets(t.begin(), t.end());
  return A;
}

}  // namespace fieldspace::testing
