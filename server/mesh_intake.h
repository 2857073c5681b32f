#ifndef FIELDSPACE_SERVER_MESH_INTAKE_H_
#define FIELDSPACE_SERVER_MESH_INTAKE_H_

#include <cstdint>
#include <string>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "core/mesh/mesh_io.h"
#include "server/records.h"
#include "server/registry.h"
#include "server/work_grant.h"

namespace fieldspace::server {

// Turning a mesh's bytes (an upload, a LoadMesh file) into a stored mesh under the memory budget:
// the text, then the arrays the reader fills beside it (admitted as they grow, since a polygon fan
// makes 12 bytes of triangles of each 2 bytes of text), then TriangleMesh::Create's peak (about
// 200 bytes a face), each admitted into one grant before it is allocated. A refusal is
// ResourceExhausted naming the request, so a hostile text costs at most what the budget allows.
class MeshIntake {
 public:
  // `grant`: what the caller admitted already (an upload's received bytes). `what` names the
  // request in a refusal ("this upload").
  MeshIntake(Registry* registry, std::string what, WorkGrant grant = WorkGrant());

  // The grant holds at least `bytes`, admitting the difference.
  absl::Status HoldAtLeast(int64_t bytes);

  // Sets options->reserve_memory to admit the reader's arrays beside `text_bytes` of text.
  void AdmitArraysOf(MeshReadOptions* options, int64_t text_bytes);

  // Admits Create's peak for `parsed` (the text is gone by now: the grant shrinks or grows to that
  // peak), then adds the mesh to the registry.
  absl::StatusOr<MeshRecord> Add(MeshReadResult parsed, const std::string& name);

 private:
  Registry* const registry_;
  const std::string what_;
  WorkGrant grant_;
};

}  // namespace fieldspace::server

#endif  // FIELDSPACE_SERVER_MESH_INTAKE_H_
