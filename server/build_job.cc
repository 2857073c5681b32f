// BuildJob: one basis build shared by every request that asked for it.

#include "server/build_job.h"

#include <utility>

namespace fieldspace::server {

BuildJob::Progress BuildJob::progress() const {
  std::lock_guard<std::mutex> lock(mu_);
  return progress_;
}

uint64_t BuildJob::Subscribe(std::function<void()> listener) {
  bool finished;
  uint64_t token;
  {
    std::lock_guard<std::mutex> lock(mu_);
    token = next_token_++;
    finished = progress_.finished;
    if (!finished) listeners_.emplace(token, listener);
  }
  if (finished) listener();
  return token;
}

void BuildJob::Unsubscribe(uint64_t token) {
  std::lock_guard<std::mutex> lock(mu_);
  listeners_.erase(token);
}

void BuildJob::SetWaitingFor(const std::string& holder) {
  {
    std::lock_guard<std::mutex> lock(mu_);
    if (progress_.finished || progress_.waiting_for == holder) return;
    progress_.stage = BuildStage::kQueued;
    progress_.fraction = 0;
    progress_.waiting_for = holder;
    last_notify_ = std::chrono::steady_clock::now();
  }
  Notify();
}

void BuildJob::SetStage(BuildStage stage, double fraction) {
  {
    std::lock_guard<std::mutex> lock(mu_);
    if (progress_.finished) return;
    progress_.waiting_for.clear();
    const bool stage_changed = stage != progress_.stage;
    progress_.stage = stage;
    progress_.fraction = std::clamp(fraction, 0.0, 1.0);
    // Core reports progress often; watchers need a few updates per second at most.
    const auto now = std::chrono::steady_clock::now();
    if (!stage_changed && now - last_notify_ < std::chrono::milliseconds(50)) return;
    last_notify_ = now;
  }
  Notify();
}

void BuildJob::Finish(absl::Status status, const BasisRecord& record) {
  std::map<uint64_t, std::function<void()>> listeners;
  {
    std::lock_guard<std::mutex> lock(mu_);
    progress_.finished = true;
    progress_.waiting_for.clear();
    progress_.status = std::move(status);
    progress_.record = record;
    if (progress_.status.ok()) {
      progress_.stage = BuildStage::kDone;
      progress_.fraction = 1.0;
    }
    listeners.swap(listeners_);
  }
  for (auto& [token, listener] : listeners) listener();
}

void BuildJob::Notify() {
  std::vector<std::function<void()>> listeners;
  {
    std::lock_guard<std::mutex> lock(mu_);
    for (const auto& [token, listener] : listeners_) listeners.push_back(listener);
  }
  for (auto& listener : listeners) listener();
}

// --- Registry ----------------------------------------------------------------------------------

}  // namespace fieldspace::server
