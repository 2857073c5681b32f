// Writes the seed corpus of every fuzz target: `make_seeds OUTDIR` fills OUTDIR/<target>/ with
// valid inputs made from the fixture's torus and bases (each file in its target's input layout,
// described at the top of the target's source).

#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <initializer_list>
#include <string>
#include <vector>

#include "absl/strings/str_cat.h"
#include "core/basis/basis_io.h"
#include "core/common/file_util.h"
#include "core/mesh/mesh_io.h"
#include "core/subspace/reduced_system.h"
#include "fieldspace/v1/fieldspace.pb.h"
#include "fuzz/tiny_bases.h"
#include "server/store.h"

namespace fieldspace::fuzz {
namespace {

namespace fs = std::filesystem;
namespace v1 = ::fieldspace::v1;

void Die(const absl::Status& status) {
  std::fprintf(stderr, "make_seeds: %s\n", status.ToString().c_str());
  std::exit(1);
}

std::string Read(const std::string& path) {
  absl::StatusOr<std::string> s = ReadFileToString(path);
  if (!s.ok()) Die(s.status());
  return *std::move(s);
}

class SeedDir {
 public:
  SeedDir(const fs::path& root, const std::string& target) : dir_(root / target) {
    fs::create_directories(dir_);
  }
  void Write(const std::string& name, std::initializer_list<uint8_t> prefix,
             const std::string& body) {
    std::ofstream out(dir_ / name, std::ios::binary | std::ios::trunc);
    for (uint8_t b : prefix) out.put(static_cast<char>(b));
    out << body;
    if (!out) Die(absl::InternalError("cannot write " + (dir_ / name).string()));
  }

 private:
  fs::path dir_;
};

void MeshSeeds(const fs::path& root, const fs::path& scratch) {
  SeedDir d(root, "mesh_io");
  d.Write("torus.obj", {0}, TinyMeshFile("obj"));
  d.Write("torus.off", {1}, TinyMeshFile("off"));
  d.Write("torus_ascii.ply", {2}, TinyMeshFile("ply"));
  d.Write("quads.obj", {0},
          "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 2 0 0\nv 2 1 0\n"
          "vt 0 0\nvn 0 0 1\ng quads\nusemtl m\nf 1 2 3 4\nf 2/1 5/1 6/1 3/1\n");
  d.Write("quads_rejected.obj", {0x10}, "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n");
  const auto& mesh = *TinyBasis(0)->mesh;
  const std::string ply = (scratch / "torus.ply").string();
  if (absl::Status s = WritePly(ply, mesh.vertices(), mesh.faces(),
                                {{"q", std::vector<float>(mesh.num_faces(), 0.5f)}});
      !s.ok()) {
    Die(s);
  }
  d.Write("torus_binary.ply", {2}, Read(ply));
  const uint32_t nv = mesh.num_vertices(), nf = mesh.num_faces();
  std::string raw(reinterpret_cast<const char*>(&nv), 4);
  raw.append(reinterpret_cast<const char*>(&nf), 4);
  raw.append(reinterpret_cast<const char*>(mesh.vertices().data()), 24 * nv);
  raw.append(reinterpret_cast<const char*>(mesh.faces().data()), 12 * nf);
  d.Write("torus.raw", {3}, raw);
}

void StoreSeeds(const fs::path& root, const fs::path& scratch) {
  SeedDir d(root, "store");
  absl::StatusOr<std::unique_ptr<server::Store>> store =
      server::Store::Open((scratch / "store").string());
  if (!store.ok()) Die(store.status());
  const auto& mesh = *TinyBasis(0)->mesh;
  server::MeshRecord m;
  m.id = kStoreMeshId;
  m.name = "torus";
  m.num_vertices = mesh.num_vertices();
  m.num_faces = mesh.num_faces();
  if (absl::Status s = (*store)->SaveMesh(m, mesh.vertices(), mesh.faces()); !s.ok()) Die(s);
  const std::string mesh_file = Read((*store)->MeshPath(kStoreMeshId));
  d.Write("mesh.fsmesh", {0}, mesh_file);
  d.Write("mesh_fix.fsmesh", {0x80}, mesh_file);
  for (int which = 0; which < kNumTinyBases; ++which) {
    const server::ServedBasis& served = *TinyBasis(which);
    absl::StatusOr<std::string> encoded = EncodeBasis(*served.basis, m.id);
    if (!encoded.ok()) Die(encoded.status());
    server::BasisRecord b = served.record;
    b.id = kStoreBasisId;
    b.key.mesh_id = m.id;
    b.columns = served.basis->dimension();
    if (absl::Status s = (*store)->SaveBasis(b, {*encoded}); !s.ok()) Die(s);
    const std::string basis_file = Read((*store)->BasisPath(kStoreBasisId));
    d.Write(absl::StrCat("basis", which, ".fsbasis"), {1}, basis_file);
    d.Write(absl::StrCat("basis", which, "_fix.fsbasis"), {0x81}, basis_file);
    d.Write(absl::StrCat("basis", which, ".basis"), {2}, *encoded);
    d.Write(absl::StrCat("basis", which, "_fix.basis"), {0x82}, *encoded);
    uint64_t hash = 0;
    if (absl::Status s = (*store)->SaveBasis(b, {*encoded}, &hash); !s.ok()) Die(s);
    if (absl::Status s =
            (*store)->SaveReduced(kStoreBasisId, hash, EncodeReducedMatrices(*served.system));
        !s.ok()) {
      Die(s);
    }
    const std::string reduced_file = Read((*store)->ReducedPath(kStoreBasisId));
    d.Write(absl::StrCat("reduced", which, ".fsreduced"), {3}, reduced_file);
    d.Write(absl::StrCat("reduced", which, "_fix.fsreduced"), {0x83}, reduced_file);
  }
}

void Fill(v1::FieldValues* f, int values_per_face, int faces, bool ambient) {
  f->set_encoding(ambient ? v1::FIELD_ENCODING_AMBIENT : v1::FIELD_ENCODING_DOF);
  for (int i = 0; i < values_per_face * faces; ++i) f->add_values(0.25f * ((i * 7) % 5 - 2));
}

void RequestSeeds(const fs::path& root) {
  SeedDir d(root, "requests");
  const int nf = TinyBasis(0)->mesh->num_faces(), dim = TinyBasis(0)->basis->dimension();
  auto write = [&d](const std::string& name, uint8_t type, uint8_t basis,
                    const google::protobuf::Message& m) {
    d.Write(name, {type, basis}, m.SerializeAsString());
  };
  for (const char* path : {"sub/torus.obj", "sub/torus.off", "sub/torus.ply", "../torus.obj"}) {
    v1::LoadMeshRequest r;
    r.set_path(path);
    write(absl::StrCat("load_", fs::path(path).filename().string()), 0, 0, r);
  }
  {
    v1::BuildBasisRequest r;
    r.set_mesh_id(kStoreMeshId);
    r.mutable_field()->set_kind(v1::FIELD_KIND_NFIELD);
    r.mutable_field()->set_n(4);
    r.set_dimension(10);
    r.set_sigma(20);
    r.set_coarse_dimension(2);
    for (int f = 0; f < 4; ++f) r.add_face_weights(1.0 + f);
    write("build", 1, 0, r);
  }
  // Per basis: 2 (vector, 2-field) or 3 (tensor) DOFs per face; ambient: 3 or 6.
  for (int b = 0; b < kNumTinyBases; ++b) {
    const int dofs = b == 2 ? 3 : 2, ambient = b == 2 ? 6 : 3;
    v1::ProjectRequest project;
    Fill(project.mutable_field(), dofs, nf, false);
    write(absl::StrCat("project", b), 2, b, project);
    v1::SolveRequest solve;
    solve.mutable_weights()->set_mu_b(0.5);
    for (int i = 0; i < 3; ++i) {
      v1::Constraint* c = solve.add_constraints();
      c->set_face(i * 50);
      for (int k = 0; k < ambient; ++k) c->add_value(k == i % ambient ? 1.0 : 0.1);
      c->set_encoding(v1::FIELD_ENCODING_AMBIENT);
      c->set_hard(i == 2);
    }
    solve.set_return_field(true);
    solve.set_singularities(true);
    write(absl::StrCat("solve", b), 3, b, solve);
    v1::LiftRequest lift;
    for (int i = 0; i < dim; ++i) lift.add_coefficients(1.0 / (1 + i));
    write(absl::StrCat("lift_all", b), 4, b, lift);
    lift.add_faces(3);
    lift.add_faces(nf - 1);
    lift.set_encoding(v1::FIELD_ENCODING_AMBIENT);
    write(absl::StrCat("lift_faces", b), 4, b, lift);
    v1::EigenfieldsRequest eigen;
    eigen.set_count(4);
    write(absl::StrCat("eigen", b), 5, b, eigen);
    v1::SingularitiesRequest sing;
    for (int i = 0; i < dim; ++i) sing.add_coefficients(i % 3 - 1.0);
    write(absl::StrCat("singularities", b), 7, b, sing);
    v1::SmoothRequest smooth;
    Fill(smooth.mutable_field(), ambient, nf, true);
    for (int f = 0; f < nf; ++f) smooth.add_face_weights(f % 4);
    smooth.set_scale_free(true);
    write(absl::StrCat("smooth", b), 8, b, smooth);
  }
  v1::CurvatureRequest curvature;
  curvature.set_principal(true);
  curvature.set_encoding(v1::FIELD_ENCODING_AMBIENT);
  write("curvature", 6, 0, curvature);
  curvature.set_estimator(static_cast<v1::CurvatureEstimator>(1));
  write("curvature_nd", 6, 0, curvature);
  v1::AlignRequest align;
  align.mutable_weights()->set_mu_s(0.01);
  write("align", 9, 1, align);
}

void DesignSeeds(const fs::path& root) {
  SeedDir d(root, "design");
  auto script = [&d](const std::string& name, uint8_t head,
                     const std::vector<v1::DesignRequest>& requests) {
    std::string body;
    for (const v1::DesignRequest& r : requests) {
      const std::string m = r.SerializeAsString();
      body.push_back(static_cast<char>(m.size() & 0xff));
      body.push_back(static_cast<char>(m.size() >> 8));
      body += m;
    }
    d.Write(name, {head}, body);
  };
  for (int b = 0; b < kNumTinyBases; ++b) {
    const int ambient = b == 2 ? 6 : 3;
    v1::DesignRequest open;
    open.set_seq(1);
    open.mutable_open()->set_basis_id(TinyBasis(b)->record.id);
    open.mutable_open()->add_watch_faces(5);
    open.mutable_open()->set_singularities(b != 2);
    v1::DesignRequest add;
    add.mutable_add()->set_id(7);
    add.mutable_add()->mutable_constraint()->set_face(10);
    add.mutable_add()->mutable_constraint()->set_encoding(v1::FIELD_ENCODING_AMBIENT);
    for (int k = 0; k < ambient; ++k) add.mutable_add()->mutable_constraint()->add_value(k + 1.0);
    v1::DesignRequest hard = add;
    hard.mutable_add()->set_id(8);
    hard.mutable_add()->mutable_constraint()->set_face(100);
    hard.mutable_add()->mutable_constraint()->set_hard(true);
    v1::DesignRequest move;
    move.mutable_move()->set_id(7);
    move.mutable_move()->set_face(50);
    for (int k = 0; k < ambient; ++k) move.mutable_move()->add_value(1.0 - k);
    move.mutable_move()->set_encoding(v1::FIELD_ENCODING_AMBIENT);
    v1::DesignRequest weights;
    weights.mutable_set_weights()->set_mu_b(0.01);
    v1::DesignRequest watch;
    watch.mutable_watch()->add_faces(1);
    watch.mutable_watch()->add_faces(2);
    v1::DesignRequest remove;
    remove.mutable_remove()->set_id(8);
    script(absl::StrCat("session", b), static_cast<uint8_t>(b),
           {open, add, hard, move, weights, watch, remove});
    // The designer's tools (the torus is closed: boundary alignment fails, features find no
    // sharp edge at 60 degrees but do at 10), moved and removed as groups.
    v1::DesignRequest stroke;
    stroke.mutable_add_stroke()->set_id(20);
    for (int f : {3, 60, 120}) {
      v1::SurfacePoint::FacePoint* p =
          stroke.mutable_add_stroke()->add_points()->mutable_face_point();
      p->set_face(f);
      for (double w : {0.2, 0.3, 0.5}) p->add_barycentric(w);
    }
    v1::Point3* q = stroke.mutable_add_stroke()->add_points()->mutable_position();
    q->set_x(0.1);
    q->set_y(-1.2);
    q->set_z(0.3);
    v1::DesignRequest singularity;
    singularity.mutable_place_singularity()->set_id(21);
    singularity.mutable_place_singularity()->set_vertex(17);
    singularity.mutable_place_singularity()->set_index(b == 1 ? 0.5 : 1.0);
    singularity.mutable_place_singularity()->set_hard(true);
    v1::DesignRequest boundary;
    boundary.mutable_align_boundary()->set_id(22);
    v1::DesignRequest features;
    features.mutable_align_features()->set_id(23);
    features.mutable_align_features()->set_angle_degrees(10);
    v1::DesignRequest move_group;
    move_group.mutable_move()->set_id(20);
    *move_group.mutable_move()->mutable_group()->mutable_stroke() = stroke.add_stroke();
    move_group.mutable_move()->mutable_group()->mutable_stroke()->mutable_points()->SwapElements(0,
                                                                                                 1);
    v1::DesignRequest remove_group;
    remove_group.mutable_remove()->set_id(21);
    script(absl::StrCat("tools", b), static_cast<uint8_t>(0x80 | b),
           {stroke, singularity, boundary, features, move_group, remove_group, hard});
    script(absl::StrCat("edits", b), static_cast<uint8_t>(0x80 | b), {add, move, weights, remove});
    if (b == 1) {
      v1::DesignRequest aligned = open;
      aligned.mutable_open()->mutable_data()->mutable_curvature();
      aligned.mutable_open()->mutable_weights()->set_mu_a(1.0);
      script("aligned", 1, {aligned, add, weights});
    }
  }
}

}  // namespace
}  // namespace fieldspace::fuzz

int main(int argc, char** argv) {
  namespace fs = std::filesystem;
  if (argc != 2) {
    std::fprintf(stderr, "usage: make_seeds OUTDIR\n");
    return 2;
  }
  const fs::path root = argv[1];
  const fs::path scratch = root / ".scratch";
  fs::remove_all(scratch);
  fs::create_directories(scratch);
  fieldspace::fuzz::MeshSeeds(root, scratch);
  fieldspace::fuzz::StoreSeeds(root, scratch);
  fieldspace::fuzz::RequestSeeds(root);
  fieldspace::fuzz::DesignSeeds(root);
  fs::remove_all(scratch);
  return 0;
}
