#ifndef FIELDSPACE_CORE_SUBSPACE_PROJECTION_H_
#define FIELDSPACE_CORE_SUBSPACE_PROJECTION_H_

#include <cstdint>

#include "Eigen/Core"
#include "absl/status/statusor.h"
#include "absl/types/span.h"
#include "core/basis/basis.h"
#include "core/common/cancel.h"
#include "core/subspace/reduced_system.h"

namespace fieldspace {

// Moving fields between the full space (k DOFs, ordered as in docs/conventions.md, DOF layout) and
// the subspace (d coefficients of the columns of U). All functions are thread-safe (const inputs
// only) and parallel over rows of U.

struct ProjectionResult {
  Eigen::VectorXd coefficients;  // d: x = argmin ||X - U x||_M (eq. 13)
  double relative_error = 0;     // ||X - U x||_M / ||X||_M (0 when X = 0)
};

// L2 (M-orthogonal) projection of eq. 13: (U^T M U) x = U^T M X. `field`: k values, finite.
// InvalidArgument for a wrong size or non-finite values.
// `cancel` (not owned, may be null) is checked for every block of 4096 rows of U: Cancelled once
// it is true. The same holds for the functions below.
absl::StatusOr<ProjectionResult> Project(const ReducedSystem& system,
                                         const Eigen::Ref<const Eigen::VectorXd>& field,
                                         const CancelFlag* cancel = nullptr);

struct ProjectionBatch {
  Eigen::MatrixXd coefficients;     // d x m
  Eigen::VectorXd relative_errors;  // m
};
// Projects the m columns of `fields` (k x m) in one pass over U.
absl::StatusOr<ProjectionBatch> ProjectMany(const ReducedSystem& system,
                                            const Eigen::Ref<const Eigen::MatrixXd>& fields,
                                            const CancelFlag* cancel = nullptr);

// U^T M X (d x m) for fields X (k x m): the right-hand side of eq. 13 and of data terms
// weighted by M. InvalidArgument for a wrong row count or non-finite values.
absl::StatusOr<Eigen::MatrixXd> MassWeightedProducts(
    const ReducedSystem& system, const Eigen::Ref<const Eigen::MatrixXd>& fields,
    const CancelFlag* cancel = nullptr);

// ||X - U x||_M / ||X||_M for each column (X: k x m fields, x: d x m coefficients), without
// forming U x. 0 for a zero field. InvalidArgument for mismatched sizes.
absl::StatusOr<Eigen::VectorXd> RelativeResiduals(
    const ReducedSystem& system, const Eigen::Ref<const Eigen::MatrixXd>& fields,
    const Eigen::Ref<const Eigen::MatrixXd>& coefficients, const CancelFlag* cancel = nullptr);

// X = U x for all faces: k values. InvalidArgument unless x has d finite entries.
absl::StatusOr<Eigen::VectorXd> Lift(const Basis& basis,
                                     const Eigen::Ref<const Eigen::VectorXd>& coefficients);
// The same into a caller-owned buffer of k doubles (no allocation: for repeated interactive
// lifts). InvalidArgument for a wrong buffer size.
absl::Status LiftInto(const Basis& basis, const Eigen::Ref<const Eigen::VectorXd>& coefficients,
                      absl::Span<double> out);
// The lifted values of the given faces only (any order, repeats allowed): |faces| x
// dofs_per_face values, face-major (face faces[i]'s DOF c at i * dofs_per_face + c).
// InvalidArgument for a face id outside [0, #F) or bad coefficients.
absl::StatusOr<Eigen::VectorXd> LiftFaces(const Basis& basis,
                                          const Eigen::Ref<const Eigen::VectorXd>& coefficients,
                                          absl::Span<const int32_t> faces);
absl::Status LiftFacesInto(const Basis& basis,
                           const Eigen::Ref<const Eigen::VectorXd>& coefficients,
                           absl::Span<const int32_t> faces, absl::Span<double> out);

// The same lifts through the system's LiftPlan (identical results, ~1.6x faster on large
// meshes: prefer these when a ReducedSystem is at hand).
absl::StatusOr<Eigen::VectorXd> Lift(const ReducedSystem& system,
                                     const Eigen::Ref<const Eigen::VectorXd>& coefficients);
absl::Status LiftInto(const ReducedSystem& system,
                      const Eigen::Ref<const Eigen::VectorXd>& coefficients,
                      absl::Span<double> out);
// The whole field narrowed to float in the lift's own pass (the wire's DOF encoding):
// InvalidArgument (kFloatOverflowMessage) when a value overflows float.
inline constexpr char kFloatOverflowMessage[] =
    "the lifted field overflows float (values beyond 3.4e38): the coefficients are too large";
absl::Status LiftIntoFloat(const ReducedSystem& system,
                           const Eigen::Ref<const Eigen::VectorXd>& coefficients,
                           absl::Span<float> out);
absl::StatusOr<Eigen::VectorXd> LiftFaces(const ReducedSystem& system,
                                          const Eigen::Ref<const Eigen::VectorXd>& coefficients,
                                          absl::Span<const int32_t> faces);
absl::Status LiftFacesInto(const ReducedSystem& system,
                           const Eigen::Ref<const Eigen::VectorXd>& coefficients,
                           absl::Span<const int32_t> faces, absl::Span<double> out);

}  // namespace fieldspace

#endif  // FIELDSPACE_CORE_SUBSPACE_PROJECTION_H_
