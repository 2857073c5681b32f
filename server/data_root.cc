#include "server/data_root.h"

#include <fcntl.h>
#include <linux/openat2.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <vector>

#include "absl/strings/str_cat.h"
#include "core/common/status_macros.h"

namespace fieldspace::server {
namespace {

// Non-blocking: opening a FIFO for reading would wait for a writer, on a compute thread, and a
// device node may block too; neither is a mesh file, and the fstat after the open refuses them.
// On a regular file O_NONBLOCK changes nothing.
constexpr int kOpenFlags = O_RDONLY | O_CLOEXEC | O_NONBLOCK;

// openat2(2) (glibc 2.36 has no wrapper); -1 with errno.
int OpenAt2(int dir, const char* path, uint64_t flags, uint64_t resolve) {
  struct open_how how = {};
  how.flags = flags;
  how.resolve = resolve;
  return static_cast<int>(::syscall(SYS_openat2, dir, path, &how, sizeof(how)));
}

// Without openat2: each component opened relative to its parent with O_NOFOLLOW, so no symlink
// is followed anywhere below the root.
int OpenWithoutSymlinks(int root, const std::vector<std::string>& parts) {
  ScopedFd dir(::fcntl(root, F_DUPFD_CLOEXEC, 0));
  if (!dir.is_open()) return -1;
  for (size_t i = 0; i + 1 < parts.size(); ++i) {
    ScopedFd next(
        ::openat(dir.get(), parts[i].c_str(), O_RDONLY | O_DIRECTORY | O_NOFOLLOW | O_CLOEXEC));
    if (!next.is_open()) return -1;
    dir = std::move(next);
  }
  return ::openat(dir.get(), parts.back().c_str(), kOpenFlags | O_NOFOLLOW);
}

}  // namespace

absl::StatusOr<ReadableFile> OpenDataFile(const std::string& root, const std::string& path) {
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
  std::vector<std::string> parts;
  for (const auto& part : rel) {
    if (part == "..") {
      return absl::InvalidArgumentError(
          absl::StrCat("path '", path, "' must not contain '..' components"));
    }
    if (part != "." && !part.empty()) parts.push_back(part.string());
  }
  if (parts.empty()) return absl::InvalidArgumentError(absl::StrCat("'", path, "' is not a file"));
  ScopedFd dir(::open(root.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC));
  if (!dir.is_open()) {
    return absl::FailedPreconditionError(
        absl::StrCat("the data root cannot be opened: ", std::strerror(errno)));
  }
  int fd = OpenAt2(dir.get(), path.c_str(), kOpenFlags, RESOLVE_BENEATH | RESOLVE_NO_MAGICLINKS);
  int err = fd < 0 ? errno : 0;
  bool strict_walk = false;
  if (fd < 0 && (err == ENOSYS || err == EPERM)) {  // no openat2 (old kernel, seccomp filter)
    fd = OpenWithoutSymlinks(dir.get(), parts);
    err = fd < 0 ? errno : 0;
    strict_walk = true;
  }
  if (fd < 0) {
    if (err == ENOENT || err == ENOTDIR) {
      return absl::NotFoundError(absl::StrCat("no file '", path, "' under the data root"));
    }
    if (err == EXDEV || (strict_walk && err == ELOOP)) {
      return absl::PermissionDeniedError(absl::StrCat(
          "path '", path, "' leads outside the data root",
          strict_walk ? " (or through a symlink, which this kernel cannot check)" : ""));
    }
    if (err == EISDIR) {
      return absl::InvalidArgumentError(absl::StrCat("'", path, "' is not a regular file"));
    }
    return absl::ErrnoToStatus(err, absl::StrCat("opening '", path, "' under the data root"));
  }
  ASSIGN_OR_RETURN(ReadableFile file, DescribeOpenFile(ScopedFd(fd), path));
  if (!file.is_regular) {
    return absl::InvalidArgumentError(absl::StrCat("'", path, "' is not a regular file"));
  }
  return file;
}

}  // namespace fieldspace::server
