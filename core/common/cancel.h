#ifndef FIELDSPACE_CORE_COMMON_CANCEL_H_
#define FIELDSPACE_CORE_COMMON_CANCEL_H_

#include <atomic>

namespace fieldspace {

// The cancellation convention of every long-running core function: an optional, not-owned flag
// that another thread (a gRPC call's OnCancel, a build's CancelBuild) sets to true. Cheap enough
// to call in inner loops.
inline bool IsCancelled(const std::atomic<bool>* cancel) {
  return cancel != nullptr && cancel->load(std::memory_order_relaxed);
}

}  // namespace fieldspace

#endif  // FIELDSPACE_CORE_COMMON_CANCEL_H_
