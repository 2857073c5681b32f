#ifndef FIELDSPACE_CLIENT_CLI_COMMANDS_H_
#define FIELDSPACE_CLIENT_CLI_COMMANDS_H_

// The commands of the `fieldspace` CLI: one table (cli_table.cc) in which each command's
// arguments, flags and help are written once; the parser, the checks of required flags and
// argument counts, `fieldspace --help` and `fieldspace COMMAND --help` all come from it. The
// handlers live in one file per group of commands.

#include <string>
#include <vector>

#include "absl/types/span.h"
#include "client/cli_context.h"
#include "core/common/command_line.h"

namespace fieldspace::client::cli {

struct CliCommand {
  CommandDoc doc;
  // Runs the command on arguments parsed and checked against `doc`; returns the exit code.
  int (*run)(Cli& cli, const CommandLine& args) = nullptr;
  // A tool of the Python package (export, render): its arguments are passed on unparsed (`doc`
  // documents the main ones; `--help` of the tool lists all), `run` is not used.
  bool python_tool = false;
  // Starts a new group in `fieldspace --help` (a blank line before it).
  bool new_group = false;
};

// The table, in the order of `fieldspace --help`.
const std::vector<CliCommand>& Commands();

// cmd_meshes.cc
int Health(Cli& cli, const CommandLine& a);
int Upload(Cli& cli, const CommandLine& a);
int Load(Cli& cli, const CommandLine& a);
int Meshes(Cli& cli, const CommandLine& a);
int Mesh(Cli& cli, const CommandLine& a);
int DeleteMesh(Cli& cli, const CommandLine& a);
// cmd_bases.cc
int Build(Cli& cli, const CommandLine& a);
int Bases(Cli& cli, const CommandLine& a);
int Basis(Cli& cli, const CommandLine& a);
int DeleteBasis(Cli& cli, const CommandLine& a);
int Cancel(Cli& cli, const CommandLine& a);
// cmd_subspace.cc
int Project(Cli& cli, const CommandLine& a);
int Solve(Cli& cli, const CommandLine& a);
int Lift(Cli& cli, const CommandLine& a);
int Eigen(Cli& cli, const CommandLine& a);
int Smoothest(Cli& cli, const CommandLine& a);
int Singularities(Cli& cli, const CommandLine& a);
// cmd_applications.cc
int Curvature(Cli& cli, const CommandLine& a);
int Smooth(Cli& cli, const CommandLine& a);
int Align(Cli& cli, const CommandLine& a);
// cmd_design.cc
int Design(Cli& cli, const CommandLine& a);
// cmd_tools.cc: replaced by `python3 -m fieldspace.<tool> ARGS --server ADDRESS [--token FILE]
// [--tls-* ...]` with the Python package on PYTHONPATH (the build tree's or the installed one,
// found next to this program). Returns only when that cannot start (or the arguments are
// refused).
int RunPythonTool(Cli& cli, const std::string& tool, absl::Span<const std::string> args);

}  // namespace fieldspace::client::cli

#endif  // FIELDSPACE_CLIENT_CLI_COMMANDS_H_
