#ifndef FIELDSPACE_SERVER_COMPUTE_POOL_H_
#define FIELDSPACE_SERVER_COMPUTE_POOL_H_

#include <condition_variable>
#include <cstdint>
#include <deque>
#include <mutex>
#include <thread>
#include <vector>

#include "absl/functional/any_invocable.h"

namespace fieldspace::server {

// Where heavy work runs: never on gRPC's threads. Two lanes so that a long basis build (minutes)
// never delays an interactive edit (milliseconds): builds queue on their own threads. Work inside a
// task may use oneTBB parallel algorithms; each pool thread then acts as the master of its own
// implicit arena, and oneTBB's workers (capped globally by the server's --threads) are shared.
class ComputePool {
 public:
  enum class Lane : uint8_t { kInteractive = 0, kBuild = 1 };

  struct Options {
    int32_t interactive_threads = 2;
    int32_t build_threads = 1;
  };

  explicit ComputePool(const Options& options);
  ComputePool(const ComputePool&) = delete;
  ComputePool& operator=(const ComputePool&) = delete;
  // Shutdown().
  ~ComputePool();

  // Queues `task` (FIFO within the lane). False, and the task is destroyed without running, once
  // Shutdown() has begun.
  bool Submit(Lane lane, absl::AnyInvocable<void() &&> task);

  // Stops accepting tasks, runs the queued ones, joins the threads. Idempotent.
  void Shutdown();

  // Tasks queued or running in `lane`.
  int64_t pending(Lane lane) const;

 private:
  struct LaneState {
    std::deque<absl::AnyInvocable<void() &&>> queue;
    int64_t running = 0;
    std::vector<std::thread> threads;
  };

  void Worker(Lane lane);

  mutable std::mutex mu_;
  std::condition_variable cv_;
  bool stopping_ = false;
  LaneState lanes_[2];
};

}  // namespace fieldspace::server

#endif  // FIELDSPACE_SERVER_COMPUTE_POOL_H_
