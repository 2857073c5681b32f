#include "core/common/file_util.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <limits>
#include <utility>

#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "core/common/status_macros.h"

namespace fieldspace {
namespace {

constexpr absl::string_view kTempMarker = ".tmp-";

// This absl's string_view is its own type, not std::string_view.
absl::string_view Abs(std::string_view s) { return absl::string_view(s.data(), s.size()); }

// Writes all of `data`; 0 or the errno of the failed write.
int WriteFully(int fd, std::string_view data) {
  while (!data.empty()) {
    const ssize_t n = ::write(fd, data.data(), data.size());
    if (n < 0) {
      if (errno == EINTR) continue;
      return errno;
    }
    data.remove_prefix(static_cast<size_t>(n));
  }
  return 0;
}

}  // namespace

absl::Status ErrnoStatus(int err, std::string_view what) {
  return absl::ErrnoToStatus(err, Abs(what));
}

void ScopedFd::reset(int fd) {
  if (fd_ >= 0) ::close(fd_);
  fd_ = fd;
}

int ScopedFd::Close() {
  const int rc = ::close(fd_);
  fd_ = -1;
  return rc == 0 ? 0 : errno;
}

absl::StatusOr<ReadableFile> OpenForReading(const std::string& path, ErrnoStatusFn errno_status) {
  ScopedFd fd(::open(path.c_str(), O_RDONLY | O_CLOEXEC));
  if (!fd.is_open()) {
    const int err = errno;  // before building the message, which may allocate
    return errno_status(err, absl::StrCat("opening '", path, "'"));
  }
  return DescribeOpenFile(std::move(fd), path, errno_status);
}

absl::StatusOr<ReadableFile> DescribeOpenFile(ScopedFd fd, const std::string& path,
                                              ErrnoStatusFn errno_status) {
  ReadableFile file;
  file.fd = std::move(fd);
  struct stat st;
  if (::fstat(file.fd.get(), &st) != 0) {
    const int err = errno;
    return errno_status(err, absl::StrCat("stat of '", path, "'"));
  }
  file.size = static_cast<int64_t>(st.st_size);
  file.is_regular = S_ISREG(st.st_mode);
  file.is_directory = S_ISDIR(st.st_mode);
  return file;
}

absl::Status ReadExactlyAt(int fd, uint64_t offset, void* data, size_t size, std::string_view path,
                           ErrnoStatusFn errno_status) {
  auto* p = static_cast<char*>(data);
  while (size > 0) {
    const ssize_t n = ::pread(fd, p, size, static_cast<off_t>(offset));
    if (n < 0) {
      if (errno == EINTR) continue;
      const int err = errno;
      return errno_status(err, absl::StrCat("reading '", Abs(path), "'"));
    }
    if (n == 0) return absl::DataLossError(absl::StrCat(Abs(path), ": unexpected end of file"));
    p += n;
    size -= static_cast<size_t>(n);
    offset += static_cast<uint64_t>(n);
  }
  return absl::OkStatus();
}

absl::Status WriteAll(int fd, std::string_view data, std::string_view path,
                      ErrnoStatusFn errno_status) {
  if (const int err = WriteFully(fd, data); err != 0) {
    return errno_status(err, absl::StrCat("writing '", Abs(path), "'"));
  }
  return absl::OkStatus();
}

absl::StatusOr<std::string> ReadFileToString(const std::string& path, int64_t max_bytes) {
  ASSIGN_OR_RETURN(ReadableFile file, OpenForReading(path));
  return ReadFileToString(std::move(file), path, max_bytes);
}

absl::StatusOr<std::string> ReadFileToString(ReadableFile file, const std::string& path,
                                             int64_t max_bytes) {
  if (file.is_directory) {
    return absl::InvalidArgumentError(absl::StrCat("'", path, "' is a directory"));
  }
  auto too_big = [&] {
    return absl::ResourceExhaustedError(
        absl::StrCat("'", path, "' is larger than the limit of ", max_bytes, " bytes"));
  };
  if (file.is_regular && file.size > max_bytes) return too_big();
  // Regular files are read in one call (size + 1 to see the end); pipes and the like in growing
  // chunks. Either way the total is bounded by max_bytes.
  max_bytes = std::max<int64_t>(max_bytes, 0);
  // One byte more than allowed, to tell "exactly max_bytes" from "more".
  const int64_t cap = max_bytes < std::numeric_limits<int64_t>::max() ? max_bytes + 1 : max_bytes;
  std::string data;
  const int64_t initial = file.is_regular ? file.size + 1 : int64_t{1} << 16;
  data.resize(static_cast<size_t>(std::min(initial, cap)));
  size_t size = 0;
  while (true) {
    if (size == data.size()) {
      if (static_cast<int64_t>(size) > max_bytes) return too_big();
      data.resize(static_cast<size_t>(
          std::min<int64_t>(std::max<int64_t>(2 * static_cast<int64_t>(size), 4096), cap)));
    }
    const ssize_t r = ::read(file.fd.get(), data.data() + size, data.size() - size);
    if (r < 0) {
      if (errno == EINTR) continue;
      const int err = errno;
      return ErrnoStatus(err, absl::StrCat("reading '", Abs(path), "'"));
    }
    if (r == 0) break;
    size += static_cast<size_t>(r);
  }
  if (static_cast<int64_t>(size) > max_bytes) return too_big();
  data.resize(size);
  return data;
}

absl::Status FsyncDirectory(const std::string& dir, ErrnoStatusFn errno_status) {
  ScopedFd fd(::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC));
  if (!fd.is_open()) {
    const int err = errno;
    return errno_status(err, absl::StrCat("opening directory '", dir, "'"));
  }
  if (::fsync(fd.get()) != 0) {
    const int err = errno;
    return errno_status(err, absl::StrCat("fsync of directory '", dir, "'"));
  }
  return absl::OkStatus();
}

bool IsTemporaryFileName(std::string_view file_name) {
  return absl::StartsWith(Abs(file_name), ".") && absl::StrContains(Abs(file_name), kTempMarker);
}

// ---------------------------------------------------------------------------------------------
// AtomicFileWriter

absl::StatusOr<AtomicFileWriter> AtomicFileWriter::Create(const std::string& path,
                                                          AtomicWriteOptions options) {
  const size_t slash = path.find_last_of('/');
  const std::string prefix = slash == std::string::npos ? "" : path.substr(0, slash + 1);
  const std::string name = slash == std::string::npos ? path : path.substr(slash + 1);
  std::string dir = slash == std::string::npos ? "." : slash == 0 ? "/" : path.substr(0, slash);
  // Unique within the process by the counter and across processes by the pid; a name left by a
  // crashed process with a reused pid is skipped.
  static std::atomic<uint64_t> counter{0};
  constexpr int kAttempts = 100;
  for (int attempt = 0;; ++attempt) {
    std::string temp_path = absl::StrCat(prefix, ".", name, kTempMarker, ::getpid(), "-",
                                         counter.fetch_add(1, std::memory_order_relaxed));
    ScopedFd fd(::open(temp_path.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, options.mode));
    if (fd.is_open()) {
      return AtomicFileWriter(path, std::move(dir), std::move(temp_path), std::move(fd),
                              std::move(options));
    }
    const int err = errno;
    if (err != EEXIST || attempt + 1 == kAttempts) {
      return options.errno_status(
          err, absl::StrCat("writing '", path, "' (creating '", temp_path, "')"));
    }
  }
}

AtomicFileWriter::AtomicFileWriter(std::string path, std::string dir, std::string temp_path,
                                   ScopedFd fd, AtomicWriteOptions options)
    : path_(std::move(path)),
      dir_(std::move(dir)),
      temp_path_(std::move(temp_path)),
      fd_(std::move(fd)),
      options_(std::move(options)),
      temp_exists_(true) {}

AtomicFileWriter::AtomicFileWriter(AtomicFileWriter&& other) noexcept
    : path_(std::move(other.path_)),
      dir_(std::move(other.dir_)),
      temp_path_(std::move(other.temp_path_)),
      fd_(std::move(other.fd_)),
      options_(std::move(other.options_)),
      written_(other.written_),
      hook_done_(other.hook_done_),
      committed_(other.committed_),
      temp_exists_(std::exchange(other.temp_exists_, false)),
      status_(std::move(other.status_)) {}

AtomicFileWriter& AtomicFileWriter::operator=(AtomicFileWriter&& other) noexcept {
  if (this != &other) {
    Abandon();
    path_ = std::move(other.path_);
    dir_ = std::move(other.dir_);
    temp_path_ = std::move(other.temp_path_);
    fd_ = std::move(other.fd_);
    options_ = std::move(other.options_);
    written_ = other.written_;
    hook_done_ = other.hook_done_;
    committed_ = other.committed_;
    temp_exists_ = std::exchange(other.temp_exists_, false);
    status_ = std::move(other.status_);
  }
  return *this;
}

AtomicFileWriter::~AtomicFileWriter() { Abandon(); }

void AtomicFileWriter::Abandon() {
  fd_.reset();
  if (temp_exists_) ::unlink(temp_path_.c_str());
  temp_exists_ = false;
}

absl::Status AtomicFileWriter::StepError(int err, std::string_view step) const {
  return options_.errno_status(err, absl::StrCat("writing '", path_, "' (", Abs(step), ")"));
}

absl::Status AtomicFileWriter::Fail(absl::Status status) {
  Abandon();
  status_ = std::move(status);
  return status_;
}

void AtomicFileWriter::RunHookIfDue(bool at_commit) {
  if (!options_.midway_hook || hook_done_) return;
  if (at_commit || written_ >= options_.midway_hook_at_byte) {
    hook_done_ = true;
    options_.midway_hook();
  }
}

absl::Status AtomicFileWriter::Append(std::string_view data) {
  if (!status_.ok()) return status_;
  if (committed_) return absl::FailedPreconditionError(absl::StrCat(path_, ": already committed"));
  while (true) {
    RunHookIfDue(/*at_commit=*/false);
    if (data.empty()) return absl::OkStatus();
    size_t n = data.size();
    if (options_.midway_hook && !hook_done_) {
      // Stop at the hook's byte so that it runs with exactly that much written.
      n = static_cast<size_t>(std::min<uint64_t>(n, options_.midway_hook_at_byte - written_));
    }
    if (const int err = WriteFully(fd_.get(), data.substr(0, n)); err != 0) {
      return Fail(StepError(err, absl::StrCat("writing '", temp_path_, "'")));
    }
    written_ += n;
    data.remove_prefix(n);
  }
}

absl::Status AtomicFileWriter::Commit() {
  if (!status_.ok()) return status_;
  if (committed_) return absl::FailedPreconditionError(absl::StrCat(path_, ": already committed"));
  RunHookIfDue(/*at_commit=*/true);
  if (::fsync(fd_.get()) != 0) {
    const int err = errno;
    return Fail(StepError(err, absl::StrCat("fsync of '", temp_path_, "'")));
  }
  if (const int err = fd_.Close(); err != 0) {
    return Fail(StepError(err, absl::StrCat("closing '", temp_path_, "'")));
  }
  if (::rename(temp_path_.c_str(), path_.c_str()) != 0) {
    const int err = errno;
    return Fail(StepError(err, absl::StrCat("renaming '", temp_path_, "' over it")));
  }
  temp_exists_ = false;
  committed_ = true;
  status_ = FsyncDirectory(dir_, options_.errno_status);
  return status_;
}

absl::Status WriteFileAtomically(const std::string& path, absl::Span<const std::string_view> pieces,
                                 AtomicWriteOptions options) {
  ASSIGN_OR_RETURN(AtomicFileWriter out, AtomicFileWriter::Create(path, std::move(options)));
  for (std::string_view piece : pieces) RETURN_IF_ERROR(out.Append(piece));
  return out.Commit();
}

}  // namespace fieldspace
