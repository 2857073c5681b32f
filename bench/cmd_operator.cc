// `fieldspace-bench operator MESH --field vector|nfield|tensor [--n N] [--out DIR] [--timing]`:
// assembles the field operator (docs/conventions.md, Operators) and writes DIR/S.mtx and DIR/M.mtx
// (MatrixMarket coordinate real general, both triangles, 1-based, %.17g; M as a diagonal sparse
// matrix) in the DOF order of docs/conventions.md. Prints {"dofs":..,"nnz_s":..}; --timing adds
// "seconds":{"load":..,"assemble":..[,"write":..]}.
#include "bench/cmd_operator.h"

#include <cstdio>
#include <filesystem>
#include <optional>
#include <string>
#include <system_error>

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"
#include "bench/bench_util.h"
#include "bench/commands.h"
#include "core/linalg/matrix_market.h"
#include "core/mesh/mesh_io.h"
#include "core/mesh/triangle_mesh.h"
#include "core/operators/field_operator.h"
#include "core/operators/field_type.h"

namespace fieldspace::bench {

// --field and --n as a FieldType; --n is only read for n-fields.
absl::StatusOr<FieldType> FieldTypeFromArgs(const Args& args) {
  const std::optional<std::string> field = args.Get("field");
  if (!field.has_value()) return absl::InvalidArgumentError("--field is required");
  std::optional<int32_t> n;
  if (*field == "nfield" && args.Has("n")) {
    absl::StatusOr<int64_t> value = args.GetInt("n", 0);
    if (!value.ok()) return value.status();
    if (*value < 1 || *value > 64) {
      return absl::InvalidArgumentError(absl::StrCat("--n ", *value, " outside [1, 64]"));
    }
    n = static_cast<int32_t>(*value);
  }
  return ParseFieldType(*field, n);
}

absl::StatusOr<TriangleMesh> LoadBenchMesh(const std::string& path) {
  absl::StatusOr<MeshReadResult> read = ReadMeshFile(path);
  if (!read.ok()) return read.status();
  return TriangleMesh::Create(std::move(read->arrays));
}

int RunOperator(const Args& args) {
  auto type = FieldTypeFromArgs(args);
  if (!type.ok()) return ReportError(type.status());

  Stopwatch load_watch;
  auto mesh = LoadBenchMesh(args.positional()[0]);
  if (!mesh.ok()) return ReportError(mesh.status());
  const double load_seconds = load_watch.Seconds();

  Stopwatch assemble_watch;
  auto op = BuildFieldOperator(*mesh, *type);
  if (!op.ok()) return ReportError(op.status());
  const double assemble_seconds = assemble_watch.Seconds();

  std::optional<double> write_seconds;
  if (const std::optional<std::string> out = args.Get("out"); out.has_value()) {
    Stopwatch write_watch;
    std::error_code ec;
    std::filesystem::create_directories(*out, ec);
    if (ec) {
      return ReportError(absl::InvalidArgumentError(
          absl::StrCat("cannot create output directory ", *out, ": ", ec.message())));
    }
    const std::filesystem::path dir(*out);
    if (auto st = WriteMatrixMarket((dir / "S.mtx").string(), op->stiffness); !st.ok()) {
      return ReportError(st);
    }
    if (auto st = WriteMatrixMarketDiagonal((dir / "M.mtx").string(), op->mass); !st.ok()) {
      return ReportError(st);
    }
    write_seconds = write_watch.Seconds();
  }

  JsonWriter json;
  json.BeginObject().Int("dofs", op->dofs()).Int("nnz_s", op->stiffness.nonZeros());
  if (args.Has("timing")) {
    json.BeginObject("seconds").Double("load", load_seconds).Double("assemble", assemble_seconds);
    if (write_seconds.has_value()) json.Double("write", *write_seconds);
    json.EndObject();
  }
  json.EndObject();
  std::printf("%s\n", json.str().c_str());
  return 0;
}

}  // namespace fieldspace::bench
