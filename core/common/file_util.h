#ifndef FIELDSPACE_CORE_COMMON_FILE_UTIL_H_
#define FIELDSPACE_CORE_COMMON_FILE_UTIL_H_

// File plumbing shared by the mesh reader/writer, the basis files and the server's store: an
// owning file descriptor, whole-file and positioned reads, and the one atomic file writer
// (temporary file in the same directory, fsync, rename, fsync of the directory).

#include <sys/types.h>

#include <cstddef>
#include <cstdint>
#include <functional>
#include <string>
#include <string_view>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/types/span.h"

namespace fieldspace {

// How an errno becomes a status. `what` says what failed, naming the path; the message of the
// result is "<what>: <strerror(err)>".
using ErrnoStatusFn = absl::Status (*)(int err, std::string_view what);

// The default: absl::ErrnoToStatus (ENOENT is NotFound, EACCES PermissionDenied, ENOSPC
// ResourceExhausted, ...).
absl::Status ErrnoStatus(int err, std::string_view what);

// A file descriptor owned by one object: closed when it is destroyed or reset. Move-only; a
// moved-from or default-constructed ScopedFd holds -1.
class ScopedFd {
 public:
  ScopedFd() = default;
  explicit ScopedFd(int fd) : fd_(fd) {}
  ScopedFd(ScopedFd&& other) noexcept : fd_(other.release()) {}
  ScopedFd& operator=(ScopedFd&& other) noexcept {
    if (this != &other) reset(other.release());
    return *this;
  }
  ScopedFd(const ScopedFd&) = delete;
  ScopedFd& operator=(const ScopedFd&) = delete;
  ~ScopedFd() { reset(); }

  int get() const { return fd_; }
  bool is_open() const { return fd_ >= 0; }
  // Gives up ownership without closing.
  int release() {
    const int fd = fd_;
    fd_ = -1;
    return fd;
  }
  // Closes the descriptor held (errors ignored) and takes `fd`.
  void reset(int fd = -1);
  // Closes now and returns 0 or the errno of close(2), which can report a delayed write error.
  int Close();

 private:
  int fd_ = -1;
};

// A file opened for reading and what fstat(2) said about it.
struct ReadableFile {
  ScopedFd fd;
  int64_t size = 0;  // st_size (meaningful for regular files)
  bool is_regular = false;
  bool is_directory = false;
};

// Opens `path` read-only and stats it. Errors: "opening '<path>'" or "stat of '<path>'" with the
// errno's status (NotFound if it does not exist).
absl::StatusOr<ReadableFile> OpenForReading(const std::string& path,
                                            ErrnoStatusFn errno_status = ErrnoStatus);

// Reads exactly `size` bytes at `offset` (pread, retrying interrupted and short reads). DataLoss
// "<path>: unexpected end of file" if the file ends first; "reading '<path>'" with the errno's
// status if a read fails.
absl::Status ReadExactlyAt(int fd, uint64_t offset, void* data, size_t size, std::string_view path,
                           ErrnoStatusFn errno_status = ErrnoStatus);

// Writes all of `data` at the current position (retrying interrupted and short writes);
// "writing '<path>'" with the errno's status if a write fails.
absl::Status WriteAll(int fd, std::string_view data, std::string_view path,
                      ErrnoStatusFn errno_status = ErrnoStatus);

// Reads a whole file (regular file, pipe, ...). NotFound if it does not exist, InvalidArgument
// for a directory, ResourceExhausted if it holds more than max_bytes bytes (the message names the
// path and the limit; a larger file is never read), otherwise the errno's status.
absl::StatusOr<std::string> ReadFileToString(const std::string& path,
                                             int64_t max_bytes = int64_t{1} << 33);
// The same for a file already opened (OpenForReading, or an openat2 below a directory); `path`
// names it in messages.
absl::StatusOr<std::string> ReadFileToString(ReadableFile file, const std::string& path,
                                             int64_t max_bytes);

// Stats an opened file into a ReadableFile ("stat of '<path>'" on failure).
absl::StatusOr<ReadableFile> DescribeOpenFile(ScopedFd fd, const std::string& path,
                                              ErrnoStatusFn errno_status = ErrnoStatus);

// fsync(2) of a directory, so that a rename or unlink in it survives a crash.
absl::Status FsyncDirectory(const std::string& dir, ErrnoStatusFn errno_status = ErrnoStatus);

// The atomic writer's temporary files are "<dir>/.<name>.tmp-<pid>-<n>" for "<dir>/<name>": hidden
// and recognisable, so that whoever owns a directory can remove those a crash left behind.
bool IsTemporaryFileName(std::string_view file_name);

struct AtomicWriteOptions {
  // Permission bits of the new file (the umask applies).
  mode_t mode = 0644;
  // How errno values become statuses.
  ErrnoStatusFn errno_status = ErrnoStatus;
  // Testing hook: called once, on the writing thread, when the first `midway_hook_at_byte` bytes
  // are in the temporary file (at the latest just before the fsync): the final name does not exist
  // yet, so a test can pause here and kill the process in the middle of a save.
  std::function<void()> midway_hook;
  uint64_t midway_hook_at_byte = 0;
};

// Writes a file so that readers of `path` see the old contents or the complete new ones, never a
// part: the bytes go to a temporary file in the same directory, which Commit() fsyncs and renames
// over `path` before fsyncing the directory. Any failure, and destruction without a successful
// Commit(), removes the temporary file. Errors name `path` (and the temporary file) with the errno
// text, e.g. "writing '/d/x.ply' (creating '/d/.x.ply.tmp-12-0'): No such file or directory".
//
//   ASSIGN_OR_RETURN(AtomicFileWriter out, AtomicFileWriter::Create(path));
//   RETURN_IF_ERROR(out.Append(header));
//   RETURN_IF_ERROR(out.Append(body));
//   RETURN_IF_ERROR(out.Commit());
class AtomicFileWriter {
 public:
  // Creates the temporary file.
  static absl::StatusOr<AtomicFileWriter> Create(const std::string& path,
                                                 AtomicWriteOptions options = {});

  AtomicFileWriter(AtomicFileWriter&& other) noexcept;
  AtomicFileWriter& operator=(AtomicFileWriter&& other) noexcept;
  AtomicFileWriter(const AtomicFileWriter&) = delete;
  AtomicFileWriter& operator=(const AtomicFileWriter&) = delete;
  // Without a successful Commit(): closes and removes the temporary file.
  ~AtomicFileWriter();

  // Appends bytes. After a failure the temporary file is gone and every later call returns the
  // same error.
  absl::Status Append(std::string_view data);
  // fsync, close, rename over `path`, fsync of the directory. Once only.
  absl::Status Commit();

  const std::string& path() const { return path_; }
  const std::string& temp_path() const { return temp_path_; }
  uint64_t bytes_written() const { return written_; }

 private:
  AtomicFileWriter(std::string path, std::string dir, std::string temp_path, ScopedFd fd,
                   AtomicWriteOptions options);

  // The status for a failed step (`step` names the operation) with the errno `err`.
  absl::Status StepError(int err, std::string_view step) const;
  // Records the first error and removes the temporary file.
  absl::Status Fail(absl::Status status);
  // Runs the midway hook once its byte is written (or, at_commit, in any case).
  void RunHookIfDue(bool at_commit);
  // Closes and removes the temporary file, if any.
  void Abandon();

  std::string path_;
  std::string dir_;
  std::string temp_path_;
  ScopedFd fd_;
  AtomicWriteOptions options_;
  uint64_t written_ = 0;
  bool hook_done_ = false;
  bool committed_ = false;
  bool temp_exists_ = false;
  absl::Status status_;  // the first error
};

// The same for contents given as pieces (written in order, never concatenated in memory).
absl::Status WriteFileAtomically(const std::string& path, absl::Span<const std::string_view> pieces,
                                 AtomicWriteOptions options = {});

}  // namespace fieldspace

#endif  // FIELDSPACE_CORE_COMMON_FILE_UTIL_H_
