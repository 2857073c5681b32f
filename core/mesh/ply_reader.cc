#include <array>
#include <bit>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <optional>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include "absl/strings/ascii.h"
#include "absl/strings/match.h"
#include "absl/strings/strip.h"
#include "core/common/status_macros.h"
#include "core/mesh/mesh_tokenizer.h"

namespace fieldspace::mesh_io_internal {
namespace {

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

}  // namespace

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
  ArrayMemory memory(options);
  RETURN_IF_ERROR(memory.Resize(0, num_vertices * 3 * int64_t{sizeof(double)}));
  result.arrays.vertices.resize(num_vertices, 3);
  TriangleSink sink(options, label, memory);
  RETURN_IF_ERROR(sink.Reserve(num_faces));
  if (header.encoding == PlyEncoding::kAscii) {
    RETURN_IF_ERROR(ReadPlyAscii(header, body, label, sink, result.arrays.vertices));
  } else {
    RETURN_IF_ERROR(PlyBinaryReader(header, body, label, sink, result.arrays.vertices).Read());
  }
  result.arrays.faces = sink.Take();
  result.polygons_triangulated = sink.polygons();
  return result;
}

}  // namespace fieldspace::mesh_io_internal
