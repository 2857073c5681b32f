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

#include <cstddef>
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

 private:
  std::vector<std::string> positional_;
  std::map<std::string, std::string> flags_;
};

// A table of subcommands (fieldspace's and fieldspace-bench's), in which each command's flags are
// written once: the parser's FlagSpec, the check of the required flags and of the number of
// positional arguments, and the usage text all come from it, so that a flag cannot be documented
// other than it is parsed.

// One flag of a command.
struct FlagDoc {
  std::string name;  // without the dashes
  std::string
      value;  // the value as the usage names it ("D", "jet|normal-differences"); "": a switch
  bool required = false;  // the command needs it (the usage shows it without brackets)
};

// One subcommand.
struct CommandDoc {
  std::string name;
  // The positional arguments as the usage shows them, one word each ("BASIS_ID FIELD_FILE"); an
  // optional one in brackets ("MESH [FIELD_FILE]").
  std::string arguments = "";
  std::vector<FlagDoc> flags = {};
  // What the command does, a paragraph (wrapped by the usage); may be empty.
  std::string help = "";
};

// The FlagSpec of the command's flags (plus `extra_switches`, e.g. "help").
FlagSpec FlagSpecOf(const CommandDoc& command, std::vector<std::string> extra_switches = {});

// Parses the command's arguments (those after its name) and checks them against the table:
// the FlagSpec's errors, then InvalidArgument "NAME needs --flag VALUE" for a missing required
// flag and "NAME takes N argument(s), got M" for a wrong number of positional arguments.
absl::StatusOr<CommandLine> ParseCommand(const CommandDoc& command,
                                         absl::Span<const std::string> args);

// "NAME ARGUMENTS --required V [--optional V] [--switch]" wrapped to `width` columns, indented by
// `indent` (continued lines by `indent` + 4); then the help wrapped in the columns from
// `help_indent` on, from the synopsis's last line when it ends 2 columns before.
std::string FormatCommandUsage(const CommandDoc& command, int indent, int help_indent, int width);

}  // namespace fieldspace

#endif  // FIELDSPACE_CORE_COMMON_COMMAND_LINE_H_
