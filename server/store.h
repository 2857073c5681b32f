#ifndef FIELDSPACE_SERVER_STORE_H_
#define FIELDSPACE_SERVER_STORE_H_

#include <chrono>
#include <cstdint>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "core/basis/basis_io.h"
#include "core/common/file_util.h"
#include "core/mesh/triangle_mesh.h"
#include "server/hash.h"
#include "server/records.h"

namespace fieldspace::server {

struct StoreOptions {
  // Testing only: pause this long in the middle of writing a mesh or basis payload (before the
  // fsync and the rename), so that a crash test can kill the process during a save.
  int32_t save_pause_ms = 0;
  // Several daemons use the store (--shared-store): Open leaves other daemons' temporary files
  // alone unless they are older than `stale_temp_age` (a save in progress keeps writing).
  bool shared = false;
  std::chrono::seconds stale_temp_age{600};
};

// A store file that exists but cannot be used (bad header, checksum mismatch, truncated).
struct DamagedEntry {
  std::string id;  // from the file name
  bool is_basis = false;
  absl::Status status;  // DataLoss with the reason
};

struct StoreContents {
  std::vector<MeshRecord> meshes;
  std::vector<BasisRecord> bases;
  std::vector<DamagedEntry> damaged;
};

// The on-disk store (docs/api.md, Store): DIR/meshes/<id>.fsmesh and DIR/bases/<id>.fsbasis, with
// DIR/bases/<id>.fsreduced beside a basis (its reduced matrices, a cache).
//
// Every file is one container: a 40-byte header (magic, format version, metadata and payload
// lengths, XXH64 of the payload, XXH64 of header + metadata), the metadata (the record), the
// payload. Files are written to a temporary name, fsynced, renamed into place and the directory is
// fsynced, so after a crash a file is either complete or absent. Checksums catch everything else
// (bit rot, truncation, foreign files): such files give DataLoss and are never loaded.
//
// Thread-safe: distinct files never share state; writes of the same id are idempotent (the content
// is a function of the id) and the rename is atomic.
class Store {
 public:
  // Creates DIR (and its subfolders) if needed and removes temporary files left by a crash.
  static absl::StatusOr<std::unique_ptr<Store>> Open(const std::string& dir,
                                                     const StoreOptions& options = {});

  const std::string& dir() const { return dir_; }

  // Reads every file's header and metadata (not the payloads): O(number of files).
  StoreContents Scan() const;

  // Mesh payload: the canonical arrays (V #V x 3 float64, F #F x 3 int32), which must match
  // record.num_vertices / num_faces.
  absl::Status SaveMesh(const MeshRecord& record, const VertexMatrix& V, const FaceMatrix& F) const;
  // NotFound if absent, DataLoss if damaged.
  absl::StatusOr<MeshArrays> LoadMesh(const std::string& id) const;
  // OK if the file of `id` holds exactly V and F (reads and checks the whole payload: a header
  // that Scan found fine says nothing about it). NotFound if absent, DataLoss otherwise.
  absl::Status VerifyMesh(const std::string& id, const VertexMatrix& V, const FaceMatrix& F) const;

  // Basis payload: opaque serialized bytes (see registry.cc), possibly in several pieces that are
  // concatenated. `payload_hash`, if not null, receives the payload's checksum (what SaveReduced
  // ties a reduced-matrices file to).
  absl::Status SaveBasis(const BasisRecord& record, const std::vector<std::string_view>& payload,
                         uint64_t* payload_hash = nullptr) const;
  struct LoadedBasisFile {
    BasisRecord record;
    std::string payload;
    uint64_t payload_hash = 0;  // the payload's checksum (XXH64)
  };
  absl::StatusOr<LoadedBasisFile> LoadBasis(const std::string& id) const;
  // The payload of a basis file, read in order and checksummed on the way, for core's
  // DecodeBasisFrom: the bytes go straight into the basis's arrays, no copy of the payload is
  // held beside them. Finish() after the last read: DataLoss unless every byte was read exactly
  // once, in order, and the checksum matches; otherwise the payload's checksum.
  class BasisPayloadReader final : public BasisByteSource {
   public:
    const BasisRecord& record() const { return record_; }
    // The checksum the file says its payload has (Finish confirms it): what LoadReduced takes
    // before the payload is read.
    uint64_t expected_payload_hash() const { return expected_hash_; }
    uint64_t size() const override { return length_; }
    absl::Status ReadAt(uint64_t offset, void* dst, size_t size) override;
    absl::StatusOr<uint64_t> Finish() const;

   private:
    friend class Store;
    BasisPayloadReader() = default;
    BasisRecord record_;
    std::string path_;
    ReadableFile file_;
    uint64_t start_ = 0;   // of the payload in the file
    uint64_t length_ = 0;  // of the payload
    uint64_t next_ = 0;    // the offset the next read must start at
    uint64_t expected_hash_ = 0;
    Hasher hasher_;
  };
  // NotFound if absent, DataLoss if the header or record is damaged (the payload is checked as
  // it is read).
  absl::StatusOr<std::unique_ptr<BasisPayloadReader>> OpenBasisPayload(const std::string& id) const;

  // The reduced matrices of a stored basis (core's EncodeReducedMatrices):
  // DIR/bases/<id>.fsreduced, a cache beside the basis file that spares a basis loaded again the
  // product pass over U. Its metadata holds the id and the basis payload's checksum it was computed
  // from, so a basis file replaced since (another build of the id) makes it stale. Same container,
  // atomic write and checksums as the other files; Scan ignores these files, DeleteBasis removes
  // them.
  absl::Status SaveReduced(const std::string& id, uint64_t basis_payload_hash,
                           std::string_view payload) const;
  // NotFound if absent; DataLoss if damaged; FailedPrecondition if computed from another basis
  // file (a stale cache).
  absl::StatusOr<std::string> LoadReduced(const std::string& id, uint64_t basis_payload_hash) const;

  // The record of one file (header and metadata only): NotFound if absent, DataLoss if damaged.
  // For lookups on a miss in a shared store.
  absl::StatusOr<MeshRecord> ReadMeshRecord(const std::string& id) const;
  absl::StatusOr<BasisRecord> ReadBasisRecord(const std::string& id) const;
  // Whether the file exists (one stat).
  bool HasMesh(const std::string& id) const;
  bool HasBasis(const std::string& id) const;
  // DIR/leases: build leases of a shared store (server/lease.h).
  std::string LeaseDir() const { return dir_ + "/leases"; }

  // OK if the file did not exist. `id` may be any id Scan reported, including the name of a
  // damaged file that is not a valid id.
  absl::Status DeleteMesh(const std::string& id) const;
  absl::Status DeleteBasis(const std::string& id) const;

  std::string MeshPath(const std::string& id) const;
  std::string BasisPath(const std::string& id) const;
  std::string ReducedPath(const std::string& id) const;

 private:
  Store(std::string dir, const StoreOptions& options) : dir_(std::move(dir)), options_(options) {}

  std::string dir_;
  StoreOptions options_;
};

}  // namespace fieldspace::server

#endif  // FIELDSPACE_SERVER_STORE_H_
