// Tests of InterruptWatch: Ctrl-C runs the callback on its own thread and exits with 130, and the
// owner's writes taken under output_mutex() never land inside the callback's message.
#include "client/interrupt_watch.h"

#include <signal.h>

#include <chrono>
#include <iostream>
#include <mutex>
#include <thread>

#include "gtest/gtest.h"

namespace fieldspace::client::cli {
namespace {

// The child writes "progress" lines as fast as it can while the interrupt's message is written in
// three pieces with pauses between them; with both sides under output_mutex() the message comes
// out whole (without it the progress lines fill the pauses).
void InterruptDuringProgress() {
  InterruptWatch watch([](const std::string& basis_id, bool joined) {
    std::cerr << "fieldspace: build " << std::flush;
    std::this_thread::sleep_for(std::chrono::milliseconds(30));
    std::cerr << basis_id << (joined ? " joined" : "") << std::flush;
    std::this_thread::sleep_for(std::chrono::milliseconds(30));
    std::cerr << " cancelled on the server\n" << std::flush;
  });
  watch.Name("b-0123", false);
  raise(SIGINT);
  const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(10);
  while (std::chrono::steady_clock::now() < until) {
    {
      const std::lock_guard<std::mutex> output(watch.output_mutex());
      std::cerr << "build b-0123: eigensolve 50%\n" << std::flush;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
}

TEST(InterruptWatchTest, MessageIsNotInterleavedWithTheOwnersOutput) {
  GTEST_FLAG_SET(death_test_style, "threadsafe");
  EXPECT_EXIT(InterruptDuringProgress(), ::testing::ExitedWithCode(130),
              "fieldspace: build b-0123 cancelled on the server\n");
}

}  // namespace
}  // namespace fieldspace::client::cli
