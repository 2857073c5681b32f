#ifndef FIELDSPACE_CORE_COMMON_INDEX_CHECK_H_
#define FIELDSPACE_CORE_COMMON_INDEX_CHECK_H_

// The one check (and message) for face indices given by a caller: constraints, lifts, watched
// faces, value conversions.

#include <cstdint>

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/string_view.h"
#include "absl/types/span.h"

namespace fieldspace {

// InvalidArgument "<what>: face F is out of range [0, N)" ("face F is ..." when `what` is empty)
// unless 0 <= face < num_faces.
inline absl::Status CheckFace(int64_t face, int64_t num_faces, absl::string_view what) {
  if (face >= 0 && face < num_faces) return absl::OkStatus();
  return absl::InvalidArgumentError(absl::StrCat(what, what.empty() ? "" : ": ", "face ", face,
                                                 " is out of range [0, ", num_faces, ")"));
}

// The same for every face of `faces` (the first one out of range).
inline absl::Status CheckFaces(absl::Span<const int32_t> faces, int64_t num_faces,
                               absl::string_view what) {
  for (int32_t f : faces) {
    if (f < 0 || f >= num_faces) return CheckFace(f, num_faces, what);
  }
  return absl::OkStatus();
}

}  // namespace fieldspace

#endif  // FIELDSPACE_CORE_COMMON_INDEX_CHECK_H_
