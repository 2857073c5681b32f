#ifndef FIELDSPACE_TESTS_CORE_LINALG_LINALG_TEST_UTIL_H_
#define FIELDSPACE_TESTS_CORE_LINALG_LINALG_TEST_UTIL_H_

#include <vector>

#include "Eigen/SparseCore"

namespace fieldspace::testing {

// 5-point Laplacian of an n x n grid (Neumann: degree on the diagonal) plus `diagonal` * I:
// symmetric, positive definite for diagonal > 0, indefinite for diagonal < 0 (beyond -8).
inline Eigen::SparseMatrix<double> GridLaplacian(int n, double diagonal) {
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

#endif  // FIELDSPACE_TESTS_CORE_LINALG_LINALG_TEST_UTIL_H_
