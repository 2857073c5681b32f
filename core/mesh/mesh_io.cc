#include "core/mesh/mesh_io.h"

#include <algorithm>
#include <array>
#include <bit>
#include <charconv>
#include <cmath>
#include <cstring>
#include <limits>
#include <optional>
#include <string>
#include <string_view>
#include <system_error>
#include <type_traits>
#include <utility>
#include <vector>

#include "absl/status/status.h"
#include "absl/strings/ascii.h"
#include "absl/strings/escaping.h"
#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/string_view.h"
#include "absl/strings/strip.h"
#include "core/common/file_util.h"
#include "core/common/status_macros.h"

namespace fieldspace {
namespace {

constexpr int64_t kMaxIndex = std::numeric_limits<int32_t>::max();

// ---------------------------------------------------------------------------------------------
// Errors

// Quotes a piece of input for an error message: bounded length, non-printable bytes escaped (the
// input may be binary garbage).
std::string Quote(absl::string_view s) {
  constexpr size_t kMaxShown = 40;
  std::string out = absl::StrCat("'", absl::CHexEscape(s.substr(0, kMaxShown)));
  if (s.size() > kMaxShown) out += "...";
  out += "'";
  return out;
}

template <typename... Args>
absl::Status LineError(absl::string_view label, int64_t line, const Args&... args) {
  return absl::InvalidArgumentError(absl::StrCat(label, " line ", line, ": ", args...));
}

template <typename... Args>
absl::Status DataError(absl::string_view label, const Args&... args) {
  return absl::InvalidArgumentError(absl::StrCat(label, ": ", args...));
}

absl::Status TooManyVertices(absl::string_view label, int64_t limit) {
  return absl::ResourceExhaustedError(
      absl::StrCat(label, ": more than ", limit, " vertices (MeshReadOptions::max_vertices)"));
}

absl::Status TooManyFaces(absl::string_view label, int64_t limit) {
  return absl::ResourceExhaustedError(
      absl::StrCat(label, ": more than ", limit, " faces (MeshReadOptions::max_faces)"));
}

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
std::string NumberProblem(Num st, LineCursor& cur, absl::string_view what) {
  switch (st) {
    case Num::kMissing:
      return absl::StrCat("missing ", what);
    case Num::kOutOfRange:
      return absl::StrCat(what, " ", Quote(cur.PeekToken()), " is out of range");
    default:
      return absl::StrCat("invalid ", what, " ", Quote(cur.PeekToken()));
  }
}

// Appends rows to a row-major #rows x 3 Eigen matrix, growing it geometrically. Rows are written
// straight into the matrix the result returns: Eigen's conservativeResize on the row count of a
// row-major matrix is a realloc, so neither growth nor the final trim copies through a second
// buffer (for the 1.8M-face meshes that copy costs more than parsing).
template <typename Matrix>
class RowBuffer {
 public:
  using Scalar = typename Matrix::Scalar;

  void Reserve(int64_t rows) {
    if (rows > matrix_.rows()) matrix_.conservativeResize(rows, 3);
  }
  void Append(Scalar a, Scalar b, Scalar c) {
    if (size_ == matrix_.rows()) matrix_.conservativeResize(std::max<int64_t>(64, 2 * size_), 3);
    Scalar* row = matrix_.data() + 3 * size_;
    row[0] = a;
    row[1] = b;
    row[2] = c;
    ++size_;
  }
  int64_t size() const { return size_; }
  Matrix Take() {
    if (matrix_.rows() != size_) matrix_.conservativeResize(size_, 3);
    size_ = 0;
    return std::move(matrix_);
  }

 private:
  Matrix matrix_;
  int64_t size_ = 0;
};

// Collected triangles; the fan triangulation and the face limit live here so that every reader
// treats polygons the same way.
class TriangleSink {
 public:
  TriangleSink(const MeshReadOptions& options, absl::string_view label)
      : options_(options), label_(label) {}

  void Reserve(int64_t triangles) { faces_.Reserve(triangles); }

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
    for (int64_t k = 1; k + 1 < n; ++k) faces_.Append(corners[0], corners[k], corners[k + 1]);
    return absl::OkStatus();
  }

  // The common case without building a location string.
  absl::Status AddTriangle(int32_t a, int32_t b, int32_t c) {
    if (faces_.size() >= options_.max_faces) return TooManyFaces(label_, options_.max_faces);
    faces_.Append(a, b, c);
    return absl::OkStatus();
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
// OBJ

// Statements that carry nothing we need (texture coordinates, normals, groups, materials,
// smoothing, free-form geometry, lines and points).
bool IsIgnoredObjStatement(absl::string_view kw) {
  static constexpr std::array<absl::string_view, 37> kIgnored = {
      "vt",        "vn",     "vp",     "l",      "p",        "o",        "g",    "s",
      "usemtl",    "mtllib", "usemap", "maplib", "cstype",   "deg",      "bmat", "step",
      "curv",      "curv2",  "surf",   "parm",   "trim",     "hole",     "scrv", "sp",
      "end",       "con",    "mg",     "bevel",  "c_interp", "d_interp", "lod",  "shadow_obj",
      "trace_obj", "ctech",  "stech",  "call",   "csh"};
  return std::find(kIgnored.begin(), kIgnored.end(), kw) != kIgnored.end();
}

// Parses one face corner "v", "v/t", "v/t/n" or "v//n" into its raw vertex index (1-based, or
// negative = relative to the end). Texture and normal indices are checked for syntax only.
Num ParseObjCorner(LineCursor& cur, int64_t* v) {
  cur.SkipBlanks();
  const char* tok = cur.p;
  Num st = ParseNumber(cur.p, cur.end, v);
  if (st != Num::kOk) {
    cur.p = tok;
    return st;
  }
  for (int slashes = 0; slashes < 2 && cur.p != cur.end && *cur.p == '/'; ++slashes) {
    ++cur.p;
    if (cur.p != cur.end && *cur.p != '/' && !IsBlank(*cur.p)) {
      int64_t ignored = 0;
      if (ParseNumber(cur.p, cur.end, &ignored) == Num::kBad) {
        cur.p = tok;
        return Num::kBad;
      }
    }
  }
  if (cur.p != cur.end && !IsBlank(*cur.p)) {
    cur.p = tok;
    return Num::kBad;
  }
  return Num::kOk;
}

absl::StatusOr<MeshReadResult> ParseObj(absl::string_view data, const MeshReadOptions& options,
                                        absl::string_view label) {
  RowBuffer<VertexMatrix> vertices;
  TriangleSink sink(options, label);
  std::vector<int32_t> corners;
  LineReader lines(data);
  absl::string_view line;
  while (lines.Next(&line)) {
    LineCursor cur(line);
    const absl::string_view kw = cur.Token();
    if (kw.empty() || kw[0] == '#') continue;
    const int64_t num_vertices = vertices.size();
    if (kw == "v") {
      if (num_vertices >= options.max_vertices) {
        return TooManyVertices(label, options.max_vertices);
      }
      // Extra components (w, vertex colors) after x y z are ignored.
      double xyz[3];
      for (double& value : xyz) {
        if (Num st = cur.Number(&value); st != Num::kOk) {
          return LineError(label, lines.line_number(), NumberProblem(st, cur, "vertex coordinate"));
        }
      }
      vertices.Append(xyz[0], xyz[1], xyz[2]);
    } else if (kw == "f") {
      corners.clear();
      while (!cur.AtEnd() && *cur.p != '#') {
        int64_t raw = 0;
        if (Num st = ParseObjCorner(cur, &raw); st != Num::kOk) {
          if (st == Num::kOutOfRange) {
            return LineError(label, lines.line_number(), "vertex index ", Quote(cur.PeekToken()),
                             " does not fit int32");
          }
          return LineError(label, lines.line_number(), "invalid face corner ",
                           Quote(cur.PeekToken()));
        }
        int64_t index = 0;
        if (raw > 0) {
          index = raw - 1;
        } else if (raw < 0) {
          index = num_vertices + raw;
          if (index < 0) {
            return LineError(label, lines.line_number(), "relative vertex index ", raw,
                             " refers before the first vertex (", num_vertices,
                             " vertices so far)");
          }
        } else {
          return LineError(label, lines.line_number(),
                           "vertex index 0 is invalid (OBJ indices start at 1)");
        }
        if (index > kMaxIndex) {
          return LineError(label, lines.line_number(), "vertex index ", raw, " does not fit int32");
        }
        corners.push_back(static_cast<int32_t>(index));
      }
      const int64_t n = static_cast<int64_t>(corners.size());
      if (n == 3) {
        RETURN_IF_ERROR(sink.AddTriangle(corners[0], corners[1], corners[2]));
      } else {
        RETURN_IF_ERROR(
            sink.AddFace(corners.data(), n, absl::StrCat(label, " line ", lines.line_number())));
      }
    } else if (!IsIgnoredObjStatement(kw)) {
      return LineError(label, lines.line_number(), "unknown OBJ statement ", Quote(kw));
    }
  }
  MeshReadResult result;
  result.arrays.vertices = vertices.Take();
  result.arrays.faces = sink.Take();
  result.polygons_triangulated = sink.polygons();
  return result;
}

// ---------------------------------------------------------------------------------------------
// OFF

// The next line with content, '#' comments removed. False at the end of the data.
bool NextOffLine(LineReader& lines, absl::string_view* line) {
  while (lines.Next(line)) {
    if (const size_t hash = line->find('#'); hash != absl::string_view::npos) {
      *line = line->substr(0, hash);
    }
    LineCursor cur(*line);
    if (!cur.AtEnd()) return true;
  }
  return false;
}

absl::StatusOr<MeshReadResult> ParseOff(absl::string_view data, const MeshReadOptions& options,
                                        absl::string_view label) {
  LineReader lines(data);
  absl::string_view line;
  if (!NextOffLine(lines, &line)) return DataError(label, "empty file (no OFF header)");
  LineCursor header(line);
  // Header keyword [ST][C][N][4][n]OFF: texture coordinates, colors and normals only add columns
  // to the vertex lines, which we skip; 4D and n-dimensional vertices we cannot use.
  const absl::string_view kw = header.Token();
  if (!absl::EndsWith(kw, "OFF")) {
    return LineError(label, lines.line_number(), "expected an OFF header, found ", Quote(kw));
  }
  absl::string_view prefix = kw.substr(0, kw.size() - 3);
  bool higher_dimension = false;
  for (absl::string_view part : {"ST", "C", "N", "4", "n"}) {
    if (absl::ConsumePrefix(&prefix, part)) higher_dimension |= (part == "4" || part == "n");
  }
  if (!prefix.empty()) {
    return LineError(label, lines.line_number(), "unknown OFF header ", Quote(kw));
  }
  if (higher_dimension) {
    return LineError(label, lines.line_number(), "OFF header ", Quote(kw),
                     ": only 3D vertices are supported");
  }
  if (header.PeekToken() == "BINARY") {
    return LineError(label, lines.line_number(), "binary OFF is not supported");
  }
  // Counts follow on the same line or on the next line with content.
  LineCursor counts = header;
  if (counts.AtEnd()) {
    if (!NextOffLine(lines, &line)) return DataError(label, "missing vertex and face counts");
    counts = LineCursor(line);
  }
  int64_t num_vertices = 0;
  int64_t num_faces = 0;
  if (Num st = counts.Number(&num_vertices); st != Num::kOk) {
    return LineError(label, lines.line_number(), NumberProblem(st, counts, "vertex count"));
  }
  if (Num st = counts.Number(&num_faces); st != Num::kOk) {
    return LineError(label, lines.line_number(), NumberProblem(st, counts, "face count"));
  }
  // The edge count, if present, is not needed.
  if (num_vertices < 0 || num_faces < 0) {
    return LineError(label, lines.line_number(), "negative vertex or face count");
  }
  if (num_vertices > options.max_vertices) return TooManyVertices(label, options.max_vertices);
  if (num_faces > options.max_faces) return TooManyFaces(label, options.max_faces);
  // Each vertex line needs at least "0 0 0\n" (6 bytes), each face "3 0 1 2\n" (8 bytes); the last
  // line may lack its newline. Checked before allocating for the declared counts.
  const int64_t available = lines.remaining();
  if (num_vertices > available / 6 || num_faces > available / 8 ||
      6 * num_vertices + 8 * num_faces - 1 > available) {
    return DataError(label, "header declares ", num_vertices, " vertices and ", num_faces,
                     " faces but only ", available, " bytes follow");
  }

  MeshReadResult result;
  VertexMatrix& V = result.arrays.vertices;
  V.resize(num_vertices, 3);
  for (int64_t i = 0; i < num_vertices; ++i) {
    if (!NextOffLine(lines, &line)) {
      return DataError(label, "file ends after ", i, " of ", num_vertices, " vertices");
    }
    LineCursor cur(line);
    for (int k = 0; k < 3; ++k) {
      if (Num st = cur.Number(&V(i, k)); st != Num::kOk) {
        return LineError(label, lines.line_number(), NumberProblem(st, cur, "vertex coordinate"));
      }
    }
  }
  TriangleSink sink(options, label);
  sink.Reserve(num_faces);
  std::vector<int32_t> corners;
  for (int64_t f = 0; f < num_faces; ++f) {
    if (!NextOffLine(lines, &line)) {
      return DataError(label, "file ends after ", f, " of ", num_faces, " faces");
    }
    LineCursor cur(line);
    int64_t n = 0;
    if (Num st = cur.Number(&n); st != Num::kOk) {
      return LineError(label, lines.line_number(), NumberProblem(st, cur, "face corner count"));
    }
    corners.clear();
    // Reads at most the indices present on the line, so an absurd n cannot allocate.
    for (int64_t k = 0; k < n; ++k) {
      int64_t index = 0;
      if (Num st = cur.Number(&index); st != Num::kOk) {
        if (st == Num::kMissing) {
          return LineError(label, lines.line_number(), "face declares ", n, " vertices but lists ",
                           k);
        }
        return LineError(label, lines.line_number(), NumberProblem(st, cur, "vertex index"));
      }
      if (index < 0 || index > kMaxIndex) {
        return LineError(label, lines.line_number(), "vertex index ", index,
                         index < 0 ? " is negative" : " does not fit int32");
      }
      corners.push_back(static_cast<int32_t>(index));
    }
    // Anything after the indices (a face color) is ignored.
    if (n == 3) {
      RETURN_IF_ERROR(sink.AddTriangle(corners[0], corners[1], corners[2]));
    } else {
      RETURN_IF_ERROR(
          sink.AddFace(corners.data(), n, absl::StrCat(label, " line ", lines.line_number())));
    }
  }
  result.arrays.faces = sink.Take();
  result.polygons_triangulated = sink.polygons();
  return result;
}

// ---------------------------------------------------------------------------------------------
// PLY

enum class PlyType : uint8_t {
  kInt8,
  kUInt8,
  kInt16,
  kUInt16,
  kInt32,
  kUInt32,
  kFloat32,
  kFloat64
};

std::optional<PlyType> ParsePlyType(absl::string_view name) {
  static constexpr std::array<std::pair<absl::string_view, PlyType>, 16> kNames = {{
      {"char", PlyType::kInt8},
      {"int8", PlyType::kInt8},
      {"uchar", PlyType::kUInt8},
      {"uint8", PlyType::kUInt8},
      {"short", PlyType::kInt16},
      {"int16", PlyType::kInt16},
      {"ushort", PlyType::kUInt16},
      {"uint16", PlyType::kUInt16},
      {"int", PlyType::kInt32},
      {"int32", PlyType::kInt32},
      {"uint", PlyType::kUInt32},
      {"uint32", PlyType::kUInt32},
      {"float", PlyType::kFloat32},
      {"float32", PlyType::kFloat32},
      {"double", PlyType::kFloat64},
      {"float64", PlyType::kFloat64},
  }};
  for (const auto& [n, t] : kNames) {
    if (n == name) return t;
  }
  return std::nullopt;
}

int PlyTypeSize(PlyType t) {
  switch (t) {
    case PlyType::kInt8:
    case PlyType::kUInt8:
      return 1;
    case PlyType::kInt16:
    case PlyType::kUInt16:
      return 2;
    case PlyType::kInt32:
    case PlyType::kUInt32:
    case PlyType::kFloat32:
      return 4;
    case PlyType::kFloat64:
      return 8;
  }
  return 0;
}

bool IsIntegral(PlyType t) { return t != PlyType::kFloat32 && t != PlyType::kFloat64; }

enum class PlyEncoding : uint8_t { kAscii, kBinaryLittleEndian, kBinaryBigEndian };

// What the reader does with a property.
enum class PlyRole : uint8_t { kSkip, kX, kY, kZ, kFaceIndices };

struct PlyProperty {
  std::string name;
  bool is_list = false;
  PlyType type = PlyType::kFloat32;      // scalar type, or the list's item type
  PlyType count_type = PlyType::kUInt8;  // lists only
  PlyRole role = PlyRole::kSkip;
};

struct PlyElement {
  std::string name;
  int64_t count = 0;
  std::vector<PlyProperty> properties;
};

struct PlyHeader {
  PlyEncoding encoding = PlyEncoding::kAscii;
  std::vector<PlyElement> elements;
  size_t body_offset = 0;  // first byte after the end_header line
  int64_t body_line = 1;   // line number of the body's first line (ascii)
};

absl::StatusOr<PlyHeader> ParsePlyHeader(absl::string_view data, absl::string_view label) {
  PlyHeader header;
  size_t pos = 0;
  int64_t line_number = 0;
  bool have_format = false;
  while (true) {
    const size_t nl = data.find('\n', pos);
    if (nl == absl::string_view::npos) {
      return line_number == 0 ? DataError(label, "not a PLY file (no 'ply' line)")
                              : DataError(label, "header has no end_header line");
    }
    absl::string_view line = data.substr(pos, nl - pos);
    if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
    pos = nl + 1;
    ++line_number;
    LineCursor cur(line);
    if (line_number == 1) {
      if (cur.Token() != "ply" || !cur.AtEnd()) return DataError(label, "not a PLY file");
      continue;
    }
    const absl::string_view kw = cur.Token();
    if (kw == "comment" || kw == "obj_info" || kw.empty()) continue;
    if (kw == "end_header") break;
    if (kw == "format") {
      const absl::string_view enc = cur.Token();
      if (enc == "ascii") {
        header.encoding = PlyEncoding::kAscii;
      } else if (enc == "binary_little_endian") {
        header.encoding = PlyEncoding::kBinaryLittleEndian;
      } else if (enc == "binary_big_endian") {
        header.encoding = PlyEncoding::kBinaryBigEndian;
      } else {
        return LineError(label, line_number, "unknown format ", Quote(enc));
      }
      have_format = true;
    } else if (kw == "element") {
      PlyElement element;
      element.name = std::string(cur.Token());
      if (element.name.empty()) return LineError(label, line_number, "element without a name");
      if (Num st = cur.Number(&element.count); st != Num::kOk) {
        return LineError(label, line_number, NumberProblem(st, cur, "element count"));
      }
      if (element.count < 0) return LineError(label, line_number, "negative element count");
      for (const PlyElement& other : header.elements) {
        if (other.name == element.name) {
          return LineError(label, line_number, "duplicate element ", Quote(element.name));
        }
      }
      header.elements.push_back(std::move(element));
    } else if (kw == "property") {
      if (header.elements.empty()) {
        return LineError(label, line_number, "property before any element");
      }
      PlyProperty property;
      absl::string_view type_name = cur.Token();
      if (type_name == "list") {
        property.is_list = true;
        const absl::string_view count_name = cur.Token();
        const std::optional<PlyType> count_type = ParsePlyType(count_name);
        if (!count_type.has_value() || !IsIntegral(*count_type)) {
          return LineError(label, line_number, "invalid list count type ", Quote(count_name));
        }
        property.count_type = *count_type;
        type_name = cur.Token();
      }
      const std::optional<PlyType> type = ParsePlyType(type_name);
      if (!type.has_value()) {
        return LineError(label, line_number, "unknown property type ", Quote(type_name));
      }
      property.type = *type;
      property.name = std::string(cur.Token());
      if (property.name.empty()) return LineError(label, line_number, "property without a name");
      PlyElement& element = header.elements.back();
      for (const PlyProperty& other : element.properties) {
        if (other.name == property.name) {
          return LineError(label, line_number, "duplicate property ", Quote(property.name),
                           " in element ", Quote(element.name));
        }
      }
      element.properties.push_back(std::move(property));
    } else {
      return LineError(label, line_number, "unknown header line ", Quote(line));
    }
  }
  if (!have_format) return DataError(label, "header has no format line");
  header.body_offset = pos;
  header.body_line = line_number + 1;
  return header;
}

// Marks the properties the reader needs (x, y, z of 'vertex', the index list of 'face') and
// checks they exist with usable types. Returns the indices of the two elements.
absl::Status AssignPlyRoles(PlyHeader& header, absl::string_view label, int* vertex_element,
                            int* face_element) {
  *vertex_element = -1;
  *face_element = -1;
  for (int e = 0; e < static_cast<int>(header.elements.size()); ++e) {
    PlyElement& element = header.elements[e];
    if (element.name == "vertex") {
      *vertex_element = e;
      for (char axis : {'x', 'y', 'z'}) {
        auto it =
            std::find_if(element.properties.begin(), element.properties.end(),
                         [&](const PlyProperty& p) { return p.name == std::string(1, axis); });
        if (it == element.properties.end()) {
          return DataError(label, "element 'vertex' has no property '", std::string(1, axis), "'");
        }
        if (it->is_list) {
          return DataError(label, "vertex property '", std::string(1, axis), "' is a list");
        }
        it->role = axis == 'x' ? PlyRole::kX : axis == 'y' ? PlyRole::kY : PlyRole::kZ;
      }
    } else if (element.name == "face") {
      *face_element = e;
      auto it = std::find_if(element.properties.begin(), element.properties.end(),
                             [](const PlyProperty& p) {
                               return p.name == "vertex_indices" || p.name == "vertex_index";
                             });
      if (it == element.properties.end()) {
        return DataError(label,
                         "element 'face' has no property 'vertex_indices' or 'vertex_index'");
      }
      if (!it->is_list || !IsIntegral(it->type)) {
        return DataError(label, "face property '", it->name, "' is not a list of integers");
      }
      it->role = PlyRole::kFaceIndices;
    }
  }
  if (*vertex_element < 0) return DataError(label, "no 'vertex' element");
  if (*face_element < 0) return DataError(label, "no 'face' element");
  return absl::OkStatus();
}

// Checks that every element can fit in the bytes after the header, assuming the smallest possible
// encoding of each item (binary: scalars and list counts, empty lists; ascii: one digit and one
// separator per scalar or list count). Keeps absurd header counts from allocating or looping.
absl::Status CheckPlySizes(const PlyHeader& header, int64_t available, absl::string_view label) {
  int64_t needed = 0;
  for (const PlyElement& element : header.elements) {
    int64_t per_item = 0;
    for (const PlyProperty& p : element.properties) {
      per_item += header.encoding == PlyEncoding::kAscii
                      ? 2
                      : PlyTypeSize(p.is_list ? p.count_type : p.type);
    }
    if (per_item == 0) continue;
    const int64_t budget = available - needed + (header.encoding == PlyEncoding::kAscii ? 1 : 0);
    if (element.count > budget / per_item) {
      return DataError(label, "header declares ", element.count, " items of element '",
                       element.name, "' but only ", available, " bytes of data follow the header");
    }
    needed += element.count * per_item;
  }
  return absl::OkStatus();
}

// ---- binary

template <typename T>
T Load(const char* p, bool swap) {
  if constexpr (sizeof(T) == 1) {
    T v;
    std::memcpy(&v, p, 1);
    return v;
  } else {
    using U = std::conditional_t<sizeof(T) == 2, uint16_t,
                                 std::conditional_t<sizeof(T) == 4, uint32_t, uint64_t>>;
    U u;
    std::memcpy(&u, p, sizeof(U));
    if (swap) {
      if constexpr (sizeof(T) == 2) {
        u = __builtin_bswap16(u);
      } else if constexpr (sizeof(T) == 4) {
        u = __builtin_bswap32(u);
      } else {
        u = __builtin_bswap64(u);
      }
    }
    T v;
    std::memcpy(&v, &u, sizeof(T));
    return v;
  }
}

double LoadAsDouble(PlyType t, const char* p, bool swap) {
  switch (t) {
    case PlyType::kInt8:
      return Load<int8_t>(p, swap);
    case PlyType::kUInt8:
      return Load<uint8_t>(p, swap);
    case PlyType::kInt16:
      return Load<int16_t>(p, swap);
    case PlyType::kUInt16:
      return Load<uint16_t>(p, swap);
    case PlyType::kInt32:
      return Load<int32_t>(p, swap);
    case PlyType::kUInt32:
      return Load<uint32_t>(p, swap);
    case PlyType::kFloat32:
      return Load<float>(p, swap);
    case PlyType::kFloat64:
      return Load<double>(p, swap);
  }
  return 0.0;
}

// Integral types only (checked in the header).
int64_t LoadAsInt(PlyType t, const char* p, bool swap) {
  switch (t) {
    case PlyType::kInt8:
      return Load<int8_t>(p, swap);
    case PlyType::kUInt8:
      return Load<uint8_t>(p, swap);
    case PlyType::kInt16:
      return Load<int16_t>(p, swap);
    case PlyType::kUInt16:
      return Load<uint16_t>(p, swap);
    case PlyType::kInt32:
      return Load<int32_t>(p, swap);
    case PlyType::kUInt32:
      return Load<uint32_t>(p, swap);
    default:
      return 0;
  }
}

absl::Status IndexError(absl::string_view label, int64_t face, int64_t index) {
  return DataError(label, "face ", face, " has vertex index ", index,
                   index < 0 ? " (negative)" : " (does not fit int32)");
}

// Reads the body of a binary PLY. `result.arrays.vertices` is already sized.
class PlyBinaryReader {
 public:
  PlyBinaryReader(const PlyHeader& header, absl::string_view body, absl::string_view label,
                  TriangleSink& sink, VertexMatrix& V)
      : header_(header),
        p_(body.data()),
        end_(body.data() + body.size()),
        swap_((header.encoding == PlyEncoding::kBinaryLittleEndian) !=
              (std::endian::native == std::endian::little)),
        label_(label),
        sink_(sink),
        V_(V) {}

  absl::Status Read() {
    for (const PlyElement& element : header_.elements) {
      RETURN_IF_ERROR(ReadElement(element));
    }
    return absl::OkStatus();
  }

 private:
  absl::Status Truncated(const PlyElement& element, int64_t item) const {
    return DataError(label_, "truncated binary data in element '", element.name, "' at item ",
                     item);
  }

  absl::Status ReadElement(const PlyElement& element) {
    bool fixed_size = true;
    int64_t item_size = 0;
    for (const PlyProperty& p : element.properties) {
      fixed_size &= !p.is_list;
      item_size += PlyTypeSize(p.type);
    }
    if (fixed_size) {
      // CheckPlySizes assumed the earlier elements' lists were empty; they may not have been.
      if (item_size > 0 && (end_ - p_) / item_size < element.count) {
        return Truncated(element, (end_ - p_) / item_size);
      }
      if (element.name == "vertex") ReadFixedVertices(element, item_size);
      p_ += element.count * item_size;
      return absl::OkStatus();
    }
    if (element.name == "face" && element.properties.size() == 1 &&
        PlyTypeSize(element.properties[0].count_type) == 1 &&
        PlyTypeSize(element.properties[0].type) == 4) {
      return ReadTriangleFaces(element);
    }
    for (int64_t i = 0; i < element.count; ++i) {
      RETURN_IF_ERROR(ReadItem(element, i));
    }
    return absl::OkStatus();
  }

  // Vertex element without lists: x, y, z at fixed offsets in fixed-size records.
  void ReadFixedVertices(const PlyElement& element, int64_t item_size) {
    std::array<int64_t, 3> offset{};
    std::array<PlyType, 3> type{};
    int64_t at = 0;
    for (const PlyProperty& p : element.properties) {
      if (p.role >= PlyRole::kX && p.role <= PlyRole::kZ) {
        const int k = static_cast<int>(p.role) - static_cast<int>(PlyRole::kX);
        offset[k] = at;
        type[k] = p.type;
      }
      at += PlyTypeSize(p.type);
    }
    const bool all_float = type[0] == PlyType::kFloat32 && type[1] == PlyType::kFloat32 &&
                           type[2] == PlyType::kFloat32;
    const char* record = p_;
    for (int64_t i = 0; i < element.count; ++i, record += item_size) {
      if (all_float) {
        for (int k = 0; k < 3; ++k) V_(i, k) = Load<float>(record + offset[k], swap_);
      } else {
        for (int k = 0; k < 3; ++k) V_(i, k) = LoadAsDouble(type[k], record + offset[k], swap_);
      }
    }
  }

  // Face element whose only property is a list with a 1-byte count and 4-byte indices (the layout
  // of nearly every binary PLY): triangles are read with three fixed-offset loads.
  absl::Status ReadTriangleFaces(const PlyElement& element) {
    const PlyType type = element.properties[0].type;
    for (int64_t i = 0; i < element.count; ++i) {
      if (end_ - p_ >= 13 && static_cast<uint8_t>(*p_) == 3) {
        const int64_t a = LoadAsInt(type, p_ + 1, swap_);
        const int64_t b = LoadAsInt(type, p_ + 5, swap_);
        const int64_t c = LoadAsInt(type, p_ + 9, swap_);
        if ((a | b | c) < 0 || a > kMaxIndex || b > kMaxIndex || c > kMaxIndex) {
          const int64_t bad = (a < 0 || a > kMaxIndex) ? a : (b < 0 || b > kMaxIndex) ? b : c;
          return IndexError(label_, i, bad);
        }
        RETURN_IF_ERROR(sink_.AddTriangle(static_cast<int32_t>(a), static_cast<int32_t>(b),
                                          static_cast<int32_t>(c)));
        p_ += 13;
      } else {
        RETURN_IF_ERROR(ReadItem(element, i));
      }
    }
    return absl::OkStatus();
  }

  // One item of any element, property by property.
  absl::Status ReadItem(const PlyElement& element, int64_t item) {
    for (const PlyProperty& p : element.properties) {
      if (!p.is_list) {
        const int size = PlyTypeSize(p.type);
        if (end_ - p_ < size) return Truncated(element, item);
        if (p.role != PlyRole::kSkip) {
          V_(item, static_cast<int>(p.role) - static_cast<int>(PlyRole::kX)) =
              LoadAsDouble(p.type, p_, swap_);
        }
        p_ += size;
        continue;
      }
      const int count_size = PlyTypeSize(p.count_type);
      if (end_ - p_ < count_size) return Truncated(element, item);
      const int64_t n = LoadAsInt(p.count_type, p_, swap_);
      p_ += count_size;
      if (n < 0) {
        return DataError(label_, "negative list length ", n, " in element '", element.name,
                         "' at item ", item);
      }
      const int64_t size = PlyTypeSize(p.type);
      if (n > (end_ - p_) / size) return Truncated(element, item);
      if (p.role == PlyRole::kFaceIndices) {
        corners_.clear();
        for (int64_t k = 0; k < n; ++k) {
          const int64_t index = LoadAsInt(p.type, p_ + k * size, swap_);
          if (index < 0 || index > kMaxIndex) return IndexError(label_, item, index);
          corners_.push_back(static_cast<int32_t>(index));
        }
        RETURN_IF_ERROR(sink_.AddFace(corners_.data(), n, absl::StrCat(label_, ": face ", item)));
      }
      p_ += n * size;
    }
    return absl::OkStatus();
  }

  const PlyHeader& header_;
  const char* p_;
  const char* const end_;
  const bool swap_;
  absl::string_view label_;
  TriangleSink& sink_;
  VertexMatrix& V_;
  std::vector<int32_t> corners_;
};

// ---- ascii

// Whitespace-separated tokens across lines, with line numbers for errors.
class AsciiTokens {
 public:
  AsciiTokens(absl::string_view body, int64_t first_line)
      : p_(body.data()), end_(body.data() + body.size()), line_(first_line) {}

  // The next token, or empty at the end of the data.
  absl::string_view Next() {
    while (p_ != end_ && IsSpace(*p_)) {
      if (*p_ == '\n') ++line_;
      ++p_;
    }
    const char* s = p_;
    while (p_ != end_ && !IsSpace(*p_)) ++p_;
    return absl::string_view(s, static_cast<size_t>(p_ - s));
  }

  int64_t line() const { return line_; }

 private:
  const char* p_;
  const char* const end_;
  int64_t line_;
};

template <typename T>
Num ParseToken(absl::string_view token, T* out) {
  if (token.empty()) return Num::kMissing;
  const char* p = token.data();
  const char* end = p + token.size();
  const Num st = ParseNumber(p, end, out);
  if (st == Num::kOk && p != end) return Num::kBad;
  return st;
}

absl::Status ReadPlyAscii(const PlyHeader& header, absl::string_view body, absl::string_view label,
                          TriangleSink& sink, VertexMatrix& V) {
  AsciiTokens tokens(body, header.body_line);
  std::vector<int32_t> corners;
  for (const PlyElement& element : header.elements) {
    if (element.properties.empty()) continue;
    for (int64_t item = 0; item < element.count; ++item) {
      auto problem = [&](Num st, absl::string_view token, absl::string_view what) {
        const std::string where = absl::StrCat(" of element '", element.name, "' item ", item);
        if (st == Num::kMissing) {
          return DataError(label, "data ends before ", what, where);
        }
        return LineError(label, tokens.line(),
                         st == Num::kOutOfRange ? "out-of-range " : "invalid ", what, " ",
                         Quote(token), where);
      };
      for (const PlyProperty& p : element.properties) {
        if (!p.is_list) {
          const absl::string_view token = tokens.Next();
          if (p.role == PlyRole::kSkip) {
            if (token.empty()) return problem(Num::kMissing, token, "property '" + p.name + "'");
            continue;
          }
          double value = 0.0;
          if (Num st = ParseToken(token, &value); st != Num::kOk) {
            return problem(st, token, "property '" + p.name + "'");
          }
          V(item, static_cast<int>(p.role) - static_cast<int>(PlyRole::kX)) = value;
          continue;
        }
        const absl::string_view count_token = tokens.Next();
        int64_t n = 0;
        if (Num st = ParseToken(count_token, &n); st != Num::kOk) {
          return problem(st, count_token, "list length of '" + p.name + "'");
        }
        if (n < 0) return problem(Num::kBad, count_token, "list length of '" + p.name + "'");
        if (p.role == PlyRole::kFaceIndices) corners.clear();
        // Tokens run out long before an absurd n could matter: each one is consumed from the data.
        for (int64_t k = 0; k < n; ++k) {
          const absl::string_view token = tokens.Next();
          if (p.role != PlyRole::kFaceIndices) {
            if (token.empty()) return problem(Num::kMissing, token, "list '" + p.name + "'");
            continue;
          }
          int64_t index = 0;
          if (Num st = ParseToken(token, &index); st != Num::kOk) {
            return problem(st, token, "vertex index");
          }
          if (index < 0 || index > kMaxIndex) return IndexError(label, item, index);
          corners.push_back(static_cast<int32_t>(index));
        }
        if (p.role == PlyRole::kFaceIndices) {
          RETURN_IF_ERROR(sink.AddFace(corners.data(), n, absl::StrCat(label, ": face ", item)));
        }
      }
    }
  }
  return absl::OkStatus();
}

absl::StatusOr<MeshReadResult> ParsePly(absl::string_view data, const MeshReadOptions& options,
                                        absl::string_view label) {
  ASSIGN_OR_RETURN(PlyHeader header, ParsePlyHeader(data, label));
  int vertex_element = -1;
  int face_element = -1;
  RETURN_IF_ERROR(AssignPlyRoles(header, label, &vertex_element, &face_element));
  const int64_t num_vertices = header.elements[vertex_element].count;
  const int64_t num_faces = header.elements[face_element].count;
  if (num_vertices > options.max_vertices) return TooManyVertices(label, options.max_vertices);
  if (num_faces > options.max_faces) return TooManyFaces(label, options.max_faces);
  const absl::string_view body = data.substr(header.body_offset);
  RETURN_IF_ERROR(CheckPlySizes(header, static_cast<int64_t>(body.size()), label));

  MeshReadResult result;
  result.arrays.vertices.resize(num_vertices, 3);
  TriangleSink sink(options, label);
  sink.Reserve(num_faces);
  if (header.encoding == PlyEncoding::kAscii) {
    RETURN_IF_ERROR(ReadPlyAscii(header, body, label, sink, result.arrays.vertices));
  } else {
    RETURN_IF_ERROR(PlyBinaryReader(header, body, label, sink, result.arrays.vertices).Read());
  }
  result.arrays.faces = sink.Take();
  result.polygons_triangulated = sink.polygons();
  return result;
}

absl::StatusOr<MeshReadResult> ReadMeshLabeled(absl::string_view data, MeshFormat format,
                                               const MeshReadOptions& options,
                                               absl::string_view label) {
  switch (format) {
    case MeshFormat::kObj:
      return ParseObj(data, options, label);
    case MeshFormat::kOff:
      return ParseOff(data, options, label);
    case MeshFormat::kPly:
      return ParsePly(data, options, label);
  }
  return absl::InvalidArgumentError("unknown mesh format");
}

absl::string_view FormatName(MeshFormat format) {
  switch (format) {
    case MeshFormat::kObj:
      return "OBJ";
    case MeshFormat::kOff:
      return "OFF";
    case MeshFormat::kPly:
      return "PLY";
  }
  return "mesh";
}

// ---------------------------------------------------------------------------------------------
// Files

// Little-endian output through a fixed buffer, flushed into an atomic file writer.
class BinaryWriter {
 public:
  explicit BinaryWriter(AtomicFileWriter& out) : out_(out) { buffer_.reserve(kCapacity); }

  template <typename T>
  void Put(T value) {
    if constexpr (sizeof(T) > 1 && std::endian::native == std::endian::big) {
      char bytes[sizeof(T)];
      std::memcpy(bytes, &value, sizeof(T));
      std::reverse(bytes, bytes + sizeof(T));
      PutBytes(bytes, sizeof(T));
    } else {
      PutBytes(&value, sizeof(T));
    }
  }

  void PutBytes(const void* data, size_t n) {
    if (buffer_.size() + n > kCapacity) Flush().IgnoreError();
    buffer_.append(static_cast<const char*>(data), n);
  }

  // The status of the first failed write (later writes are skipped).
  absl::Status Flush() {
    if (status_.ok()) status_ = out_.Append(buffer_);
    buffer_.clear();
    return status_;
  }

 private:
  static constexpr size_t kCapacity = size_t{1} << 20;
  AtomicFileWriter& out_;
  absl::Status status_;
  std::string buffer_;
};

bool IsValidPropertyName(absl::string_view name) {
  if (name.empty()) return false;
  for (char c : name) {
    if (!absl::ascii_isgraph(static_cast<unsigned char>(c))) return false;
  }
  return true;
}

}  // namespace

absl::StatusOr<MeshFormat> MeshFormatFromPath(std::string_view path_in) {
  const absl::string_view path(path_in.data(), path_in.size());
  const size_t slash = path.find_last_of('/');
  const absl::string_view name = slash == absl::string_view::npos ? path : path.substr(slash + 1);
  const size_t dot = name.find_last_of('.');
  if (dot != absl::string_view::npos) {
    const std::string ext = absl::AsciiStrToLower(name.substr(dot + 1));
    if (ext == "obj") return MeshFormat::kObj;
    if (ext == "off") return MeshFormat::kOff;
    if (ext == "ply") return MeshFormat::kPly;
  }
  return absl::InvalidArgumentError(absl::StrCat("cannot tell the mesh format of ", Quote(path),
                                                 ": expected extension .obj, .off or .ply"));
}

absl::StatusOr<MeshReadResult> ReadMesh(std::string_view data, MeshFormat format,
                                        const MeshReadOptions& options) {
  return ReadMeshLabeled(absl::string_view(data.data(), data.size()), format, options,
                         FormatName(format));
}

absl::StatusOr<MeshReadResult> ReadMeshFile(const std::string& path,
                                            const MeshReadOptions& options) {
  RETURN_IF_ERROR(MeshFormatFromPath(path).status());  // an unknown extension before opening
  ASSIGN_OR_RETURN(ReadableFile file, OpenForReading(path));
  return ReadMeshFile(std::move(file), path, options);
}

absl::StatusOr<MeshReadResult> ReadMeshFile(ReadableFile file, const std::string& path,
                                            const MeshReadOptions& options) {
  ASSIGN_OR_RETURN(const MeshFormat format, MeshFormatFromPath(path));
  ASSIGN_OR_RETURN(const std::string data,
                   ReadFileToString(std::move(file), path, options.max_file_bytes));
  const size_t slash = path.find_last_of('/');
  const absl::string_view name = slash == std::string::npos
                                     ? absl::string_view(path)
                                     : absl::string_view(path).substr(slash + 1);
  return ReadMeshLabeled(data, format, options, name);
}

absl::Status WritePly(const std::string& path, const VertexMatrix& V, const FaceMatrix& F,
                      const std::vector<FaceProperty>& face_properties) {
  const int64_t num_vertices = V.rows();
  const int64_t num_faces = F.rows();
  if (num_vertices > kMaxIndex) {
    return absl::InvalidArgumentError(absl::StrCat("WritePly: ", num_vertices, " vertices"));
  }
  for (int64_t f = 0; f < num_faces; ++f) {
    for (int k = 0; k < 3; ++k) {
      if (F(f, k) < 0 || F(f, k) >= num_vertices) {
        return absl::InvalidArgumentError(absl::StrCat("WritePly: face ", f, " has vertex index ",
                                                       F(f, k), " outside [0, ", num_vertices,
                                                       ")"));
      }
    }
  }
  // Coordinates are stored as float: a value the float cannot hold would come back as inf.
  constexpr double kFloatMax = std::numeric_limits<float>::max();
  for (int64_t i = 0; i < num_vertices; ++i) {
    for (int k = 0; k < 3; ++k) {
      if (!(std::abs(V(i, k)) <= kFloatMax)) {
        return absl::InvalidArgumentError(absl::StrCat("WritePly: vertex ", i, " coordinate ",
                                                       V(i, k), " is not a finite float"));
      }
    }
  }
  for (size_t i = 0; i < face_properties.size(); ++i) {
    const FaceProperty& prop = face_properties[i];
    if (!IsValidPropertyName(prop.name) || prop.name == "vertex_indices" ||
        prop.name == "vertex_index") {
      return absl::InvalidArgumentError(
          absl::StrCat("WritePly: invalid face property name ", Quote(prop.name)));
    }
    for (size_t j = 0; j < i; ++j) {
      if (face_properties[j].name == prop.name) {
        return absl::InvalidArgumentError(
            absl::StrCat("WritePly: duplicate face property ", Quote(prop.name)));
      }
    }
    if (static_cast<int64_t>(prop.values.size()) != num_faces) {
      return absl::InvalidArgumentError(absl::StrCat("WritePly: face property ", Quote(prop.name),
                                                     " has ", prop.values.size(), " values for ",
                                                     num_faces, " faces"));
    }
  }

  std::string header =
      absl::StrCat("ply\nformat binary_little_endian 1.0\ncomment fieldspace\n", "element vertex ",
                   num_vertices, "\nproperty float x\nproperty float y\nproperty float z\n",
                   "element face ", num_faces, "\nproperty list uchar int vertex_indices\n");
  for (const FaceProperty& prop : face_properties) {
    absl::StrAppend(&header, "property float ", prop.name, "\n");
  }
  header += "end_header\n";

  // A temporary file next to `path`, renamed over it once complete.
  AtomicWriteOptions write_options;
  write_options.mode = 0666;
  ASSIGN_OR_RETURN(AtomicFileWriter file, AtomicFileWriter::Create(path, std::move(write_options)));
  BinaryWriter out(file);
  out.PutBytes(header.data(), header.size());
  for (int64_t i = 0; i < num_vertices; ++i) {
    for (int k = 0; k < 3; ++k) out.Put(static_cast<float>(V(i, k)));
  }
  for (int64_t f = 0; f < num_faces; ++f) {
    out.Put(uint8_t{3});
    for (int k = 0; k < 3; ++k) out.Put(F(f, k));
    for (const FaceProperty& prop : face_properties) out.Put(prop.values[f]);
  }
  RETURN_IF_ERROR(out.Flush());
  return file.Commit();
}

}  // namespace fieldspace
