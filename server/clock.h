#ifndef FIELDSPACE_SERVER_CLOCK_H_
#define FIELDSPACE_SERVER_CLOCK_H_

// The clock of the server's timings (the *_ms fields of responses).

#include <chrono>

namespace fieldspace::server {

using Clock = std::chrono::steady_clock;

inline double MsSince(Clock::time_point start) {
  return std::chrono::duration<double, std::milli>(Clock::now() - start).count();
}

}  // namespace fieldspace::server

#endif  // FIELDSPACE_SERVER_CLOCK_H_
