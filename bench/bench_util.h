#ifndef FIELDSPACE_BENCH_BENCH_UTIL_H_
#define FIELDSPACE_BENCH_BENCH_UTIL_H_

#include <chrono>
#include <cstdint>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "core/common/command_line.h"

namespace fieldspace::bench {

// Command-line arguments of one subcommand, parsed by the parser shared with fieldspaced and
// fieldspace against the command table of main.cc.
using Args = ::fieldspace::CommandLine;

// Minimal JSON writer for flat objects with nested objects and number arrays.
class JsonWriter {
 public:
  JsonWriter& BeginObject(const std::string& key = "");
  JsonWriter& EndObject();
  JsonWriter& Int(const std::string& key, int64_t value);
  JsonWriter& Double(const std::string& key, double value);
  JsonWriter& Bool(const std::string& key, bool value);
  JsonWriter& String(const std::string& key, const std::string& value);
  JsonWriter& DoubleArray(const std::string& key, const std::vector<double>& values);
  std::string str() const { return out_; }

 private:
  void Key(const std::string& key);
  std::string out_;
  std::vector<bool> first_;
};

// Peak resident set size of this process in MiB (VmHWM).
double PeakRssMb();
// Current resident set size of this process, MiB.
double CurrentRssMb();

class Stopwatch {
 public:
  Stopwatch() : start_(std::chrono::steady_clock::now()) {}
  double Seconds() const {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
  }

 private:
  std::chrono::steady_clock::time_point start_;
};

}  // namespace fieldspace::bench

#endif  // FIELDSPACE_BENCH_BENCH_UTIL_H_
