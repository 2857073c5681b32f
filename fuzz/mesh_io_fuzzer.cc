// Mesh readers (core/mesh/mesh_io.h) and mesh validation, as an upload reaches them: the first
// byte picks the format (OBJ, OFF, PLY, or the raw arrays of MESH_FORMAT_RAW) and whether
// polygons are triangulated; the rest is the file. What parses is validated by
// TriangleMesh::Create, as Registry::AddMesh does.

#include <cstdint>
#include <cstring>
#include <string_view>

#include "core/mesh/mesh_io.h"
#include "core/mesh/triangle_mesh.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace fieldspace;
  if (size < 1) return 0;
  const uint8_t mode = data[0];
  const std::string_view bytes(reinterpret_cast<const char*>(data) + 1, size - 1);
  MeshArrays arrays;
  if (mode % 4 == 3) {
    // Raw: u32 #V, u32 #F, then #V x 3 float64 and #F x 3 int32 (the upload's raw layout, whose
    // sizes come from the header).
    if (bytes.size() < 8) return 0;
    uint32_t nv, nf;
    std::memcpy(&nv, bytes.data(), 4);
    std::memcpy(&nf, bytes.data() + 4, 4);
    const std::string_view body = bytes.substr(8);
    if (body.size() != uint64_t{24} * nv + uint64_t{12} * nf) return 0;
    arrays.vertices.resize(nv, 3);
    arrays.faces.resize(nf, 3);
    // (The upload requires both counts > 0; here empty arrays reach validation too.)
    if (nv > 0) std::memcpy(arrays.vertices.data(), body.data(), uint64_t{24} * nv);
    if (nf > 0)
      std::memcpy(arrays.faces.data(), body.data() + uint64_t{24} * nv, uint64_t{12} * nf);
  } else {
    MeshReadOptions options;
    options.triangulate_polygons = (mode & 0x10) == 0;
    absl::StatusOr<MeshReadResult> read =
        ReadMesh(bytes, static_cast<MeshFormat>(mode % 4), options);
    if (!read.ok()) return 0;
    arrays = std::move(read->arrays);
  }
  absl::StatusOr<TriangleMesh> mesh = TriangleMesh::Create(std::move(arrays));
  if (mesh.ok() && mesh->num_faces() <= 0) __builtin_trap();  // validation admits no empty mesh
  return 0;
}
