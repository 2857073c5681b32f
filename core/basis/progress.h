#ifndef FIELDSPACE_CORE_BASIS_PROGRESS_H_
#define FIELDSPACE_CORE_BASIS_PROGRESS_H_

#include <atomic>
#include <chrono>
#include <cstdint>
#include <functional>
#include <mutex>

#include "absl/status/status.h"
#include "core/basis/basis.h"
#include "core/common/cancel.h"

namespace fieldspace::basis_internal {

// Shared by all threads of one BuildBasis call: reports (phase, fraction) through the user's
// callback at most every `interval` and notices cancellation. A check of its token() is cheap (one
// clock read and two relaxed atomic loads), so inner loops check it every few thousand steps; that
// keeps both the progress cadence and the cancellation latency well under 100 ms even inside one
// long region.
class ProgressTicker {
 public:
  ProgressTicker(std::function<void(BasisPhase, double)> callback, const CancelFlag* cancel,
                 std::chrono::milliseconds interval = std::chrono::milliseconds(50))
      : callback_(std::move(callback)), cancel_(cancel), interval_ns_(interval.count() * 1000000) {
    last_report_ns_.store(NowNs() - interval_ns_, std::memory_order_relaxed);
  }

  // Sets what the next reports say. `fraction` is clamped to [0, 1].
  void SetPhase(BasisPhase phase, double fraction) {
    phase_.store(static_cast<int>(phase), std::memory_order_relaxed);
    SetFraction(fraction);
  }
  void SetFraction(double fraction) {
    fraction_.store(fraction < 0 ? 0 : (fraction > 1 ? 1 : fraction), std::memory_order_relaxed);
  }

  // The build's cancellation as the inner loops check it: each check also reports progress when
  // the interval has passed.
  CancelToken token() {
    return CancelToken(cancel_, [this] { ReportIfDue(); });
  }

  // Reports now, regardless of the interval (phase changes, completion).
  void ReportNow() {
    if (!callback_) return;
    last_report_ns_.store(NowNs(), std::memory_order_relaxed);
    std::lock_guard<std::mutex> lock(callback_mutex_);
    callback_(static_cast<BasisPhase>(phase_.load(std::memory_order_relaxed)),
              fraction_.load(std::memory_order_relaxed));
  }

  bool cancelled() const { return IsCancelled(cancel_); }

  static absl::Status CancelledError() {
    return absl::CancelledError("basis construction cancelled");
  }

 private:
  void ReportIfDue() {
    if (!callback_) return;
    const int64_t now = NowNs();
    int64_t last = last_report_ns_.load(std::memory_order_relaxed);
    if (now - last >= interval_ns_ &&
        last_report_ns_.compare_exchange_strong(last, now, std::memory_order_relaxed)) {
      // One reporter at a time: the callback need not be thread-safe.
      std::lock_guard<std::mutex> lock(callback_mutex_);
      callback_(static_cast<BasisPhase>(phase_.load(std::memory_order_relaxed)),
                fraction_.load(std::memory_order_relaxed));
    }
  }

  static int64_t NowNs() {
    return std::chrono::duration_cast<std::chrono::nanoseconds>(
               std::chrono::steady_clock::now().time_since_epoch())
        .count();
  }

  std::function<void(BasisPhase, double)> callback_;
  const CancelFlag* cancel_;
  const int64_t interval_ns_;
  std::atomic<int64_t> last_report_ns_{0};
  std::atomic<int> phase_{0};
  std::atomic<double> fraction_{0.0};
  std::mutex callback_mutex_;
};

}  // namespace fieldspace::basis_internal

#endif  // FIELDSPACE_CORE_BASIS_PROGRESS_H_
