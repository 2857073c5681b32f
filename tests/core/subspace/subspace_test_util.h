#ifndef FIELDSPACE_TESTS_CORE_SUBSPACE_SUBSPACE_TEST_UTIL_H_
#define FIELDSPACE_TESTS_CORE_SUBSPACE_SUBSPACE_TEST_UTIL_H_

// Fixtures shared by the subspace tests: small meshes and operators built in code, and bases U
// built in the test (random sparse, identity, global eigenbasis) so that the checks do not depend
// on the quality of the local basis construction.

#include <cstdint>
#include <memory>
#include <random>
#include <vector>

#include "Eigen/Core"
#include "Eigen/SparseCore"
#include "core/basis/basis.h"
#include "core/mesh/shapes.h"
#include "core/mesh/triangle_mesh.h"
#include "core/operators/field_operator.h"
#include "gtest/gtest.h"

namespace fieldspace::testing {

inline TriangleMesh IcosphereMesh(int32_t subdivisions) {
  auto arrays = MakeIcosphere(subdivisions);
  EXPECT_TRUE(arrays.ok()) << arrays.status();
  auto mesh = TriangleMesh::Create(*std::move(arrays));
  EXPECT_TRUE(mesh.ok()) << mesh.status();
  return *std::move(mesh);
}

inline TriangleMesh TorusMesh(int32_t major, int32_t minor) {
  auto arrays = MakeTorus(1.0, 0.4, major, minor);
  EXPECT_TRUE(arrays.ok()) << arrays.status();
  auto mesh = TriangleMesh::Create(*std::move(arrays));
  EXPECT_TRUE(mesh.ok()) << mesh.status();
  return *std::move(mesh);
}

inline FieldOperator MakeOperator(const TriangleMesh& mesh, const FieldType& type) {
  auto op = BuildFieldOperator(mesh, type);
  EXPECT_TRUE(op.ok()) << op.status();
  return *std::move(op);
}

// A random sparse basis: each column has support on `rows_per_column` random rows (values in
// [-1, 1]); every row gets at least one entry so that no face is unsupported.
inline std::shared_ptr<Basis> RandomBasis(const FieldType& type, int64_t k, int64_t d,
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

inline std::shared_ptr<Basis> IdentityBasis(const FieldType& type, int64_t k) {
  auto basis = std::make_shared<Basis>();
  basis->type = type;
  basis->params.dimension = static_cast<int32_t>(k);
  basis->U.resize(k, k);
  basis->U.setIdentity();
  basis->U.makeCompressed();
  return basis;
}

// Dense double copy of the float basis.
inline Eigen::MatrixXd DenseU(const Basis& basis) {
  return Eigen::MatrixXd(basis.U.cast<double>());
}

inline double RelativeDifference(const Eigen::MatrixXd& a, const Eigen::MatrixXd& b) {
  const double scale = std::max(a.norm(), b.norm());
  return scale == 0 ? 0.0 : (a - b).norm() / scale;
}

}  // namespace fieldspace::testing

#endif  // FIELDSPACE_TESTS_CORE_SUBSPACE_SUBSPACE_TEST_UTIL_H_
