#ifndef FIELDSPACE_BENCH_CMD_OPERATOR_H_
#define FIELDSPACE_BENCH_CMD_OPERATOR_H_

// Helpers shared by the operator and spectrum subcommands (defined in cmd_operator.cc).

#include <string>

#include "absl/status/statusor.h"
#include "bench/bench_util.h"
#include "core/mesh/triangle_mesh.h"
#include "core/operators/field_type.h"

namespace fieldspace::bench {

// --field vector|nfield|tensor and --n (read for n-fields only) as a FieldType.
absl::StatusOr<FieldType> FieldTypeFromArgs(const Args& args);

// ReadMeshFile + TriangleMesh::Create.
absl::StatusOr<TriangleMesh> LoadBenchMesh(const std::string& path);

}  // namespace fieldspace::bench

#endif  // FIELDSPACE_BENCH_CMD_OPERATOR_H_
