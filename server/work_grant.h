#ifndef FIELDSPACE_SERVER_WORK_GRANT_H_
#define FIELDSPACE_SERVER_WORK_GRANT_H_

// Working memory of a request (a Solve's reduced system, an upload's buffer, a build, a design
// session), admitted against the daemon's memory budget (--memory-budget-mb) together with the
// loaded meshes and bases, and counted while its WorkGrant lives.

#include <algorithm>
#include <cstdint>
#include <functional>
#include <utility>

#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"

namespace fieldspace::server {

// Where grants are counted (the Registry).
class WorkAccount {
 public:
  virtual ~WorkAccount() = default;
  virtual void ReleaseWork(int64_t bytes) = 0;
};

// Move-only; gives its bytes back to the account when destroyed. An empty grant holds nothing.
class WorkGrant {
 public:
  WorkGrant() = default;
  WorkGrant(WorkAccount* account, int64_t bytes) : account_(account), bytes_(bytes) {}
  WorkGrant(WorkGrant&& other) noexcept
      : account_(std::exchange(other.account_, nullptr)), bytes_(std::exchange(other.bytes_, 0)) {}
  WorkGrant& operator=(WorkGrant&& other) noexcept {
    if (this != &other) {
      Release();
      account_ = std::exchange(other.account_, nullptr);
      bytes_ = std::exchange(other.bytes_, 0);
    }
    return *this;
  }
  WorkGrant(const WorkGrant&) = delete;
  WorkGrant& operator=(const WorkGrant&) = delete;
  ~WorkGrant() { Release(); }

  int64_t bytes() const { return bytes_; }
  // Takes over `more` (of the same account, or empty): one grant of both sizes.
  void Merge(WorkGrant more) {
    if (more.account_ == nullptr) return;
    if (account_ == nullptr) account_ = more.account_;
    bytes_ += std::exchange(more.bytes_, 0);
    more.account_ = nullptr;
  }
  // Gives back what exceeds `bytes` (no-op if it holds no more).
  void ShrinkTo(int64_t bytes) {
    if (account_ == nullptr || bytes >= bytes_) return;
    account_->ReleaseWork(bytes_ - std::max<int64_t>(bytes, 0));
    bytes_ = std::max<int64_t>(bytes, 0);
  }

 private:
  void Release() {
    if (account_ != nullptr) account_->ReleaseWork(bytes_);
    account_ = nullptr;
    bytes_ = 0;
  }

  WorkAccount* account_ = nullptr;
  int64_t bytes_ = 0;
};

// Admits `bytes` of working memory for `what` ("this Solve"), or ResourceExhausted naming it.
using AdmitWorkFn = std::function<absl::StatusOr<WorkGrant>(int64_t bytes, absl::string_view what)>;

}  // namespace fieldspace::server

#endif  // FIELDSPACE_SERVER_WORK_GRANT_H_
