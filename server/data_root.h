#ifndef FIELDSPACE_SERVER_DATA_ROOT_H_
#define FIELDSPACE_SERVER_DATA_ROOT_H_

#include <string>

#include "absl/status/statusor.h"
#include "core/common/file_util.h"

namespace fieldspace::server {

// LoadMesh's path rule, checked by the kernel while opening: `path` relative, without '..', and
// the file opened below `root` without leaving it through any symlink (openat2 with
// RESOLVE_BENEATH: relative symlinks that stay below the root are followed, absolute ones are
// refused; on kernels without openat2, a walk that follows no symlink at all). Opening
// and checking are one step, so swapping a directory for a symlink meanwhile cannot lead out.
// FailedPrecondition when `root` is empty (LoadMesh disabled), InvalidArgument for a malformed
// path or a non-regular file, NotFound, and PermissionDenied for a path that leads outside.
absl::StatusOr<ReadableFile> OpenDataFile(const std::string& root, const std::string& path);

}  // namespace fieldspace::server

#endif  // FIELDSPACE_SERVER_DATA_ROOT_H_
