#ifndef FIELDSPACE_CLIENT_CLI_H_
#define FIELDSPACE_CLIENT_CLI_H_

#include <ostream>
#include <string>
#include <vector>

namespace fieldspace::client {

// The `fieldspace` command line client:
//   fieldspace --server HOST:PORT [--token FILE] [--timeout SECONDS] COMMAND [ARGS]
// `args` as argv (args[0] is the program name). Machine-readable JSON goes to `out`, progress
// and human-readable errors to `err`. Returns the exit code: 0 success, 1 failure (an RPC error or
// a bad file), 2 usage error.
int RunCli(const std::vector<std::string>& args, std::ostream& out, std::ostream& err);

}  // namespace fieldspace::client

#endif  // FIELDSPACE_CLIENT_CLI_H_
