#ifndef FIELDSPACE_SERVER_DATA_ROOT_H_
#define FIELDSPACE_SERVER_DATA_ROOT_H_

#include <string>

#include "absl/status/statusor.h"

namespace fieldspace::server {

// LoadMesh's path rule: `path` relative, without '..', and inside `root` after resolving
// symlinks; returns the resolved path. FailedPrecondition when `root` is empty (LoadMesh
// disabled), InvalidArgument for a malformed path or a non-regular file, NotFound, and
// PermissionDenied for a path that resolves outside the root.
absl::StatusOr<std::string> ResolveDataPath(const std::string& root, const std::string& path);

}  // namespace fieldspace::server

#endif  // FIELDSPACE_SERVER_DATA_ROOT_H_
