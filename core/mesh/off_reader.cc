#include <cstdint>
#include <vector>

#include "absl/strings/match.h"
#include "absl/strings/strip.h"
#include "core/common/status_macros.h"
#include "core/mesh/mesh_tokenizer.h"

namespace fieldspace::mesh_io_internal {
namespace {

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

}  // namespace

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
  ArrayMemory memory(options);
  RETURN_IF_ERROR(memory.Resize(0, num_vertices * 3 * int64_t{sizeof(double)}));
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
  TriangleSink sink(options, label, memory);
  RETURN_IF_ERROR(sink.Reserve(num_faces));
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

}  // namespace fieldspace::mesh_io_internal
