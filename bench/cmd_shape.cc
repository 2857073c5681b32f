// `fieldspace-bench shape NAME --out FILE.ply [--level N]`: writes a procedural mesh (the demo
// mesh and test shapes of core/mesh/shapes.h) as binary PLY and prints its statistics.
#include <cstdio>
#include <string>

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"
#include "bench/bench_util.h"
#include "bench/commands.h"
#include "core/mesh/mesh_io.h"
#include "core/mesh/shapes.h"
#include "core/mesh/triangle_mesh.h"

namespace fieldspace::bench {

int RunShape(const Args& args) {
  const auto out = args.Get("out");
  auto level = args.GetInt("level", 4);
  if (!level.ok()) return ReportError(level.status());
  const std::string& name = args.positional()[0];
  absl::StatusOr<MeshArrays> arrays;
  if (name == "torus-knot") {
    TorusKnotOptions knot;  // the demo mesh: 2 * 1024 * 24 = 49,152 faces, genus 1
    knot.segments = 1024;
    knot.tube_segments = 24;
    arrays = MakeTorusKnot(knot);
  } else if (name == "icosphere") {
    arrays = MakeIcosphere(static_cast<int32_t>(*level));
  } else if (name == "torus") {
    arrays = MakeTorus(1.0, 0.4, 96, 48);
  } else if (name == "genus2") {
    arrays = MakeGenusSurface(2, static_cast<int32_t>(*level));
  } else {
    return ReportError(absl::InvalidArgumentError(absl::StrCat("unknown shape '", name, "'")));
  }
  if (!arrays.ok()) return ReportError(arrays.status());
  auto mesh = TriangleMesh::Create(*std::move(arrays));
  if (!mesh.ok()) return ReportError(mesh.status());
  if (auto st = WritePly(*out, mesh->vertices(), mesh->faces()); !st.ok()) return ReportError(st);
  JsonWriter json;
  json.BeginObject()
      .String("shape", name)
      .String("path", *out)
      .Int("vertices", mesh->num_vertices())
      .Int("faces", mesh->num_faces())
      .Int("genus", mesh->genus())
      .EndObject();
  std::printf("%s\n", json.str().c_str());
  return 0;
}

}  // namespace fieldspace::bench
