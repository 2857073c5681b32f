#ifndef FIELDSPACE_CORE_MESH_MESH_IO_H_
#define FIELDSPACE_CORE_MESH_MESH_IO_H_

#include <cstdint>
#include <functional>
#include <string>
#include <string_view>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "core/common/file_util.h"  // ReadFileToString, which ReadMeshFile uses
#include "core/mesh/triangle_mesh.h"

namespace fieldspace {

// Mesh readers for OBJ, OFF and PLY (ascii, binary little- and big-endian) and a binary PLY writer.
//
// The readers return a raw triangle soup (MeshArrays) and check only what they must to parse it:
// syntax, counts, and indices that cannot be represented. What they leave to
// TriangleMesh::Create: vertex indices >= #V (out of range), non-finite coordinates ("nan", "inf"
// in text, NaN/Inf bit patterns in binary PLY are read as such), repeated indices, topology.
// Rejected here (InvalidArgument): negative indices (OBJ: relative indices resolving before the
// first vertex, and index 0), indices that do not fit int32, numbers outside the double range,
// faces with fewer than 3 corners, header counts larger than the data can possibly hold.
// Trailing data after the last declared OFF face / PLY element is ignored. An OBJ without faces
// reads as an empty face list (TriangleMesh::Create rejects an empty mesh).
//
// Memory: allocation is bounded by a constant times the input size; header counts are checked
// against options.max_* (ResourceExhausted) and then against the bytes that follow the header
// (InvalidArgument) before anything is allocated. Parsing is a single linear pass.

enum class MeshFormat : uint8_t { kObj = 0, kOff = 1, kPly = 2 };

struct MeshReadOptions {
  // Polygons with more than 3 corners are fan-triangulated when true, rejected when false.
  bool triangulate_polygons = true;
  // Limits against absurd inputs; exceeding one is ResourceExhausted. max_faces bounds the
  // triangles produced (after fan triangulation).
  int64_t max_vertices = int64_t{1} << 27;
  int64_t max_faces = int64_t{1} << 27;
  // ReadMeshFile only: larger files are ResourceExhausted (checked while reading).
  int64_t max_file_bytes = int64_t{1} << 33;
  // Called before the reader allocates or grows its vertex and triangle arrays, with the bytes
  // they will then hold together (their capacity: up to twice their contents while they grow);
  // a non-OK status ends the read with that status before the allocation. For admitting the
  // parse's memory against a budget (a polygon of n corners becomes n - 2 triangles of 12 bytes,
  // so the arrays may outgrow the text several times). Unset: no check.
  std::function<absl::Status(int64_t bytes)> reserve_memory;
};

struct MeshReadResult {
  MeshArrays arrays;
  int64_t polygons_triangulated = 0;  // input polygons with > 3 corners that were fanned
};

// An upper bound of the bytes TriangleMesh::Create holds at its peak for arrays of `num_vertices`
// vertices and `num_faces` faces, the arrays included (for admitting a read mesh against a memory
// budget): the per-face geometry, the half-edge buckets and the edge tables live at once, about
// 190 bytes a face, plus the vertex remapping. Measured 210 bytes a face (vertices at #F / 2) for a
// 4M-face upload to the daemon, its store write included (bench/RESULTS.md, Session 16).
inline int64_t CreateMeshPeakBytes(int64_t num_vertices, int64_t num_faces) {
  return 200 * num_faces + 64 * num_vertices;
}

// Format from a file name's extension (.obj, .off, .ply, case-insensitive). InvalidArgument for
// any other extension.
absl::StatusOr<MeshFormat> MeshFormatFromPath(std::string_view path);

// Parses a whole file held in memory. InvalidArgument for malformed input (message says what and
// where: "OBJ line 12: face has 2 vertices", "PLY: truncated binary data in element 'face' at item
// 1234"), ResourceExhausted beyond the options' limits.
absl::StatusOr<MeshReadResult> ReadMesh(std::string_view data, MeshFormat format,
                                        const MeshReadOptions& options = {});

// Reads a file (format from its extension) in one go and parses it; error messages start with the
// file's base name instead of the format name. NotFound if it does not exist.
absl::StatusOr<MeshReadResult> ReadMeshFile(const std::string& path,
                                            const MeshReadOptions& options = {});
// The same for a file already opened (format and messages from `path`).
absl::StatusOr<MeshReadResult> ReadMeshFile(ReadableFile file, const std::string& path,
                                            const MeshReadOptions& options = {});

// A per-face scalar stored with the mesh by WritePly (e.g. a field's magnitude for a viewer).
struct FaceProperty {
  std::string name;           // PLY property name: printable ASCII, no spaces, unique
  std::vector<float> values;  // #F values, face order
};

// Writes binary little-endian PLY: `element vertex` with `float x, y, z` (V, #V x 3, rounded to
// float), `element face` with `list uchar int vertex_indices` (F, #F x 3, zero-based) followed by
// one `float` property per entry of face_properties. Writes to a temporary file next to `path`
// and renames it over `path` only after every write succeeded, so readers never see a partial
// file. InvalidArgument for indices outside [0, #V), coordinates that are not finite floats, a
// property with a bad name or not #F values (property values themselves may be anything, NaN
// included); the errno's status (e.g. NotFound for a missing directory) if writing fails.
absl::Status WritePly(const std::string& path, const VertexMatrix& V, const FaceMatrix& F,
                      const std::vector<FaceProperty>& face_properties = {});

}  // namespace fieldspace

#endif  // FIELDSPACE_CORE_MESH_MESH_IO_H_
