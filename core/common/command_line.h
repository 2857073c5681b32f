#ifndef FIELDSPACE_CORE_COMMON_COMMAND_LINE_H_
#define FIELDSPACE_CORE_COMMON_COMMAND_LINE_H_

// The one command-line parser of fieldspaced, fieldspace and fieldspace-bench. Abseil flags are
// process-global, so they cannot give the CLI's subcommands their own flags, reject a flag that
// does not apply to the subcommand, or print per-command help; hence this small parser.
//
// Syntax: `--name VALUE`, `--name=VALUE`, bare `--switch`, positional arguments anywhere (a
// lone `-` or `-h` is positional too), and `--` after which every argument is positional. A value
// is the next argument verbatim, even when it starts with a dash (`--mu-s -1`). A repeated flag
// keeps its last value. Flag names are given without the dashes; messages name them with them.

#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/types/span.h"

namespace fieldspace {

// The flags one command accepts.
struct FlagSpec {
  std::vector<std::string> value_flags;  // `--name VALUE` or `--name=VALUE`
  std::vector<std::string> switches;     // `--name`, no value
  // A flag in neither list: InvalidArgument "unknown flag --name" (the default), or, when set, a
  // flag with a value that the caller checks afterwards with CheckKnown (fieldspace-bench's
  // subcommands parse first and check their flags after).
  bool other_flags_take_values = false;
  // Stop at the first positional argument: it and all arguments after it, flags included, go to
  // positional() unparsed (global options before a subcommand).
  bool stop_at_positional = false;
};

class CommandLine {
 public:
  // `args` without the program name. InvalidArgument: "unknown flag --name", "--name needs a
  // value", "--name takes no value" (a switch given as --name=VALUE).
  static absl::StatusOr<CommandLine> Parse(absl::Span<const std::string> args,
                                           const FlagSpec& spec);
  // fieldspace-bench's form: `argv[0 .. argc)` are the arguments (no program name); every flag but
  // `switches` takes a value; check the names with CheckKnown.
  static absl::StatusOr<CommandLine> Parse(int argc, const char* const* argv,
                                           const std::vector<std::string>& switches);

  const std::vector<std::string>& positional() const { return positional_; }
  bool Has(const std::string& flag) const { return flags_.count(flag) > 0; }
  // The flag's value ("" for a switch), or nullopt when it was not given.
  std::optional<std::string> Get(const std::string& flag) const;

  // The flag's value, or `default_value` when it was not given. InvalidArgument
  // "--flag: not an integer: 'VALUE'" (also out of range of the type) and
  // "--flag: not a finite number: 'VALUE'".
  absl::StatusOr<int64_t> GetInt(const std::string& flag, int64_t default_value) const;
  absl::StatusOr<int32_t> GetInt32(const std::string& flag, int32_t default_value) const;
  absl::StatusOr<double> GetDouble(const std::string& flag, double default_value) const;

  // InvalidArgument "unknown flag --name" for the first given flag (in name order) not in `known`.
  absl::Status CheckKnown(const std::vector<std::string>& known) const;

 private:
  std::vector<std::string> positional_;
  std::map<std::string, std::string> flags_;
};

}  // namespace fieldspace

#endif  // FIELDSPACE_CORE_COMMON_COMMAND_LINE_H_
