#ifndef FIELDSPACE_CORE_OPERATORS_FIELD_OPERATOR_H_
#define FIELDSPACE_CORE_OPERATORS_FIELD_OPERATOR_H_

#include <utility>

#include "Eigen/Core"
#include "Eigen/SparseCore"
#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "core/mesh/triangle_mesh.h"
#include "core/operators/field_type.h"

namespace fieldspace {

// A Laplace operator on per-face fields of one FieldType: stiffness S and diagonal mass M.
// S may be left unassembled (0 x 0, BuildFieldOperatorWithoutStiffness) where a step does not
// read it: the operator then stands for BuildFieldOperator(mesh, type)'s on its mesh. Only the
// steps that say so accept it (BuildBasis for vector fields, ComputeKernelFields); the others
// reject it (ValidateOperatorShape).
struct FieldOperator {
  FieldType type;
  // k x k, k = dofs_per_face * #F, DOF order of docs/conventions.md (DOF layout). Sparse,
  // symmetric, positive semi-definite; column-major with both triangles stored.
  Eigen::SparseMatrix<double> stiffness;
  // k: the diagonal of M, the area of the DOF's face (positive).
  Eigen::VectorXd mass;

  int64_t dofs() const { return mass.size(); }
  // False while S is unassembled (0 x 0) and the operator is the mesh's own.
  bool has_stiffness() const { return stiffness.rows() != 0 || stiffness.cols() != 0; }

  FieldOperator() = default;
  FieldOperator(const FieldOperator&) = default;
  FieldOperator& operator=(const FieldOperator&) = default;
  // Eigen 3.4's SparseMatrix has no move operations (a "move" deep-copies hundreds of MB on
  // large meshes, e.g. every time a StatusOr<FieldOperator> is returned); swap instead.
  FieldOperator(FieldOperator&& other) noexcept : type(other.type), mass(std::move(other.mass)) {
    stiffness.swap(other.stiffness);
  }
  FieldOperator& operator=(FieldOperator&& other) noexcept {
    type = other.type;
    stiffness.swap(other.stiffness);
    mass = std::move(other.mass);
    return *this;
  }
};

// Assembles S and M for `type` on `mesh` (docs/conventions.md, Operators): the vector Hodge
// Laplacian (eq. 1), the n-field connection Laplacian, or the (1,1)-tensor Laplacian (eqs. 2,
// 14-20).
// O(#F) time and memory, assembled in parallel.
// InvalidArgument for an invalid type (FieldType::Validate), ResourceExhausted when S would need
// more than 2^31 nonzeros.
absl::StatusOr<FieldOperator> BuildFieldOperator(const TriangleMesh& mesh, const FieldType& type);

// M only, S unassembled (has_stiffness() false): for a basis build that does not read S
// (BuildReadsStiffness), which then runs without S's memory (867 MB on 1.38M faces for vector
// fields); AssembleStiffness adds it afterwards. InvalidArgument for an invalid type.
absl::StatusOr<FieldOperator> BuildFieldOperatorWithoutStiffness(const TriangleMesh& mesh,
                                                                 const FieldType& type);

// Assembles S of op->type on `mesh` into `op` (replacing any S it has): BuildFieldOperator is
// BuildFieldOperatorWithoutStiffness followed by this. InvalidArgument unless op->mass has the
// mesh's DOF count; ResourceExhausted as BuildFieldOperator.
absl::Status AssembleStiffness(const TriangleMesh& mesh, FieldOperator* op);

// InvalidArgument unless `op` is non-empty, its stiffness is assembled and k x k for k = op.dofs(),
// and k is a whole number of faces (a multiple of op.type.dofs_per_face()).
absl::Status ValidateOperatorShape(const FieldOperator& op);

// The diagonal of M: dofs_per_face * #F entries, entry p f + c = area of face f.
Eigen::VectorXd BuildFaceMass(const TriangleMesh& mesh, int32_t dofs_per_face);

}  // namespace fieldspace

#endif  // FIELDSPACE_CORE_OPERATORS_FIELD_OPERATOR_H_
