// The CLI's tools of the Python package: export and render.

#include <unistd.h>

#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <optional>

#include "absl/strings/ascii.h"
#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "client/cli_commands.h"

namespace fieldspace::client::cli {
namespace {

// The value of --out among a tool's unparsed arguments (`--out FILE` or `--out=FILE`).
std::optional<std::string> OutArgument(absl::Span<const std::string> args) {
  for (size_t i = 0; i < args.size(); ++i) {
    if (args[i] == "--out" && i + 1 < args.size()) return args[i + 1];
    if (absl::StartsWith(args[i], "--out=")) return args[i].substr(6);
  }
  return std::nullopt;
}

}  // namespace

int RunPythonTool(Cli& cli, const std::string& tool, absl::Span<const std::string> args) {
  // render writes PNG (.png) or JPEG (.jpg, .jpeg); another extension is refused here, before
  // Python starts (render.py refuses it too).
  if (const std::optional<std::string> out = OutArgument(args); tool == "render" && out) {
    const std::string ext = absl::AsciiStrToLower(std::filesystem::path(*out).extension().string());
    if (ext != ".png" && ext != ".jpg" && ext != ".jpeg") {
      throw UsageError(
          absl::StrCat("--out ", *out, ": render writes PNG (.png) or JPEG (.jpg, .jpeg)"));
    }
  }
  // The package next to this program: build/bin/../python in the build tree,
  // PREFIX/bin/../lib/python3/dist-packages when installed.
  std::error_code ec;
  const std::filesystem::path self = std::filesystem::read_symlink("/proc/self/exe", ec);
  std::string package_dir;
  for (const char* relative : {"../python", "../lib/python3/dist-packages"}) {
    const std::filesystem::path dir = self.parent_path() / relative;
    if (!ec && std::filesystem::exists(dir / "fieldspace" / "__init__.py")) {
      package_dir = std::filesystem::weakly_canonical(dir).string();
      break;
    }
  }
  if (package_dir.empty()) {
    return cli.FailLocal(absl::FailedPreconditionError(
        "the Python package fieldspace is not next to this program (build it, or `make install`)"));
  }
  const char* old_path = std::getenv("PYTHONPATH");
  const std::string python_path = old_path != nullptr && *old_path != '\0'
                                      ? absl::StrCat(package_dir, ":", old_path)
                                      : package_dir;
  setenv("PYTHONPATH", python_path.c_str(), 1);
  const char* python_env = std::getenv("FIELDSPACE_PYTHON");
  const std::string python = python_env != nullptr ? python_env : "/usr/bin/python3";
  std::vector<std::string> argv = {python, "-m", "fieldspace." + tool};
  argv.insert(argv.end(), args.begin(), args.end());
  argv.insert(argv.end(), {"--server", cli.options().address});
  if (!cli.token_file().empty()) argv.insert(argv.end(), {"--token", cli.token_file()});
  for (const auto& [flag, value] : cli.tls_flags()) argv.insert(argv.end(), {"--" + flag, value});
  std::vector<char*> raw;
  for (std::string& a : argv) raw.push_back(a.data());
  raw.push_back(nullptr);
  cli.out() << std::flush;
  cli.err() << std::flush;
  execv(python.c_str(), raw.data());
  return cli.FailLocal(
      absl::UnavailableError(absl::StrCat("cannot run ", python, ": ", strerror(errno))));
}

}  // namespace fieldspace::client::cli
