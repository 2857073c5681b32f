#ifndef FIELDSPACE_CLIENT_CLI_CONTEXT_H_
#define FIELDSPACE_CLIENT_CLI_CONTEXT_H_

// What every command of the `fieldspace` CLI shares: its streams, the client of the server, the
// global options, the three ways it fails (an RPC, a local file or check, a usage error) and the
// one writer of `--out FIELD_FILE`.

#include <memory>
#include <ostream>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "absl/status/status.h"
#include "client/field_client.h"
#include "client/field_files.h"
#include "client/json.h"
#include "core/common/command_line.h"

namespace fieldspace::client::cli {

// A usage error: the command's flags or arguments are wrong. The CLI prints it in the README's
// form with the command's usage and exits 2.
class UsageError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// The server when neither --server nor $FIELDSPACE_SERVER says (`make run`'s address, as the
// Python package).
inline constexpr char kDefaultServer[] = "127.0.0.1:50051";

class Cli {
 public:
  Cli(std::ostream& out, std::ostream& err) : out_(out), err_(err) {}

  std::ostream& out() { return out_; }
  std::ostream& err() { return err_; }
  const FieldClient& client() const { return *client_; }
  const std::string& command() const { return command_; }
  const FieldClientOptions& options() const { return options_; }

  // An RPC failure: "fieldspace: <what> failed: <CODE>: <message>" (with a hint to pass --tls-ca
  // when a plaintext call found a TLS port). Returns the exit code, 1.
  int Fail(const absl::Status& status, const std::string& what);
  // A local failure (a file that cannot be read or written, a check before any call):
  // "fieldspace: <message>", e.g. "fieldspace: cannot open mesh.obj: No such file or directory".
  int FailLocal(const absl::Status& status);
  void Emit(const JsonWriter& j) { out_ << j.str() << "\n" << std::flush; }

  // The global options that reach this server again, for commands the CLI suggests
  // ("--server HOST:PORT [--token FILE] [--tls-* ...]").
  std::string GlobalFlags() const;

  // --out FIELD_FILE's format from its extension: .txt (text, see field_files.h) or .ply (the
  // mesh with the field as face properties). UsageError naming the accepted extensions (and
  // `export` for .vtu, .vtk, .rawfield) for any other, so that a command refuses before its call.
  static void CheckFieldOut(const std::string& path);
  // Writes `field` (of type `field_type`, e.g. "vector", on the mesh `mesh_id`) to `path` in the
  // format CheckFieldOut chose: the one field writer of every command. Returns the exit code.
  int WriteFieldOut(const std::string& path, const FieldFile& field, const std::string& field_type,
                    const std::string& mesh_id);
  // Lifts all faces of `basis_id` and writes them with WriteFieldOut. Returns the exit code.
  int LiftToFile(const std::string& basis_id, const std::vector<double>& coefficients,
                 fieldspace::v1::FieldEncoding encoding, const std::string& path);
  // LiftToFile to --out (in --encoding) when the command was given --out; 0 otherwise.
  int LiftToOut(const CommandLine& a, const std::string& basis_id,
                const std::vector<double>& coefficients);

  // The dispatcher's part (cli.cc): global options, then the client for the command.
  std::vector<std::string> ParseGlobal(const std::vector<std::string>& args);
  void SetCommand(const std::string& command) { command_ = command; }
  void Connect();
  const std::string& token_file() const { return token_file_; }
  const std::vector<std::pair<std::string, std::string>>& tls_flags() const { return tls_flags_; }

 private:
  std::ostream& out_;
  std::ostream& err_;
  std::string command_;     // the command being run, for messages
  std::string token_file_;  // --token FILE, passed on to the Python tools
  // --tls-* flags as given (flag name without dashes, value), passed on to the Python tools.
  std::vector<std::pair<std::string, std::string>> tls_flags_;
  FieldClientOptions options_;
  std::unique_ptr<FieldClient> client_;
};

}  // namespace fieldspace::client::cli

#endif  // FIELDSPACE_CLIENT_CLI_CONTEXT_H_
