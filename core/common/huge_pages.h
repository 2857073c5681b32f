#ifndef FIELDSPACE_CORE_COMMON_HUGE_PAGES_H_
#define FIELDSPACE_CORE_COMMON_HUGE_PAGES_H_

#include <optional>
#include <string>

namespace fieldspace {

// Transparent huge pages for malloc (docs/design-notes.md, "Huge pages for malloc").
//
// glibc's malloc asks the kernel for transparent huge pages (madvise MADV_HUGEPAGE on the memory
// it maps) only when the tunable glibc.malloc.hugetlb=1 is in GLIBC_TUNABLES at start-up. The
// basis build and the served bases read and write arrays of hundreds of MB at scattered places
// (U, the mesh, each region's factor); with 2 MB pages instead of 4 KB ones their page-table
// walks and page faults mostly go away (bench/RESULTS.md, Session 26).

// The environment a process sees, as far as the decision goes (null: unset).
struct HugePageEnvironment {
  const char* glibc_tunables = nullptr;  // GLIBC_TUNABLES
  const char* opt_out = nullptr;         // FIELDSPACE_HUGE_PAGES ("0": leave malloc alone)
  const char* reexecuted = nullptr;      // kHugePageMarker, set on the re-executed process
  // /sys/kernel/mm/transparent_hugepage/enabled, e.g. "always [madvise] never"; empty when it
  // could not be read.
  std::string thp_enabled;
  // gnu_get_libc_version(), e.g. "2.36"; empty when not glibc.
  std::string glibc_version;
};

inline constexpr char kHugePageMarker[] = "FIELDSPACE_HUGE_PAGES_REEXEC";

// The GLIBC_TUNABLES value to re-execute with, or nullopt to run as is: when the user opted out,
// the process already is the re-executed one, the tunables already name glibc.malloc.hugetlb (the
// user's own choice stands), the kernel's THP mode is "never" or unknown, or the C library is not
// glibc 2.35 or later (the first to know the tunable). Other tunables are kept, ours appended.
std::optional<std::string> HugePageTunables(const HugePageEnvironment& env);

// The process's own HugePageEnvironment.
HugePageEnvironment CurrentHugePageEnvironment();

// Called first in main() of fieldspaced and fieldspace-bench: when HugePageTunables says so,
// re-executes the program (/proc/self/exe, the same argv) with GLIBC_TUNABLES set to its value
// and kHugePageMarker set; the re-executed process removes the marker from its environment again,
// so that programs it starts make their own choice. Returns only when it did not re-execute
// (nothing to do, or execv failed: the process then runs on with the environment it had). Nothing
// else has run yet, so no threads, files or allocations are lost by the exec.
void ReexecWithHugePageMalloc(char** argv);

}  // namespace fieldspace

#endif  // FIELDSPACE_CORE_COMMON_HUGE_PAGES_H_
