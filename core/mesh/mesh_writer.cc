#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <limits>
#include <string>
#include <vector>

#include "absl/strings/ascii.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/string_view.h"
#include "core/common/file_util.h"
#include "core/common/status_macros.h"
#include "core/mesh/mesh_io.h"
#include "core/mesh/mesh_tokenizer.h"

// WritePly (mesh_io.h): binary little-endian PLY through an atomic file writer.

namespace fieldspace {
namespace {

using mesh_io_internal::kMaxIndex;
using mesh_io_internal::Quote;

// ---------------------------------------------------------------------------------------------
// Files

// Little-endian output through a fixed buffer, flushed into an atomic file writer.
class BinaryWriter {
 public:
  explicit BinaryWriter(AtomicFileWriter& out) : out_(out) { buffer_.reserve(kCapacity); }

  template <typename T>
  void Put(T value) {
    if constexpr (sizeof(T) > 1 && std::endian::native == std::endian::big) {
      char bytes[sizeof(T)];
      std::memcpy(bytes, &value, sizeof(T));
      std::reverse(bytes, bytes + sizeof(T));
      PutBytes(bytes, sizeof(T));
    } else {
      PutBytes(&value, sizeof(T));
    }
  }

  void PutBytes(const void* data, size_t n) {
    if (buffer_.size() + n > kCapacity) Flush().IgnoreError();
    buffer_.append(static_cast<const char*>(data), n);
  }

  // The status of the first failed write (later writes are skipped).
  absl::Status Flush() {
    if (status_.ok()) status_ = out_.Append(buffer_);
    buffer_.clear();
    return status_;
  }

 private:
  static constexpr size_t kCapacity = size_t{1} << 20;
  AtomicFileWriter& out_;
  absl::Status status_;
  std::string buffer_;
};

bool IsValidPropertyName(absl::string_view name) {
  if (name.empty()) return false;
  for (char c : name) {
    if (!absl::ascii_isgraph(static_cast<unsigned char>(c))) return false;
  }
  return true;
}

}  // namespace

absl::Status WritePly(const std::string& path, const VertexMatrix& V, const FaceMatrix& F,
                      const std::vector<FaceProperty>& face_properties) {
  const int64_t num_vertices = V.rows();
  const int64_t num_faces = F.rows();
  if (num_vertices > kMaxIndex) {
    return absl::InvalidArgumentError(absl::StrCat("WritePly: ", num_vertices, " vertices"));
  }
  for (int64_t f = 0; f < num_faces; ++f) {
    for (int k = 0; k < 3; ++k) {
      if (F(f, k) < 0 || F(f, k) >= num_vertices) {
        return absl::InvalidArgumentError(absl::StrCat("WritePly: face ", f, " has vertex index ",
                                                       F(f, k), " outside [0, ", num_vertices,
                                                       ")"));
      }
    }
  }
  // Coordinates are stored as float: a value the float cannot hold would come back as inf.
  constexpr double kFloatMax = std::numeric_limits<float>::max();
  for (int64_t i = 0; i < num_vertices; ++i) {
    for (int k = 0; k < 3; ++k) {
      if (!(std::abs(V(i, k)) <= kFloatMax)) {
        return absl::InvalidArgumentError(absl::StrCat("WritePly: vertex ", i, " coordinate ",
                                                       V(i, k), " is not a finite float"));
      }
    }
  }
  for (size_t i = 0; i < face_properties.size(); ++i) {
    const FaceProperty& prop = face_properties[i];
    if (!IsValidPropertyName(prop.name) || prop.name == "vertex_indices" ||
        prop.name == "vertex_index") {
      return absl::InvalidArgumentError(
          absl::StrCat("WritePly: invalid face property name ", Quote(prop.name)));
    }
    for (size_t j = 0; j < i; ++j) {
      if (face_properties[j].name == prop.name) {
        return absl::InvalidArgumentError(
            absl::StrCat("WritePly: duplicate face property ", Quote(prop.name)));
      }
    }
    if (static_cast<int64_t>(prop.values.size()) != num_faces) {
      return absl::InvalidArgumentError(absl::StrCat("WritePly: face property ", Quote(prop.name),
                                                     " has ", prop.values.size(), " values for ",
                                                     num_faces, " faces"));
    }
  }

  std::string header =
      absl::StrCat("ply\nformat binary_little_endian 1.0\ncomment fieldspace\n", "element vertex ",
                   num_vertices, "\nproperty float x\nproperty float y\nproperty float z\n",
                   "element face ", num_faces, "\nproperty list uchar int vertex_indices\n");
  for (const FaceProperty& prop : face_properties) {
    absl::StrAppend(&header, "property float ", prop.name, "\n");
  }
  header += "end_header\n";

  // A temporary file next to `path`, renamed over it once complete.
  AtomicWriteOptions write_options;
  write_options.mode = 0666;
  ASSIGN_OR_RETURN(AtomicFileWriter file, AtomicFileWriter::Create(path, std::move(write_options)));
  BinaryWriter out(file);
  out.PutBytes(header.data(), header.size());
  for (int64_t i = 0; i < num_vertices; ++i) {
    for (int k = 0; k < 3; ++k) out.Put(static_cast<float>(V(i, k)));
  }
  for (int64_t f = 0; f < num_faces; ++f) {
    out.Put(uint8_t{3});
    for (int k = 0; k < 3; ++k) out.Put(F(f, k));
    for (const FaceProperty& prop : face_properties) out.Put(prop.values[f]);
  }
  RETURN_IF_ERROR(out.Flush());
  return file.Commit();
}

}  // namespace fieldspace
