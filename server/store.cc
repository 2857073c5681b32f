#include "server/store.h"

#include <unistd.h>

#include <bit>
#include <cerrno>
#include <chrono>
#include <cstring>
#include <filesystem>
#include <thread>

#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "core/common/file_util.h"
#include "core/common/status_macros.h"
#include "server/hash.h"
#include "server/shown_text.h"

namespace fieldspace::server {
namespace {

static_assert(std::endian::native == std::endian::little,
              "the store format and content ids are defined on little-endian hosts");

namespace fs = std::filesystem;

constexpr char kMeshMagic[8] = {'F', 'S', 'M', 'E', 'S', 'H', '\0', '\1'};
constexpr char kBasisMagic[8] = {'F', 'S', 'B', 'A', 'S', 'I', 'S', '\1'};
constexpr char kReducedMagic[8] = {'F', 'S', 'R', 'E', 'D', 'S', 'Y', '\1'};
constexpr uint32_t kFormatVersion = 1;
constexpr size_t kHeaderBytes = 40;
constexpr uint32_t kMaxMetaBytes = 1 << 20;
constexpr char kMeshExt[] = ".fsmesh";
constexpr char kBasisExt[] = ".fsbasis";
constexpr char kReducedExt[] = ".fsreduced";

// Little-endian metadata encoding: fixed-width values and length-prefixed strings.
class MetaWriter {
 public:
  template <typename T>
  void Put(T value) {
    out_.append(reinterpret_cast<const char*>(&value), sizeof(T));
  }
  void PutString(std::string_view s) {
    Put<uint32_t>(static_cast<uint32_t>(s.size()));
    out_.append(s);
  }
  std::string& bytes() { return out_; }

 private:
  std::string out_;
};

class MetaReader {
 public:
  explicit MetaReader(std::string_view in) : in_(in) {}
  template <typename T>
  T Get() {
    T value{};
    if (in_.size() < sizeof(T)) {
      ok_ = false;
      return value;
    }
    std::memcpy(&value, in_.data(), sizeof(T));
    in_.remove_prefix(sizeof(T));
    return value;
  }
  std::string GetString() {
    const uint32_t n = Get<uint32_t>();
    if (!ok_ || in_.size() < n) {
      ok_ = false;
      return {};
    }
    std::string s(in_.substr(0, n));
    in_.remove_prefix(n);
    return s;
  }
  // True if every read fit and nothing is left over.
  bool Done() const { return ok_ && in_.empty(); }

 private:
  std::string_view in_;
  bool ok_ = true;
};

std::string EncodeMeshRecord(const MeshRecord& r) {
  MetaWriter w;
  w.PutString(r.id);
  w.PutString(r.name);
  w.Put<int32_t>(r.num_vertices);
  w.Put<int32_t>(r.num_faces);
  w.Put<int32_t>(r.num_edges);
  w.Put<int32_t>(r.num_components);
  w.Put<int32_t>(r.num_boundary_loops);
  w.Put<int32_t>(r.euler_characteristic);
  w.Put<int32_t>(r.genus);
  w.Put<double>(r.total_area);
  w.Put<int32_t>(r.dropped_unreferenced_vertices);
  w.Put<int32_t>(r.polygons_triangulated);
  w.Put<int64_t>(r.created_unix_ms);
  return std::move(w.bytes());
}

bool DecodeMeshRecord(std::string_view bytes, MeshRecord* r) {
  MetaReader in(bytes);
  r->id = in.GetString();
  r->name = in.GetString();
  r->num_vertices = in.Get<int32_t>();
  r->num_faces = in.Get<int32_t>();
  r->num_edges = in.Get<int32_t>();
  r->num_components = in.Get<int32_t>();
  r->num_boundary_loops = in.Get<int32_t>();
  r->euler_characteristic = in.Get<int32_t>();
  r->genus = in.Get<int32_t>();
  r->total_area = in.Get<double>();
  r->dropped_unreferenced_vertices = in.Get<int32_t>();
  r->polygons_triangulated = in.Get<int32_t>();
  r->created_unix_ms = in.Get<int64_t>();
  return in.Done() && r->num_vertices >= 0 && r->num_faces >= 0;
}

std::string EncodeBasisRecord(const BasisRecord& r) {
  MetaWriter w;
  w.PutString(r.id);
  w.PutString(r.key.mesh_id);
  w.Put<uint8_t>(static_cast<uint8_t>(r.key.field.kind));
  w.Put<int32_t>(r.key.field.n);
  w.Put<int32_t>(r.key.dimension);
  w.Put<double>(r.key.sigma);
  w.Put<int32_t>(r.key.fields_per_region);
  w.Put<uint64_t>(r.key.seed);
  w.Put<uint64_t>(r.key.weights_hash);
  w.Put<int32_t>(r.columns);
  w.Put<int32_t>(r.num_regions);
  w.Put<int32_t>(r.dofs);
  w.Put<double>(r.radius);
  w.Put<int64_t>(r.nnz);
  w.Put<double>(r.build_seconds);
  w.Put<int64_t>(r.created_unix_ms);
  // Appended fields: records written before them end here (C = 0, no kernel columns).
  const bool paper = r.key.quality == BasisQuality::kPaper;
  if (r.key.coarse_dimension != 0 || r.key.kernel_columns || !paper) {
    w.Put<int32_t>(r.key.coarse_dimension);
  }
  if (r.key.kernel_columns || !paper) w.Put<uint8_t>(r.key.kernel_columns ? 1 : 0);
  if (!paper) w.Put<uint8_t>(static_cast<uint8_t>(r.key.quality));
  return std::move(w.bytes());
}

bool DecodeBasisRecord(std::string_view bytes, BasisRecord* r) {
  MetaReader in(bytes);
  r->id = in.GetString();
  r->key.mesh_id = in.GetString();
  const uint8_t kind = in.Get<uint8_t>();
  r->key.field.kind = static_cast<FieldKind>(kind);
  r->key.field.n = in.Get<int32_t>();
  r->key.dimension = in.Get<int32_t>();
  r->key.sigma = in.Get<double>();
  r->key.fields_per_region = in.Get<int32_t>();
  r->key.seed = in.Get<uint64_t>();
  r->key.weights_hash = in.Get<uint64_t>();
  r->columns = in.Get<int32_t>();
  r->num_regions = in.Get<int32_t>();
  r->dofs = in.Get<int32_t>();
  r->radius = in.Get<double>();
  r->nnz = in.Get<int64_t>();
  r->build_seconds = in.Get<double>();
  r->created_unix_ms = in.Get<int64_t>();
  r->key.coarse_dimension = in.Done() ? 0 : in.Get<int32_t>();
  const uint8_t kernel = in.Done() ? 0 : in.Get<uint8_t>();
  r->key.kernel_columns = kernel != 0;
  const uint8_t quality = in.Done() ? 0 : in.Get<uint8_t>();
  r->key.quality = static_cast<BasisQuality>(quality);
  return in.Done() && kind <= static_cast<uint8_t>(FieldKind::kTensor) && kernel <= 1 &&
         quality <= static_cast<uint8_t>(BasisQuality::kSmooth) &&
         (quality == 0 || r->key.coarse_dimension == 0) && r->key.coarse_dimension >= 0 &&
         (r->key.coarse_dimension == 0 || r->key.coarse_dimension < r->key.dimension);
}

struct Header {
  uint32_t meta_len = 0;
  uint64_t payload_len = 0;
  uint64_t payload_hash = 0;
};

std::string EncodeHeader(const char (&magic)[8], std::string_view meta, uint64_t payload_len,
                         uint64_t payload_hash) {
  std::string h(kHeaderBytes, '\0');
  std::memcpy(h.data(), magic, 8);
  const uint32_t version = kFormatVersion;
  const auto meta_len = static_cast<uint32_t>(meta.size());
  std::memcpy(h.data() + 8, &version, 4);
  std::memcpy(h.data() + 12, &meta_len, 4);
  std::memcpy(h.data() + 16, &payload_len, 8);
  std::memcpy(h.data() + 24, &payload_hash, 8);
  Hasher hasher;
  hasher.Update(h.data(), 32);
  hasher.Update(meta);
  const uint64_t header_hash = hasher.Digest();
  std::memcpy(h.data() + 32, &header_hash, 8);
  return h;
}

// Writes header + meta + payload pieces to `path` atomically (temp file, fsync, rename, fsync of
// the directory). `pause_ms` > 0 sleeps halfway through the payload (crash tests).
absl::Status WriteAtomically(const std::string& path, const std::string& header,
                             const std::string& meta, const std::vector<std::string_view>& payload,
                             int32_t pause_ms) {
  std::vector<std::string_view> pieces = {header, meta};
  pieces.insert(pieces.end(), payload.begin(), payload.end());
  AtomicWriteOptions options;
  options.mode = 0644;
  if (pause_ms > 0) {
    uint64_t total = 0;
    for (std::string_view piece : payload) total += piece.size();
    options.midway_hook_at_byte = header.size() + meta.size() + total / 2;
    options.midway_hook = [pause_ms] {
      std::this_thread::sleep_for(std::chrono::milliseconds(pause_ms));
    };
  }
  return WriteFileAtomically(path, pieces, std::move(options));
}

// Opens `path`, checks magic, version, header checksum and total size; returns meta bytes.
struct OpenedFile {
  ReadableFile file;
  Header header;
  std::string meta;
};

absl::StatusOr<OpenedFile> OpenContainer(const std::string& path, const char (&magic)[8]) {
  OpenedFile f;
  ASSIGN_OR_RETURN(f.file, OpenForReading(path));
  const auto file_size = static_cast<uint64_t>(f.file.size);
  if (file_size < kHeaderBytes) {
    return absl::DataLossError(
        absl::StrCat(path, ": truncated (", file_size, " bytes, shorter than the header)"));
  }
  char h[kHeaderBytes];
  RETURN_IF_ERROR(ReadExactlyAt(f.file.fd.get(), 0, h, kHeaderBytes, path));
  if (std::memcmp(h, magic, 8) != 0) {
    return absl::DataLossError(absl::StrCat(path, ": not a fieldspace store file (bad magic)"));
  }
  uint32_t version;
  std::memcpy(&version, h + 8, 4);
  if (version != kFormatVersion) {
    return absl::DataLossError(absl::StrCat(path, ": unsupported store format version ", version));
  }
  std::memcpy(&f.header.meta_len, h + 12, 4);
  std::memcpy(&f.header.payload_len, h + 16, 8);
  std::memcpy(&f.header.payload_hash, h + 24, 8);
  uint64_t header_hash;
  std::memcpy(&header_hash, h + 32, 8);
  if (f.header.meta_len > kMaxMetaBytes || f.header.meta_len > file_size - kHeaderBytes) {
    return absl::DataLossError(absl::StrCat(path, ": corrupt header (metadata length)"));
  }
  f.meta.resize(f.header.meta_len);
  RETURN_IF_ERROR(ReadExactlyAt(f.file.fd.get(), kHeaderBytes, f.meta.data(), f.meta.size(), path));
  Hasher hasher;
  hasher.Update(h, 32);
  hasher.Update(f.meta);
  if (hasher.Digest() != header_hash) {
    return absl::DataLossError(absl::StrCat(path, ": header checksum mismatch"));
  }
  const uint64_t expected = kHeaderBytes + f.header.meta_len + f.header.payload_len;
  if (file_size != expected) {
    return absl::DataLossError(absl::StrCat(path, ": size ", file_size, " bytes, header says ",
                                            expected, " (truncated or appended to)"));
  }
  return f;
}

// Reads the payload into `dst` pieces (in order), verifying its checksum.
absl::Status ReadPayload(const OpenedFile& f, const std::vector<std::pair<char*, size_t>>& dst,
                         const std::string& path) {
  uint64_t offset = kHeaderBytes + f.header.meta_len;
  Hasher hasher;
  for (const auto& [data, size] : dst) {
    // Read in slices so the hash of a slice runs while it is still in cache.
    size_t done = 0;
    while (done < size) {
      const size_t n = std::min<size_t>(size - done, size_t{8} << 20);
      RETURN_IF_ERROR(ReadExactlyAt(f.file.fd.get(), offset, data + done, n, path));
      hasher.Update(data + done, n);
      offset += n;
      done += n;
    }
  }
  if (hasher.Digest() != f.header.payload_hash) {
    return absl::DataLossError(absl::StrCat(path, ": payload checksum mismatch"));
  }
  return absl::OkStatus();
}

bool ValidId(std::string_view id, char prefix) {
  if (id.size() != 18 || id[0] != prefix || id[1] != '-') return false;
  for (char c : id.substr(2)) {
    if (!((c >= '0' && c <= '9') || (c >= 'a' && c <= 'f'))) return false;
  }
  return true;
}

// What Scan can report as an id: the name of a file in the store's folder without its extension
// (a damaged or foreign file's name need not be a valid id). Never a path.
bool IsFileStem(std::string_view id) {
  return !id.empty() && id[0] != '.' && id.find_first_of(std::string_view("/\0", 2)) == id.npos;
}

// The container of `id` at `path` with its record decoded: NotFound for an id that is not one of
// `prefix`'s, DataLoss for metadata that does not decode or names another id.
template <typename Record>
absl::StatusOr<OpenedFile> OpenRecordFile(const std::string& id, char prefix,
                                          const std::string& path, const char (&magic)[8],
                                          bool (*decode)(std::string_view, Record*),
                                          Record* record) {
  if (!ValidId(id, prefix)) {
    return absl::NotFoundError(absl::StrCat(prefix == 'm' ? "no mesh " : "no basis ", ShownId(id)));
  }
  ASSIGN_OR_RETURN(OpenedFile f, OpenContainer(path, magic));
  if (!decode(f.meta, record) || record->id != id) {
    return absl::DataLossError(path + ": corrupt metadata");
  }
  return f;
}

// The records of the files `*<ext>` in DIR/<folder> (Store::Scan): sound ones into `records`,
// the others into `damaged` (with `basis` telling which kind they are).
template <typename Record>
void ScanFolder(const std::string& dir, const char* folder, const char* ext, const char (&magic)[8],
                bool (*decode)(std::string_view, Record*), bool basis, std::vector<Record>* records,
                std::vector<DamagedEntry>* damaged) {
  std::error_code ec;
  for (const auto& entry : fs::directory_iterator(fs::path(dir) / folder, ec)) {
    const std::string name = entry.path().filename().string();
    if (!absl::EndsWith(name, ext) || absl::StartsWith(name, ".")) continue;
    const std::string id = name.substr(0, name.size() - std::strlen(ext));
    absl::StatusOr<OpenedFile> f = OpenContainer(entry.path().string(), magic);
    Record record;
    absl::Status status = f.status();
    if (status.ok() && (!decode(f->meta, &record) || record.id != id)) {
      status = absl::DataLossError(absl::StrCat(entry.path().string(), ": corrupt metadata"));
    }
    if (status.ok()) {
      records->push_back(std::move(record));
    } else {
      damaged->push_back({id, basis, status});
    }
  }
}

}  // namespace

absl::StatusOr<std::unique_ptr<Store>> Store::Open(const std::string& dir,
                                                   const StoreOptions& options) {
  if (dir.empty()) return absl::InvalidArgumentError("store directory must not be empty");
  std::error_code ec;
  for (const char* sub : {"meshes", "bases", "leases"}) {
    if (std::string_view(sub) == "leases" && !options.shared) continue;
    fs::create_directories(fs::path(dir) / sub, ec);
    if (ec) {
      return absl::PermissionDeniedError(absl::StrCat(
          "cannot create store directory ", (fs::path(dir) / sub).string(), ": ", ec.message()));
    }
  }
  // Temporary files are what a crash in the middle of a save leaves behind: never complete.
  for (const char* sub : {"meshes", "bases"}) {
    for (const auto& entry : fs::directory_iterator(fs::path(dir) / sub, ec)) {
      const std::string name = entry.path().filename().string();
      if (!IsTemporaryFileName(name)) continue;
      if (options.shared) {
        // Another daemon may be writing it right now: only old ones are a crash's leftovers.
        const auto mtime = fs::last_write_time(entry.path(), ec);
        if (ec || fs::file_time_type::clock::now() - mtime < options.stale_temp_age) continue;
      }
      fs::remove(entry.path(), ec);
    }
  }
  // Reduced matrices whose basis is gone (deleted by another daemon while this one was saving
  // them): a cache of nothing. Their basis is always written first, so none is lost here.
  for (const auto& entry : fs::directory_iterator(fs::path(dir) / "bases", ec)) {
    const std::string name = entry.path().filename().string();
    if (!absl::EndsWith(name, kReducedExt) || absl::StartsWith(name, ".")) continue;
    const std::string stem = name.substr(0, name.size() - std::strlen(kReducedExt));
    if (!fs::exists(fs::path(dir) / "bases" / (stem + kBasisExt), ec)) fs::remove(entry.path(), ec);
  }
  return std::unique_ptr<Store>(new Store(fs::absolute(dir).lexically_normal().string(), options));
}

std::string Store::MeshPath(const std::string& id) const {
  return absl::StrCat(dir_, "/meshes/", id, kMeshExt);
}

std::string Store::BasisPath(const std::string& id) const {
  return absl::StrCat(dir_, "/bases/", id, kBasisExt);
}

std::string Store::ReducedPath(const std::string& id) const {
  return absl::StrCat(dir_, "/bases/", id, kReducedExt);
}

StoreContents Store::Scan() const {
  StoreContents out;
  ScanFolder(dir_, "meshes", kMeshExt, kMeshMagic, DecodeMeshRecord, /*basis=*/false, &out.meshes,
             &out.damaged);
  ScanFolder(dir_, "bases", kBasisExt, kBasisMagic, DecodeBasisRecord, /*basis=*/true, &out.bases,
             &out.damaged);
  return out;
}

absl::Status Store::SaveMesh(const MeshRecord& record, const VertexMatrix& V,
                             const FaceMatrix& F) const {
  if (!ValidId(record.id, 'm')) return absl::InvalidArgumentError("bad mesh id " + record.id);
  if (V.rows() != record.num_vertices || F.rows() != record.num_faces) {
    return absl::InvalidArgumentError("mesh record does not match its arrays");
  }
  const std::string_view v_bytes(reinterpret_cast<const char*>(V.data()),
                                 sizeof(double) * static_cast<size_t>(V.size()));
  const std::string_view f_bytes(reinterpret_cast<const char*>(F.data()),
                                 sizeof(int32_t) * static_cast<size_t>(F.size()));
  Hasher hasher;
  hasher.Update(v_bytes);
  hasher.Update(f_bytes);
  const std::string meta = EncodeMeshRecord(record);
  const std::string header =
      EncodeHeader(kMeshMagic, meta, v_bytes.size() + f_bytes.size(), hasher.Digest());
  return WriteAtomically(MeshPath(record.id), header, meta, {v_bytes, f_bytes},
                         options_.save_pause_ms);
}

absl::StatusOr<MeshArrays> Store::LoadMesh(const std::string& id) const {
  const std::string path = MeshPath(id);
  MeshRecord record;
  ASSIGN_OR_RETURN(OpenedFile f,
                   OpenRecordFile(id, 'm', path, kMeshMagic, DecodeMeshRecord, &record));
  const uint64_t expected = uint64_t{24} * static_cast<uint64_t>(record.num_vertices) +
                            uint64_t{12} * static_cast<uint64_t>(record.num_faces);
  if (f.header.payload_len != expected) {
    return absl::DataLossError(path + ": payload size does not match the vertex/face counts");
  }
  MeshArrays arrays;
  arrays.vertices.resize(record.num_vertices, 3);
  arrays.faces.resize(record.num_faces, 3);
  RETURN_IF_ERROR(ReadPayload(
      f,
      {{reinterpret_cast<char*>(arrays.vertices.data()), sizeof(double) * arrays.vertices.size()},
       {reinterpret_cast<char*>(arrays.faces.data()), sizeof(int32_t) * arrays.faces.size()}},
      path));
  return arrays;
}

absl::Status Store::VerifyMesh(const std::string& id, const VertexMatrix& V,
                               const FaceMatrix& F) const {
  ASSIGN_OR_RETURN(MeshArrays stored, LoadMesh(id));
  if (stored.vertices.rows() != V.rows() || stored.faces.rows() != F.rows() ||
      stored.vertices != V || stored.faces != F) {
    return absl::DataLossError(MeshPath(id) + ": holds another mesh than its id names");
  }
  return absl::OkStatus();
}

absl::Status Store::SaveBasis(const BasisRecord& record,
                              const std::vector<std::string_view>& payload,
                              uint64_t* payload_hash) const {
  if (!ValidId(record.id, 'b')) return absl::InvalidArgumentError("bad basis id " + record.id);
  Hasher hasher;
  uint64_t total = 0;
  for (std::string_view piece : payload) {
    hasher.Update(piece);
    total += piece.size();
  }
  const uint64_t digest = hasher.Digest();
  const std::string meta = EncodeBasisRecord(record);
  const std::string header = EncodeHeader(kBasisMagic, meta, total, digest);
  RETURN_IF_ERROR(
      WriteAtomically(BasisPath(record.id), header, meta, payload, options_.save_pause_ms));
  if (payload_hash != nullptr) *payload_hash = digest;
  return absl::OkStatus();
}

absl::StatusOr<Store::LoadedBasisFile> Store::LoadBasis(const std::string& id) const {
  ASSIGN_OR_RETURN(std::unique_ptr<BasisPayloadReader> reader, OpenBasisPayload(id));
  LoadedBasisFile out;
  out.record = reader->record();
  out.payload.resize(reader->size());
  constexpr size_t kSlice = size_t{8} << 20;  // hashed while still in cache
  for (uint64_t done = 0; done < out.payload.size(); done += kSlice) {
    const size_t n = static_cast<size_t>(std::min<uint64_t>(kSlice, out.payload.size() - done));
    RETURN_IF_ERROR(reader->ReadAt(done, out.payload.data() + done, n));
  }
  ASSIGN_OR_RETURN(out.payload_hash, reader->Finish());
  return out;
}

absl::StatusOr<std::unique_ptr<Store::BasisPayloadReader>> Store::OpenBasisPayload(
    const std::string& id) const {
  auto reader = std::unique_ptr<BasisPayloadReader>(new BasisPayloadReader());
  reader->path_ = BasisPath(id);
  ASSIGN_OR_RETURN(OpenedFile f, OpenRecordFile(id, 'b', reader->path_, kBasisMagic,
                                                DecodeBasisRecord, &reader->record_));
  reader->start_ = kHeaderBytes + f.header.meta_len;
  reader->length_ = f.header.payload_len;
  reader->expected_hash_ = f.header.payload_hash;
  reader->file_ = std::move(f.file);
  return reader;
}

absl::Status Store::BasisPayloadReader::ReadAt(uint64_t offset, void* dst, size_t size) {
  if (offset != next_ || size > length_ - offset) {
    return absl::DataLossError(absl::StrCat(path_, ": payload read out of order"));
  }
  RETURN_IF_ERROR(ReadExactlyAt(file_.fd.get(), start_ + offset, dst, size, path_));
  hasher_.Update(dst, size);
  next_ = offset + size;
  return absl::OkStatus();
}

absl::StatusOr<uint64_t> Store::BasisPayloadReader::Finish() const {
  if (next_ != length_) return absl::DataLossError(path_ + ": payload not read to its end");
  if (hasher_.Digest() != expected_hash_) {
    return absl::DataLossError(absl::StrCat(path_, ": payload checksum mismatch"));
  }
  return expected_hash_;
}

absl::Status Store::SaveReduced(const std::string& id, uint64_t basis_payload_hash,
                                std::string_view payload) const {
  if (!ValidId(id, 'b')) return absl::InvalidArgumentError("bad basis id " + id);
  MetaWriter w;
  w.PutString(id);
  w.Put<uint64_t>(basis_payload_hash);
  const std::string meta = std::move(w.bytes());
  Hasher hasher;
  hasher.Update(payload);
  const std::string header = EncodeHeader(kReducedMagic, meta, payload.size(), hasher.Digest());
  return WriteAtomically(ReducedPath(id), header, meta, {payload}, options_.save_pause_ms);
}

absl::StatusOr<std::string> Store::LoadReduced(const std::string& id,
                                               uint64_t basis_payload_hash) const {
  if (!ValidId(id, 'b')) return absl::NotFoundError(absl::StrCat("no basis ", ShownId(id)));
  const std::string path = ReducedPath(id);
  ASSIGN_OR_RETURN(OpenedFile f, OpenContainer(path, kReducedMagic));
  MetaReader in(f.meta);
  const std::string meta_id = in.GetString();
  const uint64_t hash = in.Get<uint64_t>();
  if (!in.Done() || meta_id != id) return absl::DataLossError(path + ": corrupt metadata");
  if (hash != basis_payload_hash) {
    return absl::FailedPreconditionError(
        absl::StrCat(path, ": computed from another file of basis ", id, " (stale)"));
  }
  std::string payload(f.header.payload_len, '\0');
  RETURN_IF_ERROR(ReadPayload(f, {{payload.data(), payload.size()}}, path));
  return payload;
}

absl::StatusOr<MeshRecord> Store::ReadMeshRecord(const std::string& id) const {
  MeshRecord record;
  RETURN_IF_ERROR(
      OpenRecordFile(id, 'm', MeshPath(id), kMeshMagic, DecodeMeshRecord, &record).status());
  return record;
}

absl::StatusOr<BasisRecord> Store::ReadBasisRecord(const std::string& id) const {
  BasisRecord record;
  RETURN_IF_ERROR(
      OpenRecordFile(id, 'b', BasisPath(id), kBasisMagic, DecodeBasisRecord, &record).status());
  return record;
}

bool Store::HasMesh(const std::string& id) const {
  return ValidId(id, 'm') && ::access(MeshPath(id).c_str(), F_OK) == 0;
}

bool Store::HasBasis(const std::string& id) const {
  return ValidId(id, 'b') && ::access(BasisPath(id).c_str(), F_OK) == 0;
}

absl::Status Store::DeleteMesh(const std::string& id) const {
  if (!IsFileStem(id)) return absl::OkStatus();
  if (::unlink(MeshPath(id).c_str()) != 0 && errno != ENOENT) {
    return ErrnoStatus(errno, "deleting " + MeshPath(id));
  }
  return FsyncDirectory(dir_ + "/meshes");
}

absl::Status Store::DeleteBasis(const std::string& id) const {
  if (!IsFileStem(id)) return absl::OkStatus();
  // The cache first: a crash in between leaves a basis without it (recomputed when loaded), never
  // a cache without its basis.
  if (::unlink(ReducedPath(id).c_str()) != 0 && errno != ENOENT) {
    return ErrnoStatus(errno, "deleting " + ReducedPath(id));
  }
  if (::unlink(BasisPath(id).c_str()) != 0 && errno != ENOENT) {
    return ErrnoStatus(errno, "deleting " + BasisPath(id));
  }
  return FsyncDirectory(dir_ + "/bases");
}

}  // namespace fieldspace::server
