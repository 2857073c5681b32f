#ifndef FIELDSPACE_TESTS_TESTING_REFERENCE_H_
#define FIELDSPACE_TESTS_TESTING_REFERENCE_H_

// Independent re-implementations that the basis construction is checked against: a plain
// dual-graph Dijkstra and the dense restricted stiffness.

#include <cstdint>
#include <vector>

#include "Eigen/Core"
#include "core/basis/basis.h"
#include "core/mesh/triangle_mesh.h"
#include "core/operators/field_operator.h"

namespace fieldspace::testing {

// Dual-graph distances (#F) from face `source`, written independently of the library: arcs
// between faces sharing an edge, length |b_f - b_g| (w_f + w_g) / 2 (w = 1 when `weights` is
// empty).
std::vector<double> DualDistances(const TriangleMesh& mesh, int32_t source,
                                  const Eigen::VectorXd& weights = {});

// Dense S_bar = V^T S V (eq. 5) on the DOFs of `faces`, straight from the operator:
// (dpf |faces|) x (dpf |faces|), symmetric, entries S_ij / sqrt(M_i M_j).
Eigen::MatrixXd DenseRestricted(const FieldOperator& op, const std::vector<int32_t>& faces);

// Faces within dual distance basis.radius of the sample of region `region` (DualDistances).
std::vector<int32_t> RegionFaces(const TriangleMesh& mesh, const Basis& basis, int32_t region,
                                 const Eigen::VectorXd& weights = {});

}  // namespace fieldspace::testing

#endif  // FIELDSPACE_TESTS_TESTING_REFERENCE_H_
