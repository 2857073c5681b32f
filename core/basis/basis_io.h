#ifndef FIELDSPACE_CORE_BASIS_BASIS_IO_H_
#define FIELDSPACE_CORE_BASIS_BASIS_IO_H_

#include <cstdint>
#include <deque>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "core/basis/basis.h"

namespace fieldspace {

// Binary basis file, format version 1 (little-endian):
//   preamble, 32 bytes: magic "FSBASIS\0", u32 version, u32 byte-order mark 0x01020304,
//     u64 header size, u32 CRC-32C of the header, u32 CRC-32C of the preamble's first 28 bytes;
//   header: field type, parameters, radius, sizes (k, d, nnz(U), regions, kernel columns,
//     weights), timings and stats, the caller's mesh id (e.g. a content hash of the mesh). The
//     kernel column count (Basis::kernel_columns) sits in a slot that files written before it
//     existed hold as 0, so they load unchanged, as bases without kernel columns;
//   sections, in this order, each "u32 tag, u32 0, u64 payload bytes, payload, u32 CRC-32C of the
//     payload": sample faces (int32 x regions), local eigenvalues (float64 x d), adaptivity
//     weights (float64 x #weights), U's CSR row pointers (int32 x (k + 1)), column indices
//     (int32 x nnz), values (float32 x nnz).
// Loading checks the magic, version, byte order, every checksum, that the file has exactly the
// size the header implies (before allocating anything), and U's CSR structure; any failure is
// DataLoss with the reason. A checksum per section detects any changed byte.

struct LoadedBasis {
  std::string mesh_id;
  Basis basis;
};

// Header-only view of a basis file (cheap: reads the preamble and header).
struct BasisFileInfo {
  std::string mesh_id;
  FieldType type;
  BasisParams params;  // face_weights left empty; see num_weights
  int64_t num_weights = 0;
  int64_t rows = 0;  // k
  int64_t nnz = 0;   // nonzeros of U
  int32_t num_regions = 0;
  int32_t kernel_columns = 0;
  int64_t file_bytes = 0;
};

// Writes `basis` to `path` atomically: a temporary file in the same folder, fsync, rename over
// `path`, fsync of the folder. Errors from the file system keep their errno meaning (NotFound for
// a missing folder, PermissionDenied, ...).
absl::Status SaveBasisFile(const std::string& path, const Basis& basis, std::string_view mesh_id);

// NotFound when `path` does not exist; DataLoss for anything damaged, truncated or foreign.
absl::StatusOr<LoadedBasis> LoadBasisFile(const std::string& path);
absl::StatusOr<BasisFileInfo> ReadBasisFileInfo(const std::string& path);

// The same format in memory.
absl::StatusOr<std::string> EncodeBasis(const Basis& basis, std::string_view mesh_id);
// The same bytes as pieces to be written one after another (a daemon's store takes them): the
// small ones (preamble, header, section heads, checksums) held in `*storage`, the arrays
// referenced where they are, so that no copy of U (8 bytes a nonzero) is made to save it.
// `basis` and `*storage` must outlive the pieces. (A U that is not compressed is encoded into
// `*storage` whole.)
absl::StatusOr<std::vector<std::string_view>> EncodeBasisPieces(const Basis& basis,
                                                                std::string_view mesh_id,
                                                                std::deque<std::string>* storage);
absl::StatusOr<LoadedBasis> DecodeBasis(std::string_view bytes);

// Where DecodeBasisFrom reads a basis's bytes. It reads them once, in order, each read starting
// where the previous one ended (so a source may checksum them as they pass), straight into the
// basis's arrays.
class BasisByteSource {
 public:
  virtual ~BasisByteSource() = default;
  virtual uint64_t size() const = 0;
  // Exactly `size` bytes at `offset` (the caller has checked the range).
  virtual absl::Status ReadAt(uint64_t offset, void* dst, size_t size) = 0;
};
// The format from `src`, as DecodeBasis: no copy of the bytes beside the basis.
absl::StatusOr<LoadedBasis> DecodeBasisFrom(BasisByteSource& src);

// Where DecodeBasisFrom can send U's CSR arrays instead of keeping them: a daemon builds its
// face-major copy of U as the file streams by (LiftPlan::StreamBuilder) and never holds U's CSR
// arrays. Everything a sink gets has passed the checks of a loaded U (see above): the row
// pointers before it gets any column, each column before it gets any value. It is called from
// the decoding thread, in file order.
class BasisRowsSink {
 public:
  virtual ~BasisRowsSink() = default;
  // First: U's size (rows a multiple of dofs_per_face) and its row pointers.
  virtual void Begin(int64_t rows, int64_t cols, int32_t dofs_per_face,
                     const std::vector<int32_t>& row_pointers) = 0;
  // Then U's column indices, in pieces of any size, in order; then its values likewise.
  virtual void AddColumns(const int32_t* cols, int64_t n) = 0;
  virtual void AddValues(const float* vals, int64_t n) = 0;
};
// The same, U's arrays sent to `rows` as they are read: the basis's U then has its k x d
// dimensions and no nonzeros. After an error the sink may have got part of U.
absl::StatusOr<LoadedBasis> DecodeBasisFrom(BasisByteSource& src, BasisRowsSink& rows);
absl::StatusOr<LoadedBasis> DecodeBasis(std::string_view bytes, BasisRowsSink& rows);

}  // namespace fieldspace

#endif  // FIELDSPACE_CORE_BASIS_BASIS_IO_H_
