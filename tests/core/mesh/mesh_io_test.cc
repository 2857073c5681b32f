#include "core/mesh/mesh_io.h"

#include <unistd.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <random>
#include <string>
#include <utility>
#include <vector>

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"
#include "core/mesh/triangle_mesh.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tests/testing/matchers.h"
#include "tests/testing/test_meshes.h"

namespace fieldspace {
namespace {

using ::fieldspace::testing::StatusIs;
using ::testing::AnyOf;
using ::testing::HasSubstr;
using ::testing::StartsWith;

// ---------------------------------------------------------------------------------------------
// Helpers

MeshReadResult MustRead(const std::string& data, MeshFormat format,
                        const MeshReadOptions& options = {}) {
  absl::StatusOr<MeshReadResult> r = ReadMesh(data, format, options);
  EXPECT_TRUE(r.ok()) << r.status();
  return r.ok() ? *std::move(r) : MeshReadResult{};
}

// Expects `data` to fail with `code` and a message containing `message`.
void ExpectError(const std::string& data, MeshFormat format, absl::StatusCode code,
                 const std::string& message, const MeshReadOptions& options = {}) {
  absl::StatusOr<MeshReadResult> r = ReadMesh(data, format, options);
  ASSERT_FALSE(r.ok()) << "accepted: " << ::testing::PrintToString(data.substr(0, 200));
  EXPECT_THAT(r, StatusIs(code, HasSubstr(message)));
}

VertexMatrix Verts(const std::vector<std::array<double, 3>>& v) {
  VertexMatrix V(static_cast<Eigen::Index>(v.size()), 3);
  for (size_t i = 0; i < v.size(); ++i) {
    for (int k = 0; k < 3; ++k) V(static_cast<Eigen::Index>(i), k) = v[i][k];
  }
  return V;
}

FaceMatrix Faces(const std::vector<std::array<int32_t, 3>>& f) {
  FaceMatrix F(static_cast<Eigen::Index>(f.size()), 3);
  for (size_t i = 0; i < f.size(); ++i) {
    for (int k = 0; k < 3; ++k) F(static_cast<Eigen::Index>(i), k) = f[i][k];
  }
  return F;
}

// Exact comparison (the inputs are chosen to be exactly representable).
void ExpectArrays(const MeshReadResult& r, const VertexMatrix& V, const FaceMatrix& F) {
  ASSERT_EQ(r.arrays.vertices.rows(), V.rows());
  ASSERT_EQ(r.arrays.faces.rows(), F.rows());
  for (Eigen::Index i = 0; i < V.rows(); ++i) {
    for (int k = 0; k < 3; ++k) EXPECT_EQ(r.arrays.vertices(i, k), V(i, k)) << "vertex " << i;
  }
  for (Eigen::Index i = 0; i < F.rows(); ++i) {
    for (int k = 0; k < 3; ++k) EXPECT_EQ(r.arrays.faces(i, k), F(i, k)) << "face " << i;
  }
}

std::string TempPath(const std::string& name) {
  return (std::filesystem::path(::testing::TempDir()) /
          absl::StrCat("mesh_io_test_", ::getpid(), "_", name))
      .string();
}

void WriteFile(const std::string& path, const std::string& data) {
  std::ofstream out(path, std::ios::binary);
  out.write(data.data(), static_cast<std::streamsize>(data.size()));
  ASSERT_TRUE(out.good());
}

// Encodes values as a PLY file body, independently of the reader: each value is converted to the
// C type of its PLY type name and its bytes are written in the requested order.
class PlyBytes {
 public:
  explicit PlyBytes(bool big_endian) : big_endian_(big_endian) {}

  void Put(const std::string& type, double v) {
    if (type == "char" || type == "int8") return PutRaw(static_cast<int8_t>(v));
    if (type == "uchar" || type == "uint8") return PutRaw(static_cast<uint8_t>(v));
    if (type == "short" || type == "int16") return PutRaw(static_cast<int16_t>(v));
    if (type == "ushort" || type == "uint16") return PutRaw(static_cast<uint16_t>(v));
    if (type == "int" || type == "int32") return PutRaw(static_cast<int32_t>(v));
    if (type == "uint" || type == "uint32") return PutRaw(static_cast<uint32_t>(v));
    if (type == "float" || type == "float32") return PutRaw(static_cast<float>(v));
    if (type == "double" || type == "float64") return PutRaw(v);
    ADD_FAILURE() << "unknown type " << type;
  }

  std::string data;

 private:
  template <typename T>
  void PutRaw(T v) {
    char b[sizeof(T)];
    std::memcpy(b, &v, sizeof(T));
    if (big_endian_ != (std::endian::native == std::endian::big)) std::reverse(b, b + sizeof(T));
    data.append(b, sizeof(T));
  }
  bool big_endian_;
};

// A tetrahedron-ish test mesh with a quad: 5 vertices, faces {0,1,2}, {0,3,4,1} (-> 2 triangles).
const std::vector<std::array<double, 3>> kCoords = {
    {0.5, -1.25, 2.0}, {3.0, 0.0, -0.125}, {-7.5, 1.0, 4.0}, {1e-3, 2.5e10, -0.0}, {6.0, 6.5, 7.0}};
const FaceMatrix kFannedFaces = Faces({{0, 1, 2}, {0, 3, 4}, {0, 4, 1}});

// ---------------------------------------------------------------------------------------------
// MeshFormatFromPath

TEST(MeshFormatFromPathTest, RecognizesExtensionsCaseInsensitively) {
  EXPECT_EQ(*MeshFormatFromPath("a/b/mesh.obj"), MeshFormat::kObj);
  EXPECT_EQ(*MeshFormatFromPath("MESH.OFF"), MeshFormat::kOff);
  EXPECT_EQ(*MeshFormatFromPath("x.tar.Ply"), MeshFormat::kPly);
}

TEST(MeshFormatFromPathTest, RejectsUnknownOrMissingExtensions) {
  for (const char* path : {"mesh.stl", "mesh", "dir.obj/mesh", "obj", ""}) {
    absl::StatusOr<MeshFormat> f = MeshFormatFromPath(path);
    EXPECT_THAT(f, StatusIs(absl::StatusCode::kInvalidArgument)) << path;
  }
}

// ---------------------------------------------------------------------------------------------
// OBJ

TEST(ObjTest, ReadsAllCornerFormsAndIgnoresOtherStatements) {
  const std::string obj =
      "# a comment\r\n"
      "mtllib foo.mtl\r\n"
      "o object\n"
      "g group\n"
      "v 0.5 -1.25 2\n"
      "v\t3.0\t0\t-0.125\t1.0\n"  // w component
      "v -7.5 1 4 0.2 0.3 0.4\n"  // vertex colors
      "vt 0.5 0.5\n"
      "vn 0 0 1\n"
      "usemtl red\n"
      "s 1\n"
      "f 1 2 3\n"
      "v +1e-3 2.5e10 -0\n"
      "v 6 6.5 7 # trailing comment\n"
      "f 1/1 2/1 3/1\n"
      "f 1/1/1 2/1/1 3/1/1\n"
      "  f 1//1 4//1 5//1   # indented, trailing comment\r\n"
      "s off\n"
      "l 1 2\n";
  MeshReadResult r = MustRead(obj, MeshFormat::kObj);
  ExpectArrays(r, Verts(kCoords), Faces({{0, 1, 2}, {0, 1, 2}, {0, 1, 2}, {0, 3, 4}}));
  EXPECT_EQ(r.polygons_triangulated, 0);
  EXPECT_TRUE(std::signbit(r.arrays.vertices(3, 2)));  // "-0" keeps its sign
}

TEST(ObjTest, NegativeIndicesAreRelativeToTheVerticesReadSoFar) {
  const std::string obj =
      "v 0 0 0\nv 1 0 0\nv 0 1 0\n"
      "f -3 -2 -1\n"
      "v 1 1 0\n"
      "f -3/-1 -1//-2 -2\n";  // vertices 2, 4, 3 (1-based)
  MeshReadResult r = MustRead(obj, MeshFormat::kObj);
  ExpectArrays(r, Verts({{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {1, 1, 0}}),
               Faces({{0, 1, 2}, {1, 3, 2}}));
}

TEST(ObjTest, PolygonsAreFanTriangulated) {
  const std::string obj =
      "v 0.5 -1.25 2\nv 3 0 -0.125\nv -7.5 1 4\nv 1e-3 2.5e10 -0\nv 6 6.5 7\n"
      "f 1 2 3\n"
      "f 1 4 5 2\n";
  MeshReadResult r = MustRead(obj, MeshFormat::kObj);
  ExpectArrays(r, Verts(kCoords), kFannedFaces);
  EXPECT_EQ(r.polygons_triangulated, 1);

  // A hexagon becomes 4 triangles sharing its first corner.
  MeshReadResult hex = MustRead(
      "v 0 0 0\nv 1 0 0\nv 2 1 0\nv 1 2 0\nv 0 2 0\nv -1 1 0\nf 1 2 3 4 5 6\n", MeshFormat::kObj);
  ExpectArrays(hex, hex.arrays.vertices, Faces({{0, 1, 2}, {0, 2, 3}, {0, 3, 4}, {0, 4, 5}}));
  EXPECT_EQ(hex.polygons_triangulated, 1);
}

TEST(ObjTest, PolygonsRejectedWhenTriangulationIsOff) {
  MeshReadOptions options;
  options.triangulate_polygons = false;
  ExpectError("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3\n\nf 1 2 3 4\n", MeshFormat::kObj,
              absl::StatusCode::kInvalidArgument,
              "OBJ line 7: face has 4 vertices (polygon triangulation is disabled)", options);
}

TEST(ObjTest, BareCarriageReturnsSeparateLines) {
  MeshReadResult r = MustRead("v 0 0 0\rv 1 0 0\rv 0 1 0\rf 1 2 3\r", MeshFormat::kObj);
  ExpectArrays(r, Verts({{0, 0, 0}, {1, 0, 0}, {0, 1, 0}}), Faces({{0, 1, 2}}));
}

TEST(ObjTest, EmptyInputGivesAnEmptySoup) {
  MeshReadResult r = MustRead("# nothing\n\n", MeshFormat::kObj);
  EXPECT_EQ(r.arrays.vertices.rows(), 0);
  EXPECT_EQ(r.arrays.faces.rows(), 0);
}

// Non-finite coordinates are parsed and left to TriangleMesh::Create to reject.
TEST(ObjTest, NanAndInfinityAreParsedNotRejected) {
  MeshReadResult r = MustRead("v nan 0 0\nv 0 inf -inf\nv 0 0 1\nf 1 2 3\n", MeshFormat::kObj);
  ASSERT_EQ(r.arrays.vertices.rows(), 3);
  EXPECT_TRUE(std::isnan(r.arrays.vertices(0, 0)));
  EXPECT_EQ(r.arrays.vertices(1, 1), std::numeric_limits<double>::infinity());
  EXPECT_EQ(r.arrays.vertices(1, 2), -std::numeric_limits<double>::infinity());
}

TEST(ObjTest, OutOfRangePositiveIndicesAreLeftToTheMesh) {
  MeshReadResult r = MustRead("v 0 0 0\nf 1 2 7\n", MeshFormat::kObj);
  ExpectArrays(r, Verts({{0, 0, 0}}), Faces({{0, 1, 6}}));
}

TEST(ObjTest, MalformedInputIsInvalidArgumentWithLineNumber) {
  const std::string v3 = "v 0 0 0\nv 1 0 0\nv 0 1 0\n";
  struct Case {
    std::string obj;
    std::string message;
  };
  const std::vector<Case> cases = {
      {v3 + "f 1 2\n", "OBJ line 4: face has 2 vertices"},
      {v3 + "f\n", "OBJ line 4: face has 0 vertices"},
      {v3 + "f 0 1 2\n", "OBJ line 4: vertex index 0 is invalid"},
      {v3 + "f 1 2 -4\n", "OBJ line 4: relative vertex index -4 refers before the first vertex"},
      {v3 + "f 1 2 2147483649\n", "OBJ line 4: vertex index 2147483649 does not fit int32"},
      {v3 + "f 1 2 99999999999999999999\n", "OBJ line 4: vertex index"},
      {v3 + "f 1 2 x\n", "OBJ line 4: invalid face corner 'x'"},
      {v3 + "f 1 2 3x\n", "OBJ line 4: invalid face corner '3x'"},
      {v3 + "f 1 2 3/1/1/1\n", "OBJ line 4: invalid face corner"},
      {v3 + "f 1 2 1.5\n", "OBJ line 4: invalid face corner '1.5'"},
      {"v 1 2\n", "OBJ line 1: missing vertex coordinate"},
      {"\n\nv 1 2 abc\n", "OBJ line 3: invalid vertex coordinate 'abc'"},
      {"v 1 2 3.5.5\n", "OBJ line 1: invalid vertex coordinate '3.5.5'"},
      {"v 1 2 1e999\n", "OBJ line 1: vertex coordinate '1e999' is out of range"},
      {"v 1 2 3\nvx 1 2\n", "OBJ line 2: unknown OBJ statement 'vx'"},
      {std::string("v 1 2 3\n\x01\xff\x7f garbage\n", 20), "OBJ line 2: unknown OBJ statement"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.obj);
    ExpectError(c.obj, MeshFormat::kObj, absl::StatusCode::kInvalidArgument, c.message);
  }
}

TEST(ObjTest, LimitsAreResourceExhausted) {
  MeshReadOptions options;
  options.max_vertices = 3;
  options.max_faces = 2;
  const std::string v3 = "v 0 0 0\nv 1 0 0\nv 0 1 0\n";
  ExpectError(v3 + "v 1 1 1\n", MeshFormat::kObj, absl::StatusCode::kResourceExhausted,
              "more than 3 vertices", options);
  // Three triangles from one pentagon exceed max_faces = 2.
  ExpectError(v3 + "f 1 2 3 1 2\n", MeshFormat::kObj, absl::StatusCode::kResourceExhausted,
              "more than 2 faces", options);
  ExpectError(v3 + "f 1 2 3\nf 1 2 3\nf 1 2 3\n", MeshFormat::kObj,
              absl::StatusCode::kResourceExhausted, "more than 2 faces", options);
  MustRead(v3 + "f 1 2 3\nf 3 2 1\n", MeshFormat::kObj, options);
}

// ---------------------------------------------------------------------------------------------
// OFF

TEST(OffTest, ReadsCommentsBlankLinesCrlfAndTrailingColors) {
  const std::string off =
      "OFF\r\n"
      "# a comment before the counts\r\n"
      "\r\n"
      "5 2 0 # with the edge count\r\n"
      "0.5 -1.25 2\r\n"
      "  # comment between vertices\r\n"
      "3 0 -0.125 255 0 0\r\n"  // a vertex color
      "-7.5\t1 4\r\n"
      "1e-3 2.5e10 -0\r\n"
      "6 6.5 7\r\n"
      "\r\n"
      "3 0 1 2 0.5 0.5 0.5 1.0\r\n"  // a face color
      "4 0 3 4 1 # a quad\r\n";
  MeshReadResult r = MustRead(off, MeshFormat::kOff);
  ExpectArrays(r, Verts(kCoords), kFannedFaces);
  EXPECT_EQ(r.polygons_triangulated, 1);
}

TEST(OffTest, CountsOnTheHeaderLineAndHeaderVariants) {
  for (const char* header : {"OFF 3 1 0", "COFF 3 1", "NOFF\n3 1 0", "CNOFF 3 1 3", "STOFF 3 1"}) {
    SCOPED_TRACE(header);
    MeshReadResult r =
        MustRead(absl::StrCat(header, "\n0 0 0\n1 0 0\n0 1 0\n3 2 1 0\n"), MeshFormat::kOff);
    ExpectArrays(r, Verts({{0, 0, 0}, {1, 0, 0}, {0, 1, 0}}), Faces({{2, 1, 0}}));
  }
}

TEST(OffTest, PolygonsRejectedWhenTriangulationIsOff) {
  MeshReadOptions options;
  options.triangulate_polygons = false;
  ExpectError("OFF\n4 1 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n", MeshFormat::kOff,
              absl::StatusCode::kInvalidArgument,
              "OFF line 7: face has 4 vertices (polygon triangulation is disabled)", options);
}

TEST(OffTest, MalformedInputIsInvalidArgument) {
  const std::string head = "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n";
  // Keeps short inputs above the minimal size the header counts imply, so that the error under
  // test is reached (rather than the size check).
  const std::string pad = "# padding to pass the size check\n";
  struct Case {
    std::string off;
    std::string message;
  };
  const std::vector<Case> cases = {
      {"", "OFF: empty file"},
      {"# only a comment\n", "OFF: empty file"},
      {"PLY\n3 1 0\n", "OFF line 1: expected an OFF header, found 'PLY'"},
      {"XOFF\n3 1 0\n", "OFF line 1: unknown OFF header 'XOFF'"},
      {"4OFF\n3 1 0\n", "only 3D vertices are supported"},
      {"nOFF\n4\n3 1 0\n", "only 3D vertices are supported"},
      {"OFF BINARY\n", "binary OFF is not supported"},
      {"OFF\n", "OFF: missing vertex and face counts"},
      {"OFF\n3\n", "OFF line 2: missing face count"},
      {"OFF\n3 x 0\n", "OFF line 2: invalid face count 'x'"},
      {"OFF\n-3 1 0\n", "OFF line 2: negative vertex or face count"},
      {"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n" + pad, "OFF: file ends after 0 of 1 faces"},
      {"OFF\n3 1 0\n0 0 0\n1 0 0\n" + pad, "OFF: file ends after 2 of 3 vertices"},
      {"OFF\n3 1 0\n0 0 0\n1 0\n0 1 0\n3 0 1 2\n" + pad, "OFF line 4: missing vertex coordinate"},
      {"OFF\n3 1 0\n0 0 0\n1 0 z\n0 1 0\n3 0 1 2\n", "OFF line 4: invalid vertex coordinate 'z'"},
      {head + "2 0 1\n" + pad, "OFF line 6: face has 2 vertices"},
      {head + "4 0 1 2\n" + pad, "OFF line 6: face declares 4 vertices but lists 3"},
      {head + "3 0 1 -2\n", "OFF line 6: vertex index -2 is negative"},
      {head + "3 0 1 2147483648\n", "OFF line 6: vertex index 2147483648 does not fit int32"},
      {head + "3 0 1 99999999999999999999\n", "OFF line 6: vertex index"},
      {head + "3 0 1 2.5\n", "OFF line 6: invalid vertex index '2.5'"},
      {head + "three 0 1 2\n", "OFF line 6: invalid face corner count 'three'"},
      // Counts larger than the file can hold are caught before allocating.
      {"OFF\n1000 1 0\n0 0 0\n", "OFF: header declares 1000 vertices and 1 faces but only"},
      {"OFF\n3 100000000 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n", "but only 26 bytes follow"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.off);
    ExpectError(c.off, MeshFormat::kOff, absl::StatusCode::kInvalidArgument, c.message);
  }
}

TEST(OffTest, AbsurdCountsAndLimitsAreResourceExhausted) {
  ExpectError("OFF\n999999999999 1 0\n0 0 0\n", MeshFormat::kOff,
              absl::StatusCode::kResourceExhausted, "vertices (MeshReadOptions::max_vertices)");
  ExpectError("OFF\n3 999999999999 0\n0 0 0\n", MeshFormat::kOff,
              absl::StatusCode::kResourceExhausted, "faces (MeshReadOptions::max_faces)");
  MeshReadOptions options;
  options.max_faces = 1;
  ExpectError("OFF\n4 1 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n", MeshFormat::kOff,
              absl::StatusCode::kResourceExhausted, "more than 1 faces", options);
}

// ---------------------------------------------------------------------------------------------
// PLY

// The mesh of kCoords / kFannedFaces with extra vertex and face properties, extra list
// properties and extra elements (before, between and after the ones we read), in any encoding.
// Vertex x y z are doubles; face counts are `int`, indices `uint`.
std::string RichPly(const std::string& format) {
  const bool ascii = format == "ascii";
  std::string out = absl::StrCat("ply\nformat ", format,
                                 " 1.0\n"
                                 "comment made by the test\n"
                                 "obj_info anything at all\n"
                                 "element material 2\n"
                                 "property uchar red\n"
                                 "property float shininess\n"
                                 "element vertex 5\n"
                                 "property float nx\n"
                                 "property double x\n"
                                 "property double y\n"
                                 "property list uchar short tags\n"
                                 "property double z\n"
                                 "property uchar alpha\n"
                                 "element face 2\n"
                                 "property int flags\n"
                                 "property list int uint vertex_indices\n"
                                 "property list ushort double texcoord\n"
                                 "property float quality\n"
                                 "element edge 3\n"
                                 "property list uint8 int32 vertex1\n"
                                 "property int16 crease\n"
                                 "end_header\n");
  const std::vector<std::vector<int32_t>> faces = {{0, 1, 2}, {0, 3, 4, 1}};
  if (ascii) {
    out += "255 0.5\n1 2.5\n";
    for (int i = 0; i < 5; ++i) {
      absl::StrAppend(&out, 0.25 * i, " ", kCoords[i][0], " ", kCoords[i][1], " ", i % 3);
      for (int t = 0; t < i % 3; ++t) absl::StrAppend(&out, " ", -t);
      absl::StrAppend(&out, " ", kCoords[i][2], " ", 7 * i, "\n");
    }
    // StrAppend(double) prints 6 significant digits, which is exact for every value used here.
    for (size_t f = 0; f < faces.size(); ++f) {
      absl::StrAppend(&out, -1, " ", faces[f].size());
      for (int32_t v : faces[f]) absl::StrAppend(&out, " ", v);
      absl::StrAppend(&out, " 2 0.5 0.25 ", 3.5 * f, "\n");
    }
    out += "2 0 1 -3\n0 7\n3 1 2 3 100\n";
    return out;
  }
  PlyBytes b(format == "binary_big_endian");
  b.Put("uchar", 255), b.Put("float", 0.5), b.Put("uchar", 1), b.Put("float", 2.5);
  for (int i = 0; i < 5; ++i) {
    b.Put("float", 0.25 * i);
    b.Put("double", kCoords[i][0]);
    b.Put("double", kCoords[i][1]);
    b.Put("uchar", i % 3);
    for (int t = 0; t < i % 3; ++t) b.Put("short", -t);
    b.Put("double", kCoords[i][2]);
    b.Put("uchar", 7 * i);
  }
  for (size_t f = 0; f < faces.size(); ++f) {
    b.Put("int", -1);
    b.Put("int", static_cast<double>(faces[f].size()));
    for (int32_t v : faces[f]) b.Put("uint", v);
    b.Put("ushort", 2), b.Put("double", 0.5), b.Put("double", 0.25);
    b.Put("float", 3.5 * f);
  }
  b.Put("uint8", 2), b.Put("int32", 0), b.Put("int32", 1), b.Put("int16", -3);
  b.Put("uint8", 0), b.Put("int16", 7);
  b.Put("uint8", 3), b.Put("int32", 1), b.Put("int32", 2), b.Put("int32", 3), b.Put("int16", 100);
  return out + b.data;
}

class PlyEncodingTest : public ::testing::TestWithParam<std::string> {};

TEST_P(PlyEncodingTest, ReadsExtraPropertiesListsAndElements) {
  MeshReadResult r = MustRead(RichPly(GetParam()), MeshFormat::kPly);
  ExpectArrays(r, Verts(kCoords), kFannedFaces);
  EXPECT_EQ(r.polygons_triangulated, 1);
}

TEST_P(PlyEncodingTest, EveryTruncationIsAnErrorAndNeverACrash) {
  const std::string ply = RichPly(GetParam());
  const size_t header_end = ply.find("end_header\n") + 11;
  for (size_t n = 0; n < ply.size(); ++n) {
    absl::StatusOr<MeshReadResult> r = ReadMesh(ply.substr(0, n), MeshFormat::kPly);
    // Ascii may stop inside the last number and still parse; binary never can.
    if (GetParam() != "ascii" || n < header_end) {
      ASSERT_FALSE(r.ok()) << "truncated at " << n;
      EXPECT_THAT(r, StatusIs(absl::StatusCode::kInvalidArgument)) << r.status();
    }
  }
}

INSTANTIATE_TEST_SUITE_P(Encodings, PlyEncodingTest,
                         ::testing::Values("ascii", "binary_little_endian", "binary_big_endian"),
                         [](const auto& info) { return info.param; });

// Every scalar type name for x y z and every integral type for list counts and indices, in all
// three encodings.
TEST(PlyTest, AllTypeNames) {
  const std::vector<std::string> coord_types = {
      "char", "int8",  "uchar", "uint8",  "short", "int16",   "ushort", "uint16",
      "int",  "int32", "uint",  "uint32", "float", "float32", "double", "float64"};
  const std::vector<std::string> int_types = {"char",  "int8",  "uchar",  "uint8",
                                              "short", "int16", "ushort", "uint16",
                                              "int",   "int32", "uint",   "uint32"};
  // Values representable in every type above.
  const std::vector<std::array<double, 3>> coords = {{0, 1, 2}, {3, 4, 5}, {6, 7, 126}};
  for (const std::string format : {"ascii", "binary_little_endian", "binary_big_endian"}) {
    for (size_t t = 0; t < coord_types.size(); ++t) {
      const std::string& coord = coord_types[t];
      const std::string& count = int_types[t % int_types.size()];
      const std::string& index = int_types[(t * 5 + 3) % int_types.size()];
      SCOPED_TRACE(absl::StrCat(format, " ", coord, " ", count, " ", index));
      std::string ply = absl::StrCat("ply\nformat ", format, " 1.0\nelement vertex 3\n",
                                     "property ", coord, " x\nproperty ", coord, " y\nproperty ",
                                     coord, " z\nelement face 2\nproperty list ", count, " ", index,
                                     " vertex_index\nend_header\n");
      const std::vector<std::array<int, 3>> faces = {{0, 1, 2}, {2, 1, 0}};
      if (format == "ascii") {
        for (const auto& c : coords) absl::StrAppend(&ply, c[0], " ", c[1], " ", c[2], "\n");
        for (const auto& f : faces) absl::StrAppend(&ply, "3 ", f[0], " ", f[1], " ", f[2], "\n");
      } else {
        PlyBytes b(format == "binary_big_endian");
        for (const auto& c : coords) {
          for (double v : c) b.Put(coord, v);
        }
        for (const auto& f : faces) {
          b.Put(count, 3);
          for (int v : f) b.Put(index, v);
        }
        ply += b.data;
      }
      MeshReadResult r = MustRead(ply, MeshFormat::kPly);
      ExpectArrays(r, Verts(coords), Faces({{0, 1, 2}, {2, 1, 0}}));
    }
  }
}

// The layout of the shared binary meshes (float x y z; uchar int lists), which has a fast path,
// mixed with polygons and big-endian data that must leave it.
TEST(PlyTest, CommonBinaryLayoutWithPolygons) {
  for (bool big_endian : {false, true}) {
    PlyBytes b(big_endian);
    for (const auto& c : kCoords) {
      for (double v : c) b.Put("float", v);
    }
    b.Put("uchar", 3), b.Put("int", 0), b.Put("int", 1), b.Put("int", 2);
    b.Put("uchar", 4), b.Put("int", 0), b.Put("int", 3), b.Put("int", 4), b.Put("int", 1);
    b.Put("uchar", 3), b.Put("int", 4), b.Put("int", 3), b.Put("int", 2);
    const std::string ply =
        absl::StrCat("ply\r\nformat ", big_endian ? "binary_big_endian" : "binary_little_endian",
                     " 1.0\r\nelement vertex 5\r\nproperty float x\r\nproperty float y\r\n",
                     "property float z\r\nelement face 3\r\n",
                     "property list uchar int vertex_indices\r\nend_header\r\n", b.data);
    MeshReadResult r = MustRead(ply, MeshFormat::kPly);
    VertexMatrix V = Verts(kCoords).cast<float>().cast<double>();
    ExpectArrays(r, V, Faces({{0, 1, 2}, {0, 3, 4}, {0, 4, 1}, {4, 3, 2}}));
    EXPECT_EQ(r.polygons_triangulated, 1);
  }
}

std::string SmallBinaryPly(const std::string& index_type, const std::vector<double>& indices,
                           int count = 3) {
  PlyBytes b(false);
  for (int i = 0; i < 9; ++i) b.Put("float", i);
  b.Put("uchar", count);
  for (double v : indices) b.Put(index_type, v);
  return absl::StrCat(
      "ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float "
      "y\nproperty float z\nelement face 1\nproperty list uchar ",
      index_type, " vertex_indices\nend_header\n", b.data);
}

TEST(PlyTest, MalformedInputIsInvalidArgument) {
  const std::string vertex3 =
      "element vertex 3\nproperty float x\nproperty float y\nproperty float z\n";
  const std::string ascii_head = "ply\nformat ascii 1.0\n" + vertex3 +
                                 "element face 1\nproperty list uchar int vertex_indices\n"
                                 "end_header\n0 0 0\n1 0 0\n0 1 0\n";
  struct Case {
    std::string ply;
    std::string message;
  };
  const std::vector<Case> cases = {
      {"", "PLY: not a PLY file"},
      {"plyx\nformat ascii 1.0\nend_header\n", "PLY: not a PLY file"},
      {"solid stl\n", "PLY: not a PLY file"},
      {"ply\nformat ascii 1.0\n", "PLY: header has no end_header line"},
      {"ply\nformat utf8 1.0\nend_header\n", "PLY line 2: unknown format 'utf8'"},
      {"ply\n" + vertex3 + "end_header\n", "PLY: header has no format line"},
      {"ply\nformat ascii 1.0\nproperty float x\nend_header\n",
       "PLY line 3: property before any element"},
      {"ply\nformat ascii 1.0\nelement vertex 1\nproperty float128 x\nend_header\n",
       "PLY line 4: unknown property type 'float128'"},
      {"ply\nformat ascii 1.0\nelement face 1\nproperty list float int vertex_indices\n"
       "end_header\n",
       "PLY line 4: invalid list count type 'float'"},
      {"ply\nformat ascii 1.0\nelement vertex x\nend_header\n",
       "PLY line 3: invalid element count 'x'"},
      {"ply\nformat ascii 1.0\nelement vertex -1\nend_header\n",
       "PLY line 3: negative element count"},
      {"ply\nformat ascii 1.0\nelement vertex 0\nelement vertex 0\nend_header\n",
       "PLY line 4: duplicate element 'vertex'"},
      {"ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nproperty int x\nend_header\n",
       "PLY line 5: duplicate property 'x' in element 'vertex'"},
      {"ply\nformat ascii 1.0\nfoo bar\nend_header\n", "PLY line 3: unknown header line 'foo bar'"},
      {"ply\nformat ascii 1.0\nelement face 0\nproperty list uchar int vertex_indices\n"
       "end_header\n",
       "PLY: no 'vertex' element"},
      {"ply\nformat ascii 1.0\n" + vertex3 + "end_header\n", "PLY: no 'face' element"},
      {"ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nproperty float z\n"
       "end_header\n",
       "PLY: element 'vertex' has no property 'y'"},
      {"ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nproperty float y\n"
       "property list uchar float z\nend_header\n",
       "vertex property 'z' is a list"},
      {"ply\nformat ascii 1.0\n" + vertex3 + "element face 0\nproperty int vertex_indices\n" +
           "end_header\n",
       "PLY: face property 'vertex_indices' is not a list of integers"},
      {"ply\nformat ascii 1.0\n" + vertex3 + "element face 0\nproperty list uchar float " +
           "vertex_indices\nend_header\n",
       "PLY: face property 'vertex_indices' is not a list of integers"},
      {"ply\nformat ascii 1.0\n" + vertex3 + "element face 0\nproperty uchar flags\n" +
           "end_header\n",
       "PLY: element 'face' has no property 'vertex_indices' or 'vertex_index'"},
      // Ascii body.
      {ascii_head + "3 0 1\n", "PLY: data ends before vertex index of element 'face' item 0"},
      {ascii_head + "3 0 1 x\n", "PLY line 13: invalid vertex index 'x' of element 'face' item 0"},
      {ascii_head + "2 0 1\n", "PLY: face 0: face has 2 vertices"},
      {ascii_head + "3 0 1 -1\n", "PLY: face 0 has vertex index -1 (negative)"},
      {ascii_head + "3 0 1 4294967295\n",
       "PLY: face 0 has vertex index 4294967295 (does not fit int32)"},
      {ascii_head + "-3 0 1 2\n", "PLY line 13: invalid list length of 'vertex_indices'"},
      {ascii_head + "x 0 1 2\n", "PLY line 13: invalid list length of 'vertex_indices'"},
      {"ply\nformat ascii 1.0\n" + vertex3 +
           "element face 0\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 "
           "1 nope\n",
       "PLY line 12: invalid property 'z' 'nope' of element 'vertex' item 2"},
      {"ply\nformat ascii 1.0\n" + vertex3 +
           "element face 0\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 "
           "1 1e400\n",
       "PLY line 12: out-of-range property 'z' '1e400' of element 'vertex' item 2"},
      // Binary body.
      {SmallBinaryPly("int", {0, 1, -5}), "PLY: face 0 has vertex index -5 (negative)"},
      {SmallBinaryPly("uint", {0, 1, 3000000000.0}),
       "PLY: face 0 has vertex index 3000000000 (does not fit int32)"},
      {SmallBinaryPly("short", {0, -1, 2}), "PLY: face 0 has vertex index -1 (negative)"},
      {SmallBinaryPly("int", {0, 1}, 2), "PLY: face 0: face has 2 vertices"},
      {SmallBinaryPly("int", {0, 1, 2}, 4),
       "PLY: truncated binary data in element 'face' at item 0"},
      {SmallBinaryPly("int", {0, 1, 2}).substr(0, SmallBinaryPly("int", {0, 1, 2}).size() - 1),
       "PLY: truncated binary data in element 'face' at item 0"},
      // Header counts that the data cannot possibly hold are caught before allocating.
      {"ply\nformat binary_little_endian 1.0\nelement vertex 1000\nproperty float x\n"
       "property float y\nproperty float z\nelement face 0\nproperty list uchar int "
       "vertex_indices\nend_header\n" +
           std::string(200, '\0'),
       "PLY: header declares 1000 items of element 'vertex' but only 200 bytes of data follow"},
      {"ply\nformat ascii 1.0\nelement junk 99999999\nproperty uchar a\n" + vertex3 +
           "element face 0\nproperty list uchar int vertex_indices\nend_header\n1 2 3\n",
       "PLY: header declares 99999999 items of element 'junk'"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.ply);
    ExpectError(c.ply, MeshFormat::kPly, absl::StatusCode::kInvalidArgument, c.message);
  }
}

TEST(PlyTest, BinaryListsLongerThanTheDataAreTruncationErrors) {
  // A list count of 4 billion in a uint count: must be detected without allocating or looping.
  PlyBytes b(false);
  for (int i = 0; i < 9; ++i) b.Put("float", i);
  b.Put("uint", 4294967295.0);
  b.Put("int", 0);
  const std::string ply =
      "ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float "
      "y\nproperty float z\nelement face 1\nproperty list uint int vertex_indices\nend_header\n" +
      b.data;
  ExpectError(ply, MeshFormat::kPly, absl::StatusCode::kInvalidArgument,
              "PLY: truncated binary data in element 'face' at item 0");
}

TEST(PlyTest, ElementsWithoutPropertiesAndHugeCountsDoNotLoop) {
  // No property means no bytes per item: 10^15 items occupy nothing and are skipped at once.
  const std::string ply =
      "ply\nformat ascii 1.0\nelement nothing 1000000000000000\nelement vertex 3\nproperty float "
      "x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int "
      "vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n";
  ExpectArrays(MustRead(ply, MeshFormat::kPly), Verts({{0, 0, 0}, {1, 0, 0}, {0, 1, 0}}),
               Faces({{0, 1, 2}}));
}

TEST(PlyTest, AbsurdCountsAndLimitsAreResourceExhausted) {
  const std::string tail =
      "property float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar "
      "int vertex_indices\nend_header\n";
  ExpectError("ply\nformat binary_little_endian 1.0\nelement vertex 999999999999\n" + tail +
                  std::string(100, '\0'),
              MeshFormat::kPly, absl::StatusCode::kResourceExhausted,
              "PLY: more than 134217728 vertices (MeshReadOptions::max_vertices)");
  ExpectError(
      "ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\n"
      "property float y\nproperty float z\nelement face 999999999999\nproperty list "
      "uchar int vertex_indices\nend_header\n",
      MeshFormat::kPly, absl::StatusCode::kResourceExhausted, "faces");
  MeshReadOptions options;
  options.max_faces = 2;
  // One declared face, but it is a pentagon: 3 triangles.
  ExpectError("ply\nformat ascii 1.0\nelement vertex 5\n" + tail +
                  "0 0 0\n1 0 0\n1 1 0\n0 1 0\n0 2 0\n5 0 1 2 3 4\n",
              MeshFormat::kPly, absl::StatusCode::kResourceExhausted, "more than 2 faces", options);
  options.triangulate_polygons = false;
  ExpectError("ply\nformat ascii 1.0\nelement vertex 5\n" + tail +
                  "0 0 0\n1 0 0\n1 1 0\n0 1 0\n0 2 0\n5 0 1 2 3 4\n",
              MeshFormat::kPly, absl::StatusCode::kInvalidArgument,
              "PLY: face 0: face has 5 vertices (polygon triangulation is disabled)", options);
}

// ---------------------------------------------------------------------------------------------
// Robustness: random bytes, truncations and mutations of valid files must give a status.

std::vector<std::pair<std::string, MeshFormat>> ValidSamples() {
  return {
      {"# c\nv 0.5 -1.25 2\nv 3 0 -0.125\nv -7.5 1 4\nv 1e-3 2.5e10 -0\nv 6 6.5 7\nvn 0 0 1\n"
       "f 1//1 2//1 3//1\nf -5/1 -2/1 -1/1 2/1\n",
       MeshFormat::kObj},
      {"OFF\r\n# c\r\n5 2 0\r\n0.5 -1.25 2\r\n3 0 -0.125\r\n-7.5 1 4\r\n1e-3 2.5e10 -0\r\n"
       "6 6.5 7\r\n3 0 1 2\r\n4 0 3 4 1 1 0 0\r\n",
       MeshFormat::kOff},
      {RichPly("ascii"), MeshFormat::kPly},
      {RichPly("binary_little_endian"), MeshFormat::kPly},
      {RichPly("binary_big_endian"), MeshFormat::kPly},
  };
}

// Whatever the input: a failure is InvalidArgument or ResourceExhausted, and a successful read
// returns indices >= 0.
void ExpectSane(const absl::StatusOr<MeshReadResult>& r) {
  if (!r.ok()) {
    EXPECT_THAT(r, AnyOf(StatusIs(absl::StatusCode::kInvalidArgument),
                         StatusIs(absl::StatusCode::kResourceExhausted)));
    return;
  }
  if (r->arrays.faces.size() > 0) {
    EXPECT_GE(r->arrays.faces.minCoeff(), 0);
  }
}

TEST(FuzzTest, RandomBytesTruncationsAndMutations) {
  std::mt19937_64 rng(20240611);
  auto random_byte = [&] { return static_cast<char>(rng() & 0xff); };
  const std::vector<MeshFormat> formats = {MeshFormat::kObj, MeshFormat::kOff, MeshFormat::kPly};
  // Random byte strings, also with a valid-looking start.
  for (int trial = 0; trial < 3000; ++trial) {
    std::string data(rng() % 300, '\0');
    for (char& c : data) c = random_byte();
    const MeshFormat format = formats[trial % 3];
    if (trial % 2 == 1) {
      const char* starts[] = {"v 1 2 3\nf ", "OFF\n3 1 0\n",
                              "ply\nformat binary_little_endian "
                              "1.0\nelement vertex 3\n"};
      data = starts[trial % 3] + data;
    }
    ExpectSane(ReadMesh(data, format));
  }
  for (const auto& [sample, format] : ValidSamples()) {
    ExpectSane(ReadMesh(sample, format));
    ASSERT_TRUE(ReadMesh(sample, format).ok()) << ReadMesh(sample, format).status();
    // Every prefix.
    for (size_t n = 0; n < sample.size(); ++n) ExpectSane(ReadMesh(sample.substr(0, n), format));
    // Random byte changes: replacements, insertions of digits and separators, deletions.
    for (int trial = 0; trial < 1500; ++trial) {
      std::string data = sample;
      const int edits = 1 + static_cast<int>(rng() % 4);
      for (int e = 0; e < edits && !data.empty(); ++e) {
        const size_t at = rng() % data.size();
        switch (rng() % 4) {
          case 0:
            data[at] = random_byte();
            break;
          case 1:
            data.insert(at, 1, "0123456789 -\n/#e."[rng() % 17]);
            break;
          case 2:
            data.erase(at, 1 + rng() % 8);
            break;
          default:
            data[at] = static_cast<char>(0xff);  // large counts in binary data
            break;
        }
      }
      ExpectSane(ReadMesh(data, format));
    }
  }
}

// ---------------------------------------------------------------------------------------------
// Files and WritePly

TEST(FileTest, MissingFilesAreNotFound) {
  const std::string path = TempPath("does_not_exist.obj");
  EXPECT_THAT(ReadMeshFile(path), StatusIs(absl::StatusCode::kNotFound));
  EXPECT_THAT(ReadFileToString(path), StatusIs(absl::StatusCode::kNotFound));
}

TEST(FileTest, DirectoriesAndUnknownExtensionsAreInvalidArgument) {
  const std::string dir = TempPath("dir.obj");
  std::filesystem::create_directories(dir);
  EXPECT_THAT(ReadFileToString(dir), StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(ReadMeshFile(dir), StatusIs(absl::StatusCode::kInvalidArgument));
  std::filesystem::remove(dir);
  const std::string stl = TempPath("mesh.stl");
  WriteFile(stl, "solid x\n");
  EXPECT_THAT(ReadMeshFile(stl), StatusIs(absl::StatusCode::kInvalidArgument));
  std::filesystem::remove(stl);
}

TEST(FileTest, ReadsWholeFilesAndEnforcesTheSizeLimit) {
  const std::string path = TempPath("limit.off");
  std::string data = "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n";
  data += std::string(100000, '\n');  // more than one read chunk of blank lines
  WriteFile(path, data);
  absl::StatusOr<std::string> read = ReadFileToString(path);
  ASSERT_TRUE(read.ok()) << read.status();
  EXPECT_EQ(*read, data);
  EXPECT_THAT(ReadFileToString(path, static_cast<int64_t>(data.size())),
              StatusIs(absl::StatusCode::kOk));
  EXPECT_THAT(ReadFileToString(path, static_cast<int64_t>(data.size()) - 1),
              StatusIs(absl::StatusCode::kResourceExhausted));
  MeshReadOptions options;
  options.max_file_bytes = 1000;
  EXPECT_THAT(ReadMeshFile(path, options), StatusIs(absl::StatusCode::kResourceExhausted));
  ExpectArrays(*ReadMeshFile(path), Verts({{0, 0, 0}, {1, 0, 0}, {0, 1, 0}}), Faces({{0, 1, 2}}));
  std::filesystem::remove(path);
}

TEST(FileTest, ErrorsNameTheFile) {
  const std::string path = TempPath("broken.obj");
  WriteFile(path, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2\n");
  absl::StatusOr<MeshReadResult> r = ReadMeshFile(path);
  EXPECT_THAT(r, StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_EQ(r.status().message(),
            absl::StrCat("mesh_io_test_", ::getpid(), "_broken.obj line 4: face has 2 vertices"));
  std::filesystem::remove(path);
}

TEST(WritePlyTest, RoundTripIsExactForFloatData) {
  const VertexMatrix V = Verts(kCoords).cast<float>().cast<double>();
  const FaceMatrix F = Faces({{0, 1, 2}, {0, 3, 4}, {0, 4, 1}, {4, 3, 2}});
  const std::vector<FaceProperty> props = {{"magnitude", {0.5f, 1.5f, -2.0f, 1e30f}},
                                           {"angle", {0.f, 1.f, 2.f, 3.f}}};
  const std::string path = TempPath("roundtrip.ply");
  ASSERT_TRUE(WritePly(path, V, F, props).ok());
  absl::StatusOr<MeshReadResult> r = ReadMeshFile(path);
  ASSERT_TRUE(r.ok()) << r.status();
  ExpectArrays(*r, V, F);

  // The layout is exactly the documented one: header, 12 bytes per vertex, 1 + 12 + 4 * 2 bytes
  // per face, and the property values in face order after the indices.
  absl::StatusOr<std::string> bytes = ReadFileToString(path);
  ASSERT_TRUE(bytes.ok());
  const size_t header_end = bytes->find("end_header\n") + 11;
  EXPECT_THAT(bytes->substr(0, header_end),
              HasSubstr("element face 4\nproperty list uchar int vertex_indices\n"
                        "property float magnitude\nproperty float angle\nend_header\n"));
  ASSERT_EQ(bytes->size(), header_end + 5 * 12 + 4 * 21);
  if (std::endian::native == std::endian::little) {
    for (int f = 0; f < 4; ++f) {
      const char* rec = bytes->data() + header_end + 5 * 12 + f * 21;
      EXPECT_EQ(rec[0], 3);
      float mag;
      std::memcpy(&mag, rec + 13, 4);
      EXPECT_EQ(mag, props[0].values[f]);
    }
  }
  std::filesystem::remove(path);
}

TEST(WritePlyTest, RoundTripOfANoisyMeshRoundsCoordinatesToFloat) {
  const MeshArrays noisy = testing::CatalogueArrays("NoisySphere");
  // Its coordinates are not floats: the round trip must round them.
  ASSERT_NE(noisy.vertices.cast<float>().cast<double>(), noisy.vertices);
  const std::string out = TempPath("noisy_sphere.ply");
  ASSERT_TRUE(WritePly(out, noisy.vertices, noisy.faces).ok());
  absl::StatusOr<MeshReadResult> ply = ReadMeshFile(out);
  ASSERT_TRUE(ply.ok()) << ply.status();
  ExpectArrays(*ply, noisy.vertices.cast<float>().cast<double>(), noisy.faces);
  std::filesystem::remove(out);
}

TEST(WritePlyTest, OverwritesAndLeavesNoTemporaryFiles) {
  const std::string dir = TempPath("overwrite_dir");
  std::filesystem::create_directories(dir);
  const std::string path = dir + "/mesh.ply";
  WriteFile(path, "old contents");
  const VertexMatrix V = Verts({{0, 0, 0}, {1, 0, 0}, {0, 1, 0}});
  ASSERT_TRUE(WritePly(path, V, Faces({{0, 1, 2}})).ok());
  ASSERT_TRUE(WritePly(path, V, Faces({{0, 2, 1}})).ok());
  ExpectArrays(*ReadMeshFile(path), V, Faces({{0, 2, 1}}));
  int files = 0;
  for ([[maybe_unused]] const auto& entry : std::filesystem::directory_iterator(dir)) ++files;
  EXPECT_EQ(files, 1);
  std::filesystem::remove_all(dir);
}

TEST(WritePlyTest, InvalidInputsAreRejectedWithoutWriting) {
  const std::string path = TempPath("invalid.ply");
  const VertexMatrix V = Verts({{0, 0, 0}, {1, 0, 0}, {0, 1, 0}});
  const FaceMatrix F = Faces({{0, 1, 2}});
  EXPECT_THAT(WritePly(path, V, Faces({{0, 1, 3}})), StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(WritePly(path, V, Faces({{-1, 1, 2}})), StatusIs(absl::StatusCode::kInvalidArgument));
  for (const std::string name : {"", "two words", "vertex_indices", "tab\tbed"}) {
    EXPECT_THAT(WritePly(path, V, F, {{name, {1.f}}}), StatusIs(absl::StatusCode::kInvalidArgument))
        << name;
  }
  EXPECT_THAT(WritePly(path, V, F, {{"a", {1.f, 2.f}}}),
              StatusIs(absl::StatusCode::kInvalidArgument));
  for (double bad : {1e39, -1e300, std::numeric_limits<double>::quiet_NaN(),
                     std::numeric_limits<double>::infinity()}) {
    VertexMatrix W = V;
    W(1, 2) = bad;
    EXPECT_THAT(WritePly(path, W, F), StatusIs(absl::StatusCode::kInvalidArgument)) << bad;
  }
  EXPECT_THAT(WritePly(path, V, F, {{"a", {1.f}}, {"a", {2.f}}}),
              StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_FALSE(std::filesystem::exists(path));
  EXPECT_THAT(WritePly(TempPath("no_such_dir") + "/x.ply", V, F),
              StatusIs(absl::StatusCode::kNotFound));
}

// ---------------------------------------------------------------------------------------------
// Every catalogue mesh in the variants real files come in (OBJ with vn / vt / usemtl and CRLF
// line endings, OFF with CRLF, binary PLY, unreferenced vertices): read back to the same arrays,
// and to a mesh of the catalogue's topology. The real meshes of ../shared/meshes are checked the
// same way by the large-mesh checks (shared_mesh_catalogue_test.cc).

struct FileVariant {
  const char* name;
  const char* extension;
  testing::MeshTextOptions text;  // unused for "ply"
};

const FileVariant kFileVariants[] = {
    {"obj", "obj", {}},
    {"obj_normals_crlf", "obj", {.crlf = true, .normals = true}},
    {"obj_texcoords_materials", "obj", {.texcoords = true, .material = true}},
    {"obj_all_crlf_unreferenced",
     "obj",
     {.crlf = true,
      .normals = true,
      .texcoords = true,
      .material = true,
      .unreferenced_vertices = 113}},
    {"off", "off", {}},
    {"off_crlf_unreferenced", "off", {.crlf = true, .unreferenced_vertices = 7}},
    {"binary_ply", "ply", {}},
};

class MeshFileVariantsTest : public ::testing::TestWithParam<testing::MeshCase> {};

TEST_P(MeshFileVariantsTest, ReadBackToTheSameMesh) {
  const testing::MeshCase& c = GetParam();
  absl::StatusOr<MeshArrays> arrays = c.build();
  ASSERT_TRUE(arrays.ok()) << arrays.status();
  for (const FileVariant& variant : kFileVariants) {
    SCOPED_TRACE(variant.name);
    const std::string path =
        TempPath(absl::StrCat(c.name, "_", variant.name, ".", variant.extension));
    const std::string ext = variant.extension;
    VertexMatrix expected = arrays->vertices;
    if (ext == "ply") {
      ASSERT_TRUE(WritePly(path, arrays->vertices, arrays->faces).ok());
      expected = expected.cast<float>().cast<double>();
    } else {
      const std::string text = testing::MeshText(*arrays, ext, variant.text);
      EXPECT_EQ(text.find("\r\n") != std::string::npos, variant.text.crlf);
      WriteFile(path, text);
    }
    absl::StatusOr<MeshReadResult> r = ReadMeshFile(path);
    std::filesystem::remove(path);
    ASSERT_TRUE(r.ok()) << r.status();
    EXPECT_EQ(r->polygons_triangulated, 0);
    const int32_t extra = ext == "ply" ? 0 : variant.text.unreferenced_vertices;
    ASSERT_EQ(r->arrays.vertices.rows(), expected.rows() + extra);
    EXPECT_EQ(r->arrays.vertices.topRows(expected.rows()), expected);  // %.17g is exact
    EXPECT_EQ(r->arrays.faces, arrays->faces);
    absl::StatusOr<TriangleMesh> mesh = TriangleMesh::Create(std::move(r->arrays));
    ASSERT_TRUE(mesh.ok()) << mesh.status();
    EXPECT_EQ(mesh->dropped_unreferenced_vertices(), extra);
    EXPECT_EQ(mesh->num_faces(), arrays->faces.rows());
    EXPECT_EQ(mesh->genus(), c.genus);
    EXPECT_EQ(static_cast<int>(mesh->boundary_loops().size()), c.boundary_loops);
    EXPECT_EQ(mesh->euler_characteristic(), c.euler_characteristic);
  }
}

INSTANTIATE_TEST_SUITE_P(Catalogue, MeshFileVariantsTest,
                         ::testing::ValuesIn(testing::MeshCatalogue()), testing::MeshCaseName);

// The statements of an OBJ file exported with normals, texture coordinates and materials are
// where they belong: `vn` and `vt` lines, `v/t/n` corners, `usemtl` and `g` lines.
TEST(MeshTextTest, ObjVariantsHaveTheirStatements) {
  const MeshArrays a = testing::CatalogueArrays("Torus");
  const std::string all = testing::MeshText(
      a, "obj", {.crlf = true, .normals = true, .texcoords = true, .material = true});
  EXPECT_THAT(all, HasSubstr("\r\nvn "));
  EXPECT_THAT(all, HasSubstr("\r\nvt "));
  EXPECT_THAT(all, HasSubstr("\r\nusemtl material1\r\n"));
  EXPECT_THAT(all, HasSubstr("\r\nf 1/1/1 "));
  EXPECT_EQ(all.find("\n\n"), std::string::npos);
  const std::string normals = testing::MeshText(a, "obj", {.normals = true});
  EXPECT_THAT(normals, HasSubstr("\nf 1//1 "));
  EXPECT_EQ(normals.find('\r'), std::string::npos);
  const std::string off = testing::MeshText(a, "off", {.unreferenced_vertices = 3});
  EXPECT_THAT(
      off, StartsWith(absl::StrCat("OFF\n", a.vertices.rows() + 3, " ", a.faces.rows(), " 0\n")));
}

// MeshReadOptions::reserve_memory sees the arrays' bytes before each allocation: their final
// capacity covers what the read returns, a polygon fan's triangles outgrow its text, and a refusal
// ends the read with the callback's status, in every format.
TEST(MeshReadMemoryTest, ReserveMemoryCoversTheArraysAndCanRefuseThem) {
  // One 1000-gon over 1000 vertices: 998 triangles.
  std::string fan;
  for (int i = 0; i < 1000; ++i)
    absl::StrAppend(&fan, "v ", std::cos(i * 0.00628), " ", std::sin(i * 0.00628), " 0\n");
  absl::StrAppend(&fan, "f");
  for (int i = 1; i <= 1000; ++i) absl::StrAppend(&fan, " ", i);
  absl::StrAppend(&fan, "\n");
  int64_t last = 0, calls = 0;
  MeshReadOptions options;
  options.reserve_memory = [&](int64_t bytes) {
    EXPECT_GT(bytes, last);  // called only when the arrays grow
    last = bytes;
    ++calls;
    return absl::OkStatus();
  };
  absl::StatusOr<MeshReadResult> read = ReadMesh(fan, MeshFormat::kObj, options);
  ASSERT_TRUE(read.ok()) << read.status();
  EXPECT_EQ(read->arrays.faces.rows(), 998);
  EXPECT_GE(last, 24 * 1000 + 12 * 998);
  EXPECT_LE(last, 2 * (24 * 1000 + 12 * 998) + 2 * 12 * 64);
  EXPECT_GT(calls, 2);

  const MeshArrays a = testing::CatalogueArrays("Torus");
  std::string ply = absl::StrCat("ply\nformat ascii 1.0\nelement vertex ", a.vertices.rows(),
                                 "\nproperty double x\nproperty double y\nproperty double z\n"
                                 "element face ",
                                 a.faces.rows(),
                                 "\nproperty list uchar int vertex_indices\n"
                                 "end_header\n");
  for (int64_t v = 0; v < a.vertices.rows(); ++v) {
    absl::StrAppend(&ply, a.vertices(v, 0), " ", a.vertices(v, 1), " ", a.vertices(v, 2), "\n");
  }
  for (int64_t f = 0; f < a.faces.rows(); ++f) {
    absl::StrAppend(&ply, "3 ", a.faces(f, 0), " ", a.faces(f, 1), " ", a.faces(f, 2), "\n");
  }
  for (const char* format : {"obj", "off", "ply"}) {
    const std::string text = std::string(format) == "ply" ? ply : testing::MeshText(a, format, {});
    const MeshFormat f = *MeshFormatFromPath(absl::StrCat("x.", format));
    MeshReadOptions refuse;
    int64_t asked = 0;
    refuse.reserve_memory = [&](int64_t bytes) {
      asked = bytes;
      return bytes > 1000 ? absl::ResourceExhaustedError("over the test's budget")
                          : absl::OkStatus();
    };
    absl::StatusOr<MeshReadResult> refused = ReadMesh(text, f, refuse);
    EXPECT_EQ(refused.status().code(), absl::StatusCode::kResourceExhausted) << format;
    EXPECT_EQ(refused.status().message(), "over the test's budget") << format;
    EXPECT_GT(asked, 1000) << format;
    MeshReadOptions count;
    int64_t held = 0;
    count.reserve_memory = [&](int64_t bytes) {
      held = bytes;
      return absl::OkStatus();
    };
    absl::StatusOr<MeshReadResult> whole = ReadMesh(text, f, count);
    ASSERT_TRUE(whole.ok()) << format << ": " << whole.status();
    EXPECT_GE(held, 24 * whole->arrays.vertices.rows() + 12 * whole->arrays.faces.rows()) << format;
  }
}

}  // namespace
}  // namespace fieldspace
