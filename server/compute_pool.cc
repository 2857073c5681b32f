#include "server/compute_pool.h"

#include <algorithm>
#include <utility>

namespace fieldspace::server {

ComputePool::ComputePool(const Options& options) {
  const int32_t counts[2] = {std::max(1, options.interactive_threads),
                             std::max(1, options.build_threads)};
  for (int lane = 0; lane < 2; ++lane) {
    for (int32_t i = 0; i < counts[lane]; ++i) {
      lanes_[lane].threads.emplace_back([this, lane] { Worker(static_cast<Lane>(lane)); });
    }
  }
}

ComputePool::~ComputePool() { Shutdown(); }

bool ComputePool::Submit(Lane lane, absl::AnyInvocable<void() &&> task) {
  {
    std::lock_guard<std::mutex> lock(mu_);
    if (stopping_) return false;
    lanes_[static_cast<int>(lane)].queue.push_back(std::move(task));
  }
  cv_.notify_all();
  return true;
}

void ComputePool::Shutdown() {
  {
    std::lock_guard<std::mutex> lock(mu_);
    if (stopping_ && lanes_[0].threads.empty() && lanes_[1].threads.empty()) return;
    stopping_ = true;
  }
  cv_.notify_all();
  for (LaneState& lane : lanes_) {
    for (std::thread& t : lane.threads) {
      if (t.joinable()) t.join();
    }
  }
  std::lock_guard<std::mutex> lock(mu_);
  for (LaneState& lane : lanes_) lane.threads.clear();
}

int64_t ComputePool::pending(Lane lane) const {
  std::lock_guard<std::mutex> lock(mu_);
  const LaneState& state = lanes_[static_cast<int>(lane)];
  return static_cast<int64_t>(state.queue.size()) + state.running;
}

void ComputePool::Worker(Lane lane) {
  LaneState& state = lanes_[static_cast<int>(lane)];
  std::unique_lock<std::mutex> lock(mu_);
  while (true) {
    cv_.wait(lock, [&] { return stopping_ || !state.queue.empty(); });
    if (state.queue.empty()) return;  // stopping and drained
    absl::AnyInvocable<void()&&> task = std::move(state.queue.front());
    state.queue.pop_front();
    ++state.running;
    lock.unlock();
    std::move(task)();
    task = nullptr;  // destroy captures outside the lock
    lock.lock();
    --state.running;
  }
}

}  // namespace fieldspace::server
