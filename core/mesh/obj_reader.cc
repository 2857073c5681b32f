#include <array>
#include <cstdint>
#include <vector>

#include "absl/strings/match.h"
#include "core/common/status_macros.h"
#include "core/mesh/mesh_tokenizer.h"

namespace fieldspace::mesh_io_internal {
namespace {

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

}  // namespace

absl::StatusOr<MeshReadResult> ParseObj(absl::string_view data, const MeshReadOptions& options,
                                        absl::string_view label) {
  ArrayMemory memory(options);
  RowBuffer<VertexMatrix> vertices(memory);
  TriangleSink sink(options, label, memory);
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
      RETURN_IF_ERROR(vertices.Append(xyz[0], xyz[1], xyz[2]));
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

}  // namespace fieldspace::mesh_io_internal
