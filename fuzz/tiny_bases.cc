#include "fuzz/tiny_bases.h"

#include <array>
#include <cstdio>
#include <cstdlib>

#include "absl/strings/str_cat.h"
#include "core/mesh/shapes.h"
#include "core/mesh/triangle_mesh.h"

namespace fieldspace::fuzz {
namespace {

MeshArrays TorusArrays() {
  absl::StatusOr<MeshArrays> arrays = MakeTorus(1.0, 0.4, 12, 8);  // 192 faces, genus 1
  if (!arrays.ok()) {
    std::fprintf(stderr, "fuzz fixture: %s\n", arrays.status().ToString().c_str());
    std::abort();
  }
  return *std::move(arrays);
}

std::shared_ptr<const server::ServedBasis> Build(const std::shared_ptr<const TriangleMesh>& mesh,
                                                 const FieldType& type, const std::string& id) {
  server::BasisKey key;
  key.mesh_id = "m-0000000000000000";
  key.field = type;
  key.dimension = 20;
  key.fields_per_region = 2;
  key.kernel_columns = true;
  server::BuildContext context;
  context.threads = 1;
  absl::StatusOr<server::BuiltBasis> built =
      server::BuildBasisForKey(*mesh, key, Eigen::VectorXd(), context);
  absl::StatusOr<std::shared_ptr<const server::ServedBasis>> served =
      built.ok()
          ? server::ServeBasis({.id = id, .key = key}, mesh, built->basis, built->op.get(), context)
          : built.status();
  if (!served.ok()) {
    std::fprintf(stderr, "fuzz fixture: basis %s: %s\n", id.c_str(),
                 served.status().ToString().c_str());
    std::abort();
  }
  return *std::move(served);
}

}  // namespace

const std::shared_ptr<const server::ServedBasis>& TinyBasis(int which) {
  static const auto* const bases = [] {
    absl::StatusOr<TriangleMesh> mesh = TriangleMesh::Create(TorusArrays());
    if (!mesh.ok()) {
      std::fprintf(stderr, "fuzz fixture: %s\n", mesh.status().ToString().c_str());
      std::abort();
    }
    auto shared = std::make_shared<const TriangleMesh>(*std::move(mesh));
    return new std::array<std::shared_ptr<const server::ServedBasis>, kNumTinyBases>{
        Build(shared, FieldType::Vector(), "b-0000000000000001"),
        Build(shared, FieldType::NField(2), "b-0000000000000002"),
        Build(shared, FieldType::Tensor(), "b-0000000000000003")};
  }();
  return (*bases)[static_cast<unsigned>(which) % kNumTinyBases];
}

std::string TinyMeshFile(std::string_view format) {
  const MeshArrays m = TorusArrays();
  const auto nv = m.vertices.rows(), nf = m.faces.rows();
  std::string out;
  if (format == "obj") {
    absl::StrAppend(&out, "# torus\n");
    for (Eigen::Index v = 0; v < nv; ++v) {
      absl::StrAppend(&out, "v ", m.vertices(v, 0), " ", m.vertices(v, 1), " ", m.vertices(v, 2),
                      "\n");
    }
    // 1-based, with the a/b/c and a//c forms and a negative index on the first faces.
    for (Eigen::Index f = 0; f < nf; ++f) {
      const int a = m.faces(f, 0) + 1, b = m.faces(f, 1) + 1, c = m.faces(f, 2) + 1;
      if (f == 0) {
        absl::StrAppend(&out, "f ", a, "/1/1 ", b, "//2 ", c - (nv + 1), "\n");
      } else {
        absl::StrAppend(&out, "f ", a, " ", b, " ", c, "\n");
      }
    }
  } else if (format == "off") {
    absl::StrAppend(&out, "OFF\n# torus\n", nv, " ", nf, " 0\n");
    for (Eigen::Index v = 0; v < nv; ++v) {
      absl::StrAppend(&out, m.vertices(v, 0), " ", m.vertices(v, 1), " ", m.vertices(v, 2), "\n");
    }
    for (Eigen::Index f = 0; f < nf; ++f) {
      absl::StrAppend(&out, "3 ", m.faces(f, 0), " ", m.faces(f, 1), " ", m.faces(f, 2), "\r\n");
    }
  } else {
    absl::StrAppend(&out, "ply\nformat ascii 1.0\ncomment torus\nelement vertex ", nv,
                    "\nproperty double x\nproperty double y\nproperty double z\n"
                    "property uchar red\nelement face ",
                    nf, "\nproperty list uchar int vertex_indices\nend_header\n");
    for (Eigen::Index v = 0; v < nv; ++v) {
      absl::StrAppend(&out, m.vertices(v, 0), " ", m.vertices(v, 1), " ", m.vertices(v, 2), " 7\n");
    }
    for (Eigen::Index f = 0; f < nf; ++f) {
      absl::StrAppend(&out, "3 ", m.faces(f, 0), " ", m.faces(f, 1), " ", m.faces(f, 2), "\n");
    }
  }
  return out;
}

}  // namespace fieldspace::fuzz
