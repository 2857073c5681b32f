#ifndef FIELDSPACE_CLIENT_FIELD_FILES_H_
#define FIELDSPACE_CLIENT_FIELD_FILES_H_

// The client's file formats (documented in docs/cli.md, "File formats"):
// - field files (text, one face per line; or PLY with face properties for viewers),
// - coefficient files (whitespace-separated numbers, or the JSON that `solve` / `project` print),
// - constraint files (JSON lines, one constraint each),
// - design edit scripts (JSON lines, one edit each).

#include <cstdint>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"
#include "fieldspace/v1/fieldspace.pb.h"
#include "google/protobuf/struct.pb.h"

namespace fieldspace::client {

// A per-face field as the client handles it: `values_per_face` numbers per face, face-major.
struct FieldFile {
  fieldspace::v1::FieldEncoding encoding = fieldspace::v1::FIELD_ENCODING_AMBIENT;
  int32_t values_per_face = 0;
  std::vector<double> values;
  int64_t num_faces() const {
    return values_per_face == 0 ? 0 : static_cast<int64_t>(values.size()) / values_per_face;
  }
};

// Text field file: '#' starts a comment; a comment "# encoding: dof" (or "ambient", the default)
// sets the encoding; every other non-empty line is one face's values, all lines with the same
// count. InvalidArgument (with the line number) for anything else.
absl::StatusOr<FieldFile> ParseFieldText(absl::string_view text);
absl::StatusOr<FieldFile> ReadFieldFile(const std::string& path);

// Writes `field` as text (with an "# encoding:" header) or, for a path ending in .ply, as binary
// PLY with the mesh (V: #V x 3 row-major, F: #F x 3 row-major) and one float face property per
// value: vx vy vz (+ magnitude) for ambient vector and n-fields, txx tyy tzz txy tyz tzx for
// ambient tensors, d0 d1 (d2) for DOFs.
absl::Status WriteFieldText(const std::string& path, const FieldFile& field,
                            const std::string& field_type);
absl::Status WriteFieldPly(const std::string& path, const std::vector<double>& vertices,
                           const std::vector<int32_t>& faces, const FieldFile& field);

// Coefficients: a JSON object with a "coefficients" array (what `solve` and `project` print), a
// JSON array, or whitespace/comma-separated numbers. The eigenfields `eigen --coefficients` prints
// (an array of arrays) need `mode` >= 0 to pick one; a single field needs `mode` < 0.
absl::StatusOr<std::vector<double>> ParseCoefficients(absl::string_view text, int mode = -1);

// One constraint from a JSON object: {"face": F, "vector": [x, y, z]} (ambient; also for
// n-fields: one of the n directions), or "tensor": [xx, yy, zz, xy, yz, zx], or "dofs": [...]
// (DOF encoding); optional "weight" (> 0) and "hard" (bool). `where` prefixes errors.
absl::StatusOr<fieldspace::v1::Constraint> ParseConstraint(const google::protobuf::Struct& object,
                                                           absl::string_view where);
// Constraint file: JSON lines (one object each; blank lines and lines starting with '#' skipped),
// or one JSON array of objects. With `groups`, items that are a designer's tool ({"stroke":
// {...}}, see client/design_tools_json.h) go there as constraint groups.
absl::StatusOr<std::vector<fieldspace::v1::Constraint>> ParseConstraints(
    absl::string_view text, std::vector<fieldspace::v1::ConstraintGroup>* groups = nullptr);

// Edit script line -> DesignRequest (seq not set). Formats: {"add": {"id", "face", "vector" |
// "tensor" | "dofs", "weight"?, "hard"?}}, {"move": {"id", "face", "vector" | ...}},
// {"remove": {"id"}}, {"weights": {"mu_s", "mu_b", "mu_c"}}, {"watch": {"faces": [...],
// "encoding"?: "ambient" | "dof"}}, and the designer's tools of client/design_tools_json.h.
absl::StatusOr<fieldspace::v1::DesignRequest> ParseEdit(absl::string_view line,
                                                        absl::string_view where);

// Reads a whole file. The errno's status ("cannot open PATH: No such file or directory").
absl::StatusOr<std::string> ReadFile(const std::string& path);

}  // namespace fieldspace::client

#endif  // FIELDSPACE_CLIENT_FIELD_FILES_H_
