// The dispatcher of the `fieldspace` CLI: global options, the command's table entry
// (cli_commands.h), usage and help, and the error forms.

#include "client/cli.h"

#include <algorithm>
#include <cstdlib>
#include <string>
#include <vector>

#include "absl/strings/ascii.h"
#include "absl/strings/str_cat.h"
#include "absl/types/span.h"
#include "client/cli_commands.h"
#include "client/cli_context.h"
#include "client/cli_flags.h"
#include "grpc/support/log.h"

namespace fieldspace::client {
namespace {

using cli::Cli;
using cli::CliCommand;
using cli::UsageError;

constexpr int kWidth = 100;
constexpr int kHelpColumn = 38;

// The global options (before COMMAND), written once like the commands' flags.
const CommandDoc& GlobalOptions() {
  static const CommandDoc global = {"usage: fieldspace",
                                    "",
                                    {{"server", "HOST:PORT"},
                                     {"token", "FILE"},
                                     {"timeout", "SECONDS"},
                                     {"tls-ca", "FILE"},
                                     {"tls-cert", "FILE"},
                                     {"tls-key", "FILE"},
                                     {"tls-server-name", "NAME"}},
                                    ""};
  return global;
}

constexpr char kNotes[] =
    R"(
FIELD_FILE: text (one face per line; '# encoding: dof' or ambient, the default) in a .txt file
or, for output, .ply (the mesh with the field as face properties). Formats: docs/cli.md.

The server is --server, else $FIELDSPACE_SERVER, else 127.0.0.1:50051. TLS (a server started
with --tls-cert): any --tls-* option turns it on: --tls-ca FILE (the CA of the server's
certificate; default: the system's roots), --tls-cert FILE --tls-key FILE (this client's
certificate and key, for a server with --tls-client-ca), --tls-server-name NAME (the name to
expect in the server's certificate; default: HOST).
)";

std::string Usage() {
  std::string usage = FormatCommandUsage(GlobalOptions(), 0, 0, kWidth);
  usage.pop_back();
  absl::StrAppend(&usage,
                  " COMMAND [ARGS]\n\ncommands (JSON on stdout, errors on stderr, non-zero exit "
                  "on failure):\n");
  for (const CliCommand& c : cli::Commands()) {
    if (c.new_group) usage += "\n";
    usage += FormatCommandUsage(c.doc, 2, kHelpColumn, kWidth);
  }
  return usage + kNotes;
}

std::string CommandUsage(const CliCommand& command) {
  return absl::StrCat(
      "usage: fieldspace [--server HOST:PORT] [--token FILE] [--timeout SECONDS] [--tls-* ...] ",
      command.doc.name, " ...\n\n", FormatCommandUsage(command.doc, 2, kHelpColumn, kWidth),
      "\nThe server defaults to $FIELDSPACE_SERVER, else 127.0.0.1:50051; FIELD_FILE formats "
      "and TLS options: fieldspace --help.\n");
}

// gRPC C-core's own log lines ("E1127 12:00:00.000 ... hpack_parser.cc ...") would reach the
// user's terminal beside the CLI's message, which already says what failed; they are dropped
// unless GRPC_VERBOSITY asks for them (debugging a connection).
void QuietGrpcLogs() {
  if (std::getenv("GRPC_VERBOSITY") != nullptr) return;
  gpr_set_log_function([](gpr_log_func_args*) {});
}

int Run(Cli& cli, const std::vector<std::string>& args) {
  try {
    const std::vector<std::string> command_line = cli.ParseGlobal(args);
    if (command_line.empty()) throw UsageError("no command given");
    const std::string& name = command_line[0];
    const std::vector<CliCommand>& commands = cli::Commands();
    auto it = std::find_if(commands.begin(), commands.end(),
                           [&](const CliCommand& c) { return c.doc.name == name; });
    if (it == commands.end()) throw UsageError("unknown command '" + name + "'");
    cli.SetCommand(name);
    const absl::Span<const std::string> rest = absl::MakeConstSpan(command_line).subspan(1);
    if (!it->python_tool && (std::find(rest.begin(), rest.end(), "--help") != rest.end() ||
                             std::find(rest.begin(), rest.end(), "-h") != rest.end())) {
      cli.out() << CommandUsage(*it);
      return 0;
    }
    try {
      if (it->python_tool) return cli::RunPythonTool(cli, name, rest);
      absl::StatusOr<CommandLine> parsed = ParseCommand(it->doc, rest);
      if (!parsed.ok()) throw UsageError(std::string(parsed.status().message()));
      cli.Connect();
      return it->run(cli, *parsed);
    } catch (const UsageError& e) {
      // A usage error of a known command: the README's error form, then that command's usage.
      cli.Fail(absl::InvalidArgumentError(e.what()), name);
      cli.err() << "\n" << CommandUsage(*it);
      return 2;
    }
  } catch (const UsageError& e) {
    if (*e.what() != '\0') cli.err() << "fieldspace: " << e.what() << "\n\n";
    cli.err() << Usage();
    return *e.what() == '\0' ? 0 : 2;
  }
}

}  // namespace

namespace cli {

std::vector<std::string> Cli::ParseGlobal(const std::vector<std::string>& args) {
  options_.address = kDefaultServer;
  if (const char* env = std::getenv("FIELDSPACE_SERVER"); env != nullptr && *env != '\0') {
    options_.address = env;
  }
  FlagSpec spec = FlagSpecOf(GlobalOptions(), {"help"});
  spec.stop_at_positional = true;
  absl::StatusOr<CommandLine> parsed =
      CommandLine::Parse(absl::MakeConstSpan(args).subspan(std::min<size_t>(1, args.size())), spec);
  if (!parsed.ok()) throw UsageError(std::string(parsed.status().message()));
  const CommandLine& global = *parsed;
  if (global.Has("help") || (!global.positional().empty() && global.positional()[0] == "-h")) {
    throw UsageError("");
  }
  options_.address = GetString(global, "server", options_.address);
  if (options_.address.empty()) throw UsageError("--server needs a value (HOST:PORT)");
  if (global.Has("timeout")) {
    const absl::StatusOr<double> seconds = global.GetDouble("timeout", 0);
    if (!seconds.ok() || *seconds < 0) {
      throw UsageError("--timeout needs a non-negative number of seconds");
    }
    if (*seconds > 0) {
      options_.timeout = std::chrono::milliseconds(static_cast<int64_t>(*seconds * 1000));
    }
  }
  token_file_ = GetString(global, "token");
  if (!token_file_.empty()) {
    absl::StatusOr<std::string> token = ReadFile(token_file_);
    if (!token.ok()) throw UsageError("cannot read --token file " + token_file_);
    options_.token = std::string(absl::StripAsciiWhitespace(*token));
  }
  ClientTlsOptions tls;
  const std::pair<const char*, std::string*> tls_flags[] = {{"tls-ca", &tls.ca_file},
                                                            {"tls-cert", &tls.cert_file},
                                                            {"tls-key", &tls.key_file},
                                                            {"tls-server-name", &tls.server_name}};
  for (const auto& [flag, target] : tls_flags) {
    if (!global.Has(flag)) continue;
    *target = GetString(global, flag);
    if (target->empty()) throw UsageError(absl::StrCat("--", flag, " needs a value"));
    tls_flags_.emplace_back(flag, *target);
  }
  if (!tls_flags_.empty()) options_.tls = tls;
  return global.positional();
}

}  // namespace cli

int RunCli(const std::vector<std::string>& args, std::ostream& out, std::ostream& err) {
  QuietGrpcLogs();
  Cli cli(out, err);
  return Run(cli, args);
}

}  // namespace fieldspace::client
