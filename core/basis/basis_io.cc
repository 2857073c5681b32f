#include "core/basis/basis_io.h"

#include <cmath>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <utility>
#include <vector>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "core/basis/crc32c.h"
#include "core/common/file_util.h"

namespace fieldspace {
namespace {

constexpr char kMagic[8] = {'F', 'S', 'B', 'A', 'S', 'I', 'S', '\0'};
constexpr uint32_t kVersion = 1;
constexpr uint32_t kByteOrderMark = 0x01020304u;
constexpr size_t kPreambleBytes = 32;
constexpr size_t kSectionHeadBytes = 16;  // tag, reserved, size
constexpr size_t kSectionTailBytes = 4;   // crc
constexpr uint64_t kMaxMeshIdBytes = 1 << 16;

enum SectionTag : uint32_t {
  kSamples = 0x4C504D53,      // "SMPL"
  kEigenvalues = 0x56474945,  // "EIGV"
  kWeights = 0x54484757,      // "WGHT"
  kRowPointers = 0x50574F52,  // "ROWP"
  kColumns = 0x534C4F43,      // "COLS"
  kValues = 0x534C4156,       // "VALS"
};

// ---------------------------------------------------------------- header encoding

class HeaderWriter {
 public:
  template <typename T>
  void Put(T v) {
    static_assert(std::is_trivially_copyable_v<T>);
    out_.append(reinterpret_cast<const char*>(&v), sizeof(T));
  }
  void PutBytes(std::string_view s) { out_.append(s.data(), s.size()); }
  const std::string& str() const { return out_; }

 private:
  std::string out_;
};

class HeaderReader {
 public:
  explicit HeaderReader(std::string_view in) : in_(in) {}
  template <typename T>
  bool Get(T* v) {
    if (in_.size() - pos_ < sizeof(T)) return false;
    std::memcpy(v, in_.data() + pos_, sizeof(T));
    pos_ += sizeof(T);
    return true;
  }
  bool GetBytes(size_t n, std::string* s) {
    if (in_.size() - pos_ < n) return false;
    s->assign(in_.data() + pos_, n);
    pos_ += n;
    return true;
  }
  size_t remaining() const { return in_.size() - pos_; }

 private:
  std::string_view in_;
  size_t pos_ = 0;
};

struct Header {
  std::string mesh_id;
  uint8_t field_kind = 0;
  int32_t field_n = 1;
  int32_t dimension = 0;
  uint8_t has_fields_per_region = 0;
  int32_t fields_per_region = 0;
  double sigma = 0;
  uint64_t seed = 0;
  double radius = 0;
  double coverage_radius = 0;
  int64_t uncovered_faces = 0;
  int64_t rows = 0;
  int64_t cols = 0;
  int64_t nnz = 0;
  int32_t num_regions = 0;
  int32_t kernel_columns = 0;  // in a slot that was reserved (0) before kernel columns existed
  int64_t num_weights = 0;
  double timings[4] = {0, 0, 0, 0};
  uint8_t hodge_factor_used = 0;
  int32_t dense_regions = 0;
  int32_t lanczos_fallbacks = 0;
  int64_t lobpcg_iterations = 0;
  int64_t max_region_faces = 0;
  double mean_region_faces = 0;
};

std::string EncodeHeader(const Header& h) {
  HeaderWriter w;
  w.Put<uint8_t>(h.field_kind);
  w.Put<uint8_t>(h.has_fields_per_region);
  w.Put<uint16_t>(0);
  w.Put<int32_t>(h.field_n);
  w.Put<int32_t>(h.dimension);
  w.Put<int32_t>(h.fields_per_region);
  w.Put<double>(h.sigma);
  w.Put<uint64_t>(h.seed);
  w.Put<double>(h.radius);
  w.Put<double>(h.coverage_radius);
  w.Put<int64_t>(h.uncovered_faces);
  w.Put<int64_t>(h.rows);
  w.Put<int64_t>(h.cols);
  w.Put<int64_t>(h.nnz);
  w.Put<int32_t>(h.num_regions);
  w.Put<int32_t>(h.kernel_columns);
  w.Put<int64_t>(h.num_weights);
  for (double t : h.timings) w.Put<double>(t);
  w.Put<uint8_t>(h.hodge_factor_used);
  w.Put<uint8_t>(0);
  w.Put<uint16_t>(0);
  w.Put<int32_t>(h.dense_regions);
  w.Put<int32_t>(h.lanczos_fallbacks);
  w.Put<int32_t>(0);
  w.Put<int64_t>(h.lobpcg_iterations);
  w.Put<int64_t>(h.max_region_faces);
  w.Put<double>(h.mean_region_faces);
  w.Put<uint32_t>(static_cast<uint32_t>(h.mesh_id.size()));
  w.PutBytes(h.mesh_id);
  return w.str();
}

absl::Status DataLoss(std::string_view what) {
  return absl::DataLossError(
      absl::StrCat("basis file: ", absl::string_view(what.data(), what.size())));
}

absl::StatusOr<Header> DecodeHeader(std::string_view bytes) {
  HeaderReader r(bytes);
  Header h;
  uint16_t u16;
  int32_t i32;
  uint8_t u8;
  uint32_t id_len = 0;
  bool ok = r.Get(&h.field_kind) && r.Get(&h.has_fields_per_region) && r.Get(&u16) &&
            r.Get(&h.field_n) && r.Get(&h.dimension) && r.Get(&h.fields_per_region) &&
            r.Get(&h.sigma) && r.Get(&h.seed) && r.Get(&h.radius) && r.Get(&h.coverage_radius) &&
            r.Get(&h.uncovered_faces) && r.Get(&h.rows) && r.Get(&h.cols) && r.Get(&h.nnz) &&
            r.Get(&h.num_regions) && r.Get(&h.kernel_columns) && r.Get(&h.num_weights);
  for (double& t : h.timings) ok = ok && r.Get(&t);
  ok = ok && r.Get(&h.hodge_factor_used) && r.Get(&u8) && r.Get(&u16) && r.Get(&h.dense_regions) &&
       r.Get(&h.lanczos_fallbacks) && r.Get(&i32) && r.Get(&h.lobpcg_iterations) &&
       r.Get(&h.max_region_faces) && r.Get(&h.mean_region_faces) && r.Get(&id_len);
  if (!ok) return DataLoss("header too short");
  if (id_len != r.remaining()) return DataLoss("header size does not match its mesh id length");
  r.GetBytes(id_len, &h.mesh_id);
  // Semantic checks: a file with valid checksums but impossible contents is still refused.
  if (h.field_kind > 2) return DataLoss(absl::StrFormat("unknown field kind %d", h.field_kind));
  FieldType type{static_cast<FieldKind>(h.field_kind), h.field_n};
  if (!type.Validate().ok()) return DataLoss("invalid field type");
  const int64_t dpf = type.dofs_per_face();
  if (h.dimension < 1 || h.cols != h.dimension) return DataLoss("invalid dimension");
  if (h.rows < dpf || h.rows % dpf != 0 || h.rows > (int64_t{1} << 40)) {
    return DataLoss("invalid row count");
  }
  if (h.nnz < 0 || h.nnz > std::numeric_limits<int32_t>::max()) return DataLoss("invalid nnz");
  if (h.num_regions < 1 || h.num_regions > h.dimension) return DataLoss("invalid region count");
  if (h.kernel_columns < 0 || h.kernel_columns > h.dimension - h.num_regions) {
    return DataLoss("invalid kernel column count");
  }
  if (h.num_weights != 0 && h.num_weights != h.rows / dpf) return DataLoss("invalid weight count");
  if (!(h.sigma > 0) || !std::isfinite(h.sigma)) return DataLoss("invalid sigma");
  if (h.has_fields_per_region > 1 || (h.has_fields_per_region && h.fields_per_region < 1)) {
    return DataLoss("invalid fields_per_region");
  }
  return h;
}

// ---------------------------------------------------------------- byte sinks and sources

class Sink {
 public:
  virtual ~Sink() = default;
  virtual absl::Status Write(const void* data, size_t size) = 0;
};

class StringSink final : public Sink {
 public:
  explicit StringSink(std::string* out) : out_(out) {}
  absl::Status Write(const void* data, size_t size) override {
    out_->append(static_cast<const char*>(data), size);
    return absl::OkStatus();
  }

 private:
  std::string* out_;
};

class FileSink final : public Sink {
 public:
  explicit FileSink(AtomicFileWriter& out) : out_(out) {}
  absl::Status Write(const void* data, size_t size) override {
    return out_.Append(std::string_view(static_cast<const char*>(data), size));
  }

 private:
  AtomicFileWriter& out_;
};

// Pieces of at least kReferenceBytes are referenced in place; smaller ones are copied.
class PiecesSink final : public Sink {
 public:
  PiecesSink(std::vector<std::string_view>* pieces, std::deque<std::string>* storage)
      : pieces_(pieces), storage_(storage) {}
  absl::Status Write(const void* data, size_t size) override {
    constexpr size_t kReferenceBytes = 4096;
    if (size >= kReferenceBytes) {
      pieces_->emplace_back(static_cast<const char*>(data), size);
    } else {
      // A deque never moves its elements, so earlier views stay valid.
      pieces_->emplace_back(storage_->emplace_back(static_cast<const char*>(data), size));
    }
    return absl::OkStatus();
  }

 private:
  std::vector<std::string_view>* pieces_;
  std::deque<std::string>* storage_;
};

using Source = BasisByteSource;

class StringSource final : public Source {
 public:
  explicit StringSource(std::string_view bytes) : bytes_(bytes) {}
  uint64_t size() const override { return bytes_.size(); }
  absl::Status ReadAt(uint64_t offset, void* dst, size_t size) override {
    std::memcpy(dst, bytes_.data() + offset, size);
    return absl::OkStatus();
  }

 private:
  std::string_view bytes_;
};

class FileSource final : public Source {
 public:
  FileSource(ReadableFile file, std::string path)
      : file_(std::move(file)), path_(std::move(path)) {}
  uint64_t size() const override { return static_cast<uint64_t>(file_.size); }
  absl::Status ReadAt(uint64_t offset, void* dst, size_t size) override {
    return ReadExactlyAt(file_.fd.get(), offset, dst, size, path_);
  }

 private:
  ReadableFile file_;
  std::string path_;
};

// ---------------------------------------------------------------- encode

absl::Status WriteSection(Sink& sink, uint32_t tag, const void* data, uint64_t bytes) {
  uint8_t head[kSectionHeadBytes];
  const uint32_t zero = 0;
  std::memcpy(head, &tag, 4);
  std::memcpy(head + 4, &zero, 4);
  std::memcpy(head + 8, &bytes, 8);
  if (absl::Status s = sink.Write(head, sizeof(head)); !s.ok()) return s;
  // Checksum and write in chunks so that the data is read once while cache-warm.
  constexpr size_t kChunk = size_t{1} << 22;
  const char* p = static_cast<const char*>(data);
  uint32_t crc = 0;
  for (uint64_t off = 0; off < bytes; off += kChunk) {
    const size_t n = static_cast<size_t>(std::min<uint64_t>(kChunk, bytes - off));
    crc = Crc32cExtend(crc, p + off, n);
    if (absl::Status s = sink.Write(p + off, n); !s.ok()) return s;
  }
  return sink.Write(&crc, 4);
}

absl::Status Encode(const Basis& basis, std::string_view mesh_id, Sink& sink) {
  if (mesh_id.size() > kMaxMeshIdBytes) {
    return absl::InvalidArgumentError("mesh id longer than 64 KiB");
  }
  const Eigen::SparseMatrix<float, Eigen::RowMajor>* U = &basis.U;
  Eigen::SparseMatrix<float, Eigen::RowMajor> compressed;
  if (!U->isCompressed()) {
    compressed = *U;
    compressed.makeCompressed();
    U = &compressed;
  }
  if (static_cast<int64_t>(basis.local_eigenvalues.size()) != U->cols() ||
      basis.sample_faces.empty() || U->rows() < 1 || U->cols() < 1) {
    return absl::InvalidArgumentError("basis to save is inconsistent or empty");
  }
  Header h;
  h.mesh_id = std::string(mesh_id);
  h.field_kind = static_cast<uint8_t>(basis.type.kind);
  h.field_n = basis.type.n;
  h.dimension = basis.params.dimension;
  h.has_fields_per_region = basis.params.fields_per_region.has_value();
  h.fields_per_region = basis.params.fields_per_region.value_or(0);
  h.sigma = basis.params.sigma;
  h.seed = basis.params.seed;
  h.radius = basis.radius;
  h.coverage_radius = basis.coverage_radius;
  h.uncovered_faces = basis.uncovered_faces;
  h.rows = U->rows();
  h.cols = U->cols();
  h.nnz = U->nonZeros();
  h.num_regions = basis.num_regions();
  h.kernel_columns = basis.kernel_columns;
  h.num_weights = basis.params.face_weights.size();
  h.timings[0] = basis.timings.sampling_seconds;
  h.timings[1] = basis.timings.regions_seconds;
  h.timings[2] = basis.timings.eigensolve_seconds;
  h.timings[3] = basis.timings.total_seconds;
  h.hodge_factor_used = basis.stats.hodge_factor_used;
  h.dense_regions = basis.stats.dense_regions;
  h.lanczos_fallbacks = basis.stats.lanczos_fallbacks;
  h.lobpcg_iterations = basis.stats.lobpcg_iterations;
  h.max_region_faces = basis.stats.max_region_faces;
  h.mean_region_faces = basis.stats.mean_region_faces;
  if (h.dimension != h.cols) return absl::InvalidArgumentError("basis dimension != U columns");
  const std::string header = EncodeHeader(h);
  uint8_t preamble[kPreambleBytes];
  const uint64_t header_size = header.size();
  const uint32_t header_crc = Crc32c(header.data(), header.size());
  std::memcpy(preamble, kMagic, 8);
  std::memcpy(preamble + 8, &kVersion, 4);
  std::memcpy(preamble + 12, &kByteOrderMark, 4);
  std::memcpy(preamble + 16, &header_size, 8);
  std::memcpy(preamble + 24, &header_crc, 4);
  const uint32_t preamble_crc = Crc32c(preamble, 28);
  std::memcpy(preamble + 28, &preamble_crc, 4);
  if (absl::Status s = sink.Write(preamble, sizeof(preamble)); !s.ok()) return s;
  if (absl::Status s = sink.Write(header.data(), header.size()); !s.ok()) return s;
  const uint64_t nnz = static_cast<uint64_t>(h.nnz);
  const std::pair<uint32_t, std::pair<const void*, uint64_t>> sections[] = {
      {kSamples, {basis.sample_faces.data(), 4 * basis.sample_faces.size()}},
      {kEigenvalues, {basis.local_eigenvalues.data(), 8 * basis.local_eigenvalues.size()}},
      {kWeights, {basis.params.face_weights.data(), 8 * static_cast<uint64_t>(h.num_weights)}},
      {kRowPointers, {U->outerIndexPtr(), 4 * (static_cast<uint64_t>(h.rows) + 1)}},
      {kColumns, {U->innerIndexPtr(), 4 * nnz}},
      {kValues, {U->valuePtr(), 4 * nnz}},
  };
  for (const auto& [tag, payload] : sections) {
    if (absl::Status s = WriteSection(sink, tag, payload.first, payload.second); !s.ok()) return s;
  }
  return absl::OkStatus();
}

// ---------------------------------------------------------------- decode

absl::StatusOr<Header> ReadHeader(Source& src, uint64_t* header_end) {
  const uint64_t size = src.size();
  if (size < kPreambleBytes) {
    return DataLoss(absl::StrFormat("truncated: %d bytes, shorter than the %d-byte preamble", size,
                                    kPreambleBytes));
  }
  uint8_t pre[kPreambleBytes];
  if (absl::Status s = src.ReadAt(0, pre, sizeof(pre)); !s.ok()) return s;
  if (std::memcmp(pre, kMagic, 8) != 0) return DataLoss("bad magic: not a fieldspace basis file");
  uint32_t preamble_crc;
  std::memcpy(&preamble_crc, pre + 28, 4);
  if (Crc32c(pre, 28) != preamble_crc) return DataLoss("preamble checksum mismatch");
  uint32_t version, bom, header_crc;
  uint64_t header_size;
  std::memcpy(&version, pre + 8, 4);
  std::memcpy(&bom, pre + 12, 4);
  std::memcpy(&header_size, pre + 16, 8);
  std::memcpy(&header_crc, pre + 24, 4);
  if (version != kVersion) {
    return DataLoss(
        absl::StrFormat("unsupported format version %d (this build reads %d)", version, kVersion));
  }
  if (bom != kByteOrderMark) return DataLoss("written with a different byte order");
  if (header_size > kMaxMeshIdBytes + 1024 || header_size > size - kPreambleBytes) {
    return DataLoss(absl::StrFormat("truncated or corrupt: header of %d bytes in a %d-byte file",
                                    header_size, size));
  }
  std::string header(header_size, '\0');
  if (absl::Status s = src.ReadAt(kPreambleBytes, header.data(), header.size()); !s.ok()) return s;
  if (Crc32c(header.data(), header.size()) != header_crc)
    return DataLoss("header checksum mismatch");
  *header_end = kPreambleBytes + header_size;
  return DecodeHeader(header);
}

struct SectionPlan {
  uint32_t tag;
  void* dst;
  uint64_t bytes;
};

constexpr size_t kReadChunk = size_t{1} << 22;

using BasisU = decltype(Basis::U);

// Reads the section `tag` of `bytes` payload bytes at *offset: its head, the payload in chunks
// of kReadChunk bytes (a multiple of every element size) to `into(off, n)`, each then passed to
// `consume(chunk, n)`, and its checksum. An error of consume's is returned after the checksum
// matched (so a damaged section reads as a checksum mismatch); consume is not called after it.
template <typename Into, typename Consume>
absl::Status ReadSectionWith(Source& src, uint64_t* offset, uint32_t expected_tag, uint64_t bytes,
                             Into&& into, Consume&& consume) {
  uint8_t head[kSectionHeadBytes];
  if (absl::Status s = src.ReadAt(*offset, head, sizeof(head)); !s.ok()) return s;
  uint32_t tag, reserved;
  uint64_t stored_bytes;
  std::memcpy(&tag, head, 4);
  std::memcpy(&reserved, head + 4, 4);
  std::memcpy(&stored_bytes, head + 8, 8);
  const std::string name(reinterpret_cast<const char*>(&expected_tag), 4);
  if (tag != expected_tag || reserved != 0)
    return DataLoss(absl::StrCat("section ", name, ": bad tag"));
  if (stored_bytes != bytes) return DataLoss(absl::StrCat("section ", name, ": bad size"));
  *offset += kSectionHeadBytes;
  uint32_t crc = 0;
  absl::Status consumed;
  for (uint64_t off = 0; off < bytes; off += kReadChunk) {
    const size_t n = static_cast<size_t>(std::min<uint64_t>(kReadChunk, bytes - off));
    char* p = into(off, n);
    if (absl::Status s = src.ReadAt(*offset + off, p, n); !s.ok()) return s;
    crc = Crc32cExtend(crc, p, n);
    if (consumed.ok()) consumed = consume(p, n);
  }
  *offset += bytes;
  uint32_t stored;
  if (absl::Status s = src.ReadAt(*offset, &stored, 4); !s.ok()) return s;
  *offset += kSectionTailBytes;
  if (stored != crc) return DataLoss(absl::StrCat("section ", name, ": checksum mismatch"));
  return consumed;
}

// A section read whole into plan.dst.
absl::Status ReadSection(Source& src, uint64_t* offset, const SectionPlan& plan) {
  char* dst = static_cast<char*>(plan.dst);
  return ReadSectionWith(
      src, offset, plan.tag, plan.bytes, [dst](uint64_t off, size_t) { return dst + off; },
      [](const char*, size_t) { return absl::OkStatus(); });
}

// U's structure (a damaged-but-checksummed file must not crash later users of U), checked as
// its arrays pass: the row pointers whole, then the column indices and then the values, each in
// pieces of any size, in order.
class RowsCheck {
 public:
  // 0 first, nnz last, none decreasing. All of them before any column: one past nnz in the
  // middle (say 0, 5, 0 with nnz 0) would send the column check past the end of the arrays.
  static absl::Status RowPointers(const int32_t* outer, int64_t rows, int64_t nnz) {
    if (outer[0] != 0 || outer[rows] != nnz) return DataLoss("row pointers inconsistent");
    for (int64_t r = 0; r < rows; ++r) {
      if (outer[r + 1] < outer[r]) return DataLoss("row pointers decrease");
    }
    return absl::OkStatus();
  }

  // `outer`: checked row pointers, alive while columns are checked.
  RowsCheck(const int32_t* outer, int64_t cols) : outer_(outer), cols_(cols) {}

  // Each in [0, cols) and ascending within its row.
  absl::Status Columns(const int32_t* cols, int64_t n) {
    for (int64_t i = 0; i < n; ++i, ++q_) {
      while (outer_[row_ + 1] <= q_) ++row_;
      const int32_t c = cols[i];
      if (c < 0 || c >= cols_ || (q_ > outer_[row_] && c <= previous_)) {
        return DataLoss(absl::StrFormat("row %d: column indices invalid", row_));
      }
      previous_ = c;
    }
    return absl::OkStatus();
  }

  static absl::Status Values(const float* values, int64_t n) {
    for (int64_t q = 0; q < n; ++q) {
      if (!std::isfinite(values[q])) return DataLoss("non-finite value in U");
    }
    return absl::OkStatus();
  }

 private:
  const int32_t* outer_;
  int64_t cols_;
  int64_t q_ = 0;    // entries seen
  int64_t row_ = 0;  // the row of entry q_
  int32_t previous_ = 0;
};

// U's three sections into U.
absl::Status ReadRows(Source& src, uint64_t* offset, const Header& h, BasisU& U) {
  U.resize(h.rows, h.cols);
  U.resizeNonZeros(h.nnz);
  const uint64_t nnz = static_cast<uint64_t>(h.nnz);
  const SectionPlan plans[] = {
      {kRowPointers, U.outerIndexPtr(), 4 * (static_cast<uint64_t>(h.rows) + 1)},
      {kColumns, U.innerIndexPtr(), 4 * nnz},
      {kValues, U.valuePtr(), 4 * nnz},
  };
  for (const SectionPlan& plan : plans) {
    if (absl::Status s = ReadSection(src, offset, plan); !s.ok()) return s;
  }
  if (absl::Status s = RowsCheck::RowPointers(U.outerIndexPtr(), h.rows, h.nnz); !s.ok()) return s;
  RowsCheck check(U.outerIndexPtr(), h.cols);
  if (absl::Status s = check.Columns(U.innerIndexPtr(), h.nnz); !s.ok()) return s;
  return RowsCheck::Values(U.valuePtr(), h.nnz);
}

// U's three sections to `sink`, checked piece by piece; U keeps its k x d dimensions only.
absl::Status StreamRows(Source& src, uint64_t* offset, const Header& h, int32_t dofs_per_face,
                        BasisU& U, BasisRowsSink& sink) {
  U.resize(h.rows, h.cols);
  U.makeCompressed();
  std::vector<int32_t> outer(static_cast<size_t>(h.rows) + 1);
  const uint64_t nnz = static_cast<uint64_t>(h.nnz);
  if (absl::Status s = ReadSection(src, offset, {kRowPointers, outer.data(), 4 * outer.size()});
      !s.ok()) {
    return s;
  }
  if (absl::Status s = RowsCheck::RowPointers(outer.data(), h.rows, h.nnz); !s.ok()) return s;
  sink.Begin(h.rows, h.cols, dofs_per_face, outer);
  RowsCheck check(outer.data(), h.cols);
  const size_t chunk = static_cast<size_t>(std::min<uint64_t>(kReadChunk, 4 * nnz)) / 4;
  {
    std::vector<int32_t> cols(chunk);
    absl::Status s = ReadSectionWith(
        src, offset, kColumns, 4 * nnz,
        [&](uint64_t, size_t) { return reinterpret_cast<char*>(cols.data()); },
        [&](const char*, size_t n) {
          absl::Status checked = check.Columns(cols.data(), static_cast<int64_t>(n / 4));
          if (checked.ok()) sink.AddColumns(cols.data(), static_cast<int64_t>(n / 4));
          return checked;
        });
    if (!s.ok()) return s;
  }
  std::vector<float> values(chunk);
  return ReadSectionWith(
      src, offset, kValues, 4 * nnz,
      [&](uint64_t, size_t) { return reinterpret_cast<char*>(values.data()); },
      [&](const char*, size_t n) {
        absl::Status checked = RowsCheck::Values(values.data(), static_cast<int64_t>(n / 4));
        if (checked.ok()) sink.AddValues(values.data(), static_cast<int64_t>(n / 4));
        return checked;
      });
}

// The format from `src`; U's arrays into the basis, or to `rows` when given.
absl::StatusOr<LoadedBasis> Decode(Source& src, BasisRowsSink* rows) {
  uint64_t offset = 0;
  absl::StatusOr<Header> hs = ReadHeader(src, &offset);
  if (!hs.ok()) return hs.status();
  const Header& h = *hs;
  // The exact file size implied by the header, before allocating anything (all counts are
  // bounded above, so no overflow).
  const uint64_t payload[] = {
      4 * static_cast<uint64_t>(h.num_regions), 8 * static_cast<uint64_t>(h.dimension),
      8 * static_cast<uint64_t>(h.num_weights), 4 * (static_cast<uint64_t>(h.rows) + 1),
      4 * static_cast<uint64_t>(h.nnz),         4 * static_cast<uint64_t>(h.nnz)};
  uint64_t expected = offset;
  for (uint64_t b : payload) expected += kSectionHeadBytes + b + kSectionTailBytes;
  if (expected != src.size()) {
    return DataLoss(absl::StrFormat("%s: %d bytes, the header implies %d",
                                    expected > src.size() ? "truncated" : "trailing bytes",
                                    src.size(), expected));
  }
  LoadedBasis out;
  out.mesh_id = h.mesh_id;
  Basis& b = out.basis;
  b.type = FieldType{static_cast<FieldKind>(h.field_kind), h.field_n};
  const int32_t dofs_per_face = b.type.dofs_per_face();
  if (h.rows % dofs_per_face != 0) {
    return DataLoss(absl::StrFormat("%d rows for %d DOFs per face", h.rows, dofs_per_face));
  }
  b.params.dimension = h.dimension;
  if (h.has_fields_per_region) b.params.fields_per_region = h.fields_per_region;
  b.params.sigma = h.sigma;
  b.params.seed = h.seed;
  b.radius = h.radius;
  b.coverage_radius = h.coverage_radius;
  b.uncovered_faces = h.uncovered_faces;
  b.timings.sampling_seconds = h.timings[0];
  b.timings.regions_seconds = h.timings[1];
  b.timings.eigensolve_seconds = h.timings[2];
  b.timings.total_seconds = h.timings[3];
  b.kernel_columns = h.kernel_columns;
  b.stats.hodge_factor_used = h.hodge_factor_used != 0;
  b.stats.dense_regions = h.dense_regions;
  b.stats.lanczos_fallbacks = h.lanczos_fallbacks;
  b.stats.lobpcg_iterations = h.lobpcg_iterations;
  b.stats.max_region_faces = h.max_region_faces;
  b.stats.mean_region_faces = h.mean_region_faces;
  b.sample_faces.resize(h.num_regions);
  b.local_eigenvalues.resize(h.dimension);
  b.params.face_weights.resize(h.num_weights);
  const SectionPlan plans[] = {
      {kSamples, b.sample_faces.data(), payload[0]},
      {kEigenvalues, b.local_eigenvalues.data(), payload[1]},
      {kWeights, b.params.face_weights.data(), payload[2]},
  };
  for (const SectionPlan& plan : plans) {
    if (absl::Status s = ReadSection(src, &offset, plan); !s.ok()) return s;
  }
  absl::Status read = rows == nullptr ? ReadRows(src, &offset, h, b.U)
                                      : StreamRows(src, &offset, h, dofs_per_face, b.U, *rows);
  if (!read.ok()) return read;
  const int64_t faces = h.rows / dofs_per_face;
  for (int32_t s : b.sample_faces) {
    if (s < 0 || s >= faces) return DataLoss("sample face out of range");
  }
  return out;
}

absl::StatusOr<FileSource> OpenSource(const std::string& path) {
  absl::StatusOr<ReadableFile> file = OpenForReading(path);
  if (!file.ok()) return file.status();
  if (!file->is_regular) {
    return absl::InvalidArgumentError(absl::StrCat("'", path, "' is not a regular file"));
  }
  return FileSource(*std::move(file), path);
}

}  // namespace

absl::StatusOr<std::string> EncodeBasis(const Basis& basis, std::string_view mesh_id) {
  std::string out;
  out.reserve(64 + 8 * static_cast<size_t>(basis.U.nonZeros()) + 4 * basis.U.rows() +
              12 * basis.local_eigenvalues.size() + 1024);
  StringSink sink(&out);
  if (absl::Status s = Encode(basis, mesh_id, sink); !s.ok()) return s;
  return out;
}

absl::StatusOr<std::vector<std::string_view>> EncodeBasisPieces(const Basis& basis,
                                                                std::string_view mesh_id,
                                                                std::deque<std::string>* storage) {
  std::vector<std::string_view> pieces;
  if (!basis.U.isCompressed()) {
    // Encode compresses a copy of U, which would not outlive the pieces.
    absl::StatusOr<std::string> whole = EncodeBasis(basis, mesh_id);
    if (!whole.ok()) return whole.status();
    pieces.emplace_back(storage->emplace_back(*std::move(whole)));
    return pieces;
  }
  PiecesSink sink(&pieces, storage);
  if (absl::Status s = Encode(basis, mesh_id, sink); !s.ok()) return s;
  return pieces;
}

absl::StatusOr<LoadedBasis> DecodeBasis(std::string_view bytes) {
  StringSource src(bytes);
  return Decode(src, nullptr);
}

absl::StatusOr<LoadedBasis> DecodeBasisFrom(BasisByteSource& src) { return Decode(src, nullptr); }

absl::StatusOr<LoadedBasis> DecodeBasisFrom(BasisByteSource& src, BasisRowsSink& rows) {
  return Decode(src, &rows);
}

absl::StatusOr<LoadedBasis> DecodeBasis(std::string_view bytes, BasisRowsSink& rows) {
  StringSource src(bytes);
  return Decode(src, &rows);
}

absl::Status SaveBasisFile(const std::string& path, const Basis& basis, std::string_view mesh_id) {
  absl::StatusOr<AtomicFileWriter> out = AtomicFileWriter::Create(path);
  if (!out.ok()) return out.status();
  FileSink sink(*out);
  if (absl::Status s = Encode(basis, mesh_id, sink); !s.ok()) return s;
  return out->Commit();
}

absl::StatusOr<LoadedBasis> LoadBasisFile(const std::string& path) {
  absl::StatusOr<FileSource> src = OpenSource(path);
  if (!src.ok()) return src.status();
  return Decode(*src, nullptr);
}

absl::StatusOr<BasisFileInfo> ReadBasisFileInfo(const std::string& path) {
  absl::StatusOr<FileSource> src = OpenSource(path);
  if (!src.ok()) return src.status();
  uint64_t header_end = 0;
  absl::StatusOr<Header> h = ReadHeader(*src, &header_end);
  if (!h.ok()) return h.status();
  BasisFileInfo info;
  info.mesh_id = h->mesh_id;
  info.type = FieldType{static_cast<FieldKind>(h->field_kind), h->field_n};
  info.params.dimension = h->dimension;
  if (h->has_fields_per_region) info.params.fields_per_region = h->fields_per_region;
  info.params.sigma = h->sigma;
  info.params.seed = h->seed;
  info.num_weights = h->num_weights;
  info.rows = h->rows;
  info.nnz = h->nnz;
  info.num_regions = h->num_regions;
  info.kernel_columns = h->kernel_columns;
  info.file_bytes = static_cast<int64_t>(src->size());
  return info;
}

}  // namespace fieldspace
