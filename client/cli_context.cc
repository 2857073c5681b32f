#include "client/cli_context.h"

#include <filesystem>

#include "absl/strings/ascii.h"
#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "client/cli_flags.h"
#include "client/cli_json.h"

namespace fieldspace::client::cli {
namespace {

namespace v1 = ::fieldspace::v1;

// The extension of `path`, lower case, with its dot ("" when it has none).
std::string Extension(const std::string& path) {
  return absl::AsciiStrToLower(std::filesystem::path(path).extension().string());
}

}  // namespace

int Cli::Fail(const absl::Status& status, const std::string& what) {
  err_ << "fieldspace: " << what << " failed: " << absl::StatusCodeToString(status.code()) << ": "
       << status.message() << "\n";
  // A plaintext client at a TLS port: the server closes the connection at the first bytes.
  if (!options_.tls.has_value() && absl::IsUnavailable(status) &&
      absl::StrContains(status.message(), "Socket closed")) {
    err_ << "fieldspace: the server closed the connection at once: if it speaks TLS "
            "(fieldspaced --tls-cert), pass --tls-ca FILE (the CA of its certificate)\n";
  }
  return 1;
}

int Cli::FailLocal(const absl::Status& status) {
  err_ << "fieldspace: " << status.message() << "\n";
  return 1;
}

std::string Cli::GlobalFlags() const {
  std::string flags = absl::StrCat("--server ", options_.address);
  if (!token_file_.empty()) absl::StrAppend(&flags, " --token ", token_file_);
  for (const auto& [flag, value] : tls_flags_) absl::StrAppend(&flags, " --", flag, " ", value);
  return flags;
}

void Cli::Connect() {
  absl::StatusOr<std::unique_ptr<FieldClient>> client = FieldClient::Create(options_);
  if (!client.ok()) throw UsageError(std::string(client.status().message()));
  client_ = *std::move(client);
}

void Cli::CheckFieldOut(const std::string& path) {
  const std::string ext = Extension(path);
  if (ext == ".txt" || ext == ".ply") return;
  std::string message = absl::StrCat(
      "--out ", path, ": a field file is .txt (text, one face per line) or .ply (the mesh with ",
      "the field as face properties)");
  if (ext == ".vtu" || ext == ".vtk" || ext == ".rawfield") {
    absl::StrAppend(&message, "; for ", ext, " write a .txt and convert it: fieldspace export ",
                    "MESH FILE.txt --out FILE", ext);
  } else if (ext == ".png" || ext == ".jpg" || ext == ".jpeg") {
    absl::StrAppend(&message, "; for a picture write a .txt and run: fieldspace render MESH ",
                    "FILE.txt --out FILE.png");
  }
  throw UsageError(message);
}

int Cli::WriteFieldOut(const std::string& path, const FieldFile& field,
                       const std::string& field_type, const std::string& mesh_id) {
  CheckFieldOut(path);
  absl::Status written;
  if (Extension(path) == ".ply") {
    v1::GetMeshGeometryRequest request;
    request.set_mesh_id(mesh_id);
    absl::StatusOr<MeshGeometry> geometry = client_->GetMeshGeometry(request);
    if (!geometry.ok()) return Fail(geometry.status(), "GetMeshGeometry");
    written = WriteFieldPly(path, geometry->vertices, geometry->faces, field);
  } else {
    written = WriteFieldText(path, field, field_type);
  }
  return written.ok() ? 0 : FailLocal(written);
}

int Cli::LiftToFile(const std::string& basis_id, const std::vector<double>& coefficients,
                    v1::FieldEncoding encoding, const std::string& path) {
  v1::GetBasisRequest basis_request;
  basis_request.set_basis_id(basis_id);
  absl::StatusOr<v1::BasisInfo> basis = client_->GetBasis(basis_request);
  if (!basis.ok()) return Fail(basis.status(), "GetBasis");

  v1::LiftRequest request;
  request.set_basis_id(basis_id);
  request.mutable_coefficients()->Add(coefficients.begin(), coefficients.end());
  request.set_encoding(encoding);
  absl::StatusOr<std::vector<v1::FieldChunk>> chunks = client_->Lift(request);
  if (!chunks.ok()) return Fail(chunks.status(), "Lift");
  FieldFile field;
  field.encoding = encoding;
  const bool tensor = basis->field().kind() == v1::FIELD_KIND_TENSOR;
  field.values_per_face =
      encoding == v1::FIELD_ENCODING_AMBIENT ? (tensor ? 6 : 3) : (tensor ? 3 : 2);
  for (const v1::FieldChunk& chunk : *chunks) {
    if (chunk.start_face() != field.num_faces()) {
      return Fail(absl::DataLossError("Lift chunks arrived out of order"), "Lift");
    }
    if (field.values.empty()) {
      field.values.reserve(static_cast<size_t>(chunk.total_faces()) * field.values_per_face);
    }
    const auto& values = chunk.field().values();
    field.values.insert(field.values.end(), values.begin(), values.end());
  }
  return WriteFieldOut(path, field, FieldKindName(basis->field()), basis->mesh_id());
}

int Cli::LiftToOut(const CommandLine& a, const std::string& basis_id,
                   const std::vector<double>& coefficients) {
  if (!a.Has("out")) return 0;
  return LiftToFile(basis_id, coefficients, ParseEncoding(a), GetString(a, "out"));
}

}  // namespace fieldspace::client::cli
