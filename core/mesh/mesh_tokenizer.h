#ifndef FIELDSPACE_CORE_MESH_MESH_TOKENIZER_H_
#define FIELDSPACE_CORE_MESH_MESH_TOKENIZER_H_

#include <algorithm>
#include <charconv>
#include <cstdint>
#include <functional>
#include <limits>
#include <string>
#include <system_error>
#include <utility>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/string_view.h"
#include "core/mesh/mesh_io.h"

// What the mesh readers (obj_reader.cc, off_reader.cc, ply_reader.cc) share: error messages, the
// text tokenizer and the collectors of vertices and triangles. Internal to core/mesh.

namespace fieldspace::mesh_io_internal {

constexpr int64_t kMaxIndex = std::numeric_limits<int32_t>::max();

// ---------------------------------------------------------------------------------------------
// Errors

// Quotes a piece of input for an error message: bounded length, non-printable bytes escaped (the
// input may be binary garbage).
std::string Quote(absl::string_view s);

template <typename... Args>
absl::Status LineError(absl::string_view label, int64_t line, const Args&... args) {
  return absl::InvalidArgumentError(absl::StrCat(label, " line ", line, ": ", args...));
}

template <typename... Args>
absl::Status DataError(absl::string_view label, const Args&... args) {
  return absl::InvalidArgumentError(absl::StrCat(label, ": ", args...));
}

absl::Status TooManyVertices(absl::string_view label, int64_t limit);

absl::Status TooManyFaces(absl::string_view label, int64_t limit);

// ---------------------------------------------------------------------------------------------
// Text scanning (OBJ, OFF, ascii PLY). Everything works on the whole buffer with std::from_chars:
// no iostreams, no per-token allocation.

// Blanks inside a line (line breaks are handled by LineReader).
inline bool IsBlank(char c) { return c == ' ' || c == '\t' || c == '\v' || c == '\f'; }
inline bool IsSpace(char c) { return IsBlank(c) || c == '\n' || c == '\r'; }

enum class Num : uint8_t { kOk, kMissing, kBad, kOutOfRange };

// Parses a number at `p` (advancing it past the number on success or out-of-range). Accepts a
// leading '+', which std::from_chars does not.
template <typename T>
Num ParseNumber(const char*& p, const char* end, T* out) {
  const char* s = p;
  if (s != end && *s == '+' && s + 1 != end && s[1] != '+' && s[1] != '-') ++s;
  const auto [ptr, ec] = std::from_chars(s, end, *out);
  if (ec == std::errc::invalid_argument) return Num::kBad;
  p = ptr;
  return ec == std::errc::result_out_of_range ? Num::kOutOfRange : Num::kOk;
}

// Splits a buffer into lines ending in "\n", "\r\n" or a bare "\r"; the terminators are not part of
// the returned lines. Linear: every byte is looked at once.
class LineReader {
 public:
  explicit LineReader(absl::string_view data) : data_(data) {}

  bool Next(absl::string_view* line) {
    if (pos_ >= data_.size()) return false;
    const char* const begin = data_.data() + pos_;
    const char* const end = data_.data() + data_.size();
    const char* p = begin;
    while (p != end && *p != '\n' && *p != '\r') ++p;
    *line = absl::string_view(begin, static_cast<size_t>(p - begin));
    if (p != end && *p == '\r' && p + 1 != end && p[1] == '\n') ++p;
    if (p != end) ++p;
    pos_ = static_cast<size_t>(p - data_.data());
    ++line_number_;
    return true;
  }

  // 1-based number of the line last returned by Next().
  int64_t line_number() const { return line_number_; }
  // Bytes not yet returned.
  int64_t remaining() const { return static_cast<int64_t>(data_.size() - pos_); }

 private:
  absl::string_view data_;
  size_t pos_ = 0;
  int64_t line_number_ = 0;
};

// Blank-separated tokens within one line.
struct LineCursor {
  explicit LineCursor(absl::string_view line) : p(line.data()), end(line.data() + line.size()) {}

  void SkipBlanks() {
    while (p != end && IsBlank(*p)) ++p;
  }
  bool AtEnd() {
    SkipBlanks();
    return p == end;
  }
  absl::string_view Token() {
    SkipBlanks();
    const char* s = p;
    while (p != end && !IsBlank(*p)) ++p;
    return absl::string_view(s, static_cast<size_t>(p - s));
  }
  // The next token without consuming it (for error messages).
  absl::string_view PeekToken() {
    const char* saved = p;
    absl::string_view t = Token();
    p = saved;
    return t;
  }
  // Reads a whole token as a number; on failure the cursor stays at the token.
  template <typename T>
  Num Number(T* out) {
    SkipBlanks();
    if (p == end) return Num::kMissing;
    const char* tok = p;
    Num st = ParseNumber(p, end, out);
    if (st == Num::kOk && p != end && !IsBlank(*p)) st = Num::kBad;
    if (st != Num::kOk) p = tok;
    return st;
  }

  const char* p;
  const char* end;
};

// Message for a failed LineCursor::Number() call reading `what`.
std::string NumberProblem(Num st, LineCursor& cur, absl::string_view what);

// The bytes of the arrays a reader fills, reported to MeshReadOptions::reserve_memory before each
// allocation that grows them (so that a caller can refuse it before it is made).
class ArrayMemory {
 public:
  explicit ArrayMemory(const MeshReadOptions& options) : reserve_(options.reserve_memory) {}

  // One of the arrays goes from `old_bytes` to `new_bytes` (the reader allocates after an OK).
  absl::Status Resize(int64_t old_bytes, int64_t new_bytes) {
    total_ += new_bytes - old_bytes;
    if (new_bytes <= old_bytes || !reserve_) return absl::OkStatus();
    return reserve_(total_);
  }

 private:
  const std::function<absl::Status(int64_t)>& reserve_;
  int64_t total_ = 0;
};

// Appends rows to a row-major #rows x 3 Eigen matrix, growing it geometrically. Rows are written
// straight into the matrix the result returns: Eigen's conservativeResize on the row count of a
// row-major matrix is a realloc, so neither growth nor the final trim copies through a second
// buffer (for the 1.8M-face meshes that copy costs more than parsing).
template <typename Matrix>
class RowBuffer {
 public:
  using Scalar = typename Matrix::Scalar;

  explicit RowBuffer(ArrayMemory& memory) : memory_(memory) {}

  absl::Status Reserve(int64_t rows) {
    if (rows > matrix_.rows()) return Grow(rows);
    return absl::OkStatus();
  }
  absl::Status Append(Scalar a, Scalar b, Scalar c) {
    if (size_ == matrix_.rows()) {
      if (absl::Status st = Grow(std::max<int64_t>(64, 2 * size_)); !st.ok()) return st;
    }
    Scalar* row = matrix_.data() + 3 * size_;
    row[0] = a;
    row[1] = b;
    row[2] = c;
    ++size_;
    return absl::OkStatus();
  }
  int64_t size() const { return size_; }
  Matrix Take() {
    if (matrix_.rows() != size_) {
      memory_.Resize(RowBytes(matrix_.rows()), RowBytes(size_)).IgnoreError();  // a shrink
      matrix_.conservativeResize(size_, 3);
    }
    size_ = 0;
    return std::move(matrix_);
  }

 private:
  static int64_t RowBytes(int64_t rows) { return rows * 3 * int64_t{sizeof(Scalar)}; }
  absl::Status Grow(int64_t rows) {
    if (absl::Status st = memory_.Resize(RowBytes(matrix_.rows()), RowBytes(rows)); !st.ok()) {
      return st;
    }
    matrix_.conservativeResize(rows, 3);
    return absl::OkStatus();
  }

  ArrayMemory& memory_;
  Matrix matrix_;
  int64_t size_ = 0;
};

// Collected triangles; the fan triangulation and the face limit live here so that every reader
// treats polygons the same way.
class TriangleSink {
 public:
  TriangleSink(const MeshReadOptions& options, absl::string_view label, ArrayMemory& memory)
      : options_(options), label_(label), faces_(memory) {}

  absl::Status Reserve(int64_t triangles) { return faces_.Reserve(triangles); }

  // Adds a face given by its (already validated, zero-based) corners. `where` starts its error
  // messages ("OBJ line 12", "PLY: face 7").
  absl::Status AddFace(const int32_t* corners, int64_t n, const std::string& where) {
    if (n < 3) {
      return absl::InvalidArgumentError(absl::StrCat(where, ": face has ", n, " vertices"));
    }
    if (n > 3) {
      if (!options_.triangulate_polygons) {
        return absl::InvalidArgumentError(
            absl::StrCat(where, ": face has ", n, " vertices (polygon triangulation is disabled)"));
      }
      ++polygons_;
    }
    if (faces_.size() + (n - 2) > options_.max_faces) {
      return TooManyFaces(label_, options_.max_faces);
    }
    for (int64_t k = 1; k + 1 < n; ++k) {
      if (absl::Status st = faces_.Append(corners[0], corners[k], corners[k + 1]); !st.ok()) {
        return st;
      }
    }
    return absl::OkStatus();
  }

  // The common case without building a location string.
  absl::Status AddTriangle(int32_t a, int32_t b, int32_t c) {
    if (faces_.size() >= options_.max_faces) return TooManyFaces(label_, options_.max_faces);
    return faces_.Append(a, b, c);
  }

  int64_t polygons() const { return polygons_; }
  FaceMatrix Take() { return faces_.Take(); }

 private:
  const MeshReadOptions& options_;
  absl::string_view label_;
  RowBuffer<FaceMatrix> faces_;
  int64_t polygons_ = 0;
};

// ---------------------------------------------------------------------------------------------
// The readers, one per format (mesh_io.h describes what they check). `label` starts their error
// messages: the format's name, or the file's base name.

absl::StatusOr<MeshReadResult> ParseObj(absl::string_view data, const MeshReadOptions& options,
                                        absl::string_view label);
absl::StatusOr<MeshReadResult> ParseOff(absl::string_view data, const MeshReadOptions& options,
                                        absl::string_view label);
absl::StatusOr<MeshReadResult> ParsePly(absl::string_view data, const MeshReadOptions& options,
                                        absl::string_view label);

}  // namespace fieldspace::mesh_io_internal

#endif  // FIELDSPACE_CORE_MESH_MESH_TOKENIZER_H_
