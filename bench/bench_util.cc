#include "bench/bench_util.h"

#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <string>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"

namespace fieldspace::bench {

void JsonWriter::Key(const std::string& key) {
  if (!first_.empty()) {
    if (!first_.back()) out_ += ",";
    first_.back() = false;
  }
  if (!key.empty()) absl::StrAppend(&out_, "\"", key, "\":");
}

JsonWriter& JsonWriter::BeginObject(const std::string& key) {
  Key(key);
  out_ += "{";
  first_.push_back(true);
  return *this;
}

JsonWriter& JsonWriter::EndObject() {
  out_ += "}";
  first_.pop_back();
  return *this;
}

JsonWriter& JsonWriter::Int(const std::string& key, int64_t value) {
  Key(key);
  absl::StrAppend(&out_, value);
  return *this;
}

static std::string FormatDouble(double v) {
  if (!std::isfinite(v)) return "null";
  return absl::StrFormat("%.10g", v);
}

JsonWriter& JsonWriter::Double(const std::string& key, double value) {
  Key(key);
  out_ += FormatDouble(value);
  return *this;
}

JsonWriter& JsonWriter::Bool(const std::string& key, bool value) {
  Key(key);
  out_ += value ? "true" : "false";
  return *this;
}

JsonWriter& JsonWriter::String(const std::string& key, const std::string& value) {
  Key(key);
  out_ += "\"";
  for (char c : value) {
    if (c == '"' || c == '\\') {
      out_ += '\\';
      out_ += c;
    } else if (static_cast<unsigned char>(c) < 0x20) {
      absl::StrAppendFormat(&out_, "\\u%04x", static_cast<unsigned char>(c));
    } else {
      out_ += c;
    }
  }
  out_ += "\"";
  return *this;
}

JsonWriter& JsonWriter::DoubleArray(const std::string& key, const std::vector<double>& values) {
  Key(key);
  out_ += "[";
  for (size_t i = 0; i < values.size(); ++i) {
    if (i) out_ += ",";
    out_ += FormatDouble(values[i]);
  }
  out_ += "]";
  return *this;
}

namespace {

// A "Name:   123 kB" line of /proc/self/status, in MiB (0 when absent).
double StatusFieldMb(const char* name) {
  std::ifstream in("/proc/self/status");
  std::string line;
  const size_t len = std::strlen(name);
  while (std::getline(in, line)) {
    if (line.compare(0, len, name) == 0) {
      double kb = 0;
      std::sscanf(line.c_str() + len, "%lf", &kb);
      return kb / 1024.0;
    }
  }
  return 0;
}

}  // namespace

double PeakRssMb() { return StatusFieldMb("VmHWM:"); }
double CurrentRssMb() { return StatusFieldMb("VmRSS:"); }

}  // namespace fieldspace::bench
