#include "server/lease.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <fstream>
#include <random>
#include <sstream>
#include <vector>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "core/common/file_util.h"

namespace fieldspace::server {
namespace {

std::string RandomHex(int digits) {
  static thread_local std::mt19937_64 rng(std::random_device{}() ^ static_cast<uint64_t>(::getpid())
                                                                       << 32);
  std::string out;
  for (int i = 0; i < digits; ++i) out += "0123456789abcdef"[rng() % 16];
  return out;
}

std::string LeasePath(const std::string& dir, const std::string& name) {
  return absl::StrCat(dir, "/", name, ".lease");
}

int64_t MtimeNs(const struct stat& st) {
  return int64_t{st.st_mtim.tv_sec} * 1000000000 + st.st_mtim.tv_nsec;
}

absl::StatusOr<LeaseOwner> ParseOwner(const std::string& text, const std::string& path) {
  std::vector<std::string> parts =
      absl::StrSplit(text, absl::ByAnyChar(" \n"), absl::SkipWhitespace());
  LeaseOwner owner;
  if (parts.size() != 3 || !absl::SimpleAtoi(parts[1], &owner.pid)) {
    return absl::DataLossError(absl::StrCat(path, ": not a lease file"));
  }
  owner.host = parts[0];
  owner.daemon_id = parts[2];
  return owner;
}

}  // namespace

std::string LeaseOwner::ToString() const { return absl::StrCat(host, "/", pid, "/", daemon_id); }

LeaseOwner LocalLeaseOwner(const std::string& daemon_id) {
  LeaseOwner me;
  char host[256] = {};
  if (::gethostname(host, sizeof(host) - 1) != 0 || host[0] == '\0') std::strcpy(host, "unknown");
  me.host = host;
  for (char& c : me.host) {
    if (c == ' ' || c == '/' || c == '\n') c = '_';
  }
  me.pid = ::getpid();
  me.daemon_id = daemon_id.empty() ? RandomHex(8) : daemon_id;
  for (char& c : me.daemon_id) {
    if (c == ' ' || c == '/' || c == '\n') c = '_';
  }
  return me;
}

absl::StatusOr<Lease::State> Lease::Read(const std::string& dir, const std::string& name) {
  const std::string path = LeasePath(dir, name);
  const ScopedFd fd(::open(path.c_str(), O_RDONLY | O_CLOEXEC));
  if (!fd.is_open()) {
    if (errno == ENOENT) return absl::NotFoundError(absl::StrCat("no lease ", path));
    return ErrnoStatus(errno, absl::StrCat("cannot open ", path));
  }
  struct stat st;
  char buf[512] = {};
  const bool stat_ok = ::fstat(fd.get(), &st) == 0;
  const ssize_t n = ::pread(fd.get(), buf, sizeof(buf) - 1, 0);
  if (!stat_ok || n < 0) return ErrnoStatus(errno, absl::StrCat("cannot read ", path));
  State state;
  absl::StatusOr<LeaseOwner> owner = ParseOwner(std::string(buf, n), path);
  if (!owner.ok()) {
    // A lease file is complete when it appears (link of a written file); anything else is a
    // foreign file: it has no owner that could renew it, so it goes stale like a dead one.
    state.owner.host = "unreadable";
  } else {
    state.owner = *std::move(owner);
  }
  state.mtime_ns = MtimeNs(st);
  return state;
}

absl::StatusOr<std::unique_ptr<Lease>> Lease::TryAcquire(const std::string& dir,
                                                         const std::string& name,
                                                         const LeaseOwner& me,
                                                         const Options& options,
                                                         LeaseOwner* holder) {
  const std::string path = LeasePath(dir, name);
  const std::string tmp =
      absl::StrCat(dir, "/.", name, ".lease.tmp-", me.daemon_id, "-", RandomHex(8));
  const std::string content = absl::StrCat(me.host, " ", me.pid, " ", me.daemon_id, "\n");
  ScopedFd fd(::open(tmp.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0644));
  if (!fd.is_open()) return ErrnoStatus(errno, absl::StrCat("cannot create ", tmp));
  const bool written =
      ::write(fd.get(), content.data(), content.size()) == static_cast<ssize_t>(content.size()) &&
      ::fsync(fd.get()) == 0;
  const int write_errno = errno;
  fd.reset();
  if (!written) {
    ::unlink(tmp.c_str());
    return ErrnoStatus(write_errno, absl::StrCat("cannot write ", tmp));
  }
  // link() is atomic and fails with EEXIST if the lease exists, also on NFS (where O_EXCL on
  // open was not reliable before NFSv3).
  const int rc = ::link(tmp.c_str(), path.c_str());
  const int link_errno = errno;
  ::unlink(tmp.c_str());
  if (rc == 0) return std::unique_ptr<Lease>(new Lease(path, me, options));
  if (link_errno != EEXIST) return ErrnoStatus(link_errno, absl::StrCat("cannot create ", path));
  absl::StatusOr<State> state = Read(dir, name);
  if (holder != nullptr) {
    *holder = state.ok() ? state->owner : LeaseOwner{"unknown", 0, "released"};
  }
  return std::unique_ptr<Lease>();
}

absl::Status Lease::BreakStale(const std::string& dir, const std::string& name,
                               const LeaseOwner& stale_owner, int64_t stale_mtime_ns) {
  const std::string path = LeasePath(dir, name);
  // Move it aside first (only one breaker can), then check that what we moved is the stale file
  // we watched and not a fresh lease that replaced it in the meantime.
  const std::string aside = absl::StrCat(dir, "/.", name, ".lease.stale-", RandomHex(8));
  if (::rename(path.c_str(), aside.c_str()) != 0) {
    if (errno == ENOENT) return absl::OkStatus();
    return ErrnoStatus(errno, absl::StrCat("cannot break stale lease ", path));
  }
  struct stat st;
  std::ifstream in(aside);
  std::stringstream ss;
  ss << in.rdbuf();
  absl::StatusOr<LeaseOwner> owner = ParseOwner(ss.str(), aside);
  const bool same = ::stat(aside.c_str(), &st) == 0 && MtimeNs(st) == stale_mtime_ns &&
                    (!owner.ok() || *owner == stale_owner);
  if (!same) {
    // A live lease: put it back unless a newer one exists already (then ours was stale anyway).
    (void)::link(aside.c_str(), path.c_str());
  }
  ::unlink(aside.c_str());
  return absl::OkStatus();
}

Lease::Lease(std::string path, LeaseOwner me, Options options)
    : path_(std::move(path)), me_(std::move(me)), options_(options) {
  thread_ = std::thread([this] { Heartbeat(); });
}

void Lease::Heartbeat() {
  std::unique_lock<std::mutex> lock(mu_);
  while (!cv_.wait_for(lock, options_.heartbeat, [this] { return stop_; })) {
    std::ifstream in(path_);
    std::stringstream ss;
    ss << in.rdbuf();
    absl::StatusOr<LeaseOwner> owner = ParseOwner(ss.str(), path_);
    if (!in || !owner.ok() || !(*owner == me_)) {
      held_.store(false);  // taken over (we hung longer than stale_after) or removed
      return;
    }
    (void)::utimensat(AT_FDCWD, path_.c_str(), nullptr, 0);  // now (the file server's clock)
  }
}

Lease::~Lease() {
  {
    std::lock_guard<std::mutex> lock(mu_);
    stop_ = true;
  }
  cv_.notify_all();
  if (thread_.joinable()) thread_.join();
  std::ifstream in(path_);
  std::stringstream ss;
  ss << in.rdbuf();
  absl::StatusOr<LeaseOwner> owner = ParseOwner(ss.str(), path_);
  if (in && owner.ok() && *owner == me_) ::unlink(path_.c_str());
}

}  // namespace fieldspace::server
