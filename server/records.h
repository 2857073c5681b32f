#ifndef FIELDSPACE_SERVER_RECORDS_H_
#define FIELDSPACE_SERVER_RECORDS_H_

#include <chrono>
#include <cstdint>
#include <string>

#include "core/basis/basis.h"
#include "core/operators/field_type.h"

namespace fieldspace::server {

// Milliseconds since the Unix epoch (the records' created_unix_ms).
inline int64_t NowUnixMs() {
  return std::chrono::duration_cast<std::chrono::milliseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

// What the server knows about a stored mesh without loading it (kept in memory for every mesh;
// persisted in the header of the mesh's store file).

struct MeshRecord {
  std::string id;  // "m-" + 16 hex digits, hash of the canonical vertex/face arrays
  std::string name;
  int32_t num_vertices = 0;
  int32_t num_faces = 0;
  int32_t num_edges = 0;
  int32_t num_components = 0;
  int32_t num_boundary_loops = 0;
  int32_t euler_characteristic = 0;
  int32_t genus = 0;
  double total_area = 0;
  int32_t dropped_unreferenced_vertices = 0;
  int32_t polygons_triangulated = 0;
  int64_t created_unix_ms = 0;
};

// The parameters that identify a basis (everything its id is derived from, except the weights,
// which enter the id through their hash).
struct BasisKey {
  std::string mesh_id;
  FieldType field;
  int32_t dimension = 0;
  double sigma = 40.0;
  int32_t fields_per_region = 0;  // resolved m (never 0 once a request is validated)
  uint64_t seed = 0;
  uint64_t weights_hash = 0;     // 0 for uniform weights
  int32_t coarse_dimension = 0;  // C of a two-level basis (0: one level)
  // Append the kernel of S (BasisOptions::kernel_columns). The registry clears it where the kernel
  // is certainly empty (vector fields on a genus-0 mesh), so that such bases keep their id.
  bool kernel_columns = false;
  // The basis's levels (QualityLevels); kPaper is the one level above, with coarse_dimension.
  BasisQuality quality = BasisQuality::kPaper;
};

// What the server knows about a built basis without loading it.
struct BasisRecord {
  std::string id;  // "b-" + 16 hex digits, hash of the BasisKey
  BasisKey key;
  int32_t columns = 0;  // d actually built
  int32_t num_regions = 0;
  int32_t dofs = 0;  // k
  double radius = 0;
  int64_t nnz = 0;
  double build_seconds = 0;
  int64_t created_unix_ms = 0;
};

}  // namespace fieldspace::server

#endif  // FIELDSPACE_SERVER_RECORDS_H_
