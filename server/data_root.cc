#include "server/data_root.h"

#include <filesystem>

#include "absl/strings/str_cat.h"

namespace fieldspace::server {

absl::StatusOr<std::string> ResolveDataPath(const std::string& root, const std::string& path) {
  namespace fs = std::filesystem;
  if (root.empty()) {
    return absl::FailedPreconditionError(
        "LoadMesh is disabled: the server was started without --data-root");
  }
  if (path.empty()) return absl::InvalidArgumentError("path must not be empty");
  if (path.find('\0') != std::string::npos) {
    return absl::InvalidArgumentError("path must not contain NUL bytes");
  }
  const fs::path rel(path);
  if (rel.is_absolute()) {
    return absl::InvalidArgumentError(
        absl::StrCat("path '", path, "' must be relative to the data root"));
  }
  for (const auto& part : rel) {
    if (part == "..") {
      return absl::InvalidArgumentError(
          absl::StrCat("path '", path, "' must not contain '..' components"));
    }
  }
  std::error_code ec;
  const fs::path canonical_root = fs::canonical(root, ec);
  if (ec)
    return absl::FailedPreconditionError(absl::StrCat("data root ", root, ": ", ec.message()));
  const fs::path full = fs::canonical(canonical_root / rel, ec);
  if (ec) return absl::NotFoundError(absl::StrCat("no file '", path, "' under the data root"));
  // Symlinks may still point outside: compare resolved paths component by component.
  auto r = canonical_root.begin();
  auto f = full.begin();
  for (; r != canonical_root.end(); ++r, ++f) {
    if (f == full.end() || *r != *f) {
      return absl::PermissionDeniedError(
          absl::StrCat("path '", path, "' resolves outside the data root"));
    }
  }
  if (!fs::is_regular_file(full, ec)) {
    return absl::InvalidArgumentError(absl::StrCat("'", path, "' is not a regular file"));
  }
  return full.string();
}

}  // namespace fieldspace::server
