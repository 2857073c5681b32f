#ifndef FIELDSPACE_SERVER_DESIGN_TOOLS_CONVERT_H_
#define FIELDSPACE_SERVER_DESIGN_TOOLS_CONVERT_H_

// The designer's tools of the wire (Stroke, PlaceSingularity, AlignBoundary, AlignFeatures) to
// core constraint groups (core/subspace/design_tools.h), on a served basis's mesh and field type.
// Every error is InvalidArgument naming `what` (the request part), except FailedPrecondition
// for a tool the mesh cannot take (boundary alignment on a closed mesh, no sharp edge).

#include <cstdint>
#include <vector>

#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"
#include "core/subspace/problem.h"
#include "fieldspace/v1/fieldspace.pb.h"
#include "server/served_basis.h"

namespace fieldspace::server {

// The constraints of one tool.
absl::StatusOr<std::vector<FieldConstraint>> ConstraintGroupFromProto(
    const ServedBasis& basis, const fieldspace::v1::ConstraintGroup& group, absl::string_view what);

// A DesignRequest's tool edit (add_stroke, place_singularity, align_boundary, align_features) as
// a group id and its constraints; InvalidArgument for any other edit.
struct ToolEdit {
  int64_t id = 0;
  std::vector<FieldConstraint> constraints;
};
absl::StatusOr<ToolEdit> ToolEditFromProto(const ServedBasis& basis,
                                           const fieldspace::v1::DesignRequest& request);

// The group id of a tool edit (0 for any other edit).
int64_t ToolEditId(const fieldspace::v1::DesignRequest& request);

// Appends the constraints of every group to `out` ("constraint_groups i" in messages).
absl::Status AppendConstraintGroups(
    const ServedBasis& basis,
    const google::protobuf::RepeatedPtrField<fieldspace::v1::ConstraintGroup>& groups,
    std::vector<FieldConstraint>* out);

}  // namespace fieldspace::server

#endif  // FIELDSPACE_SERVER_DESIGN_TOOLS_CONVERT_H_
