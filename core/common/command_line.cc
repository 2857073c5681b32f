#include "core/common/command_line.h"

#include <algorithm>
#include <cmath>

#include "absl/strings/match.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"

namespace fieldspace {
namespace {

bool Contains(const std::vector<std::string>& names, const std::string& name) {
  return std::find(names.begin(), names.end(), name) != names.end();
}

template <typename Int>
absl::StatusOr<Int> ParseInt(const std::optional<std::string>& value, const std::string& flag,
                             Int default_value) {
  if (!value) return default_value;
  Int out;
  if (!absl::SimpleAtoi(*value, &out)) {
    return absl::InvalidArgumentError(absl::StrCat("--", flag, ": not an integer: '", *value, "'"));
  }
  return out;
}

}  // namespace

absl::StatusOr<CommandLine> CommandLine::Parse(absl::Span<const std::string> args,
                                               const FlagSpec& spec) {
  CommandLine out;
  bool flags_ended = false;
  for (size_t i = 0; i < args.size(); ++i) {
    const std::string& arg = args[i];
    if (flags_ended || !absl::StartsWith(arg, "--")) {
      out.positional_.push_back(arg);
      if (spec.stop_at_positional) {
        out.positional_.insert(out.positional_.end(), args.begin() + i + 1, args.end());
        break;
      }
      continue;
    }
    if (arg == "--") {
      flags_ended = true;
      continue;
    }
    std::string name = arg.substr(2);
    std::optional<std::string> value;
    if (size_t eq = name.find('='); eq != std::string::npos) {
      value = name.substr(eq + 1);
      name.resize(eq);
    }
    if (Contains(spec.switches, name)) {
      if (value) return absl::InvalidArgumentError(absl::StrCat("--", name, " takes no value"));
      out.flags_[name] = "";
      continue;
    }
    if (!Contains(spec.value_flags, name) && !spec.other_flags_take_values) {
      return absl::InvalidArgumentError(absl::StrCat("unknown flag --", name));
    }
    if (!value) {
      if (i + 1 >= args.size()) {
        return absl::InvalidArgumentError(absl::StrCat("--", name, " needs a value"));
      }
      value = args[++i];
    }
    out.flags_[name] = *std::move(value);
  }
  return out;
}

absl::StatusOr<CommandLine> CommandLine::Parse(int argc, const char* const* argv,
                                               const std::vector<std::string>& switches) {
  FlagSpec spec;
  spec.switches = switches;
  spec.other_flags_take_values = true;
  const std::vector<std::string> args(argv, argv + std::max(argc, 0));
  return Parse(args, spec);
}

std::optional<std::string> CommandLine::Get(const std::string& flag) const {
  auto it = flags_.find(flag);
  if (it == flags_.end()) return std::nullopt;
  return it->second;
}

absl::StatusOr<int64_t> CommandLine::GetInt(const std::string& flag, int64_t default_value) const {
  return ParseInt<int64_t>(Get(flag), flag, default_value);
}

absl::StatusOr<int32_t> CommandLine::GetInt32(const std::string& flag,
                                              int32_t default_value) const {
  return ParseInt<int32_t>(Get(flag), flag, default_value);
}

absl::StatusOr<double> CommandLine::GetDouble(const std::string& flag, double default_value) const {
  std::optional<std::string> value = Get(flag);
  if (!value) return default_value;
  double out;
  if (!absl::SimpleAtod(*value, &out) || !std::isfinite(out)) {
    return absl::InvalidArgumentError(
        absl::StrCat("--", flag, ": not a finite number: '", *value, "'"));
  }
  return out;
}

absl::Status CommandLine::CheckKnown(const std::vector<std::string>& known) const {
  for (const auto& [name, value] : flags_) {
    if (!Contains(known, name))
      return absl::InvalidArgumentError(absl::StrCat("unknown flag --", name));
  }
  return absl::OkStatus();
}

}  // namespace fieldspace
