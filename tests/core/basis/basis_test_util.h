#ifndef FIELDSPACE_TESTS_CORE_BASIS_BASIS_TEST_UTIL_H_
#define FIELDSPACE_TESTS_CORE_BASIS_BASIS_TEST_UTIL_H_

// Helpers for the basis tests: meshes, and independent re-implementations (dual-graph Dijkstra,
// dense restricted stiffness) that the construction is checked against.

#include <cmath>
#include <cstdint>
#include <limits>
#include <queue>
#include <string>
#include <utility>
#include <vector>

#include "Eigen/Core"
#include "Eigen/SparseCore"
#include "core/basis/basis.h"
#include "core/mesh/mesh_io.h"
#include "core/mesh/shapes.h"
#include "core/mesh/triangle_mesh.h"
#include "core/operators/field_operator.h"
#include "gtest/gtest.h"

namespace fieldspace::testing {

inline TriangleMesh MeshFromArrays(MeshArrays arrays) {
  auto mesh = TriangleMesh::Create(std::move(arrays));
  EXPECT_TRUE(mesh.ok()) << mesh.status();
  return *std::move(mesh);
}

inline TriangleMesh Icosphere(int32_t subdivisions, double radius = 1.0) {
  auto arrays = MakeIcosphere(subdivisions, radius);
  EXPECT_TRUE(arrays.ok()) << arrays.status();
  return MeshFromArrays(*std::move(arrays));
}

inline TriangleMesh LoadMesh(const std::string& path) {
  auto read = ReadMeshFile(path);
  EXPECT_TRUE(read.ok()) << read.status();
  return MeshFromArrays(std::move(read->arrays));
}

// Two disjoint icospheres (radius 1 at the origin, radius `r2` at x = 5).
inline TriangleMesh TwoSpheres(int32_t subdivisions, double r2) {
  auto a = MakeIcosphere(subdivisions, 1.0);
  auto b = MakeIcosphere(subdivisions, r2);
  EXPECT_TRUE(a.ok() && b.ok());
  MeshArrays m;
  const Eigen::Index va = a->vertices.rows(), vb = b->vertices.rows();
  m.vertices.resize(va + vb, 3);
  m.vertices.topRows(va) = a->vertices;
  m.vertices.bottomRows(vb) = b->vertices;
  m.vertices.bottomRows(vb).col(0).array() += 5.0;
  m.faces.resize(a->faces.rows() + b->faces.rows(), 3);
  m.faces.topRows(a->faces.rows()) = a->faces;
  m.faces.bottomRows(b->faces.rows()) = b->faces.array() + static_cast<int32_t>(va);
  return MeshFromArrays(std::move(m));
}

inline FieldOperator Operator(const TriangleMesh& mesh, const FieldType& type) {
  auto op = BuildFieldOperator(mesh, type);
  EXPECT_TRUE(op.ok()) << op.status();
  return *std::move(op);
}

// Dual-graph distances from `source` with a plain Dijkstra written independently of the library:
// arcs between faces sharing an edge, length |b_f - b_g| (w_f + w_g) / 2.
inline std::vector<double> DualDistances(const TriangleMesh& mesh, int32_t source,
                                         const Eigen::VectorXd& weights = {}) {
  const int32_t nf = mesh.num_faces();
  std::vector<double> dist(nf, std::numeric_limits<double>::infinity());
  using Item = std::pair<double, int32_t>;
  std::priority_queue<Item, std::vector<Item>, std::greater<Item>> pq;
  dist[source] = 0;
  pq.push({0, source});
  while (!pq.empty()) {
    auto [d, f] = pq.top();
    pq.pop();
    if (d > dist[f]) continue;
    for (int k = 0; k < 3; ++k) {
      const int32_t g = mesh.face_neighbors()(f, k);
      if (g == kNoFace) continue;
      double len = (mesh.face_barycenters().row(f) - mesh.face_barycenters().row(g)).norm();
      if (weights.size() > 0) len *= 0.5 * (weights[f] + weights[g]);
      if (d + len < dist[g]) {
        dist[g] = d + len;
        pq.push({dist[g], g});
      }
    }
  }
  return dist;
}

// U in column-major double storage, for column access.
inline Eigen::SparseMatrix<double> ColumnMajor(const Basis& basis) {
  Eigen::SparseMatrix<double> U = basis.U.cast<double>();
  U.makeCompressed();
  return U;
}

// Column j of U (column-major copy) as a dense vector (k).
inline Eigen::VectorXd DenseColumn(const Eigen::SparseMatrix<double>& U, int32_t j) {
  return Eigen::VectorXd(U.col(j));
}

// Dense S_bar = V^T S V (eq. 5) on the DOFs of `faces`, straight from the operator.
inline Eigen::MatrixXd DenseRestricted(const FieldOperator& op, const std::vector<int32_t>& faces) {
  const int32_t dpf = op.type.dofs_per_face();
  std::vector<int64_t> dofs;
  for (int32_t f : faces) {
    for (int32_t c = 0; c < dpf; ++c) dofs.push_back(static_cast<int64_t>(dpf) * f + c);
  }
  const Eigen::Index n = static_cast<Eigen::Index>(dofs.size());
  Eigen::MatrixXd S(n, n);
  for (Eigen::Index i = 0; i < n; ++i) {
    for (Eigen::Index j = 0; j < n; ++j) {
      S(i, j) =
          op.stiffness.coeff(dofs[i], dofs[j]) / std::sqrt(op.mass[dofs[i]] * op.mass[dofs[j]]);
    }
  }
  return S;
}

// Faces within dual distance r of the sample of region `region` (independent Dijkstra).
inline std::vector<int32_t> RegionFaces(const TriangleMesh& mesh, const Basis& basis,
                                        int32_t region, const Eigen::VectorXd& weights = {}) {
  const std::vector<double> dist = DualDistances(mesh, basis.sample_faces[region], weights);
  std::vector<int32_t> faces;
  for (int32_t f = 0; f < mesh.num_faces(); ++f) {
    if (dist[f] <= basis.radius) faces.push_back(f);
  }
  return faces;
}

}  // namespace fieldspace::testing

#endif  // FIELDSPACE_TESTS_CORE_BASIS_BASIS_TEST_UTIL_H_
