// In-process tests of fieldspace.v1.FieldSpace: a FieldServer on 127.0.0.1:0, driven through the
// generated stubs. Every RPC's success path (checked against independent computations where there
// is one) and its error paths with exact status codes.

#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "Eigen/Dense"
#include "absl/strings/str_format.h"
#include "core/basis/basis_io.h"
#include "core/mesh/shapes.h"
#include "core/operators/field_operator.h"
#include "fieldspace/v1/fieldspace.grpc.pb.h"
#include "gmock/gmock.h"
#include "grpc/health/v1/health.grpc.pb.h"
#include "grpcpp/grpcpp.h"
#include "gtest/gtest.h"
#include "server/field_server.h"
#include "server/registry.h"
#include "server/served_basis.h"
#include "server/store.h"
#include "tests/testing/server_fixture.h"

namespace fieldspace::server {
namespace {

namespace fs = std::filesystem;
namespace v1 = ::fieldspace::v1;
using ::fieldspace::testing::TestServer;
using ::testing::HasSubstr;
using ::testing::MatchesRegex;

MeshArrays Icosphere(int subdivisions) {
  absl::StatusOr<MeshArrays> m = MakeIcosphere(subdivisions, 1.0);
  EXPECT_TRUE(m.ok()) << m.status();
  return *m;
}

std::string ObjText(const MeshArrays& m) {
  std::string out;
  for (Eigen::Index i = 0; i < m.vertices.rows(); ++i) {
    out += absl::StrFormat("v %.17g %.17g %.17g\n", m.vertices(i, 0), m.vertices(i, 1),
                           m.vertices(i, 2));
  }
  for (Eigen::Index f = 0; f < m.faces.rows(); ++f) {
    out += absl::StrFormat("f %d %d %d\n", m.faces(f, 0) + 1, m.faces(f, 1) + 1, m.faces(f, 2) + 1);
  }
  return out;
}

std::string RawBytes(const MeshArrays& m) {
  std::string out(reinterpret_cast<const char*>(m.vertices.data()),
                  sizeof(double) * m.vertices.size());
  out.append(reinterpret_cast<const char*>(m.faces.data()), sizeof(int32_t) * m.faces.size());
  return out;
}

struct Uploaded {
  grpc::Status status;
  v1::MeshInfo info;
};

Uploaded Upload(v1::FieldSpace::Stub* stub, const std::vector<v1::UploadMeshRequest>& messages) {
  Uploaded out;
  grpc::ClientContext context;
  auto writer = stub->UploadMesh(&context, &out.info);
  for (const auto& m : messages) {
    if (!writer->Write(m)) break;
  }
  writer->WritesDone();
  out.status = writer->Finish();
  return out;
}

std::vector<v1::UploadMeshRequest> Chunked(const std::string& bytes, v1::UploadMeshHeader header,
                                           size_t chunk) {
  std::vector<v1::UploadMeshRequest> out;
  size_t offset = 0;
  do {
    v1::UploadMeshRequest r;
    if (out.empty()) *r.mutable_header() = header;
    r.set_offset(offset);
    r.set_data(bytes.substr(offset, chunk));
    offset += r.data().size();
    r.set_last(offset >= bytes.size());
    out.push_back(std::move(r));
  } while (offset < bytes.size());
  return out;
}

v1::UploadMeshHeader RawHeader(const MeshArrays& m) {
  v1::UploadMeshHeader h;
  h.set_name("icosphere");
  h.set_format(v1::MESH_FORMAT_RAW);
  h.set_num_vertices(m.vertices.rows());
  h.set_num_faces(m.faces.rows());
  return h;
}

struct Built {
  grpc::Status status;
  std::vector<v1::BuildBasisProgress> progress;
  v1::BasisInfo basis() const {
    return progress.empty() ? v1::BasisInfo() : progress.back().basis();
  }
};

Built Build(v1::FieldSpace::Stub* stub, const v1::BuildBasisRequest& request) {
  Built out;
  grpc::ClientContext context;
  auto reader = stub->BuildBasis(&context, request);
  v1::BuildBasisProgress p;
  while (reader->Read(&p)) out.progress.push_back(p);
  out.status = reader->Finish();
  return out;
}

v1::BuildBasisRequest BuildRequest(const std::string& mesh_id, v1::FieldKind kind, int32_t d,
                                   int32_t n = 0) {
  v1::BuildBasisRequest r;
  r.set_mesh_id(mesh_id);
  r.mutable_field()->set_kind(kind);
  r.mutable_field()->set_n(n);
  r.set_dimension(d);
  return r;
}

struct Lifted {
  grpc::Status status;
  std::vector<v1::FieldChunk> chunks;
  std::vector<float> values() const {
    std::vector<float> v;
    for (const auto& c : chunks)
      v.insert(v.end(), c.field().values().begin(), c.field().values().end());
    return v;
  }
};

Lifted Lift(v1::FieldSpace::Stub* stub, const v1::LiftRequest& request) {
  Lifted out;
  grpc::ClientContext context;
  auto reader = stub->Lift(&context, request);
  v1::FieldChunk c;
  while (reader->Read(&c)) out.chunks.push_back(c);
  out.status = reader->Finish();
  return out;
}

v1::LiftRequest LiftRequest(const std::string& basis_id, const std::vector<double>& x,
                            v1::FieldEncoding encoding, std::vector<int32_t> faces = {}) {
  v1::LiftRequest r;
  r.set_basis_id(basis_id);
  r.mutable_coefficients()->Add(x.begin(), x.end());
  r.set_encoding(encoding);
  r.mutable_faces()->Add(faces.begin(), faces.end());
  return r;
}

std::vector<double> TestCoefficients(int d) {
  std::vector<double> x(d);
  for (int i = 0; i < d; ++i) x[i] = std::sin(1.0 + 0.7 * i);
  return x;
}

v1::Constraint MakeConstraint(int face, std::vector<double> value, v1::FieldEncoding encoding,
                              bool hard, double weight = 0) {
  v1::Constraint c;
  c.set_face(face);
  c.mutable_value()->Add(value.begin(), value.end());
  c.set_encoding(encoding);
  c.set_hard(hard);
  if (weight > 0) c.set_weight(weight);
  return c;
}

// One session: write each request, read its answer; stops at the first failure.
struct Session {
  std::vector<v1::DesignUpdate> updates;
  grpc::Status status;
};

Session RunSession(v1::FieldSpace::Stub* stub, const std::vector<v1::DesignRequest>& requests) {
  Session s;
  grpc::ClientContext context;
  auto stream = stub->Design(&context);
  for (const auto& r : requests) {
    v1::DesignUpdate u;
    if (!stream->Write(r) || !stream->Read(&u)) break;
    s.updates.push_back(u);
  }
  stream->WritesDone();
  s.status = stream->Finish();
  return s;
}

v1::DesignRequest Open(const std::string& basis_id, double mu_s, double mu_b, double mu_c,
                       std::vector<int32_t> watch = {}) {
  v1::DesignRequest r;
  r.mutable_open()->set_basis_id(basis_id);
  r.mutable_open()->mutable_weights()->set_mu_s(mu_s);
  r.mutable_open()->mutable_weights()->set_mu_b(mu_b);
  r.mutable_open()->mutable_weights()->set_mu_c(mu_c);
  r.mutable_open()->mutable_watch_faces()->Add(watch.begin(), watch.end());
  r.mutable_open()->set_watch_encoding(v1::FIELD_ENCODING_DOF);
  return r;
}

v1::DesignRequest Add(int id, const v1::Constraint& c) {
  v1::DesignRequest r;
  r.mutable_add()->set_id(id);
  *r.mutable_add()->mutable_constraint() = c;
  return r;
}

double MaxAbsDiff(const google::protobuf::RepeatedField<double>& a,
                  const google::protobuf::RepeatedField<double>& b) {
  EXPECT_EQ(a.size(), b.size());
  double m = 0;
  for (int i = 0; i < std::min(a.size(), b.size()); ++i) m = std::max(m, std::abs(a[i] - b[i]));
  return m;
}

double MaxAbs(const google::protobuf::RepeatedField<double>& a) {
  double m = 0;
  for (double v : a) m = std::max(m, std::abs(v));
  return m;
}

// The shared server of most tests: an icosphere (1280 faces) with vector, 4-field and tensor
// bases, built once.
class ServiceTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    FieldServerOptions options;
    options.max_message_mb = 4;
    options.max_upload_mb = 8;
    options.max_dimension = 500;
    h_ = TestServer::Start("shared", options).release();
    ASSERT_NE(h_, nullptr);
    mesh_ = new MeshArrays(Icosphere(3));
    Uploaded up = Upload(h_->stub.get(), Chunked(RawBytes(*mesh_), RawHeader(*mesh_), 1 << 16));
    ASSERT_TRUE(up.status.ok()) << up.status.error_message();
    mesh_id_ = new std::string(up.info.id());
    for (auto [kind, n, d, out] : {std::tuple{v1::FIELD_KIND_VECTOR, 0, 60, &vector_id_},
                                   std::tuple{v1::FIELD_KIND_NFIELD, 4, 40, &nfield_id_},
                                   std::tuple{v1::FIELD_KIND_TENSOR, 0, 45, &tensor_id_}}) {
      Built b = Build(h_->stub.get(), BuildRequest(*mesh_id_, kind, d, n));
      ASSERT_TRUE(b.status.ok()) << b.status.error_message();
      *out = new std::string(b.basis().id());
    }
  }
  static void TearDownTestSuite() {
    delete h_;
    delete mesh_;
    delete mesh_id_;
    delete vector_id_;
    delete nfield_id_;
    delete tensor_id_;
  }
  static v1::FieldSpace::Stub* stub() { return h_->stub.get(); }
  static std::shared_ptr<const ServedBasis> Loaded(const std::string& id) {
    auto b = h_->server->registry()->GetBasis(id);
    EXPECT_TRUE(b.ok()) << b.status();
    return *b;
  }
  // U of basis `id` as the daemon's store holds it: the served basis keeps only its LiftPlan
  // (ReducedSystemOptions::release_basis_rows), so the file is the independent copy.
  static Eigen::SparseMatrix<float, Eigen::RowMajor> StoredU(const std::string& id) {
    auto file = h_->server->store()->LoadBasis(id);
    EXPECT_TRUE(file.ok()) << file.status();
    if (!file.ok()) return {};
    auto decoded = DecodeBasis(file->payload);
    EXPECT_TRUE(decoded.ok()) << decoded.status();
    if (!decoded.ok()) return {};
    return std::move(decoded->basis.U);
  }

  static TestServer* h_;
  static MeshArrays* mesh_;
  static std::string* mesh_id_;
  static std::string* vector_id_;
  static std::string* nfield_id_;
  static std::string* tensor_id_;
};

TestServer* ServiceTest::h_ = nullptr;
MeshArrays* ServiceTest::mesh_ = nullptr;
std::string* ServiceTest::mesh_id_ = nullptr;
std::string* ServiceTest::vector_id_ = nullptr;
std::string* ServiceTest::nfield_id_ = nullptr;
std::string* ServiceTest::tensor_id_ = nullptr;

// --- meshes ------------------------------------------------------------------------------------

TEST_F(ServiceTest, UploadIsContentAddressedAndIdempotentAcrossFormats) {
  EXPECT_THAT(*mesh_id_, MatchesRegex("m-[0-9a-f]{16}"));
  // The same arrays as OBJ text (exact decimal round trip), in tiny chunks: same id.
  v1::UploadMeshHeader header;
  header.set_name("ico.obj");  // format from the name
  const std::string obj = ObjText(*mesh_);
  header.set_total_bytes(obj.size());
  Uploaded up = Upload(stub(), Chunked(obj, header, 1000));
  ASSERT_TRUE(up.status.ok()) << up.status.error_message();
  EXPECT_EQ(up.info.id(), *mesh_id_);
  EXPECT_EQ(up.info.num_faces(), 1280);
  EXPECT_EQ(up.info.num_vertices(), 642);
  EXPECT_EQ(up.info.num_edges(), 1920);
  EXPECT_EQ(up.info.euler_characteristic(), 2);
  EXPECT_EQ(up.info.genus(), 0);
  EXPECT_NEAR(up.info.total_area(), 4 * M_PI, 0.1);
  // A different mesh has a different id.
  MeshArrays small = Icosphere(1);
  Uploaded other = Upload(stub(), Chunked(RawBytes(small), RawHeader(small), 1 << 20));
  ASSERT_TRUE(other.status.ok());
  EXPECT_NE(other.info.id(), *mesh_id_);
}

TEST_F(ServiceTest, UploadErrors) {
  const MeshArrays small = Icosphere(1);
  const std::string raw = RawBytes(small);
  auto code = [&](std::vector<v1::UploadMeshRequest> messages) {
    return Upload(stub(), messages).status.error_code();
  };
  // No messages at all; a first message without header; a second header.
  EXPECT_EQ(code({}), grpc::StatusCode::INVALID_ARGUMENT);
  std::vector<v1::UploadMeshRequest> m = Chunked(raw, RawHeader(small), 100);
  auto no_header = m;
  no_header[0].clear_header();
  EXPECT_EQ(code(no_header), grpc::StatusCode::INVALID_ARGUMENT);
  auto two_headers = m;
  *two_headers[1].mutable_header() = RawHeader(small);
  EXPECT_EQ(code(two_headers), grpc::StatusCode::INVALID_ARGUMENT);
  // Out-of-order and overlapping chunks.
  auto swapped = m;
  std::swap(swapped[1], swapped[2]);
  Uploaded out_of_order = Upload(stub(), swapped);
  EXPECT_EQ(out_of_order.status.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_THAT(out_of_order.status.error_message(), HasSubstr("out-of-order"));
  auto gap = m;
  gap[3].set_offset(gap[3].offset() + 1);
  EXPECT_EQ(code(gap), grpc::StatusCode::INVALID_ARGUMENT);
  // Truncated raw data; wrong announced total.
  EXPECT_EQ(code(Chunked(raw.substr(0, raw.size() - 4), RawHeader(small), 100)),
            grpc::StatusCode::INVALID_ARGUMENT);
  v1::UploadMeshHeader announced = RawHeader(small);
  announced.set_total_bytes(raw.size() + 1);
  EXPECT_EQ(code(Chunked(raw, announced, 100)), grpc::StatusCode::INVALID_ARGUMENT);
  // Raw counts absurd or zero.
  v1::UploadMeshHeader huge = RawHeader(small);
  huge.set_num_faces(int64_t{1} << 40);
  EXPECT_EQ(code(Chunked(raw, huge, 100)), grpc::StatusCode::INVALID_ARGUMENT);
  v1::UploadMeshHeader big = RawHeader(small);
  big.set_num_faces(int64_t{1} << 26);  // valid count, beyond the 8 MiB upload limit
  EXPECT_EQ(code(Chunked(raw, big, 100)), grpc::StatusCode::RESOURCE_EXHAUSTED);
  // Announced size beyond the limit is refused up front; so is the data itself.
  v1::UploadMeshHeader obj_header;
  obj_header.set_name("x.obj");
  obj_header.set_total_bytes(uint64_t{1} << 30);
  EXPECT_EQ(code(Chunked("v 0 0 0\n", obj_header, 100)), grpc::StatusCode::RESOURCE_EXHAUSTED);
  obj_header.set_total_bytes(0);
  EXPECT_EQ(code(Chunked(std::string(9 << 20, ' '), obj_header, 3 << 20)),
            grpc::StatusCode::RESOURCE_EXHAUSTED);
  // One message above the 4 MiB message limit: gRPC refuses it.
  EXPECT_EQ(code(Chunked(std::string(5 << 20, ' '), obj_header, 5 << 20)),
            grpc::StatusCode::RESOURCE_EXHAUSTED);
  // An upload that announces no size must mark its last message: unmarked it stores nothing,
  // and nothing may follow the marked one.
  const std::string triangle = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n";
  std::vector<v1::UploadMeshRequest> marked = Chunked(triangle, obj_header, 10);
  ASSERT_GT(marked.size(), 2u);
  auto unmarked = marked;
  unmarked.back().set_last(false);
  Uploaded refused = Upload(stub(), unmarked);
  EXPECT_EQ(refused.status.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_THAT(refused.status.error_message(), HasSubstr("without a message marked last"));
  auto early = marked;
  early[1].set_last(true);
  Uploaded after_last = Upload(stub(), early);
  EXPECT_EQ(after_last.status.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_THAT(after_last.status.error_message(), HasSubstr("follows the one marked last"));
  Uploaded whole = Upload(stub(), marked);
  ASSERT_TRUE(whole.status.ok()) << whole.status.error_message();
  EXPECT_EQ(whole.info.num_faces(), 1);
  // Unknown format, malformed text, invalid geometry.
  v1::UploadMeshHeader unnamed;
  unnamed.set_name("mesh.stl");
  EXPECT_EQ(code(Chunked("solid x", unnamed, 100)), grpc::StatusCode::INVALID_ARGUMENT);
  v1::UploadMeshHeader bad_enum;
  bad_enum.set_format(static_cast<v1::MeshFormat>(42));
  EXPECT_EQ(code(Chunked("v 0 0 0", bad_enum, 100)), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(code(Chunked("v 0 0 zero\nf 1 2 3\n", obj_header, 100)),
            grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(code(Chunked("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n", obj_header, 100)),
            grpc::StatusCode::INVALID_ARGUMENT);
  MeshArrays nan_mesh = small;
  nan_mesh.vertices(3, 1) = std::nan("");
  EXPECT_EQ(code(Chunked(RawBytes(nan_mesh), RawHeader(nan_mesh), 1000)),
            grpc::StatusCode::INVALID_ARGUMENT);
  MeshArrays bad_index = small;
  bad_index.faces(5, 2) = 1 << 30;
  EXPECT_EQ(code(Chunked(RawBytes(bad_index), RawHeader(bad_index), 1000)),
            grpc::StatusCode::INVALID_ARGUMENT);
}

TEST_F(ServiceTest, GetListAndGeometryRoundTrip) {
  v1::GetMeshRequest get;
  get.set_mesh_id(*mesh_id_);
  v1::MeshInfo info;
  {
    grpc::ClientContext c;
    ASSERT_TRUE(stub()->GetMesh(&c, get, &info).ok());
  }
  EXPECT_EQ(info.id(), *mesh_id_);
  EXPECT_EQ(info.name(), "icosphere");
  get.set_mesh_id("m-0000000000000000");
  {
    grpc::ClientContext c;
    EXPECT_EQ(stub()->GetMesh(&c, get, &info).error_code(), grpc::StatusCode::NOT_FOUND);
  }
  get.set_mesh_id("");
  {
    grpc::ClientContext c;
    EXPECT_EQ(stub()->GetMesh(&c, get, &info).error_code(), grpc::StatusCode::NOT_FOUND);
  }
  v1::ListMeshesResponse list;
  {
    grpc::ClientContext c;
    ASSERT_TRUE(stub()->ListMeshes(&c, v1::ListMeshesRequest(), &list).ok());
  }
  bool found = false;
  for (const auto& m : list.meshes()) found = found || m.id() == *mesh_id_;
  EXPECT_TRUE(found);

  v1::GetMeshGeometryRequest g;
  g.set_mesh_id(*mesh_id_);
  g.set_chunk_faces(100);
  grpc::ClientContext c;
  auto reader = stub()->GetMeshGeometry(&c, g);
  std::vector<double> v;
  std::vector<int32_t> f;
  v1::MeshGeometryChunk chunk;
  int chunks = 0;
  while (reader->Read(&chunk)) {
    EXPECT_EQ(chunk.start_vertex(), static_cast<int>(v.size() / 3));
    EXPECT_EQ(chunk.start_face(), static_cast<int>(f.size() / 3));
    v.insert(v.end(), chunk.vertices().begin(), chunk.vertices().end());
    f.insert(f.end(), chunk.faces().begin(), chunk.faces().end());
    ++chunks;
  }
  ASSERT_TRUE(reader->Finish().ok());
  EXPECT_EQ(chunks, 13);  // 1280 faces / 100
  ASSERT_EQ(v.size(), static_cast<size_t>(mesh_->vertices.size()));
  ASSERT_EQ(f.size(), static_cast<size_t>(mesh_->faces.size()));
  EXPECT_TRUE(std::equal(v.begin(), v.end(), mesh_->vertices.data()));
  EXPECT_TRUE(std::equal(f.begin(), f.end(), mesh_->faces.data()));

  for (auto [id, chunk_faces, expected] :
       {std::tuple{std::string("m-0000000000000000"), 0, grpc::StatusCode::NOT_FOUND},
        std::tuple{*mesh_id_, -1, grpc::StatusCode::INVALID_ARGUMENT}}) {
    v1::GetMeshGeometryRequest bad;
    bad.set_mesh_id(id);
    bad.set_chunk_faces(chunk_faces);
    grpc::ClientContext c2;
    auto r2 = stub()->GetMeshGeometry(&c2, bad);
    while (r2->Read(&chunk)) {
    }
    EXPECT_EQ(r2->Finish().error_code(), expected);
  }
}

TEST_F(ServiceTest, LoadMeshStaysInsideTheDataRoot) {
  const fs::path data = h_->root / "data";
  fs::create_directories(data / "sub");
  std::ofstream(data / "sub" / "ico.obj") << ObjText(Icosphere(2));
  std::ofstream(h_->root / "outside.obj") << ObjText(Icosphere(2));
  fs::create_symlink(h_->root / "outside.obj", data / "escape.obj");
  // A relative symlink that stays inside is fine; an absolute one is refused even when it points
  // inside (the kernel resolves below the root only); a directory symlink that leads out is too.
  fs::create_symlink("sub/ico.obj", data / "inner.obj");
  fs::create_symlink(data / "sub" / "ico.obj", data / "absolute.obj");
  fs::create_directories(h_->root / "elsewhere");
  std::ofstream(h_->root / "elsewhere" / "ico.obj") << ObjText(Icosphere(2));
  fs::create_symlink(h_->root / "elsewhere", data / "door");
  // Larger than --max-upload-mb 1: LoadMesh has the upload's size limit.
  {
    std::ofstream big(data / "big.obj");
    big << ObjText(Icosphere(2));
    big << std::string(1 << 20, '#') << "\n";
  }
  FieldServerOptions options;
  options.data_root = data.string();
  options.max_upload_mb = 1;
  auto h = TestServer::Start("dataroot", options);
  ASSERT_NE(h, nullptr);
  auto load = [&](const std::string& path, v1::MeshInfo* info) {
    v1::LoadMeshRequest r;
    r.set_path(path);
    grpc::ClientContext c;
    return h->stub->LoadMesh(&c, r, info).error_code();
  };
  v1::MeshInfo info;
  EXPECT_EQ(load("sub/ico.obj", &info), grpc::StatusCode::OK);
  EXPECT_EQ(info.num_faces(), 320);
  EXPECT_EQ(info.name(), "sub/ico.obj");
  EXPECT_EQ(load("../outside.obj", &info), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(load("sub/../../outside.obj", &info), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(load((h_->root / "outside.obj").string(), &info), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(load("escape.obj", &info), grpc::StatusCode::PERMISSION_DENIED);
  EXPECT_EQ(load("door/ico.obj", &info), grpc::StatusCode::PERMISSION_DENIED);
  EXPECT_EQ(load("inner.obj", &info), grpc::StatusCode::OK);
  EXPECT_EQ(load("absolute.obj", &info), grpc::StatusCode::PERMISSION_DENIED);
  EXPECT_EQ(load("./sub/ico.obj", &info), grpc::StatusCode::OK);
  EXPECT_EQ(load("big.obj", &info), grpc::StatusCode::RESOURCE_EXHAUSTED);
  EXPECT_EQ(load("sub/missing.obj", &info), grpc::StatusCode::NOT_FOUND);
  EXPECT_EQ(load("sub", &info), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(load("", &info), grpc::StatusCode::INVALID_ARGUMENT);
  // The shared server has no data root: LoadMesh is disabled there.
  v1::LoadMeshRequest r;
  r.set_path("sub/ico.obj");
  grpc::ClientContext c;
  EXPECT_EQ(stub()->LoadMesh(&c, r, &info).error_code(), grpc::StatusCode::FAILED_PRECONDITION);
}

TEST_F(ServiceTest, DeleteMeshNeedsCascadeWhenItHasBases) {
  MeshArrays m = Icosphere(2);
  Uploaded up = Upload(stub(), Chunked(RawBytes(m), RawHeader(m), 1 << 20));
  ASSERT_TRUE(up.status.ok());
  Built b = Build(stub(), BuildRequest(up.info.id(), v1::FIELD_KIND_VECTOR, 20));
  ASSERT_TRUE(b.status.ok()) << b.status.error_message();
  v1::DeleteMeshRequest del;
  del.set_mesh_id(up.info.id());
  v1::DeleteMeshResponse resp;
  {
    grpc::ClientContext c;
    EXPECT_EQ(stub()->DeleteMesh(&c, del, &resp).error_code(),
              grpc::StatusCode::FAILED_PRECONDITION);
  }
  del.set_cascade(true);
  {
    grpc::ClientContext c;
    ASSERT_TRUE(stub()->DeleteMesh(&c, del, &resp).ok());
  }
  ASSERT_EQ(resp.deleted_basis_ids_size(), 1);
  EXPECT_EQ(resp.deleted_basis_ids(0), b.basis().id());
  EXPECT_FALSE(fs::exists(h_->root / "store" / "bases" / (b.basis().id() + ".fsbasis")));
  v1::GetBasisRequest gb;
  gb.set_basis_id(b.basis().id());
  v1::BasisInfo bi;
  {
    grpc::ClientContext c;
    EXPECT_EQ(stub()->GetBasis(&c, gb, &bi).error_code(), grpc::StatusCode::NOT_FOUND);
  }
  {
    grpc::ClientContext c;
    EXPECT_EQ(stub()->DeleteMesh(&c, del, &resp).error_code(), grpc::StatusCode::NOT_FOUND);
  }
}

// --- bases -------------------------------------------------------------------------------------

TEST_F(ServiceTest, BuildStreamsProgressAndIsIdempotent) {
  v1::BuildBasisRequest r = BuildRequest(*mesh_id_, v1::FIELD_KIND_VECTOR, 60);
  Built again = Build(stub(), r);
  ASSERT_TRUE(again.status.ok());
  ASSERT_EQ(again.progress.size(), 1u);  // already built: one final message
  const v1::BasisInfo info = again.basis();
  EXPECT_EQ(info.id(), *vector_id_);
  EXPECT_THAT(info.id(), MatchesRegex("b-[0-9a-f]{16}"));
  EXPECT_EQ(info.mesh_id(), *mesh_id_);
  EXPECT_EQ(info.state(), v1::BASIS_STATE_READY);
  EXPECT_EQ(info.dofs(), 2 * 1280);
  EXPECT_EQ(info.dimension(), 60);
  EXPECT_GT(info.columns(), 0);
  EXPECT_GT(info.nnz(), info.columns());
  EXPECT_EQ(info.sigma(), 40.0);
  EXPECT_EQ(info.fields_per_region(), 2);
  // A fresh build streams phases in order and ends with the basis.
  r.set_seed(5);
  Built fresh = Build(stub(), r);
  ASSERT_TRUE(fresh.status.ok()) << fresh.status.error_message();
  ASSERT_GE(fresh.progress.size(), 2u);
  for (size_t i = 1; i < fresh.progress.size(); ++i) {
    EXPECT_GE(fresh.progress[i].phase(), fresh.progress[i - 1].phase());
    EXPECT_EQ(fresh.progress[i].basis_id(), fresh.progress[0].basis_id());
  }
  EXPECT_EQ(fresh.progress.back().phase(), v1::BUILD_PHASE_DONE);
  EXPECT_EQ(fresh.basis().id(), fresh.progress[0].basis_id());
  EXPECT_NE(fresh.basis().id(), *vector_id_);  // the seed is part of the id
  EXPECT_EQ(fresh.basis().seed(), 5u);
  EXPECT_EQ(fresh.basis().coarse_dimension(), 0);
  // A coarse second level: another basis, still d columns, more nonzeros (wider regions).
  v1::BuildBasisRequest two_level = r;
  two_level.set_coarse_dimension(12);
  Built stacked = Build(stub(), two_level);
  ASSERT_TRUE(stacked.status.ok()) << stacked.status.error_message();
  EXPECT_NE(stacked.basis().id(), fresh.basis().id());
  EXPECT_EQ(stacked.basis().coarse_dimension(), 12);
  EXPECT_EQ(stacked.basis().columns(), 60);
  EXPECT_GT(stacked.basis().nnz(), fresh.basis().nnz());
  auto loaded_stacked = Loaded(stacked.basis().id());
  ASSERT_NE(loaded_stacked, nullptr);
  EXPECT_EQ(loaded_stacked->basis->dimension(), 60);
  // The core's BuildMultiLevelBasis of a quality level, for the request r with seed 5.
  const auto core_build = [&](BasisQuality quality) -> Eigen::MatrixXf {
    absl::StatusOr<TriangleMesh> mesh = TriangleMesh::Create(*mesh_);
    absl::StatusOr<FieldOperator> op = BuildFieldOperator(*mesh, FieldType::Vector());
    BasisOptions options;
    options.params.seed = 5;
    options.params.fields_per_region = 2;
    auto levels = QualityLevels(quality, 60, 40.0);
    if (!mesh.ok() || !op.ok() || !levels.ok()) return Eigen::MatrixXf();
    auto expected = BuildMultiLevelBasis(*mesh, *op, options, *levels);
    return expected.ok() ? Eigen::MatrixXf(expected->U) : Eigen::MatrixXf();
  };
  // The low-modes quality level: three levels, its own id, the core's BuildMultiLevelBasis.
  v1::BuildBasisRequest low_modes = r;
  low_modes.set_quality(v1::BASIS_QUALITY_LOW_MODES);
  Built low = Build(stub(), low_modes);
  ASSERT_TRUE(low.status.ok()) << low.status.error_message();
  EXPECT_NE(low.basis().id(), fresh.basis().id());
  EXPECT_NE(low.basis().id(), stacked.basis().id());
  EXPECT_EQ(low.basis().quality(), v1::BASIS_QUALITY_LOW_MODES);
  EXPECT_EQ(fresh.basis().quality(), v1::BASIS_QUALITY_PAPER);
  EXPECT_EQ(low.basis().columns(), 60);
  auto loaded_low = Loaded(low.basis().id());
  ASSERT_NE(loaded_low, nullptr);
  const Eigen::MatrixXf low_u(StoredU(low.basis().id()));
  EXPECT_EQ(loaded_low->basis->U.nonZeros(), 0);  // served from its LiftPlan
  const auto same = [](const Eigen::MatrixXf& a, const Eigen::MatrixXf& b) {
    return a.rows() == b.rows() && a.cols() == b.cols() && a == b;
  };
  EXPECT_TRUE(same(low_u, core_build(BasisQuality::kLowModes)));
  // The smooth quality level: low-modes' levels with clamped fields; another id, same sparsity.
  v1::BuildBasisRequest smooth_request = r;
  smooth_request.set_quality(v1::BASIS_QUALITY_SMOOTH);
  Built smooth = Build(stub(), smooth_request);
  ASSERT_TRUE(smooth.status.ok()) << smooth.status.error_message();
  EXPECT_NE(smooth.basis().id(), low.basis().id());
  EXPECT_NE(smooth.basis().id(), fresh.basis().id());
  EXPECT_EQ(smooth.basis().quality(), v1::BASIS_QUALITY_SMOOTH);
  EXPECT_EQ(smooth.basis().columns(), 60);
  EXPECT_EQ(smooth.basis().nnz(), low.basis().nnz());
  auto loaded_smooth = Loaded(smooth.basis().id());
  ASSERT_NE(loaded_smooth, nullptr);
  const Eigen::MatrixXf smooth_u(StoredU(smooth.basis().id()));
  EXPECT_TRUE(same(smooth_u, core_build(BasisQuality::kSmooth)));
  EXPECT_FALSE(same(smooth_u, low_u));
  // Listed, and removable.
  v1::ListBasesRequest lr;
  lr.set_mesh_id(*mesh_id_);
  v1::ListBasesResponse list;
  {
    grpc::ClientContext c;
    ASSERT_TRUE(stub()->ListBases(&c, lr, &list).ok());
  }
  int matches = 0;
  for (const auto& b : list.bases())
    matches += b.id() == fresh.basis().id() || b.id() == *vector_id_;
  EXPECT_EQ(matches, 2);
  v1::DeleteBasisRequest del;
  del.set_basis_id(fresh.basis().id());
  v1::DeleteBasisResponse dr;
  {
    grpc::ClientContext c;
    ASSERT_TRUE(stub()->DeleteBasis(&c, del, &dr).ok());
  }
  {
    grpc::ClientContext c;
    EXPECT_EQ(stub()->DeleteBasis(&c, del, &dr).error_code(), grpc::StatusCode::NOT_FOUND);
  }
}

TEST_F(ServiceTest, BuildErrors) {
  auto code = [&](v1::BuildBasisRequest r) { return Build(stub(), r).status.error_code(); };
  EXPECT_EQ(code(BuildRequest("m-0000000000000000", v1::FIELD_KIND_VECTOR, 10)),
            grpc::StatusCode::NOT_FOUND);
  EXPECT_EQ(code(BuildRequest(*mesh_id_, v1::FIELD_KIND_UNSPECIFIED, 10)),
            grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(code(BuildRequest(*mesh_id_, v1::FIELD_KIND_NFIELD, 10, 0)),
            grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(code(BuildRequest(*mesh_id_, v1::FIELD_KIND_NFIELD, 10, 1000)),
            grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(code(BuildRequest(*mesh_id_, v1::FIELD_KIND_VECTOR, 0)),
            grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(code(BuildRequest(*mesh_id_, v1::FIELD_KIND_VECTOR, -3)),
            grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(code(BuildRequest(*mesh_id_, v1::FIELD_KIND_VECTOR, 501)),  // server limit 500
            grpc::StatusCode::RESOURCE_EXHAUSTED);
  EXPECT_EQ(code(BuildRequest(*mesh_id_, v1::FIELD_KIND_VECTOR, 2147483647)),
            grpc::StatusCode::RESOURCE_EXHAUSTED);
  MeshArrays tiny = Icosphere(0);  // 20 faces, 40 vector DOFs
  Uploaded up = Upload(stub(), Chunked(RawBytes(tiny), RawHeader(tiny), 1 << 20));
  ASSERT_TRUE(up.status.ok());
  EXPECT_EQ(code(BuildRequest(up.info.id(), v1::FIELD_KIND_VECTOR, 41)),
            grpc::StatusCode::INVALID_ARGUMENT);
  v1::BuildBasisRequest r = BuildRequest(*mesh_id_, v1::FIELD_KIND_VECTOR, 10);
  r.set_sigma(std::nan(""));
  EXPECT_EQ(code(r), grpc::StatusCode::INVALID_ARGUMENT);
  r.set_sigma(-1);
  EXPECT_EQ(code(r), grpc::StatusCode::INVALID_ARGUMENT);
  r.clear_sigma();
  r.set_coarse_dimension(10);  // must be below d = 10
  EXPECT_EQ(code(r), grpc::StatusCode::INVALID_ARGUMENT);
  r.set_coarse_dimension(-1);
  EXPECT_EQ(code(r), grpc::StatusCode::INVALID_ARGUMENT);
  r.set_coarse_dimension(0);
  r.set_quality(static_cast<v1::BasisQuality>(7));  // not a quality level
  EXPECT_EQ(code(r), grpc::StatusCode::INVALID_ARGUMENT);
  r.set_quality(v1::BASIS_QUALITY_LOW_MODES);  // needs d >= 40
  EXPECT_EQ(code(r), grpc::StatusCode::INVALID_ARGUMENT);
  r.set_quality(v1::BASIS_QUALITY_SMOOTH);  // so does smooth
  EXPECT_EQ(code(r), grpc::StatusCode::INVALID_ARGUMENT);
  r.set_dimension(40);
  r.set_coarse_dimension(5);  // the quality level sets the levels
  EXPECT_EQ(code(r), grpc::StatusCode::INVALID_ARGUMENT);
  r.set_dimension(10);
  r.set_coarse_dimension(0);
  r.set_quality(v1::BASIS_QUALITY_PAPER);
  r.set_fields_per_region(-2);
  EXPECT_EQ(code(r), grpc::StatusCode::INVALID_ARGUMENT);
  r.set_fields_per_region(0);
  r.add_face_weights(1.0);
  EXPECT_EQ(code(r), grpc::StatusCode::INVALID_ARGUMENT);  // 1 weight for 1280 faces
  r.clear_face_weights();
  for (int f = 0; f < 1280; ++f) r.add_face_weights(f == 7 ? 0.0 : 1.0);
  EXPECT_EQ(code(r), grpc::StatusCode::INVALID_ARGUMENT);
}

TEST_F(ServiceTest, IdenticalBuildsJoinAndCancelEndsOnlyTheCancelledOne) {
  // A build that occupies the (single) build lane, then two identical requests that queue behind
  // it: the second one joins the first instead of starting another build.
  // 81,920 faces: ~2.2 s of build on two cores, regions of ~7k faces (so the cancel lands within
  // one region's solve). Icosphere(5)'s build took 0.4 s, close enough to the few calls below
  // for a loaded machine to finish it before the cancel.
  MeshArrays big = Icosphere(6);
  Uploaded up = Upload(stub(), Chunked(RawBytes(big), RawHeader(big), 1 << 20));
  ASSERT_TRUE(up.status.ok());
  v1::BuildBasisRequest blocker = BuildRequest(up.info.id(), v1::FIELD_KIND_TENSOR, 480);
  grpc::ClientContext blocker_context;
  auto blocker_reader = stub()->BuildBasis(&blocker_context, blocker);
  v1::BuildBasisProgress first;
  ASSERT_TRUE(blocker_reader->Read(&first));
  const std::string blocker_id = first.basis_id();

  v1::BuildBasisRequest r = BuildRequest(*mesh_id_, v1::FIELD_KIND_VECTOR, 30);
  r.set_seed(77);
  // Both identical requests are opened in order and each has answered its first progress message
  // before the next step, so the test knows (rather than assumes from a sleep) who started first.
  auto open = [&](grpc::ClientContext* context, Built* out) {
    auto reader = stub()->BuildBasis(context, r);
    v1::BuildBasisProgress p;
    EXPECT_TRUE(reader->Read(&p));
    out->progress.push_back(p);
    return reader;
  };
  Built a, b;
  grpc::ClientContext a_context, b_context;
  auto a_reader = open(&a_context, &a);
  auto b_reader = open(&b_context, &b);
  // Status of a running build; cancelling it.
  v1::GetBasisRequest gb;
  gb.set_basis_id(blocker_id);
  v1::BasisInfo running;
  {
    grpc::ClientContext c;
    ASSERT_TRUE(stub()->GetBasis(&c, gb, &running).ok());
  }
  EXPECT_EQ(running.state(), v1::BASIS_STATE_BUILDING);
  v1::DeleteBasisRequest del;
  del.set_basis_id(blocker_id);
  v1::DeleteBasisResponse dr;
  {
    grpc::ClientContext c;
    EXPECT_EQ(stub()->DeleteBasis(&c, del, &dr).error_code(),
              grpc::StatusCode::FAILED_PRECONDITION);
  }
  v1::CancelBuildRequest cancel;
  cancel.set_basis_id(blocker_id);
  v1::CancelBuildResponse cr;
  const auto cancel_time = std::chrono::steady_clock::now();
  {
    grpc::ClientContext c;
    ASSERT_TRUE(stub()->CancelBuild(&c, cancel, &cr).ok());
  }
  while (blocker_reader->Read(&first)) {
  }
  EXPECT_EQ(blocker_reader->Finish().error_code(), grpc::StatusCode::CANCELLED);
  EXPECT_LT(std::chrono::steady_clock::now() - cancel_time, std::chrono::seconds(2));
  for (auto [reader, out] : {std::pair{a_reader.get(), &a}, std::pair{b_reader.get(), &b}}) {
    v1::BuildBasisProgress p;
    while (reader->Read(&p)) out->progress.push_back(p);
    out->status = reader->Finish();
  }
  ASSERT_TRUE(a.status.ok()) << a.status.error_message();
  ASSERT_TRUE(b.status.ok()) << b.status.error_message();
  EXPECT_EQ(a.basis().id(), b.basis().id());
  EXPECT_FALSE(a.progress.front().joined());
  EXPECT_TRUE(b.progress.front().joined());
  // Nothing to cancel any more.
  {
    grpc::ClientContext c;
    EXPECT_EQ(stub()->CancelBuild(&c, cancel, &cr).error_code(), grpc::StatusCode::NOT_FOUND);
  }
  cancel.set_basis_id(a.basis().id());
  {
    grpc::ClientContext c;
    EXPECT_EQ(stub()->CancelBuild(&c, cancel, &cr).error_code(),
              grpc::StatusCode::FAILED_PRECONDITION);
  }
}

TEST_F(ServiceTest, BuildContinuesWhenTheClientDisconnects) {
  v1::BuildBasisRequest r = BuildRequest(*mesh_id_, v1::FIELD_KIND_VECTOR, 30);
  r.set_seed(99);
  std::string id;
  {
    grpc::ClientContext c;
    auto reader = stub()->BuildBasis(&c, r);
    v1::BuildBasisProgress p;
    ASSERT_TRUE(reader->Read(&p));
    id = p.basis_id();
    c.TryCancel();
    while (reader->Read(&p)) {
    }
    EXPECT_EQ(reader->Finish().error_code(), grpc::StatusCode::CANCELLED);
  }
  v1::GetBasisRequest gb;
  gb.set_basis_id(id);
  v1::BasisInfo info;
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
  while (std::chrono::steady_clock::now() < deadline) {
    grpc::ClientContext c;
    grpc::Status s = stub()->GetBasis(&c, gb, &info);
    ASSERT_TRUE(s.ok()) << s.error_message();
    if (info.state() == v1::BASIS_STATE_READY) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  EXPECT_EQ(info.state(), v1::BASIS_STATE_READY);
}

// --- subspace methods ----------------------------------------------------------------------------

TEST_F(ServiceTest, LiftMatchesUTimesXInChunksAndSubsets) {
  auto loaded = Loaded(*vector_id_);
  const int d = loaded->basis->dimension();
  const std::vector<double> x = TestCoefficients(d);
  v1::LiftRequest r = LiftRequest(*vector_id_, x, v1::FIELD_ENCODING_DOF);
  r.set_chunk_faces(300);
  Lifted all = Lift(stub(), r);
  ASSERT_TRUE(all.status.ok()) << all.status.error_message();
  EXPECT_EQ(all.chunks.size(), 5u);  // 1280 / 300
  EXPECT_EQ(all.chunks[1].start_face(), 300);
  EXPECT_EQ(all.chunks[0].total_faces(), 1280);
  // Independent: U x with Eigen.
  const Eigen::VectorXd X =
      StoredU(*vector_id_).cast<double>() * Eigen::Map<const Eigen::VectorXd>(x.data(), d);
  const std::vector<float> values = all.values();
  ASSERT_EQ(values.size(), static_cast<size_t>(X.size()));
  for (Eigen::Index i = 0; i < X.size(); ++i) {
    ASSERT_NEAR(values[i], X[i], 1e-5 * (1 + std::abs(X[i]))) << i;
  }
  // A subset (any order, repeats) equals the same faces of the full lift.
  const std::vector<int32_t> faces = {1279, 0, 17, 17, 640};
  Lifted subset = Lift(stub(), LiftRequest(*vector_id_, x, v1::FIELD_ENCODING_DOF, faces));
  ASSERT_TRUE(subset.status.ok());
  const std::vector<float> sv = subset.values();
  ASSERT_EQ(sv.size(), 10u);
  for (size_t i = 0; i < faces.size(); ++i) {
    EXPECT_EQ(sv[2 * i], values[2 * faces[i]]);
    EXPECT_EQ(sv[2 * i + 1], values[2 * faces[i] + 1]);
  }
  EXPECT_THAT(subset.chunks[0].field().faces(), ::testing::ElementsAreArray(faces));
  // Ambient: tangent to the face, and its frame coordinates are the DOFs.
  Lifted ambient = Lift(stub(), LiftRequest(*vector_id_, x, v1::FIELD_ENCODING_AMBIENT, {0, 100}));
  ASSERT_TRUE(ambient.status.ok());
  const std::vector<float> av = ambient.values();
  ASSERT_EQ(av.size(), 6u);
  const TriangleMesh& mesh = *loaded->mesh;
  for (int i = 0; i < 2; ++i) {
    const int f = i == 0 ? 0 : 100;
    Eigen::Vector3d v(av[3 * i], av[3 * i + 1], av[3 * i + 2]);
    EXPECT_NEAR(v.dot(mesh.face_normals().row(f)), 0, 1e-5);
    EXPECT_NEAR(v.dot(mesh.frame_x().row(f)), X[2 * f], 1e-5);
    EXPECT_NEAR(v.dot(mesh.frame_y().row(f)), X[2 * f + 1], 1e-5);
  }
}

TEST_F(ServiceTest, LiftErrors) {
  const std::vector<double> x = TestCoefficients(Loaded(*vector_id_)->basis->dimension());
  EXPECT_EQ(Lift(stub(), LiftRequest("b-0000000000000000", x, v1::FIELD_ENCODING_DOF))
                .status.error_code(),
            grpc::StatusCode::NOT_FOUND);
  std::vector<double> short_x(x.begin(), x.end() - 1);
  EXPECT_EQ(
      Lift(stub(), LiftRequest(*vector_id_, short_x, v1::FIELD_ENCODING_DOF)).status.error_code(),
      grpc::StatusCode::INVALID_ARGUMENT);
  std::vector<double> nan_x = x;
  nan_x[3] = std::nan("");
  EXPECT_EQ(
      Lift(stub(), LiftRequest(*vector_id_, nan_x, v1::FIELD_ENCODING_DOF)).status.error_code(),
      grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(Lift(stub(), LiftRequest(*vector_id_, x, v1::FIELD_ENCODING_DOF, {0, 1280}))
                .status.error_code(),
            grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(
      Lift(stub(), LiftRequest(*vector_id_, x, v1::FIELD_ENCODING_DOF, {-1})).status.error_code(),
      grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(Lift(stub(), LiftRequest(*vector_id_, x, static_cast<v1::FieldEncoding>(9)))
                .status.error_code(),
            grpc::StatusCode::INVALID_ARGUMENT);
}

TEST_F(ServiceTest, ProjectionOfALiftedFieldRecoversItsCoefficients) {
  // lift(project(U x)) == U x for every field type and both encodings.
  for (const std::string* id : {vector_id_, nfield_id_, tensor_id_}) {
    const int d = Loaded(*id)->basis->dimension();
    const std::vector<double> x = TestCoefficients(d);
    for (v1::FieldEncoding encoding : {v1::FIELD_ENCODING_DOF, v1::FIELD_ENCODING_AMBIENT}) {
      Lifted lifted = Lift(stub(), LiftRequest(*id, x, encoding));
      ASSERT_TRUE(lifted.status.ok()) << lifted.status.error_message();
      v1::ProjectRequest p;
      p.set_basis_id(*id);
      p.mutable_field()->set_encoding(encoding);
      const std::vector<float> values = lifted.values();
      p.mutable_field()->mutable_values()->Add(values.begin(), values.end());
      v1::ProjectResponse resp;
      grpc::ClientContext c;
      grpc::Status s = stub()->Project(&c, p, &resp);
      ASSERT_TRUE(s.ok()) << s.error_message();
      ASSERT_EQ(resp.coefficients_size(), d);
      double err = 0, norm = 0;
      for (int i = 0; i < d; ++i) {
        err = std::max(err, std::abs(resp.coefficients(i) - x[i]));
        norm = std::max(norm, std::abs(x[i]));
      }
      EXPECT_LT(err, 1e-3 * norm) << *id << " encoding " << encoding;
      EXPECT_LT(resp.relative_error(), 1e-4);
    }
  }
  // A field far from the subspace has a large relative error: alternating signs per face.
  v1::ProjectRequest p;
  p.set_basis_id(*vector_id_);
  for (int f = 0; f < 1280; ++f) {
    p.mutable_field()->add_values(f % 2 ? 1.0f : -1.0f);
    p.mutable_field()->add_values(0.5f);
  }
  v1::ProjectResponse resp;
  grpc::ClientContext c;
  ASSERT_TRUE(stub()->Project(&c, p, &resp).ok());
  EXPECT_GT(resp.relative_error(), 0.3);
  EXPECT_LE(resp.relative_error(), 1.0 + 1e-9);
}

TEST_F(ServiceTest, ProjectErrors) {
  auto code = [&](const v1::ProjectRequest& p) {
    v1::ProjectResponse resp;
    grpc::ClientContext c;
    return stub()->Project(&c, p, &resp).error_code();
  };
  v1::ProjectRequest p;
  p.set_basis_id(*vector_id_);
  for (int i = 0; i < 2 * 1280; ++i) p.mutable_field()->add_values(0.1f);
  EXPECT_EQ(code(p), grpc::StatusCode::OK);
  v1::ProjectRequest wrong_size = p;
  wrong_size.mutable_field()->mutable_values()->RemoveLast();
  EXPECT_EQ(code(wrong_size), grpc::StatusCode::INVALID_ARGUMENT);
  v1::ProjectRequest ambient_size = p;  // DOF-sized values declared ambient
  ambient_size.mutable_field()->set_encoding(v1::FIELD_ENCODING_AMBIENT);
  EXPECT_EQ(code(ambient_size), grpc::StatusCode::INVALID_ARGUMENT);
  v1::ProjectRequest nan = p;
  nan.mutable_field()->set_values(77, std::nanf(""));
  EXPECT_EQ(code(nan), grpc::StatusCode::INVALID_ARGUMENT);
  v1::ProjectRequest inf = p;
  inf.mutable_field()->set_values(5, INFINITY);
  EXPECT_EQ(code(inf), grpc::StatusCode::INVALID_ARGUMENT);
  v1::ProjectRequest subset = p;
  subset.mutable_field()->add_faces(3);
  EXPECT_EQ(code(subset), grpc::StatusCode::INVALID_ARGUMENT);
  v1::ProjectRequest unknown = p;
  unknown.set_basis_id("b-0000000000000000");
  EXPECT_EQ(code(unknown), grpc::StatusCode::NOT_FOUND);
  v1::ProjectRequest bad_id = p;
  bad_id.set_basis_id("../../etc");
  EXPECT_EQ(code(bad_id), grpc::StatusCode::NOT_FOUND);
}

TEST_F(ServiceTest, SolveInterpolatesHardConstraintsAndIsLinear) {
  const int face_a = 10, face_b = 900;
  v1::SolveRequest r;
  r.set_basis_id(*vector_id_);
  r.mutable_weights()->set_mu_s(1.0);
  r.mutable_weights()->set_mu_b(0.0);
  r.mutable_weights()->set_mu_c(1.0);
  *r.add_constraints() = MakeConstraint(face_a, {0.3, -0.2}, v1::FIELD_ENCODING_DOF, true);
  *r.add_constraints() =
      MakeConstraint(face_b, {1.0, 2.0, 3.0}, v1::FIELD_ENCODING_AMBIENT, false, 2.0);
  r.set_return_field(true);
  r.set_field_encoding(v1::FIELD_ENCODING_DOF);
  v1::SolveResponse resp;
  {
    grpc::ClientContext c;
    grpc::Status s = stub()->Solve(&c, r, &resp);
    ASSERT_TRUE(s.ok()) << s.error_message();
  }
  EXPECT_EQ(resp.field().values_size(), 2 * 1280);
  EXPECT_NEAR(resp.field().values(2 * face_a), 0.3, 1e-4);
  EXPECT_NEAR(resp.field().values(2 * face_a + 1), -0.2, 1e-4);
  EXPECT_GT(resp.timings().total_ms(), 0);
  // The returned field is the lift of the returned coefficients.
  std::vector<double> x(resp.coefficients().begin(), resp.coefficients().end());
  Lifted lifted = Lift(stub(), LiftRequest(*vector_id_, x, v1::FIELD_ENCODING_DOF));
  ASSERT_TRUE(lifted.status.ok());
  const std::vector<float> lv = lifted.values();
  for (int i = 0; i < 2 * 1280; ++i) ASSERT_EQ(lv[i], resp.field().values(i));
  // Linear in the constraint values.
  v1::SolveRequest doubled = r;
  for (auto& c : *doubled.mutable_constraints()) {
    for (double& v : *c.mutable_value()) v *= 2;
  }
  doubled.set_return_field(false);
  v1::SolveResponse resp2;
  {
    grpc::ClientContext c;
    ASSERT_TRUE(stub()->Solve(&c, doubled, &resp2).ok());
  }
  for (int i = 0; i < resp.coefficients_size(); ++i) {
    EXPECT_NEAR(resp2.coefficients(i), 2 * resp.coefficients(i),
                1e-7 * (1 + std::abs(resp.coefficients(i))));
  }
  // Tensor and n-field bases take their own value sizes.
  for (auto [id, value] : {std::pair{tensor_id_, std::vector<double>{1, 0, 0, 0.5, 0, 0}},
                           std::pair{nfield_id_, std::vector<double>{0, 1, 0}}}) {
    v1::SolveRequest t;
    t.set_basis_id(*id);
    t.mutable_weights()->set_mu_s(1.0);
    t.mutable_weights()->set_mu_c(1.0);
    *t.add_constraints() = MakeConstraint(5, value, v1::FIELD_ENCODING_AMBIENT, true);
    v1::SolveResponse tr;
    grpc::ClientContext c;
    grpc::Status s = stub()->Solve(&c, t, &tr);
    ASSERT_TRUE(s.ok()) << *id << ": " << s.error_message();
    EXPECT_GT(MaxAbs(tr.coefficients()), 0);
  }
}

TEST_F(ServiceTest, SolveErrors) {
  auto code = [&](const v1::SolveRequest& r) {
    v1::SolveResponse resp;
    grpc::ClientContext c;
    return stub()->Solve(&c, r, &resp).error_code();
  };
  v1::SolveRequest good;
  good.set_basis_id(*vector_id_);
  good.mutable_weights()->set_mu_s(1.0);
  good.mutable_weights()->set_mu_c(1.0);
  *good.add_constraints() = MakeConstraint(3, {1, 0, 0}, v1::FIELD_ENCODING_AMBIENT, false);
  EXPECT_EQ(code(good), grpc::StatusCode::OK);
  v1::SolveRequest r = good;
  r.set_basis_id("b-0000000000000000");
  EXPECT_EQ(code(r), grpc::StatusCode::NOT_FOUND);
  r = good;
  r.mutable_weights()->set_mu_s(-1);
  EXPECT_EQ(code(r), grpc::StatusCode::INVALID_ARGUMENT);
  r = good;
  r.mutable_weights()->set_mu_s(0);
  EXPECT_EQ(code(r), grpc::StatusCode::INVALID_ARGUMENT);  // mu_s = mu_b = 0
  r = good;
  r.mutable_weights()->set_mu_b(std::nan(""));
  EXPECT_EQ(code(r), grpc::StatusCode::INVALID_ARGUMENT);
  r = good;
  r.mutable_constraints(0)->set_face(1280);
  EXPECT_EQ(code(r), grpc::StatusCode::INVALID_ARGUMENT);
  r = good;
  r.mutable_constraints(0)->mutable_value()->RemoveLast();
  EXPECT_EQ(code(r), grpc::StatusCode::INVALID_ARGUMENT);
  r = good;
  r.mutable_constraints(0)->set_value(1, INFINITY);
  EXPECT_EQ(code(r), grpc::StatusCode::INVALID_ARGUMENT);
  r = good;
  r.mutable_constraints(0)->set_weight(0);
  EXPECT_EQ(code(r), grpc::StatusCode::INVALID_ARGUMENT);
  r = good;
  r.mutable_constraints(0)->set_encoding(static_cast<v1::FieldEncoding>(5));
  EXPECT_EQ(code(r), grpc::StatusCode::INVALID_ARGUMENT);
  // Two hard constraints on one face are linearly dependent.
  r = good;
  *r.add_constraints() = MakeConstraint(8, {1, 0}, v1::FIELD_ENCODING_DOF, true);
  *r.add_constraints() = MakeConstraint(8, {0, 1}, v1::FIELD_ENCODING_DOF, true);
  EXPECT_EQ(code(r), grpc::StatusCode::FAILED_PRECONDITION);
}

TEST_F(ServiceTest, EigenfieldsApproximateTheSphereSpectrumFromAbove) {
  v1::EigenfieldsRequest r;
  r.set_basis_id(*vector_id_);
  r.set_count(6);
  v1::EigenfieldsResponse resp;
  {
    grpc::ClientContext c;
    grpc::Status s = stub()->Eigenfields(&c, r, &resp);
    ASSERT_TRUE(s.ok()) << s.error_message();
  }
  const int d = Loaded(*vector_id_)->basis->dimension();
  ASSERT_EQ(resp.eigenvalues_size(), 6);
  EXPECT_EQ(resp.dimension(), d);
  EXPECT_EQ(resp.coefficients_size(), 6 * d);
  // Independent: the dense generalized eigenproblem (U^T S U) y = lambda (U^T M U) y.
  auto loaded = Loaded(*vector_id_);
  auto op = BuildFieldOperator(*loaded->mesh, loaded->basis->type);
  ASSERT_TRUE(op.ok()) << op.status();
  const Eigen::MatrixXd U = Eigen::MatrixXd(StoredU(*vector_id_).cast<double>());
  const Eigen::MatrixXd K = U.transpose() * (op->stiffness * U);
  const Eigen::MatrixXd Mr = U.transpose() * op->mass.asDiagonal() * U;
  Eigen::GeneralizedSelfAdjointEigenSolver<Eigen::MatrixXd> dense(K, Mr);
  ASSERT_EQ(dense.info(), Eigen::Success);
  for (int i = 0; i < 6; ++i) {
    EXPECT_NEAR(resp.eigenvalues(i), dense.eigenvalues()(i), 1e-6 * (1 + dense.eigenvalues()(i)));
  }
  // Unit sphere, vector Hodge Laplacian: lowest eigenvalue l(l+1) = 2 (multiplicity 6). The
  // reduced eigenvalues are Rayleigh-Ritz values: above the discrete ones (~2), not far above.
  for (int i = 0; i < 6; ++i) {
    EXPECT_GT(resp.eigenvalues(i), 1.9);
    EXPECT_LT(resp.eigenvalues(i), 4.0);
    if (i > 0) {
      EXPECT_GE(resp.eigenvalues(i), resp.eigenvalues(i - 1));
    }
  }
  for (int count : {0, -1, d + 1}) {
    r.set_count(count);
    grpc::ClientContext c;
    EXPECT_EQ(stub()->Eigenfields(&c, r, &resp).error_code(), grpc::StatusCode::INVALID_ARGUMENT)
        << count;
  }
  r.set_basis_id("b-0000000000000000");
  r.set_count(1);
  grpc::ClientContext c;
  EXPECT_EQ(stub()->Eigenfields(&c, r, &resp).error_code(), grpc::StatusCode::NOT_FOUND);
}

TEST_F(ServiceTest, DesignSessionsBeyondTheCapAreResourceExhausted) {
  FieldServerOptions options;
  options.max_design_sessions = 2;
  auto h = TestServer::Start("session_cap", options);
  ASSERT_NE(h, nullptr);
  MeshArrays m = Icosphere(2);
  Uploaded up = Upload(h->stub.get(), Chunked(RawBytes(m), RawHeader(m), 1 << 20));
  ASSERT_TRUE(up.status.ok());
  Built b = Build(h->stub.get(), BuildRequest(up.info.id(), v1::FIELD_KIND_VECTOR, 20));
  ASSERT_TRUE(b.status.ok()) << b.status.error_message();
  grpc::ClientContext c1, c2;
  auto s1 = h->stub->Design(&c1);
  auto s2 = h->stub->Design(&c2);
  v1::DesignUpdate u;
  ASSERT_TRUE(s1->Write(Open(b.basis().id(), 1, 0, 1)) && s1->Read(&u));
  ASSERT_TRUE(s2->Write(Open(b.basis().id(), 1, 0, 1)) && s2->Read(&u));
  // A third is refused with a message that names the flag.
  Session third = RunSession(h->stub.get(), {Open(b.basis().id(), 1, 0, 1)});
  EXPECT_EQ(third.status.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED);
  EXPECT_THAT(third.status.error_message(), ::testing::HasSubstr("--max-design-sessions"));
  EXPECT_TRUE(third.updates.empty());
  // Closing one frees its place (once the server has finished the call: poll briefly).
  s1->WritesDone();
  EXPECT_TRUE(s1->Finish().ok());
  Session fourth;
  for (int attempt = 0; attempt < 100; ++attempt) {
    fourth = RunSession(h->stub.get(), {Open(b.basis().id(), 1, 0, 1)});
    if (fourth.status.error_code() != grpc::StatusCode::RESOURCE_EXHAUSTED) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  EXPECT_TRUE(fourth.status.ok()) << fourth.status.error_message();
  EXPECT_EQ(fourth.updates.size(), 1u);
  s2->WritesDone();
  EXPECT_TRUE(s2->Finish().ok());
}

TEST_F(ServiceTest, ConcurrentSessionsWithEqualWeightsShareOneFactorization) {
  // Two open sessions on one basis with the same (mu_s, mu_b): the second open finds the first
  // one's factorization (no refactorization), and equal edits give equal answers.
  grpc::ClientContext c1, c2;
  auto s1 = stub()->Design(&c1);
  auto s2 = stub()->Design(&c2);
  v1::DesignUpdate u1, u2;
  ASSERT_TRUE(s1->Write(Open(*vector_id_, 1.0, 0.01, 1.0)) && s1->Read(&u1));
  EXPECT_TRUE(u1.timings().refactorized());
  ASSERT_TRUE(s2->Write(Open(*vector_id_, 1.0, 0.01, 7.0)) && s2->Read(&u2));  // mu_c differs
  EXPECT_FALSE(u2.timings().refactorized());
  const v1::Constraint c = MakeConstraint(20, {0.3, -0.4}, v1::FIELD_ENCODING_DOF, true);
  ASSERT_TRUE(s1->Write(Add(1, c)) && s1->Read(&u1));
  ASSERT_TRUE(s2->Write(Add(1, c)) && s2->Read(&u2));
  ASSERT_EQ(u1.coefficients_size(), u2.coefficients_size());
  ASSERT_GT(MaxAbs(u1.coefficients()), 0);
  for (int i = 0; i < u1.coefficients_size(); ++i) {
    EXPECT_EQ(u1.coefficients(i), u2.coefficients(i)) << i;  // one hard constraint: mu_c unused
  }
  // A weight change to another mu_b factorizes; a session without a partner would too.
  v1::DesignRequest w;
  w.mutable_set_weights()->set_mu_s(1.0);
  w.mutable_set_weights()->set_mu_b(0.5);
  w.mutable_set_weights()->set_mu_c(1.0);
  ASSERT_TRUE(s1->Write(w) && s1->Read(&u1));
  EXPECT_TRUE(u1.timings().refactorized());
  ASSERT_TRUE(s2->Write(w) && s2->Read(&u2));
  EXPECT_FALSE(u2.timings().refactorized());
  for (auto* s : {s1.get(), s2.get()}) {
    s->WritesDone();
    EXPECT_TRUE(s->Finish().ok());
  }
}

TEST_F(ServiceTest, DesignSessionMatchesSolveAndNeverRefactorizesOnEdits) {
  for (const std::string* id : {vector_id_, nfield_id_}) {
    SCOPED_TRACE(*id);
    const std::string& basis_id = *id;

    const v1::Constraint soft = MakeConstraint(20, {1, 0, 0}, v1::FIELD_ENCODING_AMBIENT, false, 3);
    const v1::Constraint hard = MakeConstraint(700, {0.2, 0.4}, v1::FIELD_ENCODING_DOF, true);
    std::vector<v1::DesignRequest> requests;
    requests.push_back(Open(basis_id, 1.0, 0.0, 1.0, {700, 20}));
    requests.push_back(Add(1, soft));
    requests.push_back(Add(2, hard));
    v1::DesignRequest move;
    move.mutable_move()->set_id(1);
    move.mutable_move()->set_face(400);
    move.mutable_move()->add_value(0);
    move.mutable_move()->add_value(1);
    move.mutable_move()->add_value(0);
    move.mutable_move()->set_encoding(v1::FIELD_ENCODING_AMBIENT);
    requests.push_back(move);
    v1::DesignRequest mu_c_only;
    mu_c_only.mutable_set_weights()->set_mu_s(1.0);
    mu_c_only.mutable_set_weights()->set_mu_c(5.0);
    requests.push_back(mu_c_only);
    v1::DesignRequest new_weights;
    new_weights.mutable_set_weights()->set_mu_s(1.0);
    new_weights.mutable_set_weights()->set_mu_b(0.01);
    new_weights.mutable_set_weights()->set_mu_c(5.0);
    requests.push_back(new_weights);
    v1::DesignRequest remove;
    remove.mutable_remove()->set_id(2);
    requests.push_back(remove);
    for (size_t i = 0; i < requests.size(); ++i) requests[i].set_seq(100 + i);
    Session s = RunSession(stub(), requests);
    ASSERT_TRUE(s.status.ok()) << s.status.error_message();
    ASSERT_EQ(s.updates.size(), requests.size());
    for (size_t i = 0; i < s.updates.size(); ++i) EXPECT_EQ(s.updates[i].seq(), 100 + i);
    // Refactorization only on open and on the mu_b change.
    const std::vector<bool> refactorized = {true, false, false, false, false, true, false};
    for (size_t i = 0; i < s.updates.size(); ++i) {
      EXPECT_EQ(s.updates[i].timings().refactorized(), refactorized[i]) << i;
      EXPECT_GT(s.updates[i].timings().total_ms(), 0);
    }
    EXPECT_EQ(MaxAbs(s.updates[0].coefficients()), 0);  // no constraints yet
    EXPECT_EQ(s.updates[2].num_constraints(), 2);
    EXPECT_EQ(s.updates[2].num_hard_constraints(), 1);
    // Watched faces (700, 20) in DOF encoding: the hard constraint holds.
    ASSERT_EQ(s.updates[2].watched().values_size(), 4);
    EXPECT_NEAR(s.updates[2].watched().values(0), 0.2, 1e-4);
    EXPECT_NEAR(s.updates[2].watched().values(1), 0.4, 1e-4);

    // Each state equals a one-shot Solve of the same problem.
    auto solve = [&](double mu_s, double mu_b, double mu_c, std::vector<v1::Constraint> cs) {
      v1::SolveRequest r;
      r.set_basis_id(basis_id);
      r.mutable_weights()->set_mu_s(mu_s);
      r.mutable_weights()->set_mu_b(mu_b);
      r.mutable_weights()->set_mu_c(mu_c);
      for (auto& c : cs) *r.add_constraints() = c;
      v1::SolveResponse resp;
      grpc::ClientContext c;
      EXPECT_TRUE(stub()->Solve(&c, r, &resp).ok());
      return resp;
    };
    v1::Constraint moved = soft;
    moved.set_face(400);
    moved.clear_value();
    moved.add_value(0);
    moved.add_value(1);
    moved.add_value(0);
    const auto check = [&](size_t update, const v1::SolveResponse& expected) {
      const double scale = 1 + MaxAbs(expected.coefficients());
      EXPECT_LT(MaxAbsDiff(s.updates[update].coefficients(), expected.coefficients()), 1e-7 * scale)
          << "update " << update;
    };
    check(2, solve(1, 0, 1, {soft, hard}));
    check(3, solve(1, 0, 1, {moved, hard}));
    check(4, solve(1, 0, 5, {moved, hard}));
    check(5, solve(1, 0.01, 5, {moved, hard}));
    check(6, solve(1, 0.01, 5, {moved}));
  }
}

TEST_F(ServiceTest, MixedBiharmonicSolveAndDesignAgreeAndDifferFromTheExactForm) {
  const v1::Constraint soft = MakeConstraint(20, {1, 0, 0}, v1::FIELD_ENCODING_AMBIENT, false, 3);
  const v1::Constraint hard = MakeConstraint(700, {0.2, 0.4}, v1::FIELD_ENCODING_DOF, true);
  const auto solve = [&](v1::BiharmonicForm form) {
    v1::SolveRequest r;
    r.set_basis_id(*vector_id_);
    r.mutable_weights()->set_mu_s(0.1);
    r.mutable_weights()->set_mu_b(1.0);
    r.mutable_weights()->set_mu_c(1.0);
    r.set_biharmonic(form);
    *r.add_constraints() = soft;
    *r.add_constraints() = hard;
    v1::SolveResponse resp;
    grpc::ClientContext c;
    const grpc::Status st = stub()->Solve(&c, r, &resp);
    EXPECT_TRUE(st.ok()) << st.error_message();
    return resp;
  };
  const v1::SolveResponse mixed = solve(v1::BIHARMONIC_FORM_MIXED);
  const v1::SolveResponse exact = solve(v1::BIHARMONIC_FORM_EXACT);
  // Unset (UNSPECIFIED) is the default: mixed.
  const v1::SolveResponse unset = solve(v1::BIHARMONIC_FORM_UNSPECIFIED);
  EXPECT_EQ(MaxAbsDiff(unset.coefficients(), mixed.coefficients()), 0.0);
  const double scale = 1 + MaxAbs(mixed.coefficients());
  EXPECT_GT(MaxAbsDiff(mixed.coefficients(), exact.coefficients()), 1e-3 * scale);
  // Both converged; the mixed one through the partial fractions of the design sessions, the
  // exact one by its factorization, each with at most a refinement step or two.
  EXPECT_LE(mixed.backward_error(), 1e-12);
  EXPECT_LE(exact.backward_error(), 1e-12);
  EXPECT_LE(mixed.iterations(), 2);
  EXPECT_LE(exact.iterations(), 1);
  // The same problem past the session path's 256 constraints, the soft constraint split into
  // 300 of weight 3 / 300 on its face (the same energy): core's conjugate gradients, an
  // independent solver, reach the same minimizer.
  {
    v1::SolveRequest r;
    r.set_basis_id(*vector_id_);
    r.mutable_weights()->set_mu_s(0.1);
    r.mutable_weights()->set_mu_b(1.0);
    r.mutable_weights()->set_mu_c(1.0);
    for (int i = 0; i < 300; ++i) {
      v1::Constraint* part = r.add_constraints();
      *part = soft;
      part->set_weight(3.0 / 300);
    }
    *r.add_constraints() = hard;
    v1::SolveResponse by_cg;
    grpc::ClientContext c;
    ASSERT_TRUE(stub()->Solve(&c, r, &by_cg).ok());
    EXPECT_GT(by_cg.iterations(), 2);
    EXPECT_LE(by_cg.backward_error(), 1e-12);
    EXPECT_LT(MaxAbsDiff(by_cg.coefficients(), mixed.coefficients()), 1e-9 * scale);
  }
  // A session opened with the mixed form reaches the same solution through its own solver
  // (soft constraints in the Schur complement instead of the matrix, in the eigenbasis of K and
  // Mr: refinement steps, no conjugate gradients).
  v1::DesignRequest open = Open(*vector_id_, 0.1, 1.0, 1.0, {700});
  open.mutable_open()->set_biharmonic(v1::BIHARMONIC_FORM_MIXED);
  Session s = RunSession(stub(), {open, Add(1, soft), Add(2, hard)});
  ASSERT_TRUE(s.status.ok()) << s.status.error_message();
  ASSERT_EQ(s.updates.size(), 3u);
  EXPECT_LT(MaxAbsDiff(s.updates[2].coefficients(), mixed.coefficients()), 1e-7 * scale);
  EXPECT_LE(s.updates[2].iterations(), 4);
  // Checked periodically (the server's verify interval) like the exact form's solves: NaN when
  // this one was not.
  EXPECT_TRUE(std::isnan(s.updates[2].backward_error()) || s.updates[2].backward_error() <= 1e-12)
      << s.updates[2].backward_error();
  EXPECT_NEAR(s.updates[2].watched().values(0), 0.2, 1e-4);
  // A form the enum does not name.
  v1::SolveRequest bad;
  bad.set_basis_id(*vector_id_);
  bad.set_biharmonic(static_cast<v1::BiharmonicForm>(7));
  *bad.add_constraints() = soft;
  v1::SolveResponse resp;
  grpc::ClientContext c;
  EXPECT_EQ(stub()->Solve(&c, bad, &resp).error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  open.mutable_open()->set_biharmonic(static_cast<v1::BiharmonicForm>(7));
  EXPECT_EQ(RunSession(stub(), {open}).status.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
}

TEST_F(ServiceTest, DesignErrorsThatLeaveNoSessionEndTheStreamWithExactCodes) {
  auto final_code = [&](std::vector<v1::DesignRequest> requests) {
    return RunSession(stub(), requests).status.error_code();
  };
  const v1::Constraint c = MakeConstraint(20, {1, 0, 0}, v1::FIELD_ENCODING_AMBIENT, false);
  EXPECT_EQ(final_code({Add(1, c)}), grpc::StatusCode::FAILED_PRECONDITION);  // before open
  EXPECT_EQ(final_code({Open("b-0000000000000000", 1, 0, 1)}), grpc::StatusCode::NOT_FOUND);
  EXPECT_EQ(final_code({Open(*vector_id_, -1, 0, 1)}), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(final_code({Open(*vector_id_, 1, 0, 0)}), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(final_code({Open(*vector_id_, 1, 0, 1, {5000})}), grpc::StatusCode::INVALID_ARGUMENT);
  // A session that is simply closed by the client ends OK.
  EXPECT_EQ(final_code({Open(*vector_id_, 1, 0, 1)}), grpc::StatusCode::OK);
}

// One bad edit costs that edit, not the session: it is answered by an update with its seq and
// error code only, the session stays open and exactly as it was.
TEST_F(ServiceTest, ARefusedEditIsAnsweredWithItsErrorAndTheSessionGoesOn) {
  const v1::Constraint c = MakeConstraint(20, {1, 0, 0}, v1::FIELD_ENCODING_AMBIENT, false);
  v1::Constraint bad_face = c;
  bad_face.set_face(5000);
  v1::Constraint negative_face = c;
  negative_face.set_face(-5);
  v1::Constraint nan_value = c;
  nan_value.set_value(0, std::nan(""));
  v1::DesignRequest move_unknown;
  move_unknown.mutable_move()->set_id(9);
  move_unknown.mutable_move()->set_face(1);
  move_unknown.mutable_move()->add_value(1);
  move_unknown.mutable_move()->add_value(0);
  v1::DesignRequest remove_unknown;
  remove_unknown.mutable_remove()->set_id(9);
  v1::DesignRequest mu_c_zero;
  mu_c_zero.mutable_set_weights()->set_mu_c(0);
  v1::DesignRequest infinite_weight;
  infinite_weight.mutable_set_weights()->set_mu_s(INFINITY);
  v1::DesignRequest watch_out_of_range;
  watch_out_of_range.mutable_watch()->add_faces(5000);
  struct Refused {
    v1::DesignRequest request;
    grpc::StatusCode code;
  };
  const std::vector<Refused> refused = {
      {move_unknown, grpc::StatusCode::NOT_FOUND},
      {remove_unknown, grpc::StatusCode::NOT_FOUND},
      {Add(2, bad_face), grpc::StatusCode::INVALID_ARGUMENT},
      {Add(2, negative_face), grpc::StatusCode::INVALID_ARGUMENT},
      {Add(1, c), grpc::StatusCode::ALREADY_EXISTS},
      {Add(2, nan_value), grpc::StatusCode::INVALID_ARGUMENT},
      {mu_c_zero, grpc::StatusCode::INVALID_ARGUMENT},
      {infinite_weight, grpc::StatusCode::INVALID_ARGUMENT},
      {watch_out_of_range, grpc::StatusCode::INVALID_ARGUMENT},
      {Open(*vector_id_, 1, 0, 1), grpc::StatusCode::FAILED_PRECONDITION},
      {v1::DesignRequest(), grpc::StatusCode::INVALID_ARGUMENT},
  };
  std::vector<v1::DesignRequest> requests = {Open(*vector_id_, 1, 0, 1, {20, 21}), Add(1, c)};
  for (const Refused& r : refused) requests.push_back(r.request);
  // After the refused edits: a watch of the same faces (answers the session as it is, solves
  // nothing), then an edit that must apply to the session as it was.
  v1::DesignRequest same_watch;
  same_watch.mutable_watch()->add_faces(20);
  same_watch.mutable_watch()->add_faces(21);
  same_watch.mutable_watch()->set_encoding(v1::FIELD_ENCODING_DOF);
  requests.push_back(same_watch);
  v1::Constraint other = c;
  other.set_face(40);
  requests.push_back(Add(2, other));
  for (size_t i = 0; i < requests.size(); ++i) requests[i].set_seq(100 + i);

  const Session s = RunSession(stub(), requests);
  ASSERT_TRUE(s.status.ok()) << s.status.error_message();
  ASSERT_EQ(s.updates.size(), requests.size());
  const v1::DesignUpdate& before = s.updates[1];
  EXPECT_FALSE(before.has_error());
  EXPECT_GT(MaxAbs(before.coefficients()), 0);
  for (size_t k = 0; k < refused.size(); ++k) {
    const v1::DesignUpdate& u = s.updates[2 + k];
    SCOPED_TRACE(absl::StrFormat("refused edit %d: %s", k, u.error().message()));
    EXPECT_EQ(u.seq(), 102 + k);
    ASSERT_TRUE(u.has_error());
    EXPECT_EQ(u.error().code(), static_cast<int32_t>(refused[k].code));
    EXPECT_FALSE(u.error().message().empty());
    EXPECT_TRUE(u.coefficients().empty());
    EXPECT_EQ(u.num_constraints(), 0);
  }
  const v1::DesignUpdate& unchanged = s.updates[2 + refused.size()];
  ASSERT_FALSE(unchanged.has_error()) << unchanged.error().message();
  EXPECT_EQ(unchanged.num_constraints(), 1);
  ASSERT_EQ(unchanged.coefficients().size(), before.coefficients().size());
  for (int i = 0; i < before.coefficients().size(); ++i) {
    EXPECT_EQ(unchanged.coefficients(i), before.coefficients(i)) << "coefficient " << i;
  }
  EXPECT_EQ(unchanged.watched().values_size(), before.watched().values_size());
  const v1::DesignUpdate& next = s.updates.back();
  ASSERT_FALSE(next.has_error()) << next.error().message();
  EXPECT_EQ(next.num_constraints(), 2);
  EXPECT_GT(MaxAbsDiff(next.coefficients(), before.coefficients()), 0);
}

TEST_F(ServiceTest, ManyConcurrentSessions) {
  // 16 concurrent sessions share energy factorizations through the server's cache (two weight
  // sets, so two entries are created under contention); each must give exactly the coefficients
  // of the same edits in a session of its own.
  const v1::Constraint c = MakeConstraint(20, {1, 0, 0}, v1::FIELD_ENCODING_AMBIENT, false);
  auto requests = [&](int i) {
    v1::Constraint ci = c;
    ci.set_face(10 * i);
    return std::vector<v1::DesignRequest>{Open(*vector_id_, i % 2 == 0 ? 1 : 2, 0, 1), Add(1, ci)};
  };
  // References first, one session at a time: the cache holds entries only while a session uses
  // them, so every reference factorizes alone and the concurrent sessions start from a cold cache.
  std::vector<Session> alone(16);
  for (int i = 0; i < 16; ++i) {
    alone[i] = RunSession(stub(), requests(i));
    ASSERT_TRUE(alone[i].status.ok()) << alone[i].status.error_message();
    ASSERT_EQ(alone[i].updates.size(), 2u);
  }
  std::vector<std::thread> threads;
  std::vector<Session> sessions(16);
  for (int i = 0; i < 16; ++i) {
    threads.emplace_back([&, i] { sessions[i] = RunSession(stub(), requests(i)); });
  }
  for (auto& t : threads) t.join();
  for (const Session& s : sessions) {
    EXPECT_TRUE(s.status.ok()) << s.status.error_message();
    EXPECT_EQ(s.updates.size(), 2u);
  }
  for (int i = 0; i < 16; ++i) {
    SCOPED_TRACE(absl::StrFormat("session %d", i));
    ASSERT_EQ(sessions[i].updates.size(), alone[i].updates.size());
    for (size_t u = 0; u < alone[i].updates.size(); ++u) {
      const auto& expected = alone[i].updates[u].coefficients();
      const auto& actual = sessions[i].updates[u].coefficients();
      ASSERT_EQ(actual.size(), expected.size()) << "update " << u;
      EXPECT_LE(MaxAbsDiff(actual, expected), 1e-9 * MaxAbs(expected)) << "update " << u;
    }
    // The edit moved the field: the comparison is not between zeros.
    EXPECT_GT(MaxAbs(alone[i].updates[1].coefficients()), 0);
  }
}

// --- standard services, auth, shutdown, persistence -------------------------------------------

TEST_F(ServiceTest, HealthServesTheServiceAndOverall) {
  auto health = grpc::health::v1::Health::NewStub(h_->channel);
  for (const char* service : {"", "fieldspace.v1.FieldSpace"}) {
    grpc::health::v1::HealthCheckRequest r;
    r.set_service(service);
    grpc::health::v1::HealthCheckResponse resp;
    grpc::ClientContext c;
    ASSERT_TRUE(health->Check(&c, r, &resp).ok());
    EXPECT_EQ(resp.status(), grpc::health::v1::HealthCheckResponse::SERVING);
  }
}

TEST(ServerLifecycleTest, TokenIsRequiredWhenConfigured) {
  FieldServerOptions options;
  options.auth_token = "s3cret";
  auto h = TestServer::Start("auth", options);
  ASSERT_NE(h, nullptr);
  v1::ListMeshesResponse resp;
  {
    grpc::ClientContext c;
    EXPECT_EQ(h->stub->ListMeshes(&c, v1::ListMeshesRequest(), &resp).error_code(),
              grpc::StatusCode::UNAUTHENTICATED);
  }
  {
    grpc::ClientContext c;
    c.AddMetadata("authorization", "Bearer s3cres");
    EXPECT_EQ(h->stub->ListMeshes(&c, v1::ListMeshesRequest(), &resp).error_code(),
              grpc::StatusCode::UNAUTHENTICATED);
  }
  {
    grpc::ClientContext c;
    c.AddMetadata("authorization", "Bearer s3cret");
    EXPECT_TRUE(h->stub->ListMeshes(&c, v1::ListMeshesRequest(), &resp).ok());
  }
  {
    // Streams too.
    grpc::ClientContext c;
    auto stream = h->stub->Design(&c);
    v1::DesignUpdate u;
    stream->Write(Open("b-0000000000000000", 1, 0, 1));
    EXPECT_FALSE(stream->Read(&u));
    EXPECT_EQ(stream->Finish().error_code(), grpc::StatusCode::UNAUTHENTICATED);
  }
}

TEST(ServerLifecycleTest, ShutdownDrainsSessionsAndReportsNotServing) {
  auto h = TestServer::Start("drain", {});
  ASSERT_NE(h, nullptr);
  MeshArrays m = Icosphere(2);
  Uploaded up = Upload(h->stub.get(), Chunked(RawBytes(m), RawHeader(m), 1 << 20));
  ASSERT_TRUE(up.status.ok());
  Built b = Build(h->stub.get(), BuildRequest(up.info.id(), v1::FIELD_KIND_VECTOR, 20));
  ASSERT_TRUE(b.status.ok()) << b.status.error_message();

  auto health = grpc::health::v1::Health::NewStub(h->channel);
  grpc::ClientContext watch_context;
  grpc::health::v1::HealthCheckRequest hr;
  auto watch = health->Watch(&watch_context, hr);
  grpc::health::v1::HealthCheckResponse status;
  ASSERT_TRUE(watch->Read(&status));
  EXPECT_EQ(status.status(), grpc::health::v1::HealthCheckResponse::SERVING);

  grpc::ClientContext session_context;
  auto session = h->stub->Design(&session_context);
  v1::DesignUpdate u;
  ASSERT_TRUE(session->Write(Open(b.basis().id(), 1, 0, 1)));
  ASSERT_TRUE(session->Read(&u));

  const auto start = std::chrono::steady_clock::now();
  std::thread stopper([&] { h->server->Shutdown(std::chrono::seconds(10)); });
  // The idle session is ended by the drain, long before the 10 s bound.
  EXPECT_FALSE(session->Read(&u));
  EXPECT_EQ(session->Finish().error_code(), grpc::StatusCode::UNAVAILABLE);
  bool saw_not_serving = false;
  while (!saw_not_serving && watch->Read(&status)) {
    saw_not_serving = status.status() == grpc::health::v1::HealthCheckResponse::NOT_SERVING;
  }
  watch_context.TryCancel();  // a watch stays open until cancelled; let the drain finish
  watch->Finish();
  stopper.join();
  EXPECT_TRUE(saw_not_serving);
  EXPECT_LT(std::chrono::steady_clock::now() - start, std::chrono::seconds(5));
}

TEST(ServerLifecycleTest, RestartKeepsEverythingAndDetectsCorruption) {
  auto h = TestServer::Start("restart", {});
  ASSERT_NE(h, nullptr);
  MeshArrays m = Icosphere(2);
  Uploaded up = Upload(h->stub.get(), Chunked(RawBytes(m), RawHeader(m), 1 << 20));
  ASSERT_TRUE(up.status.ok());
  Built vb = Build(h->stub.get(), BuildRequest(up.info.id(), v1::FIELD_KIND_VECTOR, 20));
  Built tb = Build(h->stub.get(), BuildRequest(up.info.id(), v1::FIELD_KIND_TENSOR, 30));
  ASSERT_TRUE(vb.status.ok() && tb.status.ok());
  const std::vector<double> x = TestCoefficients(vb.basis().columns());
  Lifted before = Lift(h->stub.get(), LiftRequest(vb.basis().id(), x, v1::FIELD_ENCODING_DOF));
  ASSERT_TRUE(before.status.ok());
  const std::string store = (h->root / "store").string();
  h->Stop();

  FieldServerOptions options;
  options.store_dir = store;
  auto h2 = TestServer::StartIn(h->root, options, /*fresh=*/false);
  ASSERT_NE(h2, nullptr);
  v1::GetMeshRequest gm;
  gm.set_mesh_id(up.info.id());
  v1::MeshInfo mi;
  {
    grpc::ClientContext c;
    ASSERT_TRUE(h2->stub->GetMesh(&c, gm, &mi).ok());
  }
  EXPECT_EQ(mi.num_faces(), 320);
  EXPECT_FALSE(mi.loaded());  // lazily loaded
  v1::GetBasisRequest gb;
  gb.set_basis_id(vb.basis().id());
  v1::BasisInfo bi;
  {
    grpc::ClientContext c;
    ASSERT_TRUE(h2->stub->GetBasis(&c, gb, &bi).ok());
  }
  EXPECT_EQ(bi.state(), v1::BASIS_STATE_READY);
  EXPECT_EQ(bi.nnz(), vb.basis().nnz());
  EXPECT_FALSE(bi.loaded());
  Lifted after = Lift(h2->stub.get(), LiftRequest(vb.basis().id(), x, v1::FIELD_ENCODING_DOF));
  ASSERT_TRUE(after.status.ok()) << after.status.error_message();
  EXPECT_EQ(after.values(), before.values());
  h2->Stop();

  // Corrupt the tensor basis payload: listed (header fine), DATA_LOSS when used, never loaded.
  {
    const std::string path = store + "/bases/" + tb.basis().id() + ".fsbasis";
    std::fstream f(path, std::ios::in | std::ios::out | std::ios::binary);
    f.seekp(-100, std::ios::end);
    f.put('\x7f');
  }
  // Truncate the mesh file of a mesh without bases.
  MeshArrays m2 = Icosphere(1);
  auto h3 = TestServer::StartIn(h->root, options, false);
  ASSERT_NE(h3, nullptr);
  Uploaded up2 = Upload(h3->stub.get(), Chunked(RawBytes(m2), RawHeader(m2), 1 << 20));
  ASSERT_TRUE(up2.status.ok());
  h3->Stop();
  const std::string mesh_path = store + "/meshes/" + up2.info.id() + ".fsmesh";
  fs::resize_file(mesh_path, fs::file_size(mesh_path) / 2);

  auto h4 = TestServer::StartIn(h->root, options, false);
  ASSERT_NE(h4, nullptr);
  const std::vector<double> xt = TestCoefficients(tb.basis().columns());
  Lifted corrupt = Lift(h4->stub.get(), LiftRequest(tb.basis().id(), xt, v1::FIELD_ENCODING_DOF));
  EXPECT_EQ(corrupt.status.error_code(), grpc::StatusCode::DATA_LOSS);
  EXPECT_THAT(corrupt.status.error_message(), HasSubstr("checksum"));
  gm.set_mesh_id(up2.info.id());
  {
    grpc::ClientContext c;
    EXPECT_EQ(h4->stub->GetMesh(&c, gm, &mi).error_code(), grpc::StatusCode::DATA_LOSS);
  }
  // Everything else still works; a damaged entry can be replaced by uploading it again.
  Lifted fine = Lift(h4->stub.get(), LiftRequest(vb.basis().id(), x, v1::FIELD_ENCODING_DOF));
  EXPECT_EQ(fine.values(), before.values());
  Uploaded again = Upload(h4->stub.get(), Chunked(RawBytes(m2), RawHeader(m2), 1 << 20));
  ASSERT_TRUE(again.status.ok()) << again.status.error_message();
  {
    grpc::ClientContext c;
    EXPECT_TRUE(h4->stub->GetMesh(&c, gm, &mi).ok());
  }
}

TEST(ServerLifecycleTest, MemoryBudgetEvictsIdleBasesWhichReloadIdentically) {
  FieldServerOptions options;
  options.memory_budget_mb = 0;  // evict whatever is idle as soon as something else loads
  auto h = TestServer::Start("budget", options);
  ASSERT_NE(h, nullptr);
  MeshArrays m = Icosphere(2);
  Uploaded up = Upload(h->stub.get(), Chunked(RawBytes(m), RawHeader(m), 1 << 20));
  ASSERT_TRUE(up.status.ok());
  Built a = Build(h->stub.get(), BuildRequest(up.info.id(), v1::FIELD_KIND_VECTOR, 20));
  Built b = Build(h->stub.get(), BuildRequest(up.info.id(), v1::FIELD_KIND_TENSOR, 20));
  ASSERT_TRUE(a.status.ok() && b.status.ok());
  const std::vector<double> xa = TestCoefficients(a.basis().columns());
  const std::vector<double> xb = TestCoefficients(b.basis().columns());
  Lifted first = Lift(h->stub.get(), LiftRequest(a.basis().id(), xa, v1::FIELD_ENCODING_DOF));
  ASSERT_TRUE(first.status.ok());
  // The server drops its handle for `a` when the call object goes away, some time after the
  // client's Finish (later on a loaded machine). Every later use of another artifact trims memory
  // over budget, so `a` must be evicted after a bounded number of uses of `b`.
  v1::GetBasisRequest gb;
  gb.set_basis_id(a.basis().id());
  v1::BasisInfo info;
  const auto give_up = std::chrono::steady_clock::now() + std::chrono::seconds(20);
  do {
    ASSERT_TRUE(
        Lift(h->stub.get(), LiftRequest(b.basis().id(), xb, v1::FIELD_ENCODING_DOF)).status.ok());
    grpc::ClientContext c;
    ASSERT_TRUE(h->stub->GetBasis(&c, gb, &info).ok());
    if (info.loaded()) std::this_thread::sleep_for(std::chrono::milliseconds(20));
  } while (info.loaded() && std::chrono::steady_clock::now() < give_up);
  EXPECT_FALSE(info.loaded());
  Lifted reloaded = Lift(h->stub.get(), LiftRequest(a.basis().id(), xa, v1::FIELD_ENCODING_DOF));
  ASSERT_TRUE(reloaded.status.ok());
  EXPECT_EQ(reloaded.values(), first.values());
  EXPECT_LE(h->server->registry()->memory_in_use(), int64_t{64} << 20);
}

TEST(ServerLifecycleTest, DeadlineStopsEigenfieldsWorkOnTheServer) {
  // One compute thread: if the server kept working on an expired Eigenfields call (a dense
  // d = 1200 eigensolve, seconds of work), the Project call right after it would wait for it.
  FieldServerOptions options;
  options.threads = 1;
  auto h = TestServer::Start("deadline", options);
  ASSERT_NE(h, nullptr);
  MeshArrays m = Icosphere(4);  // 5120 faces
  Uploaded up = Upload(h->stub.get(), Chunked(RawBytes(m), RawHeader(m), 1 << 20));
  ASSERT_TRUE(up.status.ok());
  Built b = Build(h->stub.get(), BuildRequest(up.info.id(), v1::FIELD_KIND_VECTOR, 1200));
  ASSERT_TRUE(b.status.ok()) << b.status.error_message();
  v1::ProjectRequest p;
  p.set_basis_id(b.basis().id());
  for (int f = 0; f < 5120; ++f) {
    p.mutable_field()->add_values(1.0f);
    p.mutable_field()->add_values(0.0f);
  }
  auto project_seconds = [&] {
    v1::ProjectResponse resp;
    grpc::ClientContext c;
    const auto start = std::chrono::steady_clock::now();
    EXPECT_TRUE(h->stub->Project(&c, p, &resp).ok());
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  };
  const double unloaded = project_seconds();

  v1::EigenfieldsRequest e;
  e.set_basis_id(b.basis().id());
  e.set_count(250);
  v1::EigenfieldsResponse er;
  {
    grpc::ClientContext c;
    c.set_deadline(std::chrono::system_clock::now() + std::chrono::milliseconds(150));
    EXPECT_EQ(h->stub->Eigenfields(&c, e, &er).error_code(), grpc::StatusCode::DEADLINE_EXCEEDED);
  }
  const double after_deadline = project_seconds();
  // The same request without a deadline completes (and is what the deadline cut short).
  grpc::ClientContext c;
  const auto start = std::chrono::steady_clock::now();
  ASSERT_TRUE(h->stub->Eigenfields(&c, e, &er).ok());
  const double full =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  EXPECT_EQ(er.eigenvalues_size(), 250);
  std::cout << "project " << unloaded << " s, after the deadline " << after_deadline
            << " s, full eigensolve " << full << " s\n";
  // Had the expired eigensolve kept the only compute thread, the Project after it would have
  // waited for the rest of it, about full - 0.15 s. Compared with that rather than a fixed margin,
  // so that a loaded machine (which slows both) does not fail the test.
  const double rest = full - 0.15;
  EXPECT_GT(rest, 0.3) << "the eigensolve is too cheap for this test to discriminate";
  EXPECT_LT(after_deadline, unloaded + 0.5 * rest)
      << "the expired eigensolve kept the compute thread";
}

}  // namespace
}  // namespace fieldspace::server
