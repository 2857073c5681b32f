#ifndef FIELDSPACE_SERVER_PROTO_CONVERT_H_
#define FIELDSPACE_SERVER_PROTO_CONVERT_H_

// The one place where fieldspace.v1 messages become core types and back. Every function checks
// what it reads (sizes, ranges, finiteness) and says what is wrong with InvalidArgument; nothing
// else in the server reads request fields that carry numbers for core.

#include <cstdint>
#include <vector>

#include "Eigen/Core"
#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"
#include "absl/types/span.h"
#include "core/operators/conversions.h"
#include "core/operators/curvature.h"
#include "core/operators/field_type.h"
#include "core/subspace/problem.h"
#include "fieldspace/v1/fieldspace.pb.h"
#include "server/served_basis.h"

namespace fieldspace::server {

namespace v1 = ::fieldspace::v1;

absl::StatusOr<FieldType> FieldTypeFromProto(const v1::FieldType& p);
void FieldTypeToProto(const FieldType& t, v1::FieldType* p);

absl::StatusOr<FieldEncoding> EncodingFromProto(int encoding);
// InvalidArgument for a value the enum does not have.
absl::StatusOr<CurvatureEstimator> EstimatorFromProto(int estimator);
v1::FieldEncoding EncodingToProto(FieldEncoding e);

// InvalidArgument for a value the enum does not name.
absl::StatusOr<BiharmonicForm> BiharmonicFormFromProto(int form);

// The weights of a request; a weight the message leaves out is taken from `defaults` (the
// operation's defaults, or a Design session's current weights).
EnergyWeights WeightsFromProto(const v1::Weights& w, const EnergyWeights& defaults);

// One face's value in `encoding` -> its DOFs in the face frame. `what` names the request part in
// messages ("add id 3", "constraint 7").
absl::StatusOr<Eigen::VectorXd> ConstraintValueFromProto(const ServedBasis& basis, int32_t face,
                                                         absl::Span<const double> value,
                                                         int encoding, absl::string_view what);
absl::StatusOr<FieldConstraint> ConstraintFromProto(const ServedBasis& basis,
                                                    const v1::Constraint& c,
                                                    absl::string_view what);

// d finite coefficients (d = the basis dimension).
absl::StatusOr<Eigen::VectorXd> CoefficientsFromProto(absl::Span<const double> c,
                                                      const ServedBasis& basis);

// A field on all faces (faces empty) -> k DOFs.
absl::StatusOr<Eigen::VectorXd> FieldFromProto(const v1::FieldValues& field,
                                               const ServedBasis& basis);

// InvalidArgument unless every coefficient is finite: huge inputs (e.g. a constraint value of
// 1e308) can overflow a solve, and the answer must then be an error, not infinities with OK.
absl::Status CheckSolutionFinite(const Eigen::VectorXd& x);

}  // namespace fieldspace::server

#endif  // FIELDSPACE_SERVER_PROTO_CONVERT_H_
