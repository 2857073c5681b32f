#include "server/store_lock.h"

#include <fcntl.h>
#include <sys/file.h>
#include <unistd.h>

#include <cerrno>
#include <filesystem>
#include <string>
#include <utility>

#include "absl/strings/ascii.h"
#include "absl/strings/str_cat.h"

namespace fieldspace::server {
namespace {

constexpr char kLockFile[] = "LOCK";

// The pid recorded in the lock file, or "unknown" (it may be mid-write by its holder).
std::string RecordedPid(int fd) {
  char buf[32] = {};
  const ssize_t n = ::pread(fd, buf, sizeof(buf) - 1, 0);
  std::string pid = n > 0 ? std::string(absl::StripAsciiWhitespace(std::string(buf, n))) : "";
  return pid.empty() ? "unknown" : pid;
}

}  // namespace

absl::StatusOr<StoreLock> StoreLock::Acquire(const std::string& dir, StoreLockMode mode) {
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec) {
    return absl::InternalError(absl::StrCat("cannot create store ", dir, ": ", ec.message()));
  }
  const std::string path = (std::filesystem::path(dir) / kLockFile).string();
  ScopedFd owned(::open(path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644));
  if (!owned.is_open()) return ErrnoStatus(errno, absl::StrCat("cannot open ", path));
  const int fd = owned.get();
  StoreLock lock(std::move(owned));
  const int op = (mode == StoreLockMode::kExclusive ? LOCK_EX : LOCK_SH) | LOCK_NB;
  int rc;
  do {
    rc = ::flock(fd, op);
  } while (rc != 0 && errno == EINTR);
  if (rc != 0) {
    if (errno == EWOULDBLOCK) {
      return absl::FailedPreconditionError(
          absl::StrCat("store ", dir, " is in use by another fieldspaced (pid ", RecordedPid(fd),
                       "); one store serves one daemon unless every daemon on it is started "
                       "in shared mode"));
    }
    return ErrnoStatus(errno, absl::StrCat("cannot lock ", path));
  }
  // Record our pid (in shared mode the last daemon to start wins; any holder names the store's
  // users well enough for the error above).
  const std::string pid = absl::StrCat(::getpid(), "\n");
  if (::ftruncate(fd, 0) != 0 ||
      ::pwrite(fd, pid.data(), pid.size(), 0) != static_cast<ssize_t>(pid.size())) {
    return ErrnoStatus(errno, absl::StrCat("cannot write ", path));
  }
  return lock;
}

}  // namespace fieldspace::server
