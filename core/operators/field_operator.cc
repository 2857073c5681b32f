#include "core/operators/field_operator.h"

#include "absl/strings/str_format.h"
#include "core/common/status_macros.h"
#include "core/operators/nfield_laplacian.h"
#include "core/operators/tensor_laplacian.h"
#include "core/operators/vector_laplacian.h"
#include "tbb/blocked_range.h"
#include "tbb/parallel_for.h"

namespace fieldspace {

absl::Status ValidateOperatorShape(const FieldOperator& op) {
  const int64_t k = op.dofs();
  if (k > 0 && !op.has_stiffness()) {
    return absl::InvalidArgumentError(
        "operator: S is not assembled (BuildFieldOperator, or AssembleStiffness)");
  }
  if (k == 0 || op.stiffness.rows() != k || op.stiffness.cols() != k ||
      k % op.type.dofs_per_face() != 0) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "operator: stiffness %d x %d does not match mass of %d entries (%d per face)",
        op.stiffness.rows(), op.stiffness.cols(), k, op.type.dofs_per_face()));
  }
  return absl::OkStatus();
}

Eigen::VectorXd BuildFaceMass(const TriangleMesh& mesh, int32_t dofs_per_face) {
  const int32_t nf = mesh.num_faces();
  Eigen::VectorXd mass(static_cast<Eigen::Index>(dofs_per_face) * nf);
  const Eigen::VectorXd& area = mesh.face_areas();
  tbb::parallel_for(tbb::blocked_range<int32_t>(0, nf, 16384),
                    [&](const tbb::blocked_range<int32_t>& r) {
                      for (int32_t f = r.begin(); f != r.end(); ++f) {
                        for (int32_t c = 0; c < dofs_per_face; ++c) {
                          mass[static_cast<Eigen::Index>(dofs_per_face) * f + c] = area[f];
                        }
                      }
                    });
  return mass;
}

absl::StatusOr<FieldOperator> BuildFieldOperatorWithoutStiffness(const TriangleMesh& mesh,
                                                                 const FieldType& type) {
  RETURN_IF_ERROR(type.Validate());
  absl::StatusOr<FieldOperator> op(absl::in_place);
  op->type = type;
  op->mass = BuildFaceMass(mesh, type.dofs_per_face());
  return op;
}

absl::Status AssembleStiffness(const TriangleMesh& mesh, FieldOperator* op) {
  const FieldType& type = op->type;
  RETURN_IF_ERROR(type.Validate());
  const int64_t k = static_cast<int64_t>(type.dofs_per_face()) * mesh.num_faces();
  if (op->dofs() != k) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "operator: mass of %d entries does not match the mesh (%d DOFs)", op->dofs(), k));
  }
  // Initialized from prvalues only (guaranteed elision): assigning would deep-copy.
  absl::StatusOr<Eigen::SparseMatrix<double>> stiffness =
      [&]() -> absl::StatusOr<Eigen::SparseMatrix<double>> {
    switch (type.kind) {
      case FieldKind::kVector:
        return BuildVectorHodgeStiffness(mesh);
      case FieldKind::kNField:
        return BuildNFieldStiffness(mesh, type.n);
      case FieldKind::kTensor:
        return BuildTensorStiffness(mesh);
    }
    return absl::InvalidArgumentError("unknown field kind");
  }();
  if (!stiffness.ok()) return stiffness.status();
  // Swapped in, never copied: Eigen sparse matrices have no move operations.
  op->stiffness.swap(*stiffness);
  return absl::OkStatus();
}

absl::StatusOr<FieldOperator> BuildFieldOperator(const TriangleMesh& mesh, const FieldType& type) {
  absl::StatusOr<FieldOperator> op = BuildFieldOperatorWithoutStiffness(mesh, type);
  if (!op.ok()) return op;
  RETURN_IF_ERROR(AssembleStiffness(mesh, &*op));
  return op;
}

}  // namespace fieldspace
