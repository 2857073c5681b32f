#ifndef FIELDSPACE_SERVER_DEMO_H_
#define FIELDSPACE_SERVER_DEMO_H_

#include <memory>
#include <thread>

#include "absl/status/statusor.h"
#include "server/records.h"

namespace fieldspace::server {

class Registry;

// The bundled demo: the project's procedural torus-knot tube (core/mesh/shapes.h, 49,152 faces)
// and its default vector basis.
inline constexpr int32_t kDemoDimension = 1000;
inline constexpr char kDemoMeshName[] = "demo-torus-knot";

// Generates and stores the demo mesh (idempotent: same mesh, same id) and starts (or joins, or
// finds) the build of its vector basis. Returns the basis key's ids.
struct DemoIds {
  std::string mesh_id;
  std::string basis_id;
};
absl::StatusOr<DemoIds> LoadDemo(Registry* registry);

// Runs LoadDemo on a background thread and logs progress to stderr (`fieldspaced --demo`).
class DemoLoader {
 public:
  explicit DemoLoader(Registry* registry);
  ~DemoLoader();
  // Waits for the loader thread (the build itself continues in the registry until shutdown).
  void Stop();

 private:
  std::thread thread_;
};

std::unique_ptr<DemoLoader> StartDemo(Registry* registry);

}  // namespace fieldspace::server

#endif  // FIELDSPACE_SERVER_DEMO_H_
