#ifndef FIELDSPACE_CORE_COMMON_TIMING_H_
#define FIELDSPACE_CORE_COMMON_TIMING_H_

#include <chrono>

namespace fieldspace {

// Wall-clock seconds since `start` (steady clock), for the timings builds and solves report.
inline double SecondsSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

}  // namespace fieldspace

#endif  // FIELDSPACE_CORE_COMMON_TIMING_H_
