#ifndef FIELDSPACE_SERVER_BUILD_JOB_H_
#define FIELDSPACE_SERVER_BUILD_JOB_H_

#include <atomic>
#include <chrono>
#include <cstdint>
#include <functional>
#include <map>
#include <mutex>
#include <string>

#include "absl/status/status.h"
#include "server/records.h"
#include "server/served_basis.h"

namespace fieldspace::server {

// One basis build, shared by every request that asked for the same basis id. Runs on the compute
// pool's build lane; survives the disconnection of the clients that watch it.
class BuildJob {
 public:
  struct Progress {
    BuildStage stage = BuildStage::kQueued;
    double fraction = 0;
    bool finished = false;
    // Shared store: the replica whose lease this build waits for (stage kQueued), or empty.
    std::string waiting_for;
    absl::Status status;  // when finished
    BasisRecord record;   // when finished OK
  };

  explicit BuildJob(BasisRecord pending_record) : pending_(std::move(pending_record)) {}

  const std::string& basis_id() const { return pending_.id; }
  // The record as known before the build (key and id only).
  const BasisRecord& pending_record() const { return pending_; }
  Progress progress() const;

  // `listener` runs (on the build thread, without locks held) after every change, and once more
  // when the job finishes. If the job has already finished, it runs once, right away.
  uint64_t Subscribe(std::function<void()> listener);
  void Unsubscribe(uint64_t token);

  void Cancel() { cancel_.store(true); }
  const std::atomic<bool>* cancel_flag() const { return &cancel_; }

  // Called by the registry.
  void SetStage(BuildStage stage, double fraction);
  // Shared store: waiting (stage kQueued) for the replica `holder` that builds this basis.
  void SetWaitingFor(const std::string& holder);
  void Finish(absl::Status status, const BasisRecord& record);

 private:
  void Notify();

  const BasisRecord pending_;
  std::atomic<bool> cancel_{false};
  mutable std::mutex mu_;
  Progress progress_;
  uint64_t next_token_ = 1;
  std::map<uint64_t, std::function<void()>> listeners_;
  std::chrono::steady_clock::time_point last_notify_{};
};

}  // namespace fieldspace::server

#endif  // FIELDSPACE_SERVER_BUILD_JOB_H_
