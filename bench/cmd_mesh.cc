// `fieldspace-bench mesh FILE`: reads and validates a mesh, prints its statistics as JSON.
#include <cstdio>
#include <string>

#include "absl/status/status.h"
#include "bench/bench_util.h"
#include "bench/commands.h"
#include "core/mesh/mesh_io.h"
#include "core/mesh/triangle_mesh.h"

namespace fieldspace::bench {

int ReportError(const absl::Status& status) {
  std::string message(status.message());
  for (char& c : message) {
    if (c == '\n' || c == '\r') c = ' ';
  }
  std::fprintf(stderr, "error: %s: %s\n", absl::StatusCodeToString(status.code()).c_str(),
               message.c_str());
  switch (status.code()) {
    case absl::StatusCode::kInvalidArgument:
    case absl::StatusCode::kNotFound:
    case absl::StatusCode::kOutOfRange:
    case absl::StatusCode::kFailedPrecondition:
    case absl::StatusCode::kResourceExhausted:
    case absl::StatusCode::kDataLoss:
    case absl::StatusCode::kAlreadyExists:
    case absl::StatusCode::kPermissionDenied:
      return 2;
    default:
      return 1;
  }
}

int RunMesh(const Args& args) {
  auto read = ReadMeshFile(args.positional()[0]);
  if (!read.ok()) return ReportError(read.status());
  auto mesh = TriangleMesh::Create(std::move(read->arrays));
  if (!mesh.ok()) return ReportError(mesh.status());
  JsonWriter json;
  json.BeginObject()
      .Int("vertices", mesh->num_vertices())
      .Int("faces", mesh->num_faces())
      .Int("edges", mesh->num_edges())
      .Int("boundary_loops", static_cast<int64_t>(mesh->boundary_loops().size()))
      .Int("components", mesh->num_components())
      .Int("euler_characteristic", mesh->euler_characteristic())
      .Int("genus", mesh->genus())
      .Double("area", mesh->total_area())
      .Bool("manifold", true)
      .Int("dropped_unreferenced_vertices", mesh->dropped_unreferenced_vertices())
      .EndObject();
  std::printf("%s\n", json.str().c_str());
  return 0;
}

}  // namespace fieldspace::bench
