// The CLI's mesh commands: health, upload, load, meshes, mesh, delete-mesh.

#include <cerrno>
#include <fstream>

#include "absl/status/status.h"
#include "absl/strings/ascii.h"
#include "absl/strings/str_cat.h"
#include "client/cli_commands.h"
#include "client/cli_flags.h"
#include "client/cli_json.h"

namespace fieldspace::client::cli {

namespace v1 = ::fieldspace::v1;

int Health(Cli& cli, const CommandLine& a) {
  absl::StatusOr<grpc::health::v1::HealthCheckResponse> response =
      cli.client().Health(GetString(a, "service"));
  if (!response.ok()) return cli.Fail(response.status(), "health check");
  JsonWriter j;
  j.BeginObject().Key("status").String(
      grpc::health::v1::HealthCheckResponse::ServingStatus_Name(response->status()));
  j.EndObject();
  cli.Emit(j);
  return response->status() == grpc::health::v1::HealthCheckResponse::SERVING ? 0 : 1;
}

int Upload(Cli& cli, const CommandLine& a) {
  const std::string& path = a.positional()[0];
  v1::UploadMeshHeader header = MeshFileHeader(path, GetString(a, "name"));
  if (a.Has("format")) {
    const std::string format = absl::AsciiStrToLower(GetString(a, "format"));
    if (format == "obj") {
      header.set_format(v1::MESH_FORMAT_OBJ);
    } else if (format == "off") {
      header.set_format(v1::MESH_FORMAT_OFF);
    } else if (format == "ply") {
      header.set_format(v1::MESH_FORMAT_PLY);
    } else {
      throw UsageError("--format must be obj, off or ply");
    }
  }
  std::ifstream in(path, std::ios::binary);
  if (!in) return cli.FailLocal(absl::ErrnoToStatus(errno, absl::StrCat("cannot open ", path)));
  absl::StatusOr<v1::MeshInfo> info = cli.client().UploadMesh(header, in);
  if (!info.ok()) return cli.Fail(info.status(), "upload of " + path);
  JsonWriter j;
  WriteMeshInfo(j, *info);
  cli.Emit(j);
  return 0;
}

int Load(Cli& cli, const CommandLine& a) {
  v1::LoadMeshRequest request;
  request.set_path(a.positional()[0]);
  request.set_name(GetString(a, "name"));
  absl::StatusOr<v1::MeshInfo> info = cli.client().LoadMesh(request);
  if (!info.ok()) return cli.Fail(info.status(), "LoadMesh");
  JsonWriter j;
  WriteMeshInfo(j, *info);
  cli.Emit(j);
  return 0;
}

int Meshes(Cli& cli, const CommandLine&) {
  absl::StatusOr<v1::ListMeshesResponse> response = cli.client().ListMeshes();
  if (!response.ok()) return cli.Fail(response.status(), "ListMeshes");
  JsonWriter j;
  j.BeginObject().Key("meshes").BeginArray();
  for (const v1::MeshInfo& m : response->meshes()) WriteMeshInfo(j, m);
  j.EndArray().EndObject();
  cli.Emit(j);
  return 0;
}

int Mesh(Cli& cli, const CommandLine& a) {
  v1::GetMeshRequest request;
  request.set_mesh_id(a.positional()[0]);
  absl::StatusOr<v1::MeshInfo> info = cli.client().GetMesh(request);
  if (!info.ok()) return cli.Fail(info.status(), "GetMesh");
  JsonWriter j;
  WriteMeshInfo(j, *info);
  cli.Emit(j);
  return 0;
}

int DeleteMesh(Cli& cli, const CommandLine& a) {
  v1::DeleteMeshRequest request;
  request.set_mesh_id(a.positional()[0]);
  request.set_cascade(a.Has("cascade"));
  absl::StatusOr<v1::DeleteMeshResponse> response = cli.client().DeleteMesh(request);
  if (!response.ok()) return cli.Fail(response.status(), "DeleteMesh");
  JsonWriter j;
  j.BeginObject().Key("deleted").String(request.mesh_id()).Key("deleted_basis_ids").BeginArray();
  for (const std::string& id : response->deleted_basis_ids()) j.String(id);
  j.EndArray().EndObject();
  cli.Emit(j);
  return 0;
}

}  // namespace fieldspace::client::cli
