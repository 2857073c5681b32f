#include "core/common/huge_pages.h"

#include <unistd.h>

#include <cstdlib>
#include <fstream>
#include <optional>
#include <string>
#include <vector>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "absl/strings/string_view.h"

#if defined(__GLIBC__)
#include <gnu/libc-version.h>
#endif

namespace fieldspace {
namespace {

constexpr absl::string_view kTunable = "glibc.malloc.hugetlb";

// The value of `name` in a GLIBC_TUNABLES string ("name=value:name=value"), if present.
std::optional<absl::string_view> TunableValue(absl::string_view tunables, absl::string_view name) {
  for (absl::string_view item : absl::StrSplit(tunables, ':')) {
    const size_t eq = item.find('=');
    if (eq != absl::string_view::npos && item.substr(0, eq) == name) return item.substr(eq + 1);
  }
  return std::nullopt;
}

// glibc 2.35 introduced glibc.malloc.hugetlb; older versions ignore it.
bool GlibcKnowsTunable(absl::string_view version) {
  const std::vector<absl::string_view> parts = absl::StrSplit(version, '.');
  int major = 0, minor = 0;
  if (parts.size() < 2 || !absl::SimpleAtoi(parts[0], &major) ||
      !absl::SimpleAtoi(parts[1], &minor)) {
    return false;
  }
  return major > 2 || (major == 2 && minor >= 35);
}

}  // namespace

std::optional<std::string> HugePageTunables(const HugePageEnvironment& env) {
  if (env.opt_out != nullptr && absl::string_view(env.opt_out) == "0") return std::nullopt;
  if (env.reexecuted != nullptr) return std::nullopt;
  const absl::string_view tunables = env.glibc_tunables != nullptr ? env.glibc_tunables : "";
  if (TunableValue(tunables, kTunable).has_value()) return std::nullopt;
  // The mode in use is the bracketed one; "never" (or no THP support at all) leaves nothing to ask.
  if (env.thp_enabled.find("[always]") == std::string::npos &&
      env.thp_enabled.find("[madvise]") == std::string::npos) {
    return std::nullopt;
  }
  if (!GlibcKnowsTunable(env.glibc_version)) return std::nullopt;
  return tunables.empty() ? absl::StrCat(kTunable, "=1")
                          : absl::StrCat(tunables, ":", kTunable, "=1");
}

HugePageEnvironment CurrentHugePageEnvironment() {
  HugePageEnvironment env;
  env.glibc_tunables = std::getenv("GLIBC_TUNABLES");
  env.opt_out = std::getenv("FIELDSPACE_HUGE_PAGES");
  env.reexecuted = std::getenv(kHugePageMarker);
  std::ifstream thp("/sys/kernel/mm/transparent_hugepage/enabled");
  if (thp) std::getline(thp, env.thp_enabled);
#if defined(__GLIBC__)
  env.glibc_version = gnu_get_libc_version();
#endif
  return env;
}

void ReexecWithHugePageMalloc(char** argv) {
  const HugePageEnvironment env = CurrentHugePageEnvironment();
  const std::optional<std::string> tunables = HugePageTunables(env);
  if (env.reexecuted != nullptr) {
    // This is the re-executed process: the marker has done its work. Programs it starts decide
    // for themselves (glibc may have dropped the tunable from the GLIBC_TUNABLES they inherit).
    unsetenv(kHugePageMarker);
  }
  if (!tunables.has_value()) return;
  const std::string previous = env.glibc_tunables != nullptr ? env.glibc_tunables : "";
  const bool had_tunables = env.glibc_tunables != nullptr;
  if (setenv("GLIBC_TUNABLES", tunables->c_str(), 1) != 0) return;
  setenv(kHugePageMarker, "1", 1);
  execv("/proc/self/exe", argv);
  // Still here: the exec failed (no /proc, say). Run on as we were.
  if (had_tunables) {
    setenv("GLIBC_TUNABLES", previous.c_str(), 1);
  } else {
    unsetenv("GLIBC_TUNABLES");
  }
  unsetenv(kHugePageMarker);
}

}  // namespace fieldspace
