#include "client/cli.h"

#include <unistd.h>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <memory>
#include <set>

#include "absl/strings/ascii.h"
#include "absl/strings/match.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "client/field_files.h"
#include "client/json.h"
#include "core/common/status_macros.h"
#include "fieldspace/v1/fieldspace.grpc.pb.h"
#include "grpc/health/v1/health.grpc.pb.h"
#include "grpcpp/grpcpp.h"

namespace fieldspace::client {
namespace {

namespace v1 = ::fieldspace::v1;
using Clock = std::chrono::steady_clock;

constexpr char kUsage[] =
    R"(usage: fieldspace --server HOST:PORT [--token FILE] [--timeout SECONDS] COMMAND [ARGS]

commands (JSON on stdout, errors on stderr, non-zero exit on failure):
  health [--service NAME]             grpc.health.v1 status of the server
  upload MESH                         upload an .obj/.off/.ply file; prints MeshInfo ("id")
  meshes                              list meshes
  mesh MESH_ID                        one mesh
  delete-mesh MESH_ID [--cascade]     delete a mesh (with --cascade: and its bases)
  build MESH_ID --field vector|nfield|tensor [--n N] --dim D [--sigma S] [--seed S]
        [--fields-per-region M] [--coarse-dim C]
                                      build a basis: progress on stderr, BasisInfo ("id") on stdout;
                                      C > 0 adds a coarse level of C of the D columns
  bases [--mesh MESH_ID]              list bases (and running builds)
  basis BASIS_ID                      one basis
  delete-basis BASIS_ID               delete a basis
  cancel BASIS_ID                     cancel a running build
  project BASIS_ID FIELD_FILE         coefficients and relative error of the projection
  solve BASIS_ID --constraints FILE [--mu-s X] [--mu-b X] [--mu-c X] [--out FIELD_FILE]
        [--encoding ambient|dof]      the model problem with soft/hard constraints
  lift BASIS_ID COEFFS_FILE (--out FIELD_FILE | --faces F1,F2,...) [--encoding ambient|dof]
  eigen BASIS_ID --count K [--coefficients]
  design BASIS_ID --script EDITS.jsonl [--mu-s X] [--mu-b X] [--mu-c X] [--watch F1,F2,...]
        [--no-coefficients]           stream edits; one JSON line per update

FIELD_FILE: text (one face per line; '# encoding: dof' or ambient, the default) or, for output,
.ply (the mesh with the field as face properties). Formats: README.md.
)";

// Command line: positional arguments and --flags (with a value unless listed as boolean).
struct Args {
  std::vector<std::string> positional;
  std::map<std::string, std::string> values;
  std::set<std::string> bools;

  bool Has(const std::string& flag) const {
    return values.count(flag) > 0 || bools.count(flag) > 0;
  }
  std::string Get(const std::string& flag, const std::string& fallback = "") const {
    auto it = values.find(flag);
    return it == values.end() ? fallback : it->second;
  }
};

class UsageError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

Args ParseArgs(const std::vector<std::string>& args, size_t begin,
               const std::set<std::string>& value_flags, const std::set<std::string>& bool_flags) {
  Args out;
  for (size_t i = begin; i < args.size(); ++i) {
    std::string arg = args[i];
    if (arg.rfind("--", 0) != 0 || arg == "--") {
      out.positional.push_back(arg);
      continue;
    }
    std::string value;
    bool inline_value = false;
    if (size_t eq = arg.find('='); eq != std::string::npos) {
      value = arg.substr(eq + 1);
      arg = arg.substr(0, eq);
      inline_value = true;
    }
    if (bool_flags.count(arg) > 0 && !inline_value) {
      out.bools.insert(arg);
    } else if (value_flags.count(arg) > 0) {
      if (!inline_value) {
        if (i + 1 >= args.size()) throw UsageError(arg + " needs a value");
        value = args[++i];
      }
      out.values[arg] = value;
    } else {
      throw UsageError("unknown option " + arg);
    }
  }
  return out;
}

double ParseDouble(const Args& args, const std::string& flag, double fallback) {
  if (!args.Has(flag)) return fallback;
  double v;
  if (!absl::SimpleAtod(args.Get(flag), &v) || !std::isfinite(v)) {
    throw UsageError(flag + " needs a number");
  }
  return v;
}

int64_t ParseInt(const Args& args, const std::string& flag, int64_t fallback) {
  if (!args.Has(flag)) return fallback;
  int64_t v;
  if (!absl::SimpleAtoi(args.Get(flag), &v)) throw UsageError(flag + " needs an integer");
  return v;
}

std::vector<int32_t> ParseFaceList(const std::string& text) {
  std::vector<int32_t> faces;
  for (absl::string_view token : absl::StrSplit(text, ',', absl::SkipEmpty())) {
    int32_t f;
    if (!absl::SimpleAtoi(token, &f))
      throw UsageError("bad face index '" + std::string(token) + "'");
    faces.push_back(f);
  }
  return faces;
}

v1::FieldEncoding ParseEncoding(const Args& args) {
  const std::string e = args.Get("--encoding", "ambient");
  if (e == "ambient") return v1::FIELD_ENCODING_AMBIENT;
  if (e == "dof") return v1::FIELD_ENCODING_DOF;
  throw UsageError("--encoding must be ambient or dof");
}

const char* CodeName(grpc::StatusCode code) {
  switch (code) {
    case grpc::OK:
      return "OK";
    case grpc::CANCELLED:
      return "CANCELLED";
    case grpc::UNKNOWN:
      return "UNKNOWN";
    case grpc::INVALID_ARGUMENT:
      return "INVALID_ARGUMENT";
    case grpc::DEADLINE_EXCEEDED:
      return "DEADLINE_EXCEEDED";
    case grpc::NOT_FOUND:
      return "NOT_FOUND";
    case grpc::ALREADY_EXISTS:
      return "ALREADY_EXISTS";
    case grpc::PERMISSION_DENIED:
      return "PERMISSION_DENIED";
    case grpc::UNAUTHENTICATED:
      return "UNAUTHENTICATED";
    case grpc::RESOURCE_EXHAUSTED:
      return "RESOURCE_EXHAUSTED";
    case grpc::FAILED_PRECONDITION:
      return "FAILED_PRECONDITION";
    case grpc::ABORTED:
      return "ABORTED";
    case grpc::OUT_OF_RANGE:
      return "OUT_OF_RANGE";
    case grpc::UNIMPLEMENTED:
      return "UNIMPLEMENTED";
    case grpc::INTERNAL:
      return "INTERNAL";
    case grpc::UNAVAILABLE:
      return "UNAVAILABLE";
    case grpc::DATA_LOSS:
      return "DATA_LOSS";
    default:
      return "UNKNOWN";
  }
}

std::string FieldKindName(const v1::FieldType& t) {
  switch (t.kind()) {
    case v1::FIELD_KIND_VECTOR:
      return "vector";
    case v1::FIELD_KIND_NFIELD:
      return absl::StrCat("nfield", t.n());
    case v1::FIELD_KIND_TENSOR:
      return "tensor";
    default:
      return "unspecified";
  }
}

const char* PhaseName(v1::BuildPhase phase) {
  switch (phase) {
    case v1::BUILD_PHASE_QUEUED:
      return "queued";
    case v1::BUILD_PHASE_OPERATOR:
      return "operator";
    case v1::BUILD_PHASE_SAMPLING:
      return "sampling";
    case v1::BUILD_PHASE_REGIONS:
      return "regions";
    case v1::BUILD_PHASE_EIGENSOLVE:
      return "eigensolve";
    case v1::BUILD_PHASE_ASSEMBLY:
      return "assembly";
    case v1::BUILD_PHASE_PRECOMPUTE:
      return "precompute";
    case v1::BUILD_PHASE_SAVING:
      return "saving";
    case v1::BUILD_PHASE_DONE:
      return "done";
    default:
      return "unspecified";
  }
}

void WriteMeshInfo(JsonWriter& j, const v1::MeshInfo& m) {
  j.BeginObject();
  j.Key("id").String(m.id());
  j.Key("name").String(m.name());
  j.Key("num_vertices").Int(m.num_vertices());
  j.Key("num_faces").Int(m.num_faces());
  j.Key("num_edges").Int(m.num_edges());
  j.Key("num_components").Int(m.num_components());
  j.Key("num_boundary_loops").Int(m.num_boundary_loops());
  j.Key("euler_characteristic").Int(m.euler_characteristic());
  j.Key("genus").Int(m.genus());
  j.Key("total_area").Number(m.total_area());
  j.Key("dropped_unreferenced_vertices").Int(m.dropped_unreferenced_vertices());
  j.Key("polygons_triangulated").Int(m.polygons_triangulated());
  j.Key("loaded").Bool(m.loaded());
  j.Key("created_unix_ms").Int(m.created_unix_ms());
  j.EndObject();
}

void WriteBasisInfo(JsonWriter& j, const v1::BasisInfo& b) {
  j.BeginObject();
  j.Key("id").String(b.id());
  j.Key("mesh_id").String(b.mesh_id());
  j.Key("field").String(FieldKindName(b.field()));
  j.Key("dimension").Int(b.dimension());
  j.Key("sigma").Number(b.sigma());
  j.Key("fields_per_region").Int(b.fields_per_region());
  j.Key("seed").Int(static_cast<int64_t>(b.seed()));
  j.Key("coarse_dimension").Int(b.coarse_dimension());
  j.Key("adaptive").Bool(b.adaptive());
  j.Key("state").String(b.state() == v1::BASIS_STATE_READY ? "ready" : "building");
  j.Key("dofs").Int(b.dofs());
  if (b.state() == v1::BASIS_STATE_READY) {
    j.Key("columns").Int(b.columns());
    j.Key("num_regions").Int(b.num_regions());
    j.Key("radius").Number(b.radius());
    j.Key("nnz").Int(b.nnz());
    j.Key("build_seconds").Number(b.build_seconds());
    j.Key("loaded").Bool(b.loaded());
    j.Key("memory_bytes").Int(b.memory_bytes());
    j.Key("created_unix_ms").Int(b.created_unix_ms());
  } else {
    j.Key("phase").String(PhaseName(b.phase()));
    j.Key("fraction").Number(b.fraction());
  }
  j.EndObject();
}

template <typename T>
void WriteNumbers(JsonWriter& j, const T& values) {
  j.BeginArray();
  for (double v : values) j.Number(v);
  j.EndArray();
}

class Cli {
 public:
  Cli(std::ostream& out, std::ostream& err) : out_(out), err_(err) {}

  int Run(const std::vector<std::string>& args);

 private:
  // Global options up to the command; returns the command's index.
  size_t ParseGlobal(const std::vector<std::string>& args);
  void Connect();
  std::unique_ptr<grpc::ClientContext> Context(bool with_deadline = true) const;

  int Fail(const grpc::Status& status, const std::string& what) {
    err_ << "fieldspace: " << what << " failed: " << CodeName(status.error_code()) << ": "
         << status.error_message() << "\n";
    return 1;
  }
  int Fail(const absl::Status& status) {
    err_ << "fieldspace: " << absl::StatusCodeToString(status.code()) << ": " << status.message()
         << "\n";
    return 1;
  }
  void Emit(const JsonWriter& j) { out_ << j.str() << "\n" << std::flush; }

  int Health(const Args& a);
  int Upload(const Args& a);
  int Meshes(const Args& a);
  int Mesh(const Args& a);
  int DeleteMesh(const Args& a);
  int Build(const Args& a);
  int Bases(const Args& a);
  int Basis(const Args& a);
  int DeleteBasis(const Args& a);
  int Cancel(const Args& a);
  int Project(const Args& a);
  int Solve(const Args& a);
  int Lift(const Args& a);
  int Eigen(const Args& a);
  int Design(const Args& a);

  // Lifts all faces of `basis_id` and writes FIELD_FILE (text, or PLY with the mesh).
  int LiftToFile(const std::string& basis_id, const std::vector<double>& coefficients,
                 v1::FieldEncoding encoding, const std::string& path);

  std::ostream& out_;
  std::ostream& err_;
  std::string server_;
  std::string token_;
  double timeout_seconds_ = 0;
  std::shared_ptr<grpc::Channel> channel_;
  std::unique_ptr<v1::FieldSpace::Stub> stub_;
};

size_t Cli::ParseGlobal(const std::vector<std::string>& args) {
  if (const char* env = std::getenv("FIELDSPACE_SERVER"); env != nullptr) server_ = env;
  std::string token_file;
  size_t i = 1;
  for (; i < args.size(); ++i) {
    const std::string& arg = args[i];
    auto value = [&](const std::string& flag) -> std::string {
      if (arg.size() > flag.size() && arg[flag.size()] == '=') return arg.substr(flag.size() + 1);
      if (i + 1 >= args.size()) throw UsageError(flag + " needs a value");
      return args[++i];
    };
    if (arg == "--help" || arg == "-h") {
      throw UsageError("");
    } else if (absl::StartsWith(arg, "--server")) {
      server_ = value("--server");
    } else if (absl::StartsWith(arg, "--token")) {
      token_file = value("--token");
    } else if (absl::StartsWith(arg, "--timeout")) {
      if (!absl::SimpleAtod(value("--timeout"), &timeout_seconds_) || timeout_seconds_ < 0) {
        throw UsageError("--timeout needs a non-negative number of seconds");
      }
    } else if (absl::StartsWith(arg, "--")) {
      throw UsageError("unknown option " + arg + " before the command");
    } else {
      break;
    }
  }
  if (server_.empty()) throw UsageError("--server HOST:PORT is required");
  if (!token_file.empty()) {
    absl::StatusOr<std::string> token = ReadFile(token_file);
    if (!token.ok()) throw UsageError("cannot read --token file " + token_file);
    token_ = std::string(absl::StripAsciiWhitespace(*token));
  }
  return i;
}

void Cli::Connect() {
  grpc::ChannelArguments channel_args;
  channel_args.SetMaxReceiveMessageSize(-1);  // the server enforces its own limit
  channel_args.SetMaxSendMessageSize(-1);
  channel_ = grpc::CreateCustomChannel(server_, grpc::InsecureChannelCredentials(), channel_args);
  stub_ = v1::FieldSpace::NewStub(channel_);
}

std::unique_ptr<grpc::ClientContext> Cli::Context(bool with_deadline) const {
  auto context = std::make_unique<grpc::ClientContext>();
  if (!token_.empty()) context->AddMetadata("authorization", "Bearer " + token_);
  if (with_deadline && timeout_seconds_ > 0) {
    context->set_deadline(std::chrono::system_clock::now() +
                          std::chrono::milliseconds(static_cast<int64_t>(timeout_seconds_ * 1000)));
  }
  return context;
}

int Cli::Run(const std::vector<std::string>& args) {
  try {
    const size_t command_index = ParseGlobal(args);
    if (command_index >= args.size()) throw UsageError("no command given");
    const std::string& command = args[command_index];
    struct Command {
      std::set<std::string> value_flags;
      std::set<std::string> bool_flags;
      size_t positional;
      int (Cli::*run)(const Args&);
    };
    const std::map<std::string, Command> commands = {
        {"health", {{"--service"}, {}, 0, &Cli::Health}},
        {"upload", {{"--name"}, {}, 1, &Cli::Upload}},
        {"meshes", {{}, {}, 0, &Cli::Meshes}},
        {"mesh", {{}, {}, 1, &Cli::Mesh}},
        {"delete-mesh", {{}, {"--cascade"}, 1, &Cli::DeleteMesh}},
        {"build",
         {{"--field", "--n", "--dim", "--sigma", "--seed", "--fields-per-region", "--coarse-dim"},
          {},
          1,
          &Cli::Build}},
        {"bases", {{"--mesh"}, {}, 0, &Cli::Bases}},
        {"basis", {{}, {}, 1, &Cli::Basis}},
        {"delete-basis", {{}, {}, 1, &Cli::DeleteBasis}},
        {"cancel", {{}, {}, 1, &Cli::Cancel}},
        {"project", {{}, {}, 2, &Cli::Project}},
        {"solve",
         {{"--constraints", "--mu-s", "--mu-b", "--mu-c", "--out", "--encoding"},
          {},
          1,
          &Cli::Solve}},
        {"lift", {{"--out", "--faces", "--encoding"}, {}, 2, &Cli::Lift}},
        {"eigen", {{"--count"}, {"--coefficients"}, 1, &Cli::Eigen}},
        {"design",
         {{"--script", "--mu-s", "--mu-b", "--mu-c", "--watch"},
          {"--no-coefficients"},
          1,
          &Cli::Design}},
    };
    auto it = commands.find(command);
    if (it == commands.end()) throw UsageError("unknown command '" + command + "'");
    Args a = ParseArgs(args, command_index + 1, it->second.value_flags, it->second.bool_flags);
    if (a.positional.size() != it->second.positional) {
      throw UsageError(absl::StrCat(command, " takes ", it->second.positional, " argument(s), got ",
                                    a.positional.size()));
    }
    Connect();
    return (this->*(it->second.run))(a);
  } catch (const UsageError& e) {
    if (*e.what() != '\0') err_ << "fieldspace: " << e.what() << "\n\n";
    err_ << kUsage;
    return *e.what() == '\0' ? 0 : 2;
  }
}

int Cli::Health(const Args& a) {
  auto stub = grpc::health::v1::Health::NewStub(channel_);
  grpc::health::v1::HealthCheckRequest request;
  request.set_service(a.Get("--service"));
  grpc::health::v1::HealthCheckResponse response;
  auto context = Context();
  if (timeout_seconds_ == 0) {
    context->set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(10));
  }
  grpc::Status status = stub->Check(context.get(), request, &response);
  if (!status.ok()) return Fail(status, "health check");
  JsonWriter j;
  j.BeginObject().Key("status").String(
      grpc::health::v1::HealthCheckResponse::ServingStatus_Name(response.status()));
  j.EndObject();
  Emit(j);
  return response.status() == grpc::health::v1::HealthCheckResponse::SERVING ? 0 : 1;
}

int Cli::Upload(const Args& a) {
  const std::string& path = a.positional[0];
  std::ifstream in(path, std::ios::binary);
  if (!in) return Fail(absl::NotFoundError("cannot open " + path));
  std::error_code ec;
  const uint64_t size = std::filesystem::file_size(path, ec);
  v1::MeshInfo info;
  auto context = Context();
  auto writer = stub_->UploadMesh(context.get(), &info);
  v1::UploadMeshRequest request;
  v1::UploadMeshHeader* header = request.mutable_header();
  header->set_name(a.Get("--name", std::filesystem::path(path).filename().string()));
  const std::string ext = absl::AsciiStrToLower(std::filesystem::path(path).extension().string());
  header->set_format(ext == ".obj"   ? v1::MESH_FORMAT_OBJ
                     : ext == ".off" ? v1::MESH_FORMAT_OFF
                     : ext == ".ply" ? v1::MESH_FORMAT_PLY
                                     : v1::MESH_FORMAT_UNSPECIFIED);
  if (!ec) header->set_total_bytes(size);
  constexpr size_t kChunk = size_t{1} << 20;
  std::string buffer(kChunk, '\0');
  uint64_t offset = 0;
  bool first = true;
  while (true) {
    in.read(buffer.data(), kChunk);
    const std::streamsize n = in.gcount();
    if (n <= 0 && !first) break;
    request.set_offset(offset);
    request.set_data(buffer.data(), static_cast<size_t>(std::max<std::streamsize>(n, 0)));
    if (!writer->Write(request)) break;  // the server ended the call: Finish tells why
    offset += static_cast<uint64_t>(std::max<std::streamsize>(n, 0));
    request.clear_header();
    first = false;
    if (n < static_cast<std::streamsize>(kChunk)) break;
  }
  writer->WritesDone();
  grpc::Status status = writer->Finish();
  if (!status.ok()) return Fail(status, "upload of " + path);
  JsonWriter j;
  WriteMeshInfo(j, info);
  Emit(j);
  return 0;
}

int Cli::Meshes(const Args&) {
  v1::ListMeshesResponse response;
  grpc::Status status = stub_->ListMeshes(Context().get(), v1::ListMeshesRequest(), &response);
  if (!status.ok()) return Fail(status, "ListMeshes");
  JsonWriter j;
  j.BeginObject().Key("meshes").BeginArray();
  for (const v1::MeshInfo& m : response.meshes()) WriteMeshInfo(j, m);
  j.EndArray().EndObject();
  Emit(j);
  return 0;
}

int Cli::Mesh(const Args& a) {
  v1::GetMeshRequest request;
  request.set_mesh_id(a.positional[0]);
  v1::MeshInfo info;
  grpc::Status status = stub_->GetMesh(Context().get(), request, &info);
  if (!status.ok()) return Fail(status, "GetMesh");
  JsonWriter j;
  WriteMeshInfo(j, info);
  Emit(j);
  return 0;
}

int Cli::DeleteMesh(const Args& a) {
  v1::DeleteMeshRequest request;
  request.set_mesh_id(a.positional[0]);
  request.set_cascade(a.Has("--cascade"));
  v1::DeleteMeshResponse response;
  grpc::Status status = stub_->DeleteMesh(Context().get(), request, &response);
  if (!status.ok()) return Fail(status, "DeleteMesh");
  JsonWriter j;
  j.BeginObject().Key("deleted").String(request.mesh_id()).Key("deleted_basis_ids").BeginArray();
  for (const std::string& id : response.deleted_basis_ids()) j.String(id);
  j.EndArray().EndObject();
  Emit(j);
  return 0;
}

int Cli::Build(const Args& a) {
  v1::BuildBasisRequest request;
  request.set_mesh_id(a.positional[0]);
  const std::string field = a.Get("--field");
  if (field == "vector") {
    request.mutable_field()->set_kind(v1::FIELD_KIND_VECTOR);
  } else if (field == "nfield") {
    request.mutable_field()->set_kind(v1::FIELD_KIND_NFIELD);
    if (!a.Has("--n")) throw UsageError("--field nfield needs --n N");
    request.mutable_field()->set_n(static_cast<int32_t>(ParseInt(a, "--n", 0)));
  } else if (field == "tensor") {
    request.mutable_field()->set_kind(v1::FIELD_KIND_TENSOR);
  } else {
    throw UsageError("--field must be vector, nfield or tensor");
  }
  if (!a.Has("--dim")) throw UsageError("build needs --dim D");
  const int64_t dim = ParseInt(a, "--dim", 0);
  if (dim < 1 || dim > INT32_MAX) throw UsageError("--dim must be a positive integer");
  request.set_dimension(static_cast<int32_t>(dim));
  if (a.Has("--sigma")) request.set_sigma(ParseDouble(a, "--sigma", 40));
  request.set_seed(static_cast<uint64_t>(ParseInt(a, "--seed", 0)));
  request.set_fields_per_region(static_cast<int32_t>(ParseInt(a, "--fields-per-region", 0)));
  const int64_t coarse = ParseInt(a, "--coarse-dim", 0);
  if (coarse < 0 || coarse >= dim) throw UsageError("--coarse-dim must be in [0, --dim)");
  request.set_coarse_dimension(static_cast<int32_t>(coarse));

  auto context = Context();
  auto reader = stub_->BuildBasis(context.get(), request);
  v1::BuildBasisProgress progress;
  v1::BasisInfo final_info;
  bool have_final = false;
  const bool tty = isatty(STDERR_FILENO) != 0 && &err_ == &std::cerr;
  v1::BuildPhase last_phase = v1::BUILD_PHASE_UNSPECIFIED;
  int last_decile = -1;
  while (reader->Read(&progress)) {
    const int percent = static_cast<int>(std::lround(100 * progress.fraction()));
    if (tty) {
      const int filled = percent * 30 / 100;
      err_ << "\r[" << std::string(filled, '#') << std::string(30 - filled, ' ') << "] " << percent
           << "% " << PhaseName(progress.phase()) << "          " << std::flush;
    } else if (progress.phase() != last_phase || percent / 10 != last_decile) {
      err_ << "build " << progress.basis_id() << ": " << PhaseName(progress.phase()) << " "
           << percent << "%" << (progress.joined() ? " (joined a running build)" : "") << "\n";
    }
    last_phase = progress.phase();
    last_decile = percent / 10;
    if (progress.has_basis()) {
      final_info = progress.basis();
      have_final = true;
    }
  }
  if (tty) err_ << "\n";
  grpc::Status status = reader->Finish();
  if (!status.ok()) return Fail(status, "BuildBasis");
  if (!have_final) return Fail(absl::InternalError("the build stream ended without a basis"));
  JsonWriter j;
  WriteBasisInfo(j, final_info);
  Emit(j);
  return 0;
}

int Cli::Bases(const Args& a) {
  v1::ListBasesRequest request;
  request.set_mesh_id(a.Get("--mesh"));
  v1::ListBasesResponse response;
  grpc::Status status = stub_->ListBases(Context().get(), request, &response);
  if (!status.ok()) return Fail(status, "ListBases");
  JsonWriter j;
  j.BeginObject().Key("bases").BeginArray();
  for (const v1::BasisInfo& b : response.bases()) WriteBasisInfo(j, b);
  j.EndArray().EndObject();
  Emit(j);
  return 0;
}

int Cli::Basis(const Args& a) {
  v1::GetBasisRequest request;
  request.set_basis_id(a.positional[0]);
  v1::BasisInfo info;
  grpc::Status status = stub_->GetBasis(Context().get(), request, &info);
  if (!status.ok()) return Fail(status, "GetBasis");
  JsonWriter j;
  WriteBasisInfo(j, info);
  Emit(j);
  return 0;
}

int Cli::DeleteBasis(const Args& a) {
  v1::DeleteBasisRequest request;
  request.set_basis_id(a.positional[0]);
  v1::DeleteBasisResponse response;
  grpc::Status status = stub_->DeleteBasis(Context().get(), request, &response);
  if (!status.ok()) return Fail(status, "DeleteBasis");
  JsonWriter j;
  j.BeginObject().Key("deleted").String(request.basis_id()).EndObject();
  Emit(j);
  return 0;
}

int Cli::Cancel(const Args& a) {
  v1::CancelBuildRequest request;
  request.set_basis_id(a.positional[0]);
  v1::CancelBuildResponse response;
  grpc::Status status = stub_->CancelBuild(Context().get(), request, &response);
  if (!status.ok()) return Fail(status, "CancelBuild");
  JsonWriter j;
  j.BeginObject().Key("cancelled").String(request.basis_id()).EndObject();
  Emit(j);
  return 0;
}

int Cli::Project(const Args& a) {
  absl::StatusOr<FieldFile> field = ReadFieldFile(a.positional[1]);
  if (!field.ok()) return Fail(field.status());
  v1::ProjectRequest request;
  request.set_basis_id(a.positional[0]);
  request.mutable_field()->set_encoding(field->encoding);
  request.mutable_field()->mutable_values()->Add(field->values.begin(), field->values.end());
  v1::ProjectResponse response;
  grpc::Status status = stub_->Project(Context().get(), request, &response);
  if (!status.ok()) return Fail(status, "Project");
  JsonWriter j;
  j.BeginObject();
  j.Key("basis_id").String(request.basis_id());
  j.Key("relative_error").Number(response.relative_error());
  j.Key("seconds").Number(response.seconds());
  j.Key("coefficients");
  WriteNumbers(j, response.coefficients());
  j.EndObject();
  Emit(j);
  return 0;
}

int Cli::LiftToFile(const std::string& basis_id, const std::vector<double>& coefficients,
                    v1::FieldEncoding encoding, const std::string& path) {
  v1::GetBasisRequest basis_request;
  basis_request.set_basis_id(basis_id);
  v1::BasisInfo basis;
  grpc::Status status = stub_->GetBasis(Context().get(), basis_request, &basis);
  if (!status.ok()) return Fail(status, "GetBasis");

  v1::LiftRequest request;
  request.set_basis_id(basis_id);
  request.mutable_coefficients()->Add(coefficients.begin(), coefficients.end());
  request.set_encoding(encoding);
  auto context = Context();
  auto reader = stub_->Lift(context.get(), request);
  FieldFile field;
  field.encoding = encoding;
  const bool tensor = basis.field().kind() == v1::FIELD_KIND_TENSOR;
  field.values_per_face =
      encoding == v1::FIELD_ENCODING_AMBIENT ? (tensor ? 6 : 3) : (tensor ? 3 : 2);
  v1::FieldChunk chunk;
  while (reader->Read(&chunk)) {
    if (chunk.start_face() != field.num_faces()) {
      context->TryCancel();
      reader->Finish();
      return Fail(absl::DataLossError("Lift chunks arrived out of order"));
    }
    if (field.values.empty()) {
      field.values.reserve(static_cast<size_t>(chunk.total_faces()) * field.values_per_face);
    }
    const auto& values = chunk.field().values();
    field.values.insert(field.values.end(), values.begin(), values.end());
  }
  status = reader->Finish();
  if (!status.ok()) return Fail(status, "Lift");

  if (absl::EndsWith(absl::AsciiStrToLower(path), ".ply")) {
    v1::GetMeshGeometryRequest geometry_request;
    geometry_request.set_mesh_id(basis.mesh_id());
    auto geometry_context = Context();
    auto geometry = stub_->GetMeshGeometry(geometry_context.get(), geometry_request);
    std::vector<double> vertices;
    std::vector<int32_t> faces;
    v1::MeshGeometryChunk g;
    while (geometry->Read(&g)) {
      vertices.insert(vertices.end(), g.vertices().begin(), g.vertices().end());
      faces.insert(faces.end(), g.faces().begin(), g.faces().end());
    }
    status = geometry->Finish();
    if (!status.ok()) return Fail(status, "GetMeshGeometry");
    if (absl::Status st = WriteFieldPly(path, vertices, faces, field); !st.ok()) return Fail(st);
  } else {
    if (absl::Status st = WriteFieldText(path, field, FieldKindName(basis.field())); !st.ok()) {
      return Fail(st);
    }
  }
  return 0;
}

int Cli::Solve(const Args& a) {
  if (!a.Has("--constraints")) throw UsageError("solve needs --constraints FILE");
  absl::StatusOr<std::string> text = ReadFile(a.Get("--constraints"));
  if (!text.ok()) return Fail(text.status());
  absl::StatusOr<std::vector<v1::Constraint>> constraints = ParseConstraints(*text);
  if (!constraints.ok()) {
    return Fail(absl::InvalidArgumentError(
        absl::StrCat(a.Get("--constraints"), ": ", constraints.status().message())));
  }
  v1::SolveRequest request;
  request.set_basis_id(a.positional[0]);
  request.mutable_weights()->set_mu_s(ParseDouble(a, "--mu-s", 1.0));
  request.mutable_weights()->set_mu_b(ParseDouble(a, "--mu-b", 0.0));
  request.mutable_weights()->set_mu_c(ParseDouble(a, "--mu-c", 1.0));
  for (v1::Constraint& c : *constraints) *request.add_constraints() = std::move(c);
  v1::SolveResponse response;
  grpc::Status status = stub_->Solve(Context().get(), request, &response);
  if (!status.ok()) return Fail(status, "Solve");
  std::vector<double> coefficients(response.coefficients().begin(), response.coefficients().end());
  if (a.Has("--out")) {
    if (int rc = LiftToFile(request.basis_id(), coefficients, ParseEncoding(a), a.Get("--out"));
        rc != 0) {
      return rc;
    }
  }
  JsonWriter j;
  j.BeginObject();
  j.Key("basis_id").String(request.basis_id());
  j.Key("num_constraints").Int(request.constraints_size());
  j.Key("timings").BeginObject();
  j.Key("solve_ms").Number(response.timings().solve_ms());
  j.Key("total_ms").Number(response.timings().total_ms());
  j.EndObject();
  if (a.Has("--out")) j.Key("out").String(a.Get("--out"));
  j.Key("coefficients");
  WriteNumbers(j, coefficients);
  j.EndObject();
  Emit(j);
  return 0;
}

int Cli::Lift(const Args& a) {
  absl::StatusOr<std::string> text = ReadFile(a.positional[1]);
  if (!text.ok()) return Fail(text.status());
  absl::StatusOr<std::vector<double>> coefficients = ParseCoefficients(*text);
  if (!coefficients.ok()) {
    return Fail(absl::InvalidArgumentError(
        absl::StrCat(a.positional[1], ": ", coefficients.status().message())));
  }
  const v1::FieldEncoding encoding = ParseEncoding(a);
  if (a.Has("--out") == a.Has("--faces")) {
    throw UsageError("lift needs exactly one of --out FIELD_FILE and --faces F1,F2,...");
  }
  if (a.Has("--out")) {
    if (int rc = LiftToFile(a.positional[0], *coefficients, encoding, a.Get("--out")); rc != 0) {
      return rc;
    }
    JsonWriter j;
    j.BeginObject().Key("basis_id").String(a.positional[0]).Key("out").String(a.Get("--out"));
    j.EndObject();
    Emit(j);
    return 0;
  }
  v1::LiftRequest request;
  request.set_basis_id(a.positional[0]);
  request.mutable_coefficients()->Add(coefficients->begin(), coefficients->end());
  request.set_encoding(encoding);
  for (int32_t f : ParseFaceList(a.Get("--faces"))) request.add_faces(f);
  auto context = Context();
  auto reader = stub_->Lift(context.get(), request);
  JsonWriter j;
  j.BeginObject().Key("basis_id").String(request.basis_id()).Key("faces").BeginArray();
  v1::FieldChunk chunk;
  while (reader->Read(&chunk)) {
    const int n = chunk.field().faces_size();
    const int vpf = n == 0 ? 0 : chunk.field().values_size() / n;
    for (int i = 0; i < n; ++i) {
      j.BeginObject().Key("face").Int(chunk.field().faces(i)).Key("value").BeginArray();
      for (int c = 0; c < vpf; ++c) j.Number(chunk.field().values(i * vpf + c));
      j.EndArray().EndObject();
    }
  }
  grpc::Status status = reader->Finish();
  if (!status.ok()) return Fail(status, "Lift");
  j.EndArray().EndObject();
  Emit(j);
  return 0;
}

int Cli::Eigen(const Args& a) {
  if (!a.Has("--count")) throw UsageError("eigen needs --count K");
  v1::EigenfieldsRequest request;
  request.set_basis_id(a.positional[0]);
  const int64_t count = ParseInt(a, "--count", 0);
  if (count < 1 || count > INT32_MAX) throw UsageError("--count must be a positive integer");
  request.set_count(static_cast<int32_t>(count));
  v1::EigenfieldsResponse response;
  grpc::Status status = stub_->Eigenfields(Context().get(), request, &response);
  if (!status.ok()) return Fail(status, "Eigenfields");
  JsonWriter j;
  j.BeginObject();
  j.Key("basis_id").String(request.basis_id());
  j.Key("seconds").Number(response.seconds());
  j.Key("eigenvalues");
  WriteNumbers(j, response.eigenvalues());
  if (a.Has("--coefficients")) {
    j.Key("coefficients").BeginArray();
    const int d = response.dimension();
    for (int i = 0; d > 0 && i < response.eigenvalues_size(); ++i) {
      j.BeginArray();
      for (int c = 0; c < d; ++c) j.Number(response.coefficients(i * d + c));
      j.EndArray();
    }
    j.EndArray();
  }
  j.EndObject();
  Emit(j);
  return 0;
}

int Cli::Design(const Args& a) {
  if (!a.Has("--script")) throw UsageError("design needs --script EDITS.jsonl");
  absl::StatusOr<std::string> text = ReadFile(a.Get("--script"));
  if (!text.ok()) return Fail(text.status());
  // Parse the whole script first: a typo on line 40 should not leave a half-run session.
  std::vector<v1::DesignRequest> edits;
  std::vector<std::string> kinds;
  int64_t line_number = 0;
  for (absl::string_view line : absl::StrSplit(*text, '\n')) {
    ++line_number;
    line = absl::StripAsciiWhitespace(line);
    if (line.empty() || line[0] == '#') continue;
    absl::StatusOr<v1::DesignRequest> edit =
        ParseEdit(line, absl::StrCat(a.Get("--script"), ":", line_number));
    if (!edit.ok()) return Fail(edit.status());
    edit->set_seq(static_cast<uint64_t>(line_number));
    kinds.push_back(edit->has_add()      ? "add"
                    : edit->has_move()   ? "move"
                    : edit->has_remove() ? "remove"
                    : edit->has_watch()  ? "watch"
                                         : "weights");
    edits.push_back(*std::move(edit));
  }
  v1::DesignRequest open;
  open.set_seq(0);
  v1::OpenDesign* o = open.mutable_open();
  o->set_basis_id(a.positional[0]);
  o->mutable_weights()->set_mu_s(ParseDouble(a, "--mu-s", 1.0));
  o->mutable_weights()->set_mu_b(ParseDouble(a, "--mu-b", 0.0));
  o->mutable_weights()->set_mu_c(ParseDouble(a, "--mu-c", 1.0));
  o->set_watch_encoding(v1::FIELD_ENCODING_AMBIENT);
  for (int32_t f : ParseFaceList(a.Get("--watch"))) o->add_watch_faces(f);
  edits.insert(edits.begin(), open);
  kinds.insert(kinds.begin(), "open");

  const bool coefficients = !a.Has("--no-coefficients");
  auto context = Context();
  auto stream = stub_->Design(context.get());
  v1::DesignUpdate update;
  for (size_t i = 0; i < edits.size(); ++i) {
    const auto sent = Clock::now();
    if (!stream->Write(edits[i]) || !stream->Read(&update)) break;
    const double round_trip_ms =
        std::chrono::duration<double, std::milli>(Clock::now() - sent).count();
    JsonWriter j;
    j.BeginObject();
    j.Key("seq").Int(static_cast<int64_t>(update.seq()));
    j.Key("edit").String(kinds[i]);
    j.Key("num_constraints").Int(update.num_constraints());
    j.Key("num_hard_constraints").Int(update.num_hard_constraints());
    j.Key("refactorized").Bool(update.timings().refactorized());
    j.Key("timings").BeginObject();
    j.Key("edit_ms").Number(update.timings().edit_ms());
    j.Key("lift_ms").Number(update.timings().lift_ms());
    j.Key("total_ms").Number(update.timings().total_ms());
    j.Key("round_trip_ms").Number(round_trip_ms);
    j.EndObject();
    j.Key("watched").BeginArray();
    const auto& watched = update.watched();
    const int n = watched.faces_size();
    const int vpf = n == 0 ? 0 : watched.values_size() / n;
    for (int f = 0; f < n; ++f) {
      j.BeginObject().Key("face").Int(watched.faces(f)).Key("value").BeginArray();
      for (int c = 0; c < vpf; ++c) j.Number(watched.values(f * vpf + c));
      j.EndArray().EndObject();
    }
    j.EndArray();
    if (coefficients) {
      j.Key("coefficients");
      WriteNumbers(j, update.coefficients());
    }
    j.EndObject();
    Emit(j);
  }
  stream->WritesDone();
  grpc::Status status = stream->Finish();
  if (!status.ok()) return Fail(status, "Design");
  return 0;
}

}  // namespace

int RunCli(const std::vector<std::string>& args, std::ostream& out, std::ostream& err) {
  Cli cli(out, err);
  return cli.Run(args);
}

}  // namespace fieldspace::client
