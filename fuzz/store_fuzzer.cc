// The decoders of what the daemon reads from disk: store containers (server/store.h: header,
// metadata records, payload checksums), the basis format inside a basis container
// (core/basis/basis_io.h) and the served basis made from it, as Registry::GetMesh and
// Registry::LoadBasis do, and the reduced matrices kept beside a basis
// (core/subspace/reduced_system.h) with the system built from them.
//
// Input: one mode byte, then the file. mode % 4: 0 a mesh store file, 1 a basis store file (read
// whole, and streamed into the basis as LoadBasis does), 2 a basis file alone (DecodeBasis), 3 a
// reduced-matrices store file (served on the fixture's first tiny basis when its dimension fits).
// Mode bit 0x80: the harness first rewrites the checksums (XXH64 of the container, CRC-32C of the
// basis format's preamble, header and sections) to match the bytes, so that the fuzzer gets past
// them to the decoders behind; lengths stay the input's.

#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "core/basis/basis_io.h"
#include "core/basis/crc32c.h"
#include "core/subspace/lift_plan.h"
#include "core/subspace/reduced_system.h"
#include "fuzz/tiny_bases.h"
#include "server/hash.h"
#include "server/store.h"

namespace fieldspace::fuzz {
namespace {

template <typename T>
T LoadAt(const std::string& s, size_t at) {
  T v;
  std::memcpy(&v, s.data() + at, sizeof(T));
  return v;
}
template <typename T>
void StoreAt(std::string& s, size_t at, T v) {
  std::memcpy(s.data() + at, &v, sizeof(T));
}

// basis_io's layout: 32-byte preamble (CRC of the header at 24, of the first 28 bytes at 28),
// the header (size at 16), then sections "tag, 0, u64 size, payload, CRC-32C of the payload".
void FixBasisCrcs(std::string& b) {
  if (b.size() < 32) return;
  const uint64_t header = LoadAt<uint64_t>(b, 16);
  if (header > b.size() - 32) return;
  StoreAt<uint32_t>(b, 24, Crc32c(b.data() + 32, header));
  StoreAt<uint32_t>(b, 28, Crc32c(b.data(), 28));
  uint64_t at = 32 + header;
  while (b.size() - at >= 20) {
    const uint64_t n = LoadAt<uint64_t>(b, at + 8);
    if (n > b.size() - at - 20) return;
    StoreAt<uint32_t>(b, at + 16 + n, Crc32c(b.data() + at + 16, n));
    at += 20 + n;
  }
}

// The store container: 40-byte header (meta length at 12, XXH64 of the payload at 24, XXH64 of
// header bytes 0..32 and the metadata at 32), metadata, payload.
void FixContainer(std::string& f, bool basis_payload) {
  if (f.size() < 40) return;
  const uint32_t meta = LoadAt<uint32_t>(f, 12);
  if (meta > f.size() - 40) return;
  if (basis_payload) {
    std::string payload = f.substr(40 + meta);
    FixBasisCrcs(payload);
    f.replace(40 + meta, std::string::npos, payload);
  }
  StoreAt<uint64_t>(f, 24, server::Hash64(f.data() + 40 + meta, f.size() - 40 - meta));
  server::Hasher hasher;
  hasher.Update(f.data(), 32);
  hasher.Update(f.data() + 40, meta);
  StoreAt<uint64_t>(f, 32, hasher.Digest());
}

// The decoded basis served on the fixture's torus when it fits it (LoadBasis's checks).
void Serve(const LoadedBasis& loaded) {
  const auto& mesh = TinyBasis(0)->mesh;
  const Basis& b = loaded.basis;
  if (b.U.rows() != int64_t{b.type.dofs_per_face()} * mesh->num_faces()) return;
  server::BasisRecord record;
  record.id = kStoreBasisId;
  record.key.mesh_id = loaded.mesh_id;
  record.key.field = b.type;
  server::BuildContext context;
  context.threads = 1;
  (void)server::ServeBasis(record, mesh, std::make_shared<const Basis>(b), nullptr, context);
}

const server::Store& TheStore() {
  static server::Store* store = [] {
    const char* tmp = std::getenv("TMPDIR");
    std::string dir = std::string(access("/dev/shm", W_OK) == 0 ? "/dev/shm"
                                  : tmp                         ? tmp
                                                                : "/tmp") +
                      "/fieldspace-store-fuzz-XXXXXX";
    if (mkdtemp(dir.data()) == nullptr) std::abort();
    absl::StatusOr<std::unique_ptr<server::Store>> s = server::Store::Open(dir);
    if (!s.ok()) std::abort();
    static const std::string remove = dir;
    std::atexit([] { std::system(("rm -rf '" + remove + "'").c_str()); });
    return s->release();
  }();
  return *store;
}

void WriteFile(const std::string& path, const std::string& bytes) {
  std::FILE* f = std::fopen(path.c_str(), "wb");
  if (f == nullptr) std::abort();
  if (std::fwrite(bytes.data(), 1, bytes.size(), f) != bytes.size()) std::abort();
  std::fclose(f);
}

}  // namespace
}  // namespace fieldspace::fuzz

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace fieldspace;
  using namespace fieldspace::fuzz;
  if (size < 1) return 0;
  const uint8_t mode = data[0];
  const bool fix = (mode & 0x80) != 0;
  std::string bytes(reinterpret_cast<const char*>(data) + 1, size - 1);
  const server::Store& store = TheStore();
  switch (mode % 4) {
    case 0: {
      if (fix) FixContainer(bytes, false);
      WriteFile(store.MeshPath(kStoreMeshId), bytes);
      (void)store.Scan();
      (void)store.ReadMeshRecord(kStoreMeshId);
      absl::StatusOr<MeshArrays> arrays = store.LoadMesh(kStoreMeshId);
      if (arrays.ok()) (void)TriangleMesh::Create(*std::move(arrays));
      unlink(store.MeshPath(kStoreMeshId).c_str());  // no fsync: nothing here must survive
      break;
    }
    case 1: {
      if (fix) FixContainer(bytes, true);
      WriteFile(store.BasisPath(kStoreBasisId), bytes);
      (void)store.Scan();
      (void)store.ReadBasisRecord(kStoreBasisId);
      absl::StatusOr<server::Store::LoadedBasisFile> file = store.LoadBasis(kStoreBasisId);
      if (file.ok()) {
        absl::StatusOr<LoadedBasis> loaded = DecodeBasis(file->payload);
        if (loaded.ok()) Serve(*loaded);
      }
      auto reader = store.OpenBasisPayload(kStoreBasisId);
      std::optional<LiftPlan> plan_of_u;
      if (reader.ok()) {
        absl::StatusOr<LoadedBasis> streamed = DecodeBasisFrom(**reader);
        if (streamed.ok() && (*reader)->Finish().ok()) {
          plan_of_u = LiftPlan::Build(streamed->basis.U, streamed->basis.type.dofs_per_face());
          Serve(*streamed);
        }
      }
      // Streamed into a LiftPlan, as LoadBasis does when the reduced matrices are kept: it must
      // decode exactly when the whole read does, into the plan of the same U.
      auto plan_reader = store.OpenBasisPayload(kStoreBasisId);
      if (plan_reader.ok()) {
        LiftPlan::StreamBuilder rows;
        absl::StatusOr<LoadedBasis> streamed = DecodeBasisFrom(**plan_reader, rows);
        const bool ok = streamed.ok() && (*plan_reader)->Finish().ok();
        if (ok != plan_of_u.has_value()) std::abort();
        if (ok) {
          absl::StatusOr<LiftPlan> plan = std::move(rows).Finish();
          if (!plan.ok() || plan->memory_bytes() != plan_of_u->memory_bytes() ||
              plan->num_faces() != plan_of_u->num_faces()) {
            std::abort();
          }
          const std::vector<double> x(streamed->basis.U.cols(), 1.0);
          const size_t k = static_cast<size_t>(plan->num_faces()) * plan->dofs_per_face();
          std::vector<double> a(k), b(k);
          plan->LiftAll(x.data(), a.data());
          plan_of_u->LiftAll(x.data(), b.data());
          if (std::memcmp(a.data(), b.data(), k * sizeof(double)) != 0) std::abort();
        }
      }
      unlink(store.BasisPath(kStoreBasisId).c_str());
      break;
    }
    case 3: {
      if (fix) FixContainer(bytes, false);
      WriteFile(store.ReducedPath(kStoreBasisId), bytes);
      // The basis checksum the file claims (its metadata: the id, then the u64), so that the
      // fuzzer gets past the staleness check too.
      uint64_t claimed = 0;
      if (bytes.size() >= 44) {
        const uint32_t meta = LoadAt<uint32_t>(bytes, 12);
        const uint32_t id_len = LoadAt<uint32_t>(bytes, 40);
        if (meta <= bytes.size() - 40 && id_len <= meta && meta - id_len >= 12) {
          claimed = LoadAt<uint64_t>(bytes, 44 + id_len);
        }
      }
      absl::StatusOr<std::string> payload = store.LoadReduced(kStoreBasisId, claimed);
      if (payload.ok()) {
        absl::StatusOr<ReducedMatrices> matrices = DecodeReducedMatrices(*payload);
        const server::ServedBasis& tiny = *TinyBasis(0);
        if (matrices.ok()) {
          (void)ReducedSystem::Build(tiny.basis, tiny.system->mass(), *std::move(matrices));
        }
      }
      unlink(store.ReducedPath(kStoreBasisId).c_str());
      break;
    }
    default: {
      if (fix) FixBasisCrcs(bytes);
      absl::StatusOr<LoadedBasis> loaded = DecodeBasis(bytes);
      if (loaded.ok()) Serve(*loaded);
      break;
    }
  }
  return 0;
}
