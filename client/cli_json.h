#ifndef FIELDSPACE_CLIENT_CLI_JSON_H_
#define FIELDSPACE_CLIENT_CLI_JSON_H_

// The CLI's JSON output of the wire messages (the README shows these objects).

#include <optional>
#include <string>
#include <vector>

#include "client/json.h"
#include "fieldspace/v1/fieldspace.pb.h"

namespace fieldspace::client::cli {

// "vector", "nfield4", "tensor".
std::string FieldKindName(const fieldspace::v1::FieldType& t);
// "queued", "operator", ..., "done".
const char* PhaseName(fieldspace::v1::BuildPhase phase);

void WriteMeshInfo(JsonWriter& j, const fieldspace::v1::MeshInfo& m);
void WriteBasisInfo(JsonWriter& j, const fieldspace::v1::BasisInfo& b);

template <typename T>
void WriteNumbers(JsonWriter& j, const T& values) {
  j.BeginArray();
  for (double v : values) j.Number(v);
  j.EndArray();
}

// Per-face values as {"face": f, "value": [...]} objects, into an open array (lift --faces,
// design's "watched").
void WriteFaceValues(JsonWriter& j, const fieldspace::v1::FieldValues& values);

// One singular vertex: {"vertex": v, "index": turns, "position": [x, y, z]}.
void WriteSingularity(JsonWriter& j, const fieldspace::v1::Singularity& s);
// The fields of the `singularities` command's object (also the object under "singularities" in
// solve / smooth / align), written into an open object.
void WriteSingularityFields(JsonWriter& j, const fieldspace::v1::SingularitiesResponse& r);

// The end of a solution's object as solve, smooth and align print it: "out" (when written), the
// "singularities" object (when the answer has one) and "coefficients"; closes the object.
void EndSolution(JsonWriter& j, const std::optional<std::string>& out,
                 const fieldspace::v1::SingularitiesResponse* singularities,
                 const std::vector<double>& coefficients);

}  // namespace fieldspace::client::cli

#endif  // FIELDSPACE_CLIENT_CLI_JSON_H_
