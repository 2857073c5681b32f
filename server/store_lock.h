#ifndef FIELDSPACE_SERVER_STORE_LOCK_H_
#define FIELDSPACE_SERVER_STORE_LOCK_H_

#include <string>
#include <utility>

#include "absl/status/statusor.h"
#include "core/common/file_util.h"

namespace fieldspace::server {

// Who may use a store directory at the same time.
enum class StoreLockMode {
  // One daemon owns the store (the default): a second daemon started on it by mistake is refused.
  kExclusive,
  // Several daemons share the store by design (they coordinate per artifact); a daemon in
  // exclusive mode is still refused while any of them runs, and vice versa.
  kShared,
};

// An advisory lock (flock) on DIR/LOCK, held for the lifetime of the object. The file holds the
// pid of the (last) daemon that took it, so that a refused daemon can say which process holds the
// store. flock locks belong to the open file description: they vanish when the process dies, even
// by SIGKILL, so a crash never leaves a stale lock behind.
class StoreLock {
 public:
  // Creates DIR if needed and takes the lock without waiting. FailedPrecondition naming the
  // holder's pid when another daemon holds it in a conflicting mode; the errno's status
  // (ErrnoStatus) for I/O errors.
  static absl::StatusOr<StoreLock> Acquire(const std::string& dir, StoreLockMode mode);

  StoreLock(StoreLock&& other) noexcept = default;
  StoreLock& operator=(StoreLock&& other) noexcept = default;

 private:
  explicit StoreLock(ScopedFd fd) : fd_(std::move(fd)) {}
  ScopedFd fd_;  // closing it releases the flock
};

}  // namespace fieldspace::server

#endif  // FIELDSPACE_SERVER_STORE_LOCK_H_
