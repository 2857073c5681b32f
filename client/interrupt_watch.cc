#include "client/interrupt_watch.h"

#include <semaphore.h>

#include <cstdlib>
#include <utility>

namespace fieldspace::client::cli {
namespace {

sem_t& Semaphore() {
  static sem_t semaphore;
  return semaphore;
}

}  // namespace

InterruptWatch::InterruptWatch(Callback on_interrupt) : on_interrupt_(std::move(on_interrupt)) {
  sem_init(&Semaphore(), 0, 0);
  struct sigaction action = {};
  action.sa_handler = [](int) { sem_post(&Semaphore()); };
  sigemptyset(&action.sa_mask);
  sigaction(SIGINT, &action, &previous_);
  thread_ = std::thread([this] {
    while (sem_wait(&Semaphore()) != 0) {
    }
    if (stopping_.load()) return;
    std::string basis_id;
    bool joined = false;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      basis_id = basis_id_;
      joined = joined_;
    }
    const std::lock_guard<std::mutex> output(output_mutex_);
    on_interrupt_(basis_id, joined);
    std::_Exit(130);
  });
}

InterruptWatch::~InterruptWatch() {
  sigaction(SIGINT, &previous_, nullptr);
  stopping_.store(true);
  sem_post(&Semaphore());
  thread_.join();
  sem_destroy(&Semaphore());
}

void InterruptWatch::Name(const std::string& basis_id, bool joined) {
  std::lock_guard<std::mutex> lock(mutex_);
  basis_id_ = basis_id;
  joined_ = joined;
}

}  // namespace fieldspace::client::cli
