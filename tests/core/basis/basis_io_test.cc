#include "core/basis/basis_io.h"

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <deque>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <string>
#include <utility>

#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tests/testing/fixtures.h"
#include "tests/testing/matchers.h"
#include "tests/testing/reference.h"
#include "tests/testing/test_meshes.h"

namespace fieldspace {
namespace {

using ::fieldspace::testing::StatusIs;
using testing::Icosphere;
using testing::MustBuildOperator;

class BasisIoTest : public ::testing::Test {
 protected:
  void SetUp() override {
    const TriangleMesh mesh = Icosphere(2);
    const FieldOperator op = MustBuildOperator(mesh, FieldType::NField(3));
    BasisOptions options;
    options.params.dimension = 31;
    options.params.sigma = 12.5;
    options.params.seed = 99;
    options.params.fields_per_region = 3;
    options.params.face_weights = Eigen::VectorXd::LinSpaced(mesh.num_faces(), 1.0, 2.0);
    auto basis = BuildBasis(mesh, op, options);
    ASSERT_TRUE(basis.ok()) << basis.status();
    basis_ = *std::move(basis);
    dir_ = std::filesystem::temp_directory_path() /
           ("fieldspace_basis_io_test_" + std::to_string(::getpid()));
    std::filesystem::create_directories(dir_);
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }

  static void ExpectSame(const Basis& a, const Basis& b) {
    EXPECT_TRUE(a.type == b.type);
    EXPECT_EQ(a.params.dimension, b.params.dimension);
    EXPECT_EQ(a.params.sigma, b.params.sigma);
    EXPECT_EQ(a.params.seed, b.params.seed);
    EXPECT_EQ(a.params.fields_per_region, b.params.fields_per_region);
    EXPECT_EQ(a.params.face_weights, b.params.face_weights);
    EXPECT_EQ(a.radius, b.radius);
    EXPECT_EQ(a.coverage_radius, b.coverage_radius);
    EXPECT_EQ(a.sample_faces, b.sample_faces);
    EXPECT_EQ(a.local_eigenvalues, b.local_eigenvalues);
    EXPECT_EQ(a.timings.total_seconds, b.timings.total_seconds);
    EXPECT_EQ(a.stats.lobpcg_iterations, b.stats.lobpcg_iterations);
    ASSERT_EQ(a.U.rows(), b.U.rows());
    ASSERT_EQ(a.U.cols(), b.U.cols());
    ASSERT_EQ(a.U.nonZeros(), b.U.nonZeros());
    EXPECT_TRUE(
        std::equal(a.U.outerIndexPtr(), a.U.outerIndexPtr() + a.U.rows() + 1, b.U.outerIndexPtr()));
    EXPECT_TRUE(
        std::equal(a.U.innerIndexPtr(), a.U.innerIndexPtr() + a.U.nonZeros(), b.U.innerIndexPtr()));
    EXPECT_TRUE(std::equal(a.U.valuePtr(), a.U.valuePtr() + a.U.nonZeros(), b.U.valuePtr()));
  }

  std::string ReadFile(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    return std::string(std::istreambuf_iterator<char>(in), {});
  }
  void WriteFile(const std::string& path, const std::string& bytes) {
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  }

  Basis basis_;
  std::filesystem::path dir_;
};

TEST_F(BasisIoTest, RoundTripInMemoryAndOnDisk) {
  auto bytes = EncodeBasis(basis_, "mesh:abc123");
  ASSERT_TRUE(bytes.ok()) << bytes.status();
  auto decoded = DecodeBasis(*bytes);
  ASSERT_TRUE(decoded.ok()) << decoded.status();
  EXPECT_EQ(decoded->mesh_id, "mesh:abc123");
  ExpectSame(basis_, decoded->basis);

  const std::string path = (dir_ / "b.fsb").string();
  ASSERT_TRUE(SaveBasisFile(path, basis_, "mesh:abc123").ok());
  EXPECT_EQ(ReadFile(path), *bytes);  // same bytes through both paths
  auto loaded = LoadBasisFile(path);
  ASSERT_TRUE(loaded.ok()) << loaded.status();
  ExpectSame(basis_, loaded->basis);
  auto info = ReadBasisFileInfo(path);
  ASSERT_TRUE(info.ok());
  EXPECT_EQ(info->mesh_id, "mesh:abc123");
  EXPECT_EQ(info->params.dimension, 31);
  EXPECT_EQ(info->nnz, basis_.U.nonZeros());
  EXPECT_EQ(info->num_weights, basis_.params.face_weights.size());
  EXPECT_EQ(info->file_bytes, static_cast<int64_t>(bytes->size()));
  // Overwriting keeps working; no temporary files are left behind.
  ASSERT_TRUE(SaveBasisFile(path, basis_, "other").ok());
  EXPECT_EQ(LoadBasisFile(path)->mesh_id, "other");
  EXPECT_EQ(std::distance(std::filesystem::directory_iterator(dir_), {}), 1);
}

// The pieces a daemon saves are EncodeBasis's bytes, U's arrays referenced in place (not copied),
// also for a U that is not compressed (encoded whole then).
TEST_F(BasisIoTest, PiecesAreTheEncodedBytesWithUReferencedInPlace) {
  auto bytes = EncodeBasis(basis_, "mesh:abc123");
  ASSERT_TRUE(bytes.ok()) << bytes.status();
  std::deque<std::string> storage;
  auto pieces = EncodeBasisPieces(basis_, "mesh:abc123", &storage);
  ASSERT_TRUE(pieces.ok()) << pieces.status();
  std::string joined;
  bool values_in_place = false, columns_in_place = false;
  for (std::string_view piece : *pieces) {
    joined.append(piece);
    values_in_place |= piece.data() == reinterpret_cast<const char*>(basis_.U.valuePtr());
    columns_in_place |= piece.data() == reinterpret_cast<const char*>(basis_.U.innerIndexPtr());
  }
  EXPECT_EQ(joined, *bytes);
  EXPECT_TRUE(values_in_place);
  EXPECT_TRUE(columns_in_place);
  size_t stored = 0;
  for (const std::string& s : storage) stored += s.size();
  EXPECT_LT(stored, bytes->size() / 4);

  Basis uncompressed = basis_;
  uncompressed.U.uncompress();
  ASSERT_FALSE(uncompressed.U.isCompressed());
  std::deque<std::string> whole;
  auto one = EncodeBasisPieces(uncompressed, "mesh:abc123", &whole);
  ASSERT_TRUE(one.ok()) << one.status();
  ASSERT_EQ(one->size(), 1u);
  EXPECT_EQ((*one)[0], *bytes);
}

TEST_F(BasisIoTest, EveryFlippedByteIsDetected) {
  auto bytes = EncodeBasis(basis_, "id");
  ASSERT_TRUE(bytes.ok());
  const std::string original = *bytes;
  // Every byte of the preamble and header and the first/last bytes of every section, plus a
  // stride through the payload.
  for (size_t i = 0; i < original.size(); i += (i < 512 || i + 512 > original.size()) ? 1 : 37) {
    std::string damaged = original;
    damaged[i] = static_cast<char>(damaged[i] ^ 0x5A);
    auto r = DecodeBasis(damaged);
    ASSERT_FALSE(r.ok()) << "byte " << i;
    EXPECT_THAT(r, StatusIs(absl::StatusCode::kDataLoss)) << "byte " << i << r.status();
  }
  const std::string path = (dir_ / "flip.fsb").string();
  std::string damaged = original;
  damaged[original.size() / 2] ^= 1;
  WriteFile(path, damaged);
  EXPECT_THAT(LoadBasisFile(path), StatusIs(absl::StatusCode::kDataLoss));
}

// Found by the store fuzzer: intact checksums, no nonzeros, and row pointers 0, 5, 0, ..., 0.
// The structure check read the first row's five columns from the empty arrays before it saw the
// pointers decrease; every pointer is now checked before any column.
TEST_F(BasisIoTest, RowPointersPastTheEndAreDataLossNotARead) {
  Basis b = basis_;
  b.U.resize(basis_.U.rows(), basis_.U.cols());
  b.U.resizeNonZeros(0);
  b.U.outerIndexPtr()[1] = 5;
  auto bytes = EncodeBasis(b, "mesh");
  ASSERT_TRUE(bytes.ok()) << bytes.status();
  EXPECT_THAT(DecodeBasis(*bytes), StatusIs(absl::StatusCode::kDataLoss));
}

// What DecodeBasis sends a BasisRowsSink.
struct RecordingSink final : BasisRowsSink {
  void Begin(int64_t r, int64_t c, int32_t p, const std::vector<int32_t>& pointers) override {
    ++begun;
    rows = r;
    cols = c;
    dofs_per_face = p;
    outer = pointers;
  }
  void AddColumns(const int32_t* c, int64_t n) override { columns.insert(columns.end(), c, c + n); }
  void AddValues(const float* v, int64_t n) override { values.insert(values.end(), v, v + n); }
  // Every column it got in range and ascending within its row, every value finite.
  bool AllChecked() const {
    for (int64_t r = 0; r + 1 < static_cast<int64_t>(outer.size()); ++r) {
      for (int64_t q = outer[r]; q < outer[r + 1] && q < static_cast<int64_t>(columns.size());
           ++q) {
        if (columns[q] < 0 || columns[q] >= cols || (q > outer[r] && columns[q] <= columns[q - 1]))
          return false;
      }
    }
    return std::all_of(values.begin(), values.end(), [](float v) { return std::isfinite(v); });
  }
  int begun = 0;
  int64_t rows = 0, cols = 0;
  int32_t dofs_per_face = 0;
  std::vector<int32_t> outer, columns;
  std::vector<float> values;
};

// A daemon's load (LiftPlan::StreamBuilder as the sink): U's arrays go to the sink as stored,
// the basis keeps U's dimensions only, and a damaged file is the same DataLoss as without a sink,
// the sink never having got a column or value that failed the checks.
TEST_F(BasisIoTest, RowsStreamedToASink) {
  auto bytes = EncodeBasis(basis_, "mesh:abc");
  ASSERT_TRUE(bytes.ok()) << bytes.status();
  RecordingSink sink;
  auto decoded = DecodeBasis(*bytes, sink);
  ASSERT_TRUE(decoded.ok()) << decoded.status();
  EXPECT_EQ(decoded->mesh_id, "mesh:abc");
  Basis without_rows = basis_;
  without_rows.U.resize(basis_.U.rows(), basis_.U.cols());
  without_rows.U.makeCompressed();
  ExpectSame(without_rows, decoded->basis);
  EXPECT_EQ(sink.begun, 1);
  EXPECT_EQ(sink.rows, basis_.U.rows());
  EXPECT_EQ(sink.cols, basis_.U.cols());
  EXPECT_EQ(sink.dofs_per_face, 2);
  const auto& U = basis_.U;
  EXPECT_EQ(sink.outer, std::vector<int32_t>(U.outerIndexPtr(), U.outerIndexPtr() + U.rows() + 1));
  EXPECT_EQ(sink.columns,
            std::vector<int32_t>(U.innerIndexPtr(), U.innerIndexPtr() + U.nonZeros()));
  EXPECT_EQ(sink.values, std::vector<float>(U.valuePtr(), U.valuePtr() + U.nonZeros()));

  const std::string original = *bytes;
  for (size_t i = 0; i < original.size(); i += (i < 512 || i + 512 > original.size()) ? 1 : 37) {
    std::string damaged = original;
    damaged[i] = static_cast<char>(damaged[i] ^ 0x5A);
    RecordingSink got;
    EXPECT_THAT(DecodeBasis(damaged, got), StatusIs(absl::StatusCode::kDataLoss)) << "byte " << i;
    EXPECT_TRUE(got.AllChecked()) << "byte " << i;
  }
  // Checksummed but wrong: row pointers past the end (no Begin), a column out of range, a NaN.
  const auto expect_refused = [&](const Basis& b, const char* what, int begun) {
    auto encoded = EncodeBasis(b, "mesh");
    ASSERT_TRUE(encoded.ok()) << encoded.status();
    EXPECT_THAT(DecodeBasis(*encoded), StatusIs(absl::StatusCode::kDataLoss)) << what;
    RecordingSink got;
    auto r = DecodeBasis(*encoded, got);
    EXPECT_THAT(r, StatusIs(absl::StatusCode::kDataLoss)) << what;
    EXPECT_EQ(r.status().message(), DecodeBasis(*encoded).status().message()) << what;
    EXPECT_EQ(got.begun, begun) << what;
    EXPECT_TRUE(got.AllChecked()) << what;
  };
  Basis past_end = basis_;
  past_end.U.resize(basis_.U.rows(), basis_.U.cols());
  past_end.U.resizeNonZeros(0);
  past_end.U.outerIndexPtr()[1] = 5;
  expect_refused(past_end, "row pointers", 0);
  Basis bad_column = basis_;
  bad_column.U.innerIndexPtr()[bad_column.U.nonZeros() / 2] = static_cast<int32_t>(U.cols());
  expect_refused(bad_column, "column", 1);
  Basis nan = basis_;
  nan.U.valuePtr()[7] = std::numeric_limits<float>::quiet_NaN();
  expect_refused(nan, "NaN", 1);
}

TEST_F(BasisIoTest, TruncatedAndExtendedFilesAreDetected) {
  auto bytes = EncodeBasis(basis_, "id");
  ASSERT_TRUE(bytes.ok());
  for (size_t len : {size_t{0}, size_t{5}, size_t{31}, size_t{32}, size_t{100}, bytes->size() / 2,
                     bytes->size() - 1}) {
    auto r = DecodeBasis(std::string_view(*bytes).substr(0, len));
    EXPECT_THAT(r, StatusIs(absl::StatusCode::kDataLoss)) << len;
  }
  EXPECT_THAT(DecodeBasis(*bytes + "x"), StatusIs(absl::StatusCode::kDataLoss));
  const std::string path = (dir_ / "trunc.fsb").string();
  WriteFile(path, bytes->substr(0, bytes->size() - 10));
  auto r = LoadBasisFile(path);
  EXPECT_THAT(r, StatusIs(absl::StatusCode::kDataLoss));
  EXPECT_NE(r.status().message().find("truncated"), std::string::npos) << r.status();
  // A foreign file.
  WriteFile(path, std::string(1000, 'z'));
  EXPECT_THAT(LoadBasisFile(path), StatusIs(absl::StatusCode::kDataLoss));
  EXPECT_THAT(ReadBasisFileInfo(path), StatusIs(absl::StatusCode::kDataLoss));
}

TEST_F(BasisIoTest, FileSystemErrors) {
  EXPECT_THAT(LoadBasisFile((dir_ / "missing.fsb").string()),
              StatusIs(absl::StatusCode::kNotFound));
  EXPECT_THAT(SaveBasisFile((dir_ / "no_such_dir" / "b.fsb").string(), basis_, "id"),
              StatusIs(absl::StatusCode::kNotFound));
  Basis empty;
  EXPECT_THAT(EncodeBasis(empty, "id"), StatusIs(absl::StatusCode::kInvalidArgument));
}

}  // namespace
}  // namespace fieldspace
