#include "server/demo.h"

#include <iostream>

#include "core/common/status_macros.h"
#include "core/mesh/shapes.h"
#include "server/registry.h"

namespace fieldspace::server {

absl::StatusOr<DemoIds> LoadDemo(Registry* registry) {
  ASSIGN_OR_RETURN(MeshArrays arrays, MakeTorusKnot(TorusKnotOptions{}));
  ASSIGN_OR_RETURN(MeshRecord mesh, registry->AddMesh(std::move(arrays), kDemoMeshName, 0));
  BuildRequest request;
  request.key.mesh_id = mesh.id;
  request.key.field = FieldType::Vector();
  request.key.dimension = kDemoDimension;
  request.key.sigma = 40.0;
  ASSIGN_OR_RETURN(Registry::StartedBuild started, registry->StartBuild(std::move(request)));
  DemoIds ids;
  ids.mesh_id = mesh.id;
  ids.basis_id = started.existing.has_value() ? started.existing->id : started.job->basis_id();
  std::cerr << "demo: mesh " << mesh.id << " (" << mesh.num_faces << " faces), vector basis "
            << ids.basis_id << " (d=" << kDemoDimension << ") "
            << (started.existing.has_value() ? "already built" : "building in the background")
            << std::endl;
  if (started.job != nullptr) {
    std::shared_ptr<BuildJob> job = started.job;
    job->Subscribe([job] {
      BuildJob::Progress p = job->progress();
      if (!p.finished) return;
      if (p.status.ok()) {
        std::cerr << "demo: basis " << job->basis_id() << " ready" << std::endl;
      } else {
        std::cerr << "demo: basis build ended: " << p.status << std::endl;
      }
    });
  }
  return ids;
}

DemoLoader::DemoLoader(Registry* registry)
    : thread_([registry] {
        absl::StatusOr<DemoIds> ids = LoadDemo(registry);
        if (!ids.ok()) std::cerr << "demo: " << ids.status() << std::endl;
      }) {}

DemoLoader::~DemoLoader() { Stop(); }

void DemoLoader::Stop() {
  if (thread_.joinable()) thread_.join();
}

std::unique_ptr<DemoLoader> StartDemo(Registry* registry) {
  return std::make_unique<DemoLoader>(registry);
}

}  // namespace fieldspace::server
