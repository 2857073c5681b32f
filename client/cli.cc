#include "client/cli.h"

#include <semaphore.h>
#include <signal.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iostream>
#include <limits>
#include <map>
#include <memory>
#include <mutex>
#include <stdexcept>
#include <thread>

#include "absl/strings/ascii.h"
#include "absl/strings/match.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "absl/types/span.h"
#include "client/field_client.h"
#include "client/field_files.h"
#include "client/json.h"
#include "core/common/command_line.h"

namespace fieldspace::client {
namespace {

namespace v1 = ::fieldspace::v1;
using Clock = std::chrono::steady_clock;

constexpr char kUsage[] =
    R"(usage: fieldspace --server HOST:PORT [--token FILE] [--timeout SECONDS] COMMAND [ARGS]

commands (JSON on stdout, errors on stderr, non-zero exit on failure):
  health [--service NAME]             grpc.health.v1 status of the server
  upload MESH [--name NAME] [--format obj|off|ply]
                                      upload a mesh file (format from the extension unless
                                      --format); prints MeshInfo ("id")
  meshes                              list meshes
  mesh MESH_ID                        one mesh
  delete-mesh MESH_ID [--cascade]     delete a mesh (with --cascade: and its bases)
  build MESH_ID --field vector|nfield|tensor [--n N] --dim D [--sigma S] [--seed S]
        [--fields-per-region M] [--coarse-dim C] [--quality paper|low-modes|smooth]
        [--face-weights FILE] [--no-kernel-columns] [--cancel-on-exit]
                                      build a basis: progress on stderr, BasisInfo ("id") on stdout;
                                      C > 0 adds a coarse level of C of the D columns; FILE: #F
                                      positive adaptivity weights (smaller regions where high);
                                      --no-kernel-columns: the paper's basis exactly, without
                                      the kernel (harmonic) columns appended by default; Ctrl-C
                                      leaves the build running on the server (and says how to
                                      cancel it) unless --cancel-on-exit
  bases [--mesh MESH_ID]              list bases (and running builds)
  basis BASIS_ID                      one basis
  delete-basis BASIS_ID               delete a basis
  cancel BASIS_ID                     cancel a running build
  project BASIS_ID FIELD_FILE         coefficients and relative error of the projection
  solve BASIS_ID --constraints FILE [--mu-s X] [--mu-b X] [--mu-c X] [--out FIELD_FILE]
        [--encoding ambient|dof] [--singularities] [--raw-weights] [--biharmonic exact|mixed]
                                      the model problem with soft/hard constraints (defaults
                                      1, 0, 1; scale-free: a soft constraint alone pulls its
                                      face >= mu_c w / (1 + mu_c w) of the way, unless
                                      --raw-weights); --singularities: also the singular vertices;
                                      --biharmonic: the mu_b term as the subspace's own (mixed,
                                      the default: closer to the full space) or the paper's
                                      (exact)
  lift BASIS_ID COEFFS_FILE (--out FIELD_FILE | --faces F1,F2,...) [--encoding ambient|dof]
        [--mode K]                    --mode K: eigenfield K of `eigen --coefficients` output
  eigen BASIS_ID --count K [--coefficients]
  curvature MESH_ID --out FIELD_FILE [--encoding ambient|dof] [--estimator jet|normal-differences]
        [--principal FILE]            the per-face shape operator (1/length) into FIELD_FILE;
                                      --principal: per face k1 k2 d1x d1y d1z d2x d2y d2z
  smoothest BASIS_ID [--out FIELD_FILE] [--encoding ambient|dof]
                                      the smoothest unit field (lowest eigenfield) of the basis
  smooth BASIS_ID FIELD_FILE [--mu-s X] [--mu-b X] [--mu-c X] [--face-weights FILE] [--raw-weights]
        [--out FIELD_FILE] [--encoding ambient|dof] [--singularities]
                                      the field closest to FIELD_FILE (M-weighted) with harmonic
                                      and biharmonic fairness; scale-free weights unless
                                      --raw-weights (defaults 0.001, 0, 1)
  align BASIS_ID --curvature [--n 2|4] [--smooth-mu X] [--mu-b X] [--mu-c X] [--out FIELD_FILE]
        [--encoding ambient|dof] [--estimator jet|normal-differences] [--singularities]
                                      a smooth n-field (n-field basis, n = 2 or 4) aligned to
                                      the principal curvature directions (defaults 0.001, 0, 1)
  singularities BASIS_ID COEFFS_FILE [--zero-tolerance T] [--mode K]
                                      vertex indices (in turns) of the lifted field
  design BASIS_ID --script EDITS.jsonl [--mu-s X] [--mu-b X] [--mu-c X] [--watch F1,F2,...]
        [--no-coefficients] [--singularities] [--raw-weights] [--biharmonic exact|mixed]
        [--align-curvature [--estimator E] | --data FIELD_FILE [--face-weights FILE]] [--mu-a X]
                                      stream edits; one JSON line per update (--singularities:
                                      how the singular vertices changed, in each); weights as
                                      solve's; --align-curvature / --data: a data term (weight
                                      mu_a; then defaults 0.001, 0, 1, 1) the edits act on top of

  export MESH FIELD_FILE --out FILE.vtu|.vtk|.ply|.rawfield
                                      the field on its mesh for ParaView, meshio, Directional;
                                      MESH: a mesh id of the server or a mesh file
  render MESH [FIELD_FILE] --out FILE.png [--style glyphs|streamlines|lic|surface]
                                      a picture, off screen (VTK); both run the Python package's
                                      `python3 -m fieldspace.export|render` (--help: all options)

FIELD_FILE: text (one face per line; '# encoding: dof' or ambient, the default) or, for output,
.ply (the mesh with the field as face properties). Formats: README.md.

TLS (a server started with --tls-cert), options before COMMAND; any of them turns TLS on:
--tls-ca FILE (the CA of the server's certificate; default: the system's roots), --tls-cert FILE
--tls-key FILE (this client's certificate and key, for a server with --tls-client-ca),
--tls-server-name NAME (the name to expect in the server's certificate; default: HOST).
)";

// The usage of one command: its lines of kUsage (the line naming it and the indented lines after
// it), then the global options and the FIELD_FILE note.
std::string CommandUsage(const std::string& command) {
  std::string block;
  bool in_block = false;
  for (absl::string_view line : absl::StrSplit(kUsage, '\n')) {
    const bool command_line = absl::StartsWith(line, "  ") && line.size() > 2 && line[2] != ' ';
    if (command_line) {
      const absl::string_view name = line.substr(2, line.find(' ', 2) - 2);
      in_block = name == command;
    } else if (!absl::StartsWith(line, "  ")) {
      in_block = false;
    }
    if (in_block) absl::StrAppend(&block, line, "\n");
  }
  return absl::StrCat(
      "usage: fieldspace [--server HOST:PORT] [--token FILE] [--timeout SECONDS] [--tls-* ...] ",
      command, " ...\n\n", block,
      "\nThe server defaults to $FIELDSPACE_SERVER; FIELD_FILE formats and TLS options: "
      "fieldspace --help.\n");
}

// While alive, Ctrl-C (SIGINT) runs `on_interrupt(basis_id, joined)` on a thread of its own with
// the build the stream was last told about, then exits with 130. The signal handler only posts a
// semaphore (async-signal-safe); everything else happens on that thread.
class InterruptWatch {
 public:
  using Callback = std::function<void(const std::string& basis_id, bool joined)>;

  explicit InterruptWatch(Callback on_interrupt) : on_interrupt_(std::move(on_interrupt)) {
    sem_init(&Semaphore(), 0, 0);
    struct sigaction action = {};
    action.sa_handler = [](int) { sem_post(&Semaphore()); };
    sigemptyset(&action.sa_mask);
    sigaction(SIGINT, &action, &previous_);
    thread_ = std::thread([this] {
      while (sem_wait(&Semaphore()) != 0) {
      }
      if (stopping_.load()) return;
      std::string basis_id;
      bool joined = false;
      {
        std::lock_guard<std::mutex> lock(mutex_);
        basis_id = basis_id_;
        joined = joined_;
      }
      on_interrupt_(basis_id, joined);
      std::_Exit(130);
    });
  }
  ~InterruptWatch() {
    sigaction(SIGINT, &previous_, nullptr);
    stopping_.store(true);
    sem_post(&Semaphore());
    thread_.join();
    sem_destroy(&Semaphore());
  }
  InterruptWatch(const InterruptWatch&) = delete;
  InterruptWatch& operator=(const InterruptWatch&) = delete;

  // The build the stream is about (from its first message on).
  void Name(const std::string& basis_id, bool joined) {
    std::lock_guard<std::mutex> lock(mutex_);
    basis_id_ = basis_id;
    joined_ = joined;
  }

 private:
  static sem_t& Semaphore() {
    static sem_t semaphore;
    return semaphore;
  }

  Callback on_interrupt_;
  struct sigaction previous_ = {};
  std::atomic<bool> stopping_{false};
  std::mutex mutex_;
  std::string basis_id_;
  bool joined_ = false;
  std::thread thread_;
};

class UsageError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

FlagSpec Flags(std::vector<std::string> value_flags, std::vector<std::string> switches = {}) {
  FlagSpec spec;
  spec.value_flags = std::move(value_flags);
  spec.switches = std::move(switches);
  return spec;
}

// The value of a parsed flag, or a usage error with the parser's message.
template <typename T>
T OrUsageError(absl::StatusOr<T> value) {
  if (!value.ok()) throw UsageError(std::string(value.status().message()));
  return *std::move(value);
}

std::string GetString(const CommandLine& args, const std::string& flag,
                      const std::string& fallback = "") {
  return args.Get(flag).value_or(fallback);
}

double ParseDouble(const CommandLine& args, const std::string& flag, double fallback) {
  return OrUsageError(args.GetDouble(flag, fallback));
}

int64_t ParseInt(const CommandLine& args, const std::string& flag, int64_t fallback) {
  return OrUsageError(args.GetInt(flag, fallback));
}

// A file of numbers (coefficients, per-face weights): the JSON printed by solve / project /
// smoothest, a JSON array, or plain numbers. Errors name the file.
absl::StatusOr<std::vector<double>> ReadNumbersFile(const std::string& path, int mode = -1) {
  absl::StatusOr<std::string> text = ReadFile(path);
  if (!text.ok()) return text.status();
  absl::StatusOr<std::vector<double>> numbers = ParseCoefficients(*text, mode);
  if (!numbers.ok()) {
    return absl::InvalidArgumentError(absl::StrCat(path, ": ", numbers.status().message()));
  }
  return numbers;
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

// The weights given on the command line (mu_s under `mu_s_flag`, --mu-b, --mu-c); the ones left
// out are left out of the request too, so that the server's defaults for the operation apply.
void SetWeights(const CommandLine& a, const char* mu_s_flag, v1::Weights* w) {
  if (a.Has(mu_s_flag)) w->set_mu_s(ParseDouble(a, mu_s_flag, 0));
  if (a.Has("mu-b")) w->set_mu_b(ParseDouble(a, "mu-b", 0));
  if (a.Has("mu-c")) w->set_mu_c(ParseDouble(a, "mu-c", 0));
  if (a.Has("mu-a")) w->set_mu_a(ParseDouble(a, "mu-a", 0));
}

// --estimator jet|normal-differences (default jet).
v1::CurvatureEstimator ParseEstimator(const CommandLine& a) {
  const std::string estimator = GetString(a, "estimator", "jet");
  if (estimator == "jet") return v1::CURVATURE_ESTIMATOR_JET;
  if (estimator == "normal-differences") return v1::CURVATURE_ESTIMATOR_NORMAL_DIFFERENCES;
  throw UsageError("--estimator must be jet or normal-differences");
}

// --face-weights FILE (one number per face) into `out`; nothing without the flag.
absl::Status ReadFaceWeights(const CommandLine& a, google::protobuf::RepeatedField<double>* out) {
  if (!a.Has("face-weights")) return absl::OkStatus();
  const std::string path = GetString(a, "face-weights");
  absl::StatusOr<std::string> text = ReadFile(path);
  if (!text.ok()) return text.status();
  absl::StatusOr<std::vector<double>> weights = ParseCoefficients(*text);
  if (!weights.ok()) {
    return absl::InvalidArgumentError(absl::StrCat(path, ": ", weights.status().message()));
  }
  out->Add(weights->begin(), weights->end());
  return absl::OkStatus();
}

// --mode K (an eigenfield of `eigen --coefficients`), or -1.
int ParseMode(const CommandLine& a) {
  if (!a.Has("mode")) return -1;
  const int64_t mode = ParseInt(a, "mode", -1);
  if (mode < 0 || mode > INT32_MAX) throw UsageError("--mode must be a non-negative integer");
  return static_cast<int>(mode);
}

v1::FieldEncoding ParseEncoding(const CommandLine& args) {
  const std::string e = GetString(args, "encoding", "ambient");
  if (e == "ambient") return v1::FIELD_ENCODING_AMBIENT;
  if (e == "dof") return v1::FIELD_ENCODING_DOF;
  throw UsageError("--encoding must be ambient or dof");
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
  j.Key("kernel_columns").Bool(b.kernel_columns());
  j.Key("quality").String(b.quality() == v1::BASIS_QUALITY_LOW_MODES ? "low-modes"
                          : b.quality() == v1::BASIS_QUALITY_SMOOTH  ? "smooth"
                                                                     : "paper");
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

// One singular vertex: {"vertex": v, "index": turns, "position": [x, y, z]}.
void WriteSingularity(JsonWriter& j, const v1::Singularity& s) {
  j.BeginObject().Key("vertex").Int(s.vertex()).Key("index").Number(s.turns());
  j.Key("position");
  WriteNumbers(j, s.position());
  j.EndObject();
}

// The fields of the `singularities` command's object (also the object under "singularities" in
// solve / smooth / align), written into an open object.
void WriteSingularityFields(JsonWriter& j, const v1::SingularitiesResponse& r) {
  j.Key("n").Int(r.n());
  j.Key("singularities").BeginArray();
  for (const v1::Singularity& s : r.singularities()) WriteSingularity(j, s);
  j.EndArray();
  j.Key("index_sum").Number(r.index_sum());
  j.Key("euler_characteristic").Int(r.euler_characteristic());
  j.Key("boundary_vertices").Int(r.boundary_size());
  j.Key("undefined_vertices").Int(r.undefined_vertices_size());
}

class Cli {
 public:
  Cli(std::ostream& out, std::ostream& err) : out_(out), err_(err) {}

  int Run(const std::vector<std::string>& args);

 private:
  // Global options up to the command; returns the command and its arguments.
  std::vector<std::string> ParseGlobal(const std::vector<std::string>& args);

  // An RPC failure: "fieldspace: <what> failed: <CODE>: <message>".
  int Fail(const absl::Status& status, const std::string& what) {
    err_ << "fieldspace: " << what << " failed: " << absl::StatusCodeToString(status.code()) << ": "
         << status.message() << "\n";
    return 1;
  }
  // A local failure (a file, a check before any call): "fieldspace: <command> failed: <CODE>:
  // <message>".
  int Fail(const absl::Status& status) { return Fail(status, command_); }
  void Emit(const JsonWriter& j) { out_ << j.str() << "\n" << std::flush; }

  // `export` and `render`: replaced by `python3 -m fieldspace.<tool> ARGS --server ADDRESS
  // [--token FILE]` with the Python package on PYTHONPATH (the build tree's or the installed
  // one, found next to this program). Returns only when that cannot start.
  int RunPythonTool(const std::string& tool, absl::Span<const std::string> args);

  int Health(const CommandLine& a);
  int Upload(const CommandLine& a);
  int Meshes(const CommandLine& a);
  int Mesh(const CommandLine& a);
  int DeleteMesh(const CommandLine& a);
  int Build(const CommandLine& a);
  int Bases(const CommandLine& a);
  int Basis(const CommandLine& a);
  int DeleteBasis(const CommandLine& a);
  int Cancel(const CommandLine& a);
  int Project(const CommandLine& a);
  int Solve(const CommandLine& a);
  int Lift(const CommandLine& a);
  int Eigen(const CommandLine& a);
  int Design(const CommandLine& a);
  int Curvature(const CommandLine& a);
  int Smoothest(const CommandLine& a);
  int Singularities(const CommandLine& a);
  int Smooth(const CommandLine& a);
  int Align(const CommandLine& a);
  // Prints a Smooth / Align answer (and writes --out) as `smooth` and `align` do.
  int EmitSmoothed(const CommandLine& a, const std::string& basis_id, bool scale_free,
                   const v1::SmoothResponse& response);

  // Lifts all faces of `basis_id` and writes FIELD_FILE (text, or PLY with the mesh).
  int LiftToFile(const std::string& basis_id, const std::vector<double>& coefficients,
                 v1::FieldEncoding encoding, const std::string& path);
  // LiftToFile to --out (in --encoding) when the command was given --out; 0 otherwise.
  int LiftToOut(const CommandLine& a, const std::string& basis_id,
                const std::vector<double>& coefficients) {
    if (!a.Has("out")) return 0;
    return LiftToFile(basis_id, coefficients, ParseEncoding(a), GetString(a, "out"));
  }

  std::ostream& out_;
  std::ostream& err_;
  std::string command_;     // the command being run, for messages
  std::string token_file_;  // --token FILE, passed on to the Python tools
  // --tls-* flags as given (flag name without dashes, value), passed on to the Python tools.
  std::vector<std::pair<std::string, std::string>> tls_flags_;
  FieldClientOptions options_;
  std::unique_ptr<FieldClient> client_;
};

std::vector<std::string> Cli::ParseGlobal(const std::vector<std::string>& args) {
  if (const char* env = std::getenv("FIELDSPACE_SERVER"); env != nullptr) options_.address = env;
  FlagSpec spec;
  spec.value_flags = {"server",   "token",   "timeout",        "tls-ca",
                      "tls-cert", "tls-key", "tls-server-name"};
  spec.switches = {"help"};
  spec.stop_at_positional = true;
  const CommandLine global = OrUsageError(CommandLine::Parse(
      absl::MakeConstSpan(args).subspan(std::min<size_t>(1, args.size())), spec));
  if (global.Has("help") || (!global.positional().empty() && global.positional()[0] == "-h")) {
    throw UsageError("");
  }
  options_.address = GetString(global, "server", options_.address);
  if (global.Has("timeout")) {
    const absl::StatusOr<double> seconds = global.GetDouble("timeout", 0);
    if (!seconds.ok() || *seconds < 0) {
      throw UsageError("--timeout needs a non-negative number of seconds");
    }
    if (*seconds > 0) {
      options_.timeout = std::chrono::milliseconds(static_cast<int64_t>(*seconds * 1000));
    }
  }
  token_file_ = GetString(global, "token");
  if (const std::string token_file = token_file_; !token_file.empty()) {
    absl::StatusOr<std::string> token = ReadFile(token_file);
    if (!token.ok()) throw UsageError("cannot read --token file " + token_file);
    options_.token = std::string(absl::StripAsciiWhitespace(*token));
  }
  ClientTlsOptions tls;
  const std::pair<const char*, std::string*> tls_flags[] = {{"tls-ca", &tls.ca_file},
                                                            {"tls-cert", &tls.cert_file},
                                                            {"tls-key", &tls.key_file},
                                                            {"tls-server-name", &tls.server_name}};
  for (const auto& [flag, target] : tls_flags) {
    if (!global.Has(flag)) continue;
    *target = GetString(global, flag);
    if (target->empty()) throw UsageError(absl::StrCat("--", flag, " needs a value"));
    tls_flags_.emplace_back(flag, *target);
  }
  if (!tls_flags_.empty()) options_.tls = tls;
  return global.positional();
}

int Cli::Run(const std::vector<std::string>& args) {
  try {
    const std::vector<std::string> command_line = ParseGlobal(args);
    if (command_line.empty()) throw UsageError("no command given");
    const std::string& command = command_line[0];
    struct Command {
      FlagSpec flags;
      size_t positional;
      int (Cli::*run)(const CommandLine&);
    };
    const std::map<std::string, Command> commands = {
        {"health", {Flags({"service"}), 0, &Cli::Health}},
        {"upload", {Flags({"name", "format"}), 1, &Cli::Upload}},
        {"meshes", {{}, 0, &Cli::Meshes}},
        {"mesh", {{}, 1, &Cli::Mesh}},
        {"delete-mesh", {Flags({}, {"cascade"}), 1, &Cli::DeleteMesh}},
        {"build",
         {Flags({"field", "n", "dim", "sigma", "seed", "fields-per-region", "coarse-dim", "quality",
                 "face-weights"},
                {"cancel-on-exit", "no-kernel-columns"}),
          1, &Cli::Build}},
        {"bases", {Flags({"mesh"}), 0, &Cli::Bases}},
        {"basis", {{}, 1, &Cli::Basis}},
        {"delete-basis", {{}, 1, &Cli::DeleteBasis}},
        {"cancel", {{}, 1, &Cli::Cancel}},
        {"project", {{}, 2, &Cli::Project}},
        {"solve",
         {Flags({"constraints", "mu-s", "mu-b", "mu-c", "out", "encoding", "biharmonic"},
                {"singularities", "raw-weights"}),
          1, &Cli::Solve}},
        {"lift", {Flags({"out", "faces", "encoding", "mode"}), 2, &Cli::Lift}},
        {"eigen", {Flags({"count"}, {"coefficients"}), 1, &Cli::Eigen}},
        {"design",
         {Flags({"script", "mu-s", "mu-b", "mu-c", "mu-a", "watch", "data", "face-weights",
                 "estimator", "biharmonic"},
                {"no-coefficients", "singularities", "raw-weights", "align-curvature"}),
          1, &Cli::Design}},
        {"curvature", {Flags({"out", "encoding", "estimator", "principal"}), 1, &Cli::Curvature}},
        {"smoothest", {Flags({"out", "encoding"}), 1, &Cli::Smoothest}},
        {"singularities", {Flags({"zero-tolerance", "mode"}), 2, &Cli::Singularities}},
        {"align",
         {Flags({"n", "smooth-mu", "mu-b", "mu-c", "out", "encoding", "estimator"},
                {"curvature", "singularities"}),
          1, &Cli::Align}},
        {"smooth",
         {Flags({"mu-s", "mu-b", "mu-c", "face-weights", "out", "encoding"},
                {"raw-weights", "singularities"}),
          2, &Cli::Smooth}},
    };
    if (command == "export" || command == "render") {
      command_ = command;
      return RunPythonTool(command, absl::MakeConstSpan(command_line).subspan(1));
    }
    auto it = commands.find(command);
    if (it == commands.end()) throw UsageError("unknown command '" + command + "'");
    command_ = command;
    FlagSpec flags = it->second.flags;
    flags.switches.push_back("help");
    const absl::Span<const std::string> rest = absl::MakeConstSpan(command_line).subspan(1);
    if (std::find(rest.begin(), rest.end(), "--help") != rest.end() ||
        std::find(rest.begin(), rest.end(), "-h") != rest.end()) {
      out_ << CommandUsage(command);
      return 0;
    }
    try {
      const CommandLine a = OrUsageError(CommandLine::Parse(rest, flags));
      if (a.positional().size() != it->second.positional) {
        throw UsageError(absl::StrCat(command, " takes ", it->second.positional,
                                      " argument(s), got ", a.positional().size()));
      }
      if (options_.address.empty()) {
        throw UsageError("--server HOST:PORT (or FIELDSPACE_SERVER) is required");
      }
      absl::StatusOr<std::unique_ptr<FieldClient>> client = FieldClient::Create(options_);
      if (!client.ok()) throw UsageError(std::string(client.status().message()));
      client_ = *std::move(client);
      return (this->*(it->second.run))(a);
    } catch (const UsageError& e) {
      // A usage error of a known command: the README's error form, then that command's usage.
      Fail(absl::InvalidArgumentError(e.what()));
      err_ << "\n" << CommandUsage(command);
      return 2;
    }
  } catch (const UsageError& e) {
    if (*e.what() != '\0') err_ << "fieldspace: " << e.what() << "\n\n";
    err_ << kUsage;
    return *e.what() == '\0' ? 0 : 2;
  }
}

int Cli::RunPythonTool(const std::string& tool, absl::Span<const std::string> args) {
  // The package next to this program: build/bin/../python in the build tree,
  // PREFIX/bin/../lib/python3/dist-packages when installed.
  std::error_code ec;
  const std::filesystem::path self = std::filesystem::read_symlink("/proc/self/exe", ec);
  std::string package_dir;
  for (const char* relative : {"../python", "../lib/python3/dist-packages"}) {
    const std::filesystem::path dir = self.parent_path() / relative;
    if (!ec && std::filesystem::exists(dir / "fieldspace" / "__init__.py")) {
      package_dir = std::filesystem::weakly_canonical(dir).string();
      break;
    }
  }
  if (package_dir.empty()) {
    return Fail(absl::FailedPreconditionError(
        "the Python package fieldspace is not next to this program (build it, or `make install`)"));
  }
  const char* old_path = std::getenv("PYTHONPATH");
  const std::string python_path = old_path != nullptr && *old_path != '\0'
                                      ? absl::StrCat(package_dir, ":", old_path)
                                      : package_dir;
  setenv("PYTHONPATH", python_path.c_str(), 1);
  const char* python_env = std::getenv("FIELDSPACE_PYTHON");
  const std::string python = python_env != nullptr ? python_env : "/usr/bin/python3";
  std::vector<std::string> argv = {python, "-m", "fieldspace." + tool};
  argv.insert(argv.end(), args.begin(), args.end());
  argv.insert(argv.end(), {"--server", options_.address});
  if (!token_file_.empty()) argv.insert(argv.end(), {"--token", token_file_});
  for (const auto& [flag, value] : tls_flags_) argv.insert(argv.end(), {"--" + flag, value});
  std::vector<char*> raw;
  for (std::string& a : argv) raw.push_back(a.data());
  raw.push_back(nullptr);
  out_ << std::flush;
  err_ << std::flush;
  execv(python.c_str(), raw.data());
  return Fail(absl::UnavailableError(absl::StrCat("cannot run ", python, ": ", strerror(errno))));
}

int Cli::Health(const CommandLine& a) {
  absl::StatusOr<grpc::health::v1::HealthCheckResponse> response =
      client_->Health(GetString(a, "service"));
  if (!response.ok()) return Fail(response.status(), "health check");
  JsonWriter j;
  j.BeginObject().Key("status").String(
      grpc::health::v1::HealthCheckResponse::ServingStatus_Name(response->status()));
  j.EndObject();
  Emit(j);
  return response->status() == grpc::health::v1::HealthCheckResponse::SERVING ? 0 : 1;
}

int Cli::Upload(const CommandLine& a) {
  const std::string& path = a.positional()[0];
  std::ifstream in(path, std::ios::binary);
  if (!in) return Fail(absl::NotFoundError("cannot open " + path));
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
  absl::StatusOr<v1::MeshInfo> info = client_->UploadMesh(header, in);
  if (!info.ok()) return Fail(info.status(), "upload of " + path);
  JsonWriter j;
  WriteMeshInfo(j, *info);
  Emit(j);
  return 0;
}

int Cli::Meshes(const CommandLine&) {
  absl::StatusOr<v1::ListMeshesResponse> response = client_->ListMeshes();
  if (!response.ok()) return Fail(response.status(), "ListMeshes");
  JsonWriter j;
  j.BeginObject().Key("meshes").BeginArray();
  for (const v1::MeshInfo& m : response->meshes()) WriteMeshInfo(j, m);
  j.EndArray().EndObject();
  Emit(j);
  return 0;
}

int Cli::Mesh(const CommandLine& a) {
  v1::GetMeshRequest request;
  request.set_mesh_id(a.positional()[0]);
  absl::StatusOr<v1::MeshInfo> info = client_->GetMesh(request);
  if (!info.ok()) return Fail(info.status(), "GetMesh");
  JsonWriter j;
  WriteMeshInfo(j, *info);
  Emit(j);
  return 0;
}

int Cli::DeleteMesh(const CommandLine& a) {
  v1::DeleteMeshRequest request;
  request.set_mesh_id(a.positional()[0]);
  request.set_cascade(a.Has("cascade"));
  absl::StatusOr<v1::DeleteMeshResponse> response = client_->DeleteMesh(request);
  if (!response.ok()) return Fail(response.status(), "DeleteMesh");
  JsonWriter j;
  j.BeginObject().Key("deleted").String(request.mesh_id()).Key("deleted_basis_ids").BeginArray();
  for (const std::string& id : response->deleted_basis_ids()) j.String(id);
  j.EndArray().EndObject();
  Emit(j);
  return 0;
}

int Cli::Build(const CommandLine& a) {
  v1::BuildBasisRequest request;
  request.set_mesh_id(a.positional()[0]);
  const std::string field = GetString(a, "field");
  if (field == "vector") {
    request.mutable_field()->set_kind(v1::FIELD_KIND_VECTOR);
  } else if (field == "nfield") {
    request.mutable_field()->set_kind(v1::FIELD_KIND_NFIELD);
    if (!a.Has("n")) throw UsageError("--field nfield needs --n N");
    request.mutable_field()->set_n(static_cast<int32_t>(ParseInt(a, "n", 0)));
  } else if (field == "tensor") {
    request.mutable_field()->set_kind(v1::FIELD_KIND_TENSOR);
  } else {
    throw UsageError("--field must be vector, nfield or tensor");
  }
  if (field != "nfield" && a.Has("n")) {
    throw UsageError("--n applies only to --field nfield (a " + field + " basis has no n)");
  }
  if (!a.Has("dim")) throw UsageError("build needs --dim D");
  const int64_t dim = ParseInt(a, "dim", 0);
  if (dim < 1 || dim > INT32_MAX) throw UsageError("--dim must be a positive integer");
  request.set_dimension(static_cast<int32_t>(dim));
  if (a.Has("sigma")) request.set_sigma(ParseDouble(a, "sigma", 40));
  request.set_seed(static_cast<uint64_t>(ParseInt(a, "seed", 0)));
  request.set_fields_per_region(static_cast<int32_t>(ParseInt(a, "fields-per-region", 0)));
  const int64_t coarse = ParseInt(a, "coarse-dim", 0);
  if (coarse < 0 || coarse >= dim) throw UsageError("--coarse-dim must be in [0, --dim)");
  request.set_coarse_dimension(static_cast<int32_t>(coarse));
  if (a.Has("quality")) {
    const std::string quality = GetString(a, "quality");
    if (quality == "low-modes" || quality == "smooth") {
      if (coarse != 0) throw UsageError("--coarse-dim combines only with --quality paper");
      request.set_quality(quality == "smooth" ? v1::BASIS_QUALITY_SMOOTH
                                              : v1::BASIS_QUALITY_LOW_MODES);
    } else if (quality != "paper") {
      throw UsageError("--quality must be paper, low-modes or smooth");
    }
  }
  if (a.Has("face-weights")) {
    // Adaptivity (paper section 4.4, Fig. 9): more, smaller regions where the weights are high.
    absl::StatusOr<std::vector<double>> weights = ReadNumbersFile(GetString(a, "face-weights"));
    if (!weights.ok()) return Fail(weights.status());
    request.mutable_face_weights()->Add(weights->begin(), weights->end());
  }
  request.set_kernel_columns(!a.Has("no-kernel-columns"));

  const bool tty = isatty(STDERR_FILENO) != 0 && &err_ == &std::cerr;
  const bool cancel_on_exit = a.Has("cancel-on-exit");
  // Ctrl-C: the build belongs to the server and goes on; say so and how to cancel it, or cancel
  // it with --cancel-on-exit (not a build this stream only joined: another client started it).
  InterruptWatch interrupt([&](const std::string& basis_id, bool joined) {
    if (tty) err_ << "\n";
    if (basis_id.empty()) {
      err_ << "fieldspace: interrupted before the server named the build; `fieldspace bases` "
              "lists running builds\n";
    } else if (cancel_on_exit && !joined) {
      v1::CancelBuildRequest cancel;
      cancel.set_basis_id(basis_id);
      absl::StatusOr<v1::CancelBuildResponse> r = client_->CancelBuild(cancel);
      if (r.ok()) {
        err_ << "fieldspace: build " << basis_id << " cancelled on the server\n";
      } else {
        Fail(r.status(), "CancelBuild");
      }
    } else {
      err_ << "fieldspace: build " << basis_id << " goes on on the server"
           << (joined ? " (another client started it)" : "")
           << "; cancel it with: fieldspace cancel " << basis_id << "\n";
    }
    err_ << std::flush;
  });
  const Clock::time_point start = Clock::now();
  v1::BuildPhase last_phase = v1::BUILD_PHASE_UNSPECIFIED;
  int last_decile = -1;
  std::string last_waiting_for;
  absl::StatusOr<v1::BasisInfo> info =
      client_->BuildBasis(request, [&](const v1::BuildBasisProgress& progress) {
        interrupt.Name(progress.basis_id(), progress.joined());
        const double overall = progress.overall_fraction();
        const int percent = static_cast<int>(std::floor(100 * overall));
        if (tty) {
          // One bar over the whole build, with the time left once there is enough to go on.
          const double elapsed = std::chrono::duration<double>(Clock::now() - start).count();
          std::string eta;
          if (overall >= 0.02 && overall < 1) {
            const int64_t left = std::llround(elapsed * (1 - overall) / overall);
            eta = absl::StrCat(" ETA ", left / 60, ":", left % 60 < 10 ? "0" : "", left % 60);
          }
          const int filled = percent * 30 / 100;
          const std::string waiting = progress.waiting_for().empty()
                                          ? ""
                                          : " waiting for replica " + progress.waiting_for();
          err_ << "\r[" << std::string(filled, '#') << std::string(30 - filled, ' ') << "] "
               << percent << "% " << PhaseName(progress.phase()) << waiting << eta << "          "
               << std::flush;
        } else if (progress.phase() != last_phase || percent / 10 != last_decile ||
                   progress.waiting_for() != last_waiting_for) {
          err_ << "build " << progress.basis_id() << ": " << PhaseName(progress.phase()) << " "
               << percent << "%" << (progress.joined() ? " (joined a running build)" : "")
               << (progress.waiting_for().empty()
                       ? ""
                       : " (waiting for replica " + progress.waiting_for() + ", which builds it)")
               << "\n";
        }
        last_phase = progress.phase();
        last_decile = percent / 10;
        last_waiting_for = progress.waiting_for();
      });
  if (tty) err_ << "\n";
  if (!info.ok()) return Fail(info.status(), "BuildBasis");
  JsonWriter j;
  WriteBasisInfo(j, *info);
  Emit(j);
  return 0;
}

int Cli::Bases(const CommandLine& a) {
  v1::ListBasesRequest request;
  request.set_mesh_id(GetString(a, "mesh"));
  absl::StatusOr<v1::ListBasesResponse> response = client_->ListBases(request);
  if (!response.ok()) return Fail(response.status(), "ListBases");
  JsonWriter j;
  j.BeginObject().Key("bases").BeginArray();
  for (const v1::BasisInfo& b : response->bases()) WriteBasisInfo(j, b);
  j.EndArray().EndObject();
  Emit(j);
  return 0;
}

int Cli::Basis(const CommandLine& a) {
  v1::GetBasisRequest request;
  request.set_basis_id(a.positional()[0]);
  absl::StatusOr<v1::BasisInfo> info = client_->GetBasis(request);
  if (!info.ok()) return Fail(info.status(), "GetBasis");
  JsonWriter j;
  WriteBasisInfo(j, *info);
  Emit(j);
  return 0;
}

int Cli::DeleteBasis(const CommandLine& a) {
  v1::DeleteBasisRequest request;
  request.set_basis_id(a.positional()[0]);
  if (absl::StatusOr<v1::DeleteBasisResponse> r = client_->DeleteBasis(request); !r.ok()) {
    return Fail(r.status(), "DeleteBasis");
  }
  JsonWriter j;
  j.BeginObject().Key("deleted").String(request.basis_id()).EndObject();
  Emit(j);
  return 0;
}

int Cli::Cancel(const CommandLine& a) {
  v1::CancelBuildRequest request;
  request.set_basis_id(a.positional()[0]);
  if (absl::StatusOr<v1::CancelBuildResponse> r = client_->CancelBuild(request); !r.ok()) {
    return Fail(r.status(), "CancelBuild");
  }
  JsonWriter j;
  j.BeginObject().Key("cancelled").String(request.basis_id()).EndObject();
  Emit(j);
  return 0;
}

int Cli::Project(const CommandLine& a) {
  absl::StatusOr<FieldFile> field = ReadFieldFile(a.positional()[1]);
  if (!field.ok()) return Fail(field.status());
  v1::ProjectRequest request;
  request.set_basis_id(a.positional()[0]);
  request.mutable_field()->set_encoding(field->encoding);
  request.mutable_field()->mutable_values()->Add(field->values.begin(), field->values.end());
  absl::StatusOr<v1::ProjectResponse> response = client_->Project(request);
  if (!response.ok()) return Fail(response.status(), "Project");
  JsonWriter j;
  j.BeginObject();
  j.Key("basis_id").String(request.basis_id());
  j.Key("relative_error").Number(response->relative_error());
  j.Key("seconds").Number(response->seconds());
  j.Key("coefficients");
  WriteNumbers(j, response->coefficients());
  j.EndObject();
  Emit(j);
  return 0;
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
      return Fail(absl::DataLossError("Lift chunks arrived out of order"));
    }
    if (field.values.empty()) {
      field.values.reserve(static_cast<size_t>(chunk.total_faces()) * field.values_per_face);
    }
    const auto& values = chunk.field().values();
    field.values.insert(field.values.end(), values.begin(), values.end());
  }

  if (absl::EndsWith(absl::AsciiStrToLower(path), ".ply")) {
    v1::GetMeshGeometryRequest geometry_request;
    geometry_request.set_mesh_id(basis->mesh_id());
    absl::StatusOr<MeshGeometry> geometry = client_->GetMeshGeometry(geometry_request);
    if (!geometry.ok()) return Fail(geometry.status(), "GetMeshGeometry");
    if (absl::Status st = WriteFieldPly(path, geometry->vertices, geometry->faces, field);
        !st.ok()) {
      return Fail(st);
    }
  } else {
    if (absl::Status st = WriteFieldText(path, field, FieldKindName(basis->field())); !st.ok()) {
      return Fail(st);
    }
  }
  return 0;
}

// --biharmonic exact|mixed (default mixed).
v1::BiharmonicForm BiharmonicFormFlag(const CommandLine& a) {
  if (!a.Has("biharmonic")) return v1::BIHARMONIC_FORM_MIXED;
  const std::string form = GetString(a, "biharmonic");
  if (form == "exact") return v1::BIHARMONIC_FORM_EXACT;
  if (form == "mixed") return v1::BIHARMONIC_FORM_MIXED;
  throw UsageError(absl::StrCat("--biharmonic must be exact or mixed, got '", form, "'"));
}

int Cli::Solve(const CommandLine& a) {
  if (!a.Has("constraints")) throw UsageError("solve needs --constraints FILE");
  const std::string constraints_path = GetString(a, "constraints");
  absl::StatusOr<std::string> text = ReadFile(constraints_path);
  if (!text.ok()) return Fail(text.status());
  absl::StatusOr<std::vector<v1::Constraint>> constraints = ParseConstraints(*text);
  if (!constraints.ok()) {
    return Fail(absl::InvalidArgumentError(
        absl::StrCat(constraints_path, ": ", constraints.status().message())));
  }
  v1::SolveRequest request;
  request.set_basis_id(a.positional()[0]);
  SetWeights(a, "mu-s", request.mutable_weights());
  request.set_raw_weights(a.Has("raw-weights"));
  request.set_biharmonic(BiharmonicFormFlag(a));
  request.set_singularities(a.Has("singularities"));
  for (v1::Constraint& c : *constraints) *request.add_constraints() = std::move(c);
  absl::StatusOr<v1::SolveResponse> response = client_->Solve(request);
  if (!response.ok()) return Fail(response.status(), "Solve");
  std::vector<double> coefficients(response->coefficients().begin(),
                                   response->coefficients().end());
  if (int rc = LiftToOut(a, request.basis_id(), coefficients); rc != 0) return rc;
  JsonWriter j;
  j.BeginObject();
  j.Key("basis_id").String(request.basis_id());
  j.Key("num_constraints").Int(request.constraints_size());
  j.Key("backward_error").Number(response->backward_error());
  j.Key("iterations").Int(response->iterations());
  j.Key("timings").BeginObject();
  j.Key("solve_ms").Number(response->timings().solve_ms());
  j.Key("total_ms").Number(response->timings().total_ms());
  j.EndObject();
  if (a.Has("out")) j.Key("out").String(GetString(a, "out"));
  if (response->has_singularities()) {
    j.Key("singularities").BeginObject();
    WriteSingularityFields(j, response->singularities());
    j.EndObject();
  }
  j.Key("coefficients");
  WriteNumbers(j, coefficients);
  j.EndObject();
  Emit(j);
  return 0;
}

int Cli::Lift(const CommandLine& a) {
  absl::StatusOr<std::vector<double>> coefficients =
      ReadNumbersFile(a.positional()[1], ParseMode(a));
  if (!coefficients.ok()) return Fail(coefficients.status());
  const v1::FieldEncoding encoding = ParseEncoding(a);
  if (a.Has("out") == a.Has("faces")) {
    throw UsageError("lift needs exactly one of --out FIELD_FILE and --faces F1,F2,...");
  }
  if (a.Has("out")) {
    const std::string out = GetString(a, "out");
    if (int rc = LiftToFile(a.positional()[0], *coefficients, encoding, out); rc != 0) {
      return rc;
    }
    JsonWriter j;
    j.BeginObject().Key("basis_id").String(a.positional()[0]).Key("out").String(out);
    j.EndObject();
    Emit(j);
    return 0;
  }
  v1::LiftRequest request;
  request.set_basis_id(a.positional()[0]);
  request.mutable_coefficients()->Add(coefficients->begin(), coefficients->end());
  request.set_encoding(encoding);
  for (int32_t f : ParseFaceList(GetString(a, "faces"))) request.add_faces(f);
  absl::StatusOr<std::vector<v1::FieldChunk>> chunks = client_->Lift(request);
  if (!chunks.ok()) return Fail(chunks.status(), "Lift");
  JsonWriter j;
  j.BeginObject().Key("basis_id").String(request.basis_id()).Key("faces").BeginArray();
  for (const v1::FieldChunk& chunk : *chunks) {
    const int n = chunk.field().faces_size();
    const int vpf = n == 0 ? 0 : chunk.field().values_size() / n;
    for (int i = 0; i < n; ++i) {
      j.BeginObject().Key("face").Int(chunk.field().faces(i)).Key("value").BeginArray();
      for (int c = 0; c < vpf; ++c) j.Number(chunk.field().values(i * vpf + c));
      j.EndArray().EndObject();
    }
  }
  j.EndArray().EndObject();
  Emit(j);
  return 0;
}

int Cli::Eigen(const CommandLine& a) {
  if (!a.Has("count")) throw UsageError("eigen needs --count K");
  v1::EigenfieldsRequest request;
  request.set_basis_id(a.positional()[0]);
  const int64_t count = ParseInt(a, "count", 0);
  if (count < 1 || count > INT32_MAX) throw UsageError("--count must be a positive integer");
  request.set_count(static_cast<int32_t>(count));
  absl::StatusOr<v1::EigenfieldsResponse> response = client_->Eigenfields(request);
  if (!response.ok()) return Fail(response.status(), "Eigenfields");
  JsonWriter j;
  j.BeginObject();
  j.Key("basis_id").String(request.basis_id());
  j.Key("seconds").Number(response->seconds());
  j.Key("eigenvalues");
  WriteNumbers(j, response->eigenvalues());
  if (a.Has("coefficients")) {
    j.Key("coefficients").BeginArray();
    const int d = response->dimension();
    for (int i = 0; d > 0 && i < response->eigenvalues_size(); ++i) {
      j.BeginArray();
      for (int c = 0; c < d; ++c) j.Number(response->coefficients(i * d + c));
      j.EndArray();
    }
    j.EndArray();
  }
  j.EndObject();
  Emit(j);
  return 0;
}

int Cli::Curvature(const CommandLine& a) {
  if (!a.Has("out")) throw UsageError("curvature needs --out FIELD_FILE");
  v1::CurvatureRequest request;
  request.set_mesh_id(a.positional()[0]);
  const v1::FieldEncoding encoding = ParseEncoding(a);
  request.set_encoding(encoding);
  request.set_estimator(ParseEstimator(a));
  request.set_principal(a.Has("principal"));
  absl::StatusOr<std::vector<v1::CurvatureChunk>> chunks = client_->Curvature(request);
  if (!chunks.ok()) return Fail(chunks.status(), "Curvature");
  FieldFile field;
  field.encoding = encoding;
  field.values_per_face = encoding == v1::FIELD_ENCODING_AMBIENT ? 6 : 3;
  std::vector<double> principal;
  double k_min = std::numeric_limits<double>::infinity();
  double k_max = -std::numeric_limits<double>::infinity();
  double server_ms = 0;
  for (const v1::CurvatureChunk& chunk : *chunks) {
    if (chunk.start_face() != field.num_faces()) {
      return Fail(absl::DataLossError("Curvature chunks arrived out of order"));
    }
    field.values.insert(field.values.end(), chunk.tensor().values().begin(),
                        chunk.tensor().values().end());
    for (int i = 0; i < chunk.k1_size(); ++i) {
      k_min = std::min<double>(k_min, chunk.k2(i));
      k_max = std::max<double>(k_max, chunk.k1(i));
      principal.insert(principal.end(), {chunk.k1(i), chunk.k2(i)});
      for (int c = 0; c < 3; ++c) principal.push_back(chunk.d1(3 * i + c));
      for (int c = 0; c < 3; ++c) principal.push_back(chunk.d2(3 * i + c));
    }
    server_ms = chunk.server_ms();
  }
  const std::string out = GetString(a, "out");
  if (absl::Status st = WriteFieldText(out, field, "tensor"); !st.ok()) return Fail(st);
  if (a.Has("principal")) {
    FieldFile p;
    p.encoding = v1::FIELD_ENCODING_DOF;
    p.values_per_face = 8;
    p.values = std::move(principal);
    if (absl::Status st = WriteFieldText(GetString(a, "principal"), p, "principal curvatures");
        !st.ok()) {
      return Fail(st);
    }
  }
  JsonWriter j;
  j.BeginObject();
  j.Key("mesh_id").String(request.mesh_id());
  j.Key("faces").Int(field.num_faces());
  j.Key("estimator").String(GetString(a, "estimator", "jet"));
  j.Key("encoding").String(encoding == v1::FIELD_ENCODING_AMBIENT ? "ambient" : "dof");
  j.Key("out").String(out);
  if (a.Has("principal")) {
    j.Key("principal").String(GetString(a, "principal"));
    j.Key("k_min").Number(k_min);
    j.Key("k_max").Number(k_max);
  }
  j.Key("server_ms").Number(server_ms);
  j.EndObject();
  Emit(j);
  return 0;
}

int Cli::Smoothest(const CommandLine& a) {
  v1::EigenfieldsRequest request;
  request.set_basis_id(a.positional()[0]);
  request.set_count(1);
  absl::StatusOr<v1::EigenfieldsResponse> response = client_->Eigenfields(request);
  if (!response.ok()) return Fail(response.status(), "Eigenfields");
  const std::vector<double> coefficients(response->coefficients().begin(),
                                         response->coefficients().end());
  if (int rc = LiftToOut(a, request.basis_id(), coefficients); rc != 0) return rc;
  JsonWriter j;
  j.BeginObject();
  j.Key("basis_id").String(request.basis_id());
  // The field is M-normalized (unit L2 norm); its Dirichlet energy x^T (U^T S U) x is the lowest
  // reduced eigenvalue.
  j.Key("energy").Number(response->eigenvalues(0));
  j.Key("seconds").Number(response->seconds());
  if (a.Has("out")) j.Key("out").String(GetString(a, "out"));
  j.Key("coefficients");
  WriteNumbers(j, coefficients);
  j.EndObject();
  Emit(j);
  return 0;
}

int Cli::Singularities(const CommandLine& a) {
  absl::StatusOr<std::vector<double>> coefficients =
      ReadNumbersFile(a.positional()[1], ParseMode(a));
  if (!coefficients.ok()) return Fail(coefficients.status());
  v1::SingularitiesRequest request;
  request.set_basis_id(a.positional()[0]);
  request.mutable_coefficients()->Add(coefficients->begin(), coefficients->end());
  request.set_zero_tolerance(ParseDouble(a, "zero-tolerance", 0.0));
  absl::StatusOr<v1::SingularitiesResponse> response = client_->Singularities(request);
  if (!response.ok()) return Fail(response.status(), "Singularities");
  JsonWriter j;
  j.BeginObject();
  j.Key("basis_id").String(request.basis_id());
  WriteSingularityFields(j, *response);
  j.EndObject();
  Emit(j);
  return 0;
}

int Cli::Smooth(const CommandLine& a) {
  absl::StatusOr<FieldFile> field = ReadFieldFile(a.positional()[1]);
  if (!field.ok()) return Fail(field.status());
  v1::SmoothRequest request;
  request.set_basis_id(a.positional()[0]);
  request.mutable_field()->set_encoding(field->encoding);
  request.mutable_field()->mutable_values()->Add(field->values.begin(), field->values.end());
  SetWeights(a, "mu-s", request.mutable_weights());
  request.set_scale_free(!a.Has("raw-weights"));
  request.set_singularities(a.Has("singularities"));
  if (absl::Status st = ReadFaceWeights(a, request.mutable_face_weights()); !st.ok()) {
    return Fail(st);
  }
  absl::StatusOr<v1::SmoothResponse> response = client_->Smooth(request);
  if (!response.ok()) return Fail(response.status(), "Smooth");
  return EmitSmoothed(a, request.basis_id(), request.scale_free(), *response);
}

int Cli::Align(const CommandLine& a) {
  if (!a.Has("curvature")) {
    throw UsageError("align needs --curvature (the only target so far: the principal directions)");
  }
  v1::GetBasisRequest basis_request;
  basis_request.set_basis_id(a.positional()[0]);
  absl::StatusOr<v1::BasisInfo> basis = client_->GetBasis(basis_request);
  if (!basis.ok()) return Fail(basis.status(), "GetBasis");
  if (a.Has("n") && (basis->field().kind() != v1::FIELD_KIND_NFIELD ||
                     ParseInt(a, "n", 0) != basis->field().n())) {
    return Fail(absl::InvalidArgumentError(
        absl::StrCat("--n ", ParseInt(a, "n", 0), " does not match the basis's field type ",
                     FieldKindName(basis->field()), " (align uses the basis's n)")));
  }
  v1::AlignRequest request;
  request.set_basis_id(a.positional()[0]);
  SetWeights(a, "smooth-mu", request.mutable_weights());
  request.set_estimator(ParseEstimator(a));
  request.set_singularities(a.Has("singularities"));
  absl::StatusOr<v1::SmoothResponse> response = client_->Align(request);
  if (!response.ok()) return Fail(response.status(), "Align");
  return EmitSmoothed(a, request.basis_id(), true, *response);
}

int Cli::EmitSmoothed(const CommandLine& a, const std::string& basis_id, bool scale_free,
                      const v1::SmoothResponse& response) {
  const std::vector<double> coefficients(response.coefficients().begin(),
                                         response.coefficients().end());
  if (int rc = LiftToOut(a, basis_id, coefficients); rc != 0) return rc;
  const v1::SmoothTimings& t = response.timings();
  JsonWriter j;
  j.BeginObject();
  j.Key("basis_id").String(basis_id);
  j.Key("scale_free").Bool(scale_free);
  j.Key("timings").BeginObject();
  j.Key("rhs_ms").Number(t.rhs_ms());
  j.Key("weighted_mass_ms").Number(t.weighted_mass_ms());
  j.Key("factorize_ms").Number(t.factorize_ms());
  j.Key("solve_ms").Number(t.solve_ms());
  j.Key("total_ms").Number(t.total_ms());
  j.EndObject();
  if (a.Has("out")) j.Key("out").String(GetString(a, "out"));
  if (response.has_singularities()) {
    j.Key("singularities").BeginObject();
    WriteSingularityFields(j, response.singularities());
    j.EndObject();
  }
  j.Key("coefficients");
  WriteNumbers(j, coefficients);
  j.EndObject();
  Emit(j);
  return 0;
}

int Cli::Design(const CommandLine& a) {
  if (!a.Has("script")) throw UsageError("design needs --script EDITS.jsonl");
  const std::string script = GetString(a, "script");
  absl::StatusOr<std::string> text = ReadFile(script);
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
        ParseEdit(line, absl::StrCat(script, ":", line_number));
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
  o->set_basis_id(a.positional()[0]);
  SetWeights(a, "mu-s", o->mutable_weights());
  o->set_raw_weights(a.Has("raw-weights"));
  o->set_biharmonic(BiharmonicFormFlag(a));
  if (a.Has("align-curvature") && a.Has("data")) {
    throw UsageError("design takes one data term: --align-curvature or --data FIELD_FILE");
  }
  if (a.Has("face-weights") && !a.Has("data")) {
    throw UsageError("design --face-weights weighs the --data field");
  }
  if (a.Has("mu-a") && !a.Has("align-curvature") && !a.Has("data")) {
    throw UsageError("design --mu-a weighs a data term: give --align-curvature or --data");
  }
  if (a.Has("align-curvature")) {
    v1::CurvatureEstimator estimator = ParseEstimator(a);
    o->mutable_data()->mutable_curvature()->set_estimator(estimator);
  } else if (a.Has("data")) {
    absl::StatusOr<FieldFile> field = ReadFieldFile(GetString(a, "data"));
    if (!field.ok()) return Fail(field.status());
    v1::FieldValues* values = o->mutable_data()->mutable_field();
    values->set_encoding(field->encoding);
    values->mutable_values()->Add(field->values.begin(), field->values.end());
    if (absl::Status st = ReadFaceWeights(a, o->mutable_data()->mutable_face_weights()); !st.ok()) {
      return Fail(st);
    }
  }
  o->set_watch_encoding(v1::FIELD_ENCODING_AMBIENT);
  o->set_singularities(a.Has("singularities"));
  for (int32_t f : ParseFaceList(GetString(a, "watch"))) o->add_watch_faces(f);
  kinds.insert(kinds.begin(), "open");

  const bool coefficients = !a.Has("no-coefficients");
  // Survives the loss of its replica (a daemon behind a router that dies or drains): the session
  // is reopened and replayed, and the answer of that edit says "resumed": true.
  ResumableDesign session(client_.get(), open.open());
  absl::Status failed;
  for (size_t i = 0; i < edits.size() + 1; ++i) {
    const auto sent = Clock::now();
    absl::StatusOr<ResumableDesign::Update> resumable =
        i == 0 ? session.Open(0) : session.Edit(edits[i - 1]);
    if (!resumable.ok()) {
      failed = resumable.status();
      break;
    }
    const v1::DesignUpdate* update = &resumable->update;
    const double round_trip_ms =
        std::chrono::duration<double, std::milli>(Clock::now() - sent).count();
    JsonWriter j;
    j.BeginObject();
    j.Key("seq").Int(static_cast<int64_t>(update->seq()));
    j.Key("edit").String(kinds[i]);
    j.Key("num_constraints").Int(update->num_constraints());
    j.Key("num_hard_constraints").Int(update->num_hard_constraints());
    j.Key("refactorized").Bool(update->timings().refactorized());
    j.Key("backward_error").Number(update->backward_error());  // null when unchecked (NaN)
    j.Key("iterations").Int(update->iterations());
    if (resumable->resumed) j.Key("resumed").Bool(true);
    j.Key("timings").BeginObject();
    j.Key("edit_ms").Number(update->timings().edit_ms());
    j.Key("lift_ms").Number(update->timings().lift_ms());
    j.Key("total_ms").Number(update->timings().total_ms());
    j.Key("round_trip_ms").Number(round_trip_ms);
    j.EndObject();
    j.Key("watched").BeginArray();
    const auto& watched = update->watched();
    const int n = watched.faces_size();
    const int vpf = n == 0 ? 0 : watched.values_size() / n;
    for (int f = 0; f < n; ++f) {
      j.BeginObject().Key("face").Int(watched.faces(f)).Key("value").BeginArray();
      for (int c = 0; c < vpf; ++c) j.Number(watched.values(f * vpf + c));
      j.EndArray().EndObject();
    }
    j.EndArray();
    if (update->has_singularities()) {
      const v1::SingularityChanges& c = update->singularities();
      j.Key("singularities").BeginObject();
      j.Key("n").Int(c.n());
      j.Key("count").Int(c.count());
      j.Key("index_sum").Number(c.index_sum());
      j.Key("appeared").BeginArray();
      for (const v1::Singularity& s : c.appeared()) WriteSingularity(j, s);
      j.EndArray();
      j.Key("vanished");
      WriteNumbers(j, c.vanished());
      j.EndObject();
    }
    if (coefficients) {
      j.Key("coefficients");
      WriteNumbers(j, update->coefficients());
    }
    j.EndObject();
    Emit(j);
  }
  if (!failed.ok()) return Fail(failed, "Design");
  if (absl::Status status = session.Close(); !status.ok()) return Fail(status, "Design");
  return 0;
}

}  // namespace

int RunCli(const std::vector<std::string>& args, std::ostream& out, std::ostream& err) {
  Cli cli(out, err);
  return cli.Run(args);
}

}  // namespace fieldspace::client
