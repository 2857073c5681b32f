#ifndef FIELDSPACE_SERVER_LEASE_H_
#define FIELDSPACE_SERVER_LEASE_H_

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>

#include "absl/status/statusor.h"

namespace fieldspace::server {

// Who holds a lease: written into the lease file as one line "HOST PID DAEMON_ID".
struct LeaseOwner {
  std::string host;
  int64_t pid = 0;
  std::string daemon_id;

  std::string ToString() const;  // "HOST/PID/DAEMON_ID"
  bool operator==(const LeaseOwner& o) const {
    return host == o.host && pid == o.pid && daemon_id == o.daemon_id;
  }
};

// This process's owner identity: host name, pid and `daemon_id` (a random id when empty).
LeaseOwner LocalLeaseOwner(const std::string& daemon_id = "");

// A lease on one piece of work in a shared store directory (a basis build on a shared store):
// the file DIR/NAME.lease, created atomically (link of a complete temporary file, which fails if
// the lease exists, also on NFS), holding its owner, with its mtime as the heartbeat: the holder
// touches it every `heartbeat`. Another daemon takes it over when it has watched the mtime stand
// still for `stale_after` on its own clock (so clocks of different hosts need not agree), which
// happens only when the holder died or hung. The lease file is removed on release (if it is still
// ours). Leases guard work that is idempotent (content-addressed, atomically renamed files): a
// lost race costs a duplicate build, never a damaged artifact.
class Lease {
 public:
  struct Options {
    std::chrono::milliseconds heartbeat{2000};
    std::chrono::milliseconds stale_after{6000};  // 3 heartbeats
  };

  // Takes DIR/NAME.lease if nobody holds it: the lease (heartbeat running), or nullptr and the
  // current holder in `*holder`. Internal / PermissionDenied for I/O errors.
  static absl::StatusOr<std::unique_ptr<Lease>> TryAcquire(const std::string& dir,
                                                           const std::string& name,
                                                           const LeaseOwner& me,
                                                           const Options& options,
                                                           LeaseOwner* holder);
  // Removes the lease file of a holder seen as dead (the caller watched its heartbeat stop) if
  // the file is still the one that was watched (same owner and mtime). OK if it is gone already.
  static absl::Status BreakStale(const std::string& dir, const std::string& name,
                                 const LeaseOwner& stale_owner, int64_t stale_mtime_ns);

  // The current holder and the lease file's mtime (ns), or NotFound when there is no lease.
  struct State {
    LeaseOwner owner;
    int64_t mtime_ns = 0;
  };
  static absl::StatusOr<State> Read(const std::string& dir, const std::string& name);

  ~Lease();  // stops the heartbeat and removes the lease file if it is still ours
  Lease(const Lease&) = delete;
  Lease& operator=(const Lease&) = delete;

  const std::string& path() const { return path_; }
  // False once the heartbeat found the file gone or owned by someone else (we were taken over).
  bool held() const { return held_.load(); }

 private:
  Lease(std::string path, LeaseOwner me, Options options);
  void Heartbeat();

  const std::string path_;
  const LeaseOwner me_;
  const Options options_;
  std::atomic<bool> held_{true};
  std::mutex mu_;
  std::condition_variable cv_;
  bool stop_ = false;
  std::thread thread_;
};

}  // namespace fieldspace::server

#endif  // FIELDSPACE_SERVER_LEASE_H_
