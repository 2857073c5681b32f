#include "core/mesh/mesh_io.h"

#include <string>
#include <string_view>
#include <utility>

#include "absl/strings/ascii.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/string_view.h"
#include "core/common/file_util.h"
#include "core/common/status_macros.h"
#include "core/mesh/mesh_tokenizer.h"

// The readers' entry points: format from a file name, and the dispatch to obj_reader.cc,
// off_reader.cc and ply_reader.cc (the writer is mesh_writer.cc).

namespace fieldspace {
namespace {

using mesh_io_internal::ParseObj;
using mesh_io_internal::ParseOff;
using mesh_io_internal::ParsePly;
using mesh_io_internal::Quote;

absl::StatusOr<MeshReadResult> ReadMeshLabeled(absl::string_view data, MeshFormat format,
                                               const MeshReadOptions& options,
                                               absl::string_view label) {
  switch (format) {
    case MeshFormat::kObj:
      return ParseObj(data, options, label);
    case MeshFormat::kOff:
      return ParseOff(data, options, label);
    case MeshFormat::kPly:
      return ParsePly(data, options, label);
  }
  return absl::InvalidArgumentError("unknown mesh format");
}

absl::string_view FormatName(MeshFormat format) {
  switch (format) {
    case MeshFormat::kObj:
      return "OBJ";
    case MeshFormat::kOff:
      return "OFF";
    case MeshFormat::kPly:
      return "PLY";
  }
  return "mesh";
}

}  // namespace

absl::StatusOr<MeshFormat> MeshFormatFromPath(std::string_view path_in) {
  const absl::string_view path(path_in.data(), path_in.size());
  const size_t slash = path.find_last_of('/');
  const absl::string_view name = slash == absl::string_view::npos ? path : path.substr(slash + 1);
  const size_t dot = name.find_last_of('.');
  if (dot != absl::string_view::npos) {
    const std::string ext = absl::AsciiStrToLower(name.substr(dot + 1));
    if (ext == "obj") return MeshFormat::kObj;
    if (ext == "off") return MeshFormat::kOff;
    if (ext == "ply") return MeshFormat::kPly;
  }
  return absl::InvalidArgumentError(absl::StrCat("cannot tell the mesh format of ", Quote(path),
                                                 ": expected extension .obj, .off or .ply"));
}

absl::StatusOr<MeshReadResult> ReadMesh(std::string_view data, MeshFormat format,
                                        const MeshReadOptions& options) {
  return ReadMeshLabeled(absl::string_view(data.data(), data.size()), format, options,
                         FormatName(format));
}

absl::StatusOr<MeshReadResult> ReadMeshFile(const std::string& path,
                                            const MeshReadOptions& options) {
  RETURN_IF_ERROR(MeshFormatFromPath(path).status());  // an unknown extension before opening
  ASSIGN_OR_RETURN(ReadableFile file, OpenForReading(path));
  return ReadMeshFile(std::move(file), path, options);
}

absl::StatusOr<MeshReadResult> ReadMeshFile(ReadableFile file, const std::string& path,
                                            const MeshReadOptions& options) {
  ASSIGN_OR_RETURN(const MeshFormat format, MeshFormatFromPath(path));
  ASSIGN_OR_RETURN(const std::string data,
                   ReadFileToString(std::move(file), path, options.max_file_bytes));
  const size_t slash = path.find_last_of('/');
  const absl::string_view name = slash == std::string::npos
                                     ? absl::string_view(path)
                                     : absl::string_view(path).substr(slash + 1);
  return ReadMeshLabeled(data, format, options, name);
}

}  // namespace fieldspace
