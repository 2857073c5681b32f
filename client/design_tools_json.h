#ifndef FIELDSPACE_CLIENT_DESIGN_TOOLS_JSON_H_
#define FIELDSPACE_CLIENT_DESIGN_TOOLS_JSON_H_

// The designer's tools in the CLI's JSON (a design script's lines, `solve --constraints` files):
//   {"stroke": {"id": 1, "points": [[x, y, z], ...] | [{"face": f, "barycentric": [a, b, c]}, ...],
//               "hard": false, "weight": 1.0, "anisotropy": 1.0}}
//   {"singularity": {"id": 2, "vertex": v | "face": f, "barycentric": [a, b, c],
//                    "index": 0.25, "hard": true, "weight": 1.0}}
//   {"align_boundary": {"id": 3, "mode": "tangent" | "normal", "loops": [0, ...], "hard": true,
//                       "weight": 1.0}}
//   {"align_features": {"id": 4, "angle_degrees": 60, "hard": false, "weight": 1.0}}
// ("id" is required in a design script and ignored by solve), and in a design script
// {"move": {"id": 1, "stroke": {...}}} (any one tool) replaces group 1 as one edit.

#include <string>

#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"
#include "fieldspace/v1/fieldspace.pb.h"
#include "google/protobuf/struct.pb.h"

namespace fieldspace::client {

// Whether `key` names a tool: stroke, singularity, align_boundary, align_features.
bool IsToolKey(absl::string_view key);

// A tool's object (the value of its key) as a constraint group. `where` prefixes errors.
absl::StatusOr<fieldspace::v1::ConstraintGroup> ParseToolGroup(
    absl::string_view key, const google::protobuf::Struct& object, absl::string_view where);

// A design script's tool line ({key: object}) as its DesignRequest edit (add_stroke, ...).
absl::StatusOr<fieldspace::v1::DesignRequest> ParseToolEdit(absl::string_view key,
                                                            const google::protobuf::Struct& object,
                                                            absl::string_view where);

// {"move": {"id": N, <tool key>: {...}}}: true (and the edit) when `object` names a tool.
bool IsToolMove(const google::protobuf::Struct& object);
absl::StatusOr<fieldspace::v1::DesignRequest> ParseToolMove(const google::protobuf::Struct& object,
                                                            absl::string_view where);

// The name of an edit for the CLI's output: add, move, remove, weights, watch, stroke,
// singularity, align_boundary, align_features.
std::string DesignEditKind(const fieldspace::v1::DesignRequest& edit);

}  // namespace fieldspace::client

#endif  // FIELDSPACE_CLIENT_DESIGN_TOOLS_JSON_H_
