#ifndef FIELDSPACE_TESTS_TESTING_TEST_MESHES_H_
#define FIELDSPACE_TESTS_TESTING_TEST_MESHES_H_

#include <cstdlib>
#include <filesystem>
#include <string>

#include "gtest/gtest.h"

namespace fieldspace::testing {

// The folder of the shared test meshes: $FIELDSPACE_MESH_DIR, else ../shared/meshes next to the
// source tree.
inline std::filesystem::path SharedMeshDir() {
  if (const char* env = std::getenv("FIELDSPACE_MESH_DIR"); env != nullptr && *env != '\0') {
    return env;
  }
  return FIELDSPACE_DEFAULT_MESH_DIR;
}

// Full path of a shared mesh, or empty if it is absent.
inline std::string SharedMeshPath(const std::string& name) {
  std::filesystem::path p = SharedMeshDir() / name;
  std::error_code ec;
  return std::filesystem::exists(p, ec) ? p.string() : std::string();
}

}  // namespace fieldspace::testing

// Declares `var` as the path of shared mesh `name`, or skips the test with a clear message.
#define FS_REQUIRE_SHARED_MESH(var, name)                                           \
  const std::string var = ::fieldspace::testing::SharedMeshPath(name);              \
  if (var.empty()) {                                                                \
    GTEST_SKIP() << "shared mesh " << (name) << " not found in "                    \
                 << ::fieldspace::testing::SharedMeshDir()                          \
                 << " (set FIELDSPACE_MESH_DIR to the folder of ../shared/meshes)"; \
  }

#endif  // FIELDSPACE_TESTS_TESTING_TEST_MESHES_H_
