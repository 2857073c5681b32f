#include "core/linalg/matrix_market.h"

#include <algorithm>
#include <cerrno>
#include <charconv>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <memory>
#include <sstream>
#include <string_view>
#include <vector>

#include "absl/strings/ascii.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_split.h"
#include "absl/strings/string_view.h"
#include "core/common/file_util.h"
#include "core/linalg/sparse_checks.h"
#include "tbb/parallel_for.h"

namespace fieldspace {
namespace {

using SpMat = Eigen::SparseMatrix<double>;

// Entries formatted per batch; at ~40 bytes per line a batch is ~160 MB of text at most.
constexpr int64_t kBatchEntries = int64_t{1} << 22;
constexpr int64_t kChunkEntries = int64_t{1} << 16;

struct FileCloser {
  void operator()(std::FILE* f) const {
    if (f != nullptr) std::fclose(f);
  }
};

// Appends "row col value\n" (1-based) to `out`.
inline void AppendEntry(int64_t row, int64_t col, double value, std::string* out) {
  char buf[32];  // a 64-bit integer needs <= 20 characters, %.17g <= 24
  out->append(buf, std::to_chars(buf, buf + sizeof(buf), row + 1).ptr);
  out->push_back(' ');
  out->append(buf, std::to_chars(buf, buf + sizeof(buf), col + 1).ptr);
  out->push_back(' ');
  // Same digits as printf("%.17g"): the standard defines to_chars with a precision that way.
  out->append(buf,
              std::to_chars(buf, buf + sizeof(buf), value, std::chars_format::general, 17).ptr);
  out->push_back('\n');
}

// Writes the header and all entries: `column_start` (cols + 1) delimits each column's entry
// range, `entry(e, &row, &value)` yields entry e.
template <typename Entry>
absl::Status WriteCoordinate(const std::string& path, int64_t rows, int64_t cols, int64_t nnz,
                             const std::vector<int64_t>& column_start, Entry entry) {
  std::unique_ptr<std::FILE, FileCloser> file(std::fopen(path.c_str(), "wb"));
  if (file == nullptr) return ErrnoStatus(errno, absl::StrFormat("cannot create %s", path));
  const std::string header = absl::StrFormat(
      "%%%%MatrixMarket matrix coordinate real general\n%d %d %d\n", rows, cols, nnz);
  if (std::fwrite(header.data(), 1, header.size(), file.get()) != header.size()) {
    return ErrnoStatus(errno, absl::StrFormat("cannot write %s", path));
  }
  // Entry index ranges [e0, e1) of the chunks; each chunk is formatted by one task.
  for (int64_t batch_begin = 0; batch_begin < nnz; batch_begin += kBatchEntries) {
    const int64_t batch_end = std::min(nnz, batch_begin + kBatchEntries);
    const int64_t chunks = (batch_end - batch_begin + kChunkEntries - 1) / kChunkEntries;
    std::vector<std::string> text(chunks);
    tbb::parallel_for(int64_t{0}, chunks, [&](int64_t c) {
      const int64_t e0 = batch_begin + c * kChunkEntries;
      const int64_t e1 = std::min(batch_end, e0 + kChunkEntries);
      std::string& out = text[c];
      out.reserve(static_cast<size_t>(e1 - e0) * 44);
      // Column of entry e0: last column whose start is <= e0 (skipping empty columns).
      int64_t j =
          std::upper_bound(column_start.begin(), column_start.end(), e0) - column_start.begin() - 1;
      for (int64_t e = e0; e < e1; ++e) {
        while (column_start[j + 1] <= e) ++j;
        int64_t row;
        double value;
        entry(e, &row, &value);
        AppendEntry(row, j, value, &out);
      }
    });
    for (const std::string& t : text) {
      if (std::fwrite(t.data(), 1, t.size(), file.get()) != t.size()) {
        return ErrnoStatus(errno, absl::StrFormat("cannot write %s", path));
      }
    }
  }
  std::FILE* raw = file.release();
  if (std::fclose(raw) != 0) return ErrnoStatus(errno, absl::StrFormat("cannot write %s", path));
  return absl::OkStatus();
}

}  // namespace

absl::Status WriteMatrixMarket(const std::string& path, const SpMat& A_in) {
  SpMat compressed;
  const SpMat* A = &CompressedOrCopy(A_in, &compressed);
  std::vector<int64_t> column_start(A->cols() + 1);
  for (Eigen::Index j = 0; j <= A->cols(); ++j) column_start[j] = A->outerIndexPtr()[j];
  const int* inner = A->innerIndexPtr();
  const double* values = A->valuePtr();
  return WriteCoordinate(path, A->rows(), A->cols(), A->nonZeros(), column_start,
                         [&](int64_t e, int64_t* row, double* value) {
                           *row = inner[e];
                           *value = values[e];
                         });
}

absl::Status WriteMatrixMarketDiagonal(const std::string& path, const Eigen::VectorXd& d) {
  std::vector<int64_t> column_start(d.size() + 1);
  for (Eigen::Index j = 0; j <= d.size(); ++j) column_start[j] = j;
  return WriteCoordinate(path, d.size(), d.size(), d.size(), column_start,
                         [&](int64_t e, int64_t* row, double* value) {
                           *row = e;
                           *value = d[e];
                         });
}

namespace {

// Parses `path` into *A (see ReadMatrixMarket).
absl::Status ParseMatrixMarket(const std::string& path, SpMat* A) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) {
    return absl::NotFoundError(absl::StrFormat("%s: no such file", path));
  }
  std::ifstream in(path, std::ios::binary);
  if (!in) return ErrnoStatus(errno, absl::StrFormat("cannot open %s", path));
  std::stringstream buffer;
  buffer << in.rdbuf();
  const std::string data = buffer.str();
  std::vector<absl::string_view> lines = absl::StrSplit(data, '\n');

  auto error = [&](size_t line, const std::string& what) {
    return absl::InvalidArgumentError(absl::StrFormat("%s:%d: %s", path, line + 1, what));
  };
  if (lines.empty()) return error(0, "empty file");
  std::vector<std::string> header = absl::StrSplit(
      absl::AsciiStrToLower(absl::StripAsciiWhitespace(lines[0])), ' ', absl::SkipEmpty());
  if (header.size() != 5 || header[0] != "%%matrixmarket" || header[1] != "matrix" ||
      header[2] != "coordinate") {
    return error(0, "expected '%%MatrixMarket matrix coordinate FIELD SYMMETRY'");
  }
  if (header[3] != "real" && header[3] != "integer") {
    return error(0, "field must be real or integer, got '" + header[3] + "'");
  }
  const bool symmetric = header[4] == "symmetric";
  if (!symmetric && header[4] != "general") {
    return error(0, "symmetry must be general or symmetric, got '" + header[4] + "'");
  }

  // Parses whitespace-separated numbers of one line.
  auto parse_line = [](absl::string_view line, auto* a, auto* b, auto* c) -> bool {
    const char* p = line.data();
    const char* end = line.data() + line.size();
    auto skip = [&] {
      while (p < end && (*p == ' ' || *p == '\t' || *p == '\r')) ++p;
    };
    skip();
    auto r1 = std::from_chars(p, end, *a);
    if (r1.ec != std::errc()) return false;
    p = r1.ptr;
    skip();
    auto r2 = std::from_chars(p, end, *b);
    if (r2.ec != std::errc()) return false;
    p = r2.ptr;
    skip();
    auto r3 = std::from_chars(p, end, *c);
    if (r3.ec != std::errc()) return false;
    p = r3.ptr;
    skip();
    return p == end;
  };

  size_t li = 1;
  auto is_blank_or_comment = [](absl::string_view l) {
    l = absl::StripAsciiWhitespace(l);
    return l.empty() || l[0] == '%';
  };
  while (li < lines.size() && is_blank_or_comment(lines[li])) ++li;
  if (li >= lines.size()) return error(li - 1, "missing size line");
  int64_t rows = 0, cols = 0, nnz = 0;
  if (!parse_line(lines[li], &rows, &cols, &nnz) || rows < 0 || cols < 0 || nnz < 0) {
    return error(li, "expected 'rows cols entries'");
  }
  if (rows > INT32_MAX || cols > INT32_MAX || nnz > (int64_t{1} << 40)) {
    return error(li, "matrix too large");
  }
  ++li;
  std::vector<Eigen::Triplet<double>> triplets;
  triplets.reserve(static_cast<size_t>(std::min<int64_t>(nnz, int64_t{1} << 26)) *
                   (symmetric ? 2 : 1));
  int64_t read = 0;
  for (; li < lines.size(); ++li) {
    if (is_blank_or_comment(lines[li])) continue;
    if (read == nnz) return error(li, "more entries than declared");
    int64_t r = 0, c = 0;
    double v = 0;
    if (!parse_line(lines[li], &r, &c, &v)) return error(li, "expected 'row col value'");
    if (r < 1 || r > rows || c < 1 || c > cols) {
      return error(li, absl::StrFormat("entry (%d, %d) outside %d x %d", r, c, rows, cols));
    }
    triplets.emplace_back(r - 1, c - 1, v);
    if (symmetric && r != c) triplets.emplace_back(c - 1, r - 1, v);
    ++read;
  }
  if (read != nnz) {
    return error(lines.size() - 1, absl::StrFormat("file ends after %d of %d entries", read, nnz));
  }
  A->resize(rows, cols);
  A->setFromTriplets(triplets.begin(), triplets.end());
  return absl::OkStatus();
}

}  // namespace

absl::StatusOr<SpMat> ReadMatrixMarket(const std::string& path) {
  // One named result returned on every path (NRVO): Eigen sparse matrices have no move
  // operations, so returning a local matrix through StatusOr would copy it.
  absl::StatusOr<SpMat> result(absl::in_place);
  if (absl::Status status = ParseMatrixMarket(path, &*result); !status.ok()) result = status;
  return result;
}

}  // namespace fieldspace
