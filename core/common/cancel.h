#ifndef FIELDSPACE_CORE_COMMON_CANCEL_H_
#define FIELDSPACE_CORE_COMMON_CANCEL_H_

#include <atomic>
#include <functional>
#include <utility>

namespace fieldspace {

// The cancellation convention of every long-running core function: an optional, not-owned flag
// that another thread (a gRPC call's OnCancel, a build's CancelBuild) sets to true. Options
// structs hold it as `const CancelFlag* cancel`.
using CancelFlag = std::atomic<bool>;

// Cheap enough to call in inner loops.
inline bool IsCancelled(const CancelFlag* cancel) {
  return cancel != nullptr && cancel->load(std::memory_order_relaxed);
}

// The same flag as passed down into code that checks it every few thousand steps, with an
// optional hook run at each check while not cancelled: a long computation reports progress on
// the cancellation cadence (BuildBasis's ProgressTicker) instead of through a second callback.
// The hook must be cheap and thread-safe; checks run on worker threads. Converts implicitly from
// a flag pointer (or nullptr: never cancelled, no hook). Pass by const reference.
class CancelToken {
 public:
  CancelToken() = default;
  CancelToken(const CancelFlag* flag) : flag_(flag) {}  // NOLINT(google-explicit-constructor)
  CancelToken(const CancelFlag* flag, std::function<void()> on_check)
      : flag_(flag), on_check_(std::move(on_check)) {}

  // Whether the flag is set; runs the hook first unless it already is.
  bool Check() const {
    if (IsCancelled(flag_)) return true;
    if (on_check_) on_check_();
    return IsCancelled(flag_);
  }

  const CancelFlag* flag() const { return flag_; }

 private:
  const CancelFlag* flag_ = nullptr;
  std::function<void()> on_check_;
};

}  // namespace fieldspace

#endif  // FIELDSPACE_CORE_COMMON_CANCEL_H_
