#ifndef FIELDSPACE_TESTS_CORE_OPERATORS_OPERATOR_TEST_UTIL_H_
#define FIELDSPACE_TESTS_CORE_OPERATORS_OPERATOR_TEST_UTIL_H_

#include <algorithm>
#include <cmath>
#include <string>
#include <utility>
#include <vector>

#include "Eigen/Core"
#include "Eigen/SparseCore"
#include "absl/status/statusor.h"
#include "core/mesh/mesh_io.h"
#include "core/mesh/shapes.h"
#include "core/mesh/triangle_mesh.h"
#include "gtest/gtest.h"

namespace fieldspace::testing {

inline absl::StatusOr<TriangleMesh> LoadMesh(const std::string& path) {
  absl::StatusOr<MeshReadResult> read = ReadMeshFile(path);
  if (!read.ok()) return read.status();
  return TriangleMesh::Create(std::move(read->arrays));
}

inline TriangleMesh MustCreate(absl::StatusOr<MeshArrays> arrays) {
  EXPECT_TRUE(arrays.ok()) << arrays.status();
  absl::StatusOr<TriangleMesh> mesh = TriangleMesh::Create(*std::move(arrays));
  EXPECT_TRUE(mesh.ok()) << mesh.status();
  return *std::move(mesh);
}

inline MeshArrays Arrays(const std::vector<Eigen::Vector3d>& v,
                         const std::vector<Eigen::Vector3i>& f) {
  MeshArrays a;
  a.vertices.resize(static_cast<int64_t>(v.size()), 3);
  for (size_t i = 0; i < v.size(); ++i) a.vertices.row(i) = v[i];
  a.faces.resize(static_cast<int64_t>(f.size()), 3);
  for (size_t i = 0; i < f.size(); ++i) a.faces.row(i) = f[i];
  return a;
}

// A planar rectangular strip [0, nx] x [0, ny] (z = 0), vertices jittered deterministically,
// each cell split along a varying diagonal; face vertex orders cyclically rotated by f % 3 so the
// frames differ from face to face.
inline MeshArrays PlanarStrip(int nx, int ny) {
  std::vector<Eigen::Vector3d> v;
  for (int j = 0; j <= ny; ++j) {
    for (int i = 0; i <= nx; ++i) {
      const bool inner = i > 0 && i < nx && j > 0 && j < ny;
      const double jx = inner ? 0.2 * std::sin(1.7 * i + 2.3 * j) : 0.0;
      const double jy = inner ? 0.2 * std::cos(2.9 * i - 1.1 * j) : 0.0;
      v.emplace_back(i + jx, j + jy, 0.0);
    }
  }
  auto id = [&](int i, int j) { return j * (nx + 1) + i; };
  std::vector<Eigen::Vector3i> f;
  for (int j = 0; j < ny; ++j) {
    for (int i = 0; i < nx; ++i) {
      std::vector<Eigen::Vector3i> two;
      if ((i + j) % 2 == 0) {
        two = {{id(i, j), id(i + 1, j), id(i + 1, j + 1)},
               {id(i, j), id(i + 1, j + 1), id(i, j + 1)}};
      } else {
        two = {{id(i, j), id(i + 1, j), id(i, j + 1)},
               {id(i + 1, j), id(i + 1, j + 1), id(i, j + 1)}};
      }
      for (Eigen::Vector3i t : two) {
        const int r = static_cast<int>(f.size()) % 3;
        f.emplace_back(t[r], t[(r + 1) % 3], t[(r + 2) % 3]);
      }
    }
  }
  return Arrays(v, f);
}

// max |A_ij - B_ij| over the union of both patterns.
inline double MaxAbsDiff(const Eigen::SparseMatrix<double>& A,
                         const Eigen::SparseMatrix<double>& B) {
  const Eigen::SparseMatrix<double> D = A - B;
  double m = 0.0;
  for (int j = 0; j < D.outerSize(); ++j) {
    for (Eigen::SparseMatrix<double>::InnerIterator it(D, j); it; ++it) {
      m = std::max(m, std::abs(it.value()));
    }
  }
  return m;
}

inline double MaxAbs(const Eigen::SparseMatrix<double>& A) {
  double m = 0.0;
  for (int j = 0; j < A.outerSize(); ++j) {
    for (Eigen::SparseMatrix<double>::InnerIterator it(A, j); it; ++it) {
      m = std::max(m, std::abs(it.value()));
    }
  }
  return m;
}

}  // namespace fieldspace::testing

#endif  // FIELDSPACE_TESTS_CORE_OPERATORS_OPERATOR_TEST_UTIL_H_
