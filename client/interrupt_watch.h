#ifndef FIELDSPACE_CLIENT_INTERRUPT_WATCH_H_
#define FIELDSPACE_CLIENT_INTERRUPT_WATCH_H_

#include <signal.h>

#include <atomic>
#include <functional>
#include <mutex>
#include <string>
#include <thread>

namespace fieldspace::client::cli {

// While alive, Ctrl-C (SIGINT) runs `on_interrupt(basis_id, joined)` on a thread of its own with
// the build the stream was last told about, then exits with 130. The signal handler only posts a
// semaphore (async-signal-safe); everything else happens on that thread. One at a time.
class InterruptWatch {
 public:
  using Callback = std::function<void(const std::string& basis_id, bool joined)>;

  explicit InterruptWatch(Callback on_interrupt);
  ~InterruptWatch();
  InterruptWatch(const InterruptWatch&) = delete;
  InterruptWatch& operator=(const InterruptWatch&) = delete;

  // The build the stream is about (from its first message on).
  void Name(const std::string& basis_id, bool joined);

  // Held while on_interrupt runs and until the exit after it. The owner takes it around its own
  // writes to the stream on_interrupt writes to (build progress on stderr), so that a line of
  // one never lands inside a line of the other.
  std::mutex& output_mutex() { return output_mutex_; }

 private:
  Callback on_interrupt_;
  struct sigaction previous_ = {};
  std::atomic<bool> stopping_{false};
  std::mutex mutex_;
  std::mutex output_mutex_;
  std::string basis_id_;
  bool joined_ = false;
  std::thread thread_;
};

}  // namespace fieldspace::client::cli

#endif  // FIELDSPACE_CLIENT_INTERRUPT_WATCH_H_
