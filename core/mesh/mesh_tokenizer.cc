#include "core/mesh/mesh_tokenizer.h"

#include "absl/strings/escaping.h"

namespace fieldspace::mesh_io_internal {

std::string Quote(absl::string_view s) {
  constexpr size_t kMaxShown = 40;
  std::string out = absl::StrCat("'", absl::CHexEscape(s.substr(0, kMaxShown)));
  if (s.size() > kMaxShown) out += "...";
  out += "'";
  return out;
}

absl::Status TooManyVertices(absl::string_view label, int64_t limit) {
  return absl::ResourceExhaustedError(
      absl::StrCat(label, ": more than ", limit, " vertices (MeshReadOptions::max_vertices)"));
}

absl::Status TooManyFaces(absl::string_view label, int64_t limit) {
  return absl::ResourceExhaustedError(
      absl::StrCat(label, ": more than ", limit, " faces (MeshReadOptions::max_faces)"));
}

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

}  // namespace fieldspace::mesh_io_internal
