#include "core/common/command_line.h"

#include <algorithm>
#include <cmath>

#include "absl/strings/ascii.h"
#include "absl/strings/match.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"

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
    if (!Contains(spec.value_flags, name)) {
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

FlagSpec FlagSpecOf(const CommandDoc& command, std::vector<std::string> extra_switches) {
  FlagSpec spec;
  spec.switches = std::move(extra_switches);
  for (const FlagDoc& flag : command.flags) {
    (flag.value.empty() ? spec.switches : spec.value_flags).push_back(flag.name);
  }
  return spec;
}

absl::StatusOr<CommandLine> ParseCommand(const CommandDoc& command,
                                         absl::Span<const std::string> args) {
  absl::StatusOr<CommandLine> parsed = CommandLine::Parse(args, FlagSpecOf(command));
  if (!parsed.ok()) return parsed.status();
  for (const FlagDoc& flag : command.flags) {
    if (flag.required && !parsed->Has(flag.name)) {
      return absl::InvalidArgumentError(absl::StrCat(command.name, " needs --", flag.name,
                                                     flag.value.empty() ? "" : " ", flag.value));
    }
  }
  size_t min_args = 0;
  size_t max_args = 0;
  for (absl::string_view word : absl::StrSplit(command.arguments, ' ', absl::SkipEmpty())) {
    ++max_args;
    if (!absl::StartsWith(word, "[")) ++min_args;
  }
  const size_t given = parsed->positional().size();
  if (given < min_args || given > max_args) {
    return absl::InvalidArgumentError(absl::StrCat(
        command.name, " takes ", min_args == max_args ? "" : absl::StrCat(min_args, " to "),
        max_args, " argument(s), got ", given));
  }
  return parsed;
}

namespace {

// `words` joined by spaces into lines of at most `width` columns (a longer word gets a line of
// its own); the first line starts with `first` (a word follows it after a space unless it ends in
// one), the others with `indent` spaces. Ends with a newline.
std::string Wrap(const std::vector<std::string>& words, const std::string& first, int indent,
                 int width) {
  std::string out = first;
  size_t column = first.size();
  bool line_start = first.empty() || first.back() == ' ';
  for (const std::string& word : words) {
    if (!line_start && column + 1 + word.size() > static_cast<size_t>(width)) {
      absl::StrAppend(&out, "\n", std::string(indent, ' '));
      column = indent;
      line_start = true;
    }
    if (!line_start) {
      out += ' ';
      ++column;
    }
    out += word;
    column += word.size();
    line_start = false;
  }
  return out + "\n";
}

}  // namespace

std::string FormatCommandUsage(const CommandDoc& command, int indent, int help_indent, int width) {
  std::vector<std::string> words;
  for (absl::string_view word : absl::StrSplit(command.arguments, ' ', absl::SkipEmpty())) {
    words.emplace_back(word);
  }
  for (const FlagDoc& flag : command.flags) {
    std::string word = absl::StrCat("--", flag.name, flag.value.empty() ? "" : " ", flag.value);
    words.push_back(flag.required ? word : absl::StrCat("[", word, "]"));
  }
  const std::string synopsis =
      Wrap(words, absl::StrCat(std::string(indent, ' '), command.name), indent + 4, width);
  if (command.help.empty()) return synopsis;
  const std::vector<std::string> help = absl::StrSplit(command.help, ' ', absl::SkipEmpty());
  // The help starts on the synopsis's last line when that ends 2 columns before it.
  const size_t last_start = synopsis.find_last_of('\n', synopsis.size() - 2) + 1;
  const size_t last_size = synopsis.size() - 1 - last_start;
  if (last_size + 2 <= static_cast<size_t>(help_indent)) {
    const std::string first = absl::StrCat(synopsis.substr(last_start, last_size),
                                           std::string(help_indent - last_size, ' '));
    return absl::StrCat(synopsis.substr(0, last_start), Wrap(help, first, help_indent, width));
  }
  return absl::StrCat(synopsis, Wrap(help, std::string(help_indent, ' '), help_indent, width));
}

}  // namespace fieldspace
