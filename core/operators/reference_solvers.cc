#include "core/operators/reference_solvers.h"

#include <cmath>
#include <utility>
#include <vector>

#include "absl/strings/str_format.h"
#include "core/common/status_macros.h"

namespace fieldspace {
namespace {

using SpMat = Eigen::SparseMatrix<double>;

}  // namespace

absl::StatusOr<EigenResult> ReferenceEigenpairs(const FieldOperator& op,
                                                const EigenOptions& options) {
  RETURN_IF_ERROR(ValidateOperatorShape(op));
  return LowestEigenpairs(op.stiffness, op.mass, options);
}

SpMat BiharmonicMatrix(const FieldOperator& op) {
  const SpMat scaled = op.stiffness * op.mass.cwiseInverse().asDiagonal();
  SpMat B = scaled * op.stiffness;
  // The product sums in an order that depends on the side; mirror the upper triangle so B is
  // exactly symmetric (CHOLMOD reads one triangle; tests compare both).
  SpMat upper = B.triangularView<Eigen::Upper>();
  SpMat strict_upper = B.triangularView<Eigen::StrictlyUpper>();
  SpMat symmetric = upper + SpMat(strict_upper.transpose());
  return symmetric;
}

absl::StatusOr<Eigen::VectorXd> SmoothField(const FieldOperator& op, const Eigen::VectorXd& field,
                                            double lambda, const CholeskyOptions& cholesky) {
  RETURN_IF_ERROR(ValidateOperatorShape(op));
  if (!std::isfinite(lambda) || lambda < 0.0) {
    return absl::InvalidArgumentError(
        absl::StrFormat("smoothing: lambda = %g must be finite and >= 0", lambda));
  }
  if (field.size() != op.dofs()) {
    return absl::InvalidArgumentError(
        absl::StrFormat("smoothing: field has %d entries, expected %d", field.size(), op.dofs()));
  }
  if (!field.allFinite()) return absl::InvalidArgumentError("smoothing: field is not finite");
  if (lambda == 0.0) return field;
  const SpMat scaled = lambda * op.stiffness;
  ASSIGN_OR_RETURN(SparseCholesky factor,
                   SparseCholesky::FactorizeShifted(scaled, 1.0, op.mass, cholesky));
  return factor.Solve(op.mass.cwiseProduct(field));
}

}  // namespace fieldspace
