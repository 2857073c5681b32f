#ifndef FIELDSPACE_SERVER_FIELD_ANSWERS_H_
#define FIELDSPACE_SERVER_FIELD_ANSWERS_H_

// What responses carry about a field given by its coefficients: its lifted values (through the
// basis's LiftPlan, encoded as float) and its singularities. Solve, Smooth, Align, Lift,
// Singularities and Design answer with these.

#include <cstdint>

#include "Eigen/Core"
#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/types/span.h"
#include "core/operators/conversions.h"
#include "fieldspace/v1/fieldspace.pb.h"
#include "server/served_basis.h"

namespace fieldspace::server {

namespace v1 = ::fieldspace::v1;

// InvalidArgument unless `basis` has singularities (vector and n-field bases, not tensor bases).
absl::Status CheckHasSingularities(const ServedBasis& basis);

// The singularities of the field `dofs` (all faces) of `basis` (vector or n-field), as the
// Singularities RPC answers them; InvalidArgument for tensor bases.
absl::Status SingularitiesToProto(const ServedBasis& basis, const Eigen::VectorXd& dofs,
                                  double zero_tolerance, v1::SingularitiesResponse* out);

// Appends the DOFs of `faces` (faces.size() * dofs_per_face, in face order) to `out` in
// `encoding` (InvalidArgument when a value overflows float).
absl::Status EncodeDofs(const ServedBasis& basis, absl::Span<const int32_t> faces,
                        absl::Span<const double> dofs, FieldEncoding encoding,
                        google::protobuf::RepeatedField<float>* out);

// Lifts `x` at `faces` through the basis's LiftPlan and appends the values in `encoding` to `out`.
absl::Status LiftToValues(const ServedBasis& basis, const Eigen::VectorXd& x,
                          absl::Span<const int32_t> faces, FieldEncoding encoding,
                          google::protobuf::RepeatedField<float>* out);

// The same for all faces: one parallel pass of the LiftPlan over every row of U. `dofs`
// (optional) receives the lifted field, for a caller that needs it too (singularities).
absl::Status LiftAllToValues(const ServedBasis& basis, const Eigen::VectorXd& x,
                             FieldEncoding encoding, google::protobuf::RepeatedField<float>* out,
                             Eigen::VectorXd* dofs = nullptr);

// The lifted field of a response on all faces in `encoding`: ResourceExhausted when it would not
// fit in `message_room` bytes (the caller should stream it with Lift instead).
absl::Status CheckFieldFits(const ServedBasis& basis, FieldEncoding encoding, int64_t message_room);

// The tail of Solve, Smooth and Align: the field with coefficients `x`, lifted once, answered as
// `field` values in `encoding` (when `field` is not null) and as `singularities` (when not null).
// Returns the milliseconds spent lifting and encoding the values.
absl::StatusOr<double> AnswerField(const ServedBasis& basis, const Eigen::VectorXd& x,
                                   FieldEncoding encoding, v1::FieldValues* field,
                                   v1::SingularitiesResponse* singularities);

}  // namespace fieldspace::server

#endif  // FIELDSPACE_SERVER_FIELD_ANSWERS_H_
