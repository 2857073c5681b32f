// The CLI's basis commands: build (with its progress and Ctrl-C), bases, basis, delete-basis,
// cancel.

#include <unistd.h>

#include <chrono>
#include <cmath>
#include <iostream>
#include <mutex>

#include "absl/strings/str_cat.h"
#include "client/cli_commands.h"
#include "client/cli_flags.h"
#include "client/cli_json.h"
#include "client/interrupt_watch.h"

namespace fieldspace::client::cli {

namespace v1 = ::fieldspace::v1;
using Clock = std::chrono::steady_clock;

int Build(Cli& cli, const CommandLine& a) {
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
  // Adaptivity (paper section 4.4, Fig. 9): more, smaller regions where the weights are high.
  if (absl::Status st = ReadFaceWeights(a, request.mutable_face_weights()); !st.ok()) {
    return cli.FailLocal(st);
  }
  request.set_kernel_columns(!a.Has("no-kernel-columns"));

  const bool tty = isatty(STDERR_FILENO) != 0 && &cli.err() == &std::cerr;
  const bool cancel_on_exit = a.Has("cancel-on-exit");
  // Ctrl-C: the build belongs to the server and goes on; say so and how to cancel it, or cancel
  // it with --cancel-on-exit (not a build this stream only joined: another client started it).
  InterruptWatch interrupt([&](const std::string& basis_id, bool joined) {
    if (tty) cli.err() << "\n";
    if (basis_id.empty()) {
      cli.err() << "fieldspace: interrupted before the server named the build; `fieldspace "
                << cli.GlobalFlags() << " bases` lists running builds\n";
    } else if (cancel_on_exit && !joined) {
      v1::CancelBuildRequest cancel;
      cancel.set_basis_id(basis_id);
      absl::StatusOr<v1::CancelBuildResponse> r = cli.client().CancelBuild(cancel);
      if (r.ok()) {
        cli.err() << "fieldspace: build " << basis_id << " cancelled on the server\n";
      } else {
        cli.Fail(r.status(), "CancelBuild");
      }
    } else {
      cli.err() << "fieldspace: build " << basis_id << " goes on on the server"
                << (joined ? " (another client started it)" : "") << "; cancel it with: fieldspace "
                << cli.GlobalFlags() << " cancel " << basis_id << "\n";
    }
    cli.err() << std::flush;
  });
  const Clock::time_point start = Clock::now();
  v1::BuildPhase last_phase = v1::BUILD_PHASE_UNSPECIFIED;
  int last_decile = -1;
  std::string last_waiting_for;
  absl::StatusOr<v1::BasisInfo> info =
      cli.client().BuildBasis(request, [&](const v1::BuildBasisProgress& progress) {
        interrupt.Name(progress.basis_id(), progress.joined());
        // Not inside the Ctrl-C message (the interrupt writes to the same stream).
        const std::lock_guard<std::mutex> output(interrupt.output_mutex());
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
          cli.err() << "\r[" << std::string(filled, '#') << std::string(30 - filled, ' ') << "] "
                    << percent << "% " << PhaseName(progress.phase()) << waiting << eta
                    << "          " << std::flush;
        } else if (progress.phase() != last_phase || percent / 10 != last_decile ||
                   progress.waiting_for() != last_waiting_for) {
          cli.err() << "build " << progress.basis_id() << ": " << PhaseName(progress.phase()) << " "
                    << percent << "%" << (progress.joined() ? " (joined a running build)" : "")
                    << (progress.waiting_for().empty()
                            ? ""
                            : " (waiting for replica " + progress.waiting_for() +
                                  ", which builds it)")
                    << "\n";
        }
        last_phase = progress.phase();
        last_decile = percent / 10;
        last_waiting_for = progress.waiting_for();
      });
  {
    const std::lock_guard<std::mutex> output(interrupt.output_mutex());
    if (tty) cli.err() << "\n";
    if (!info.ok()) return cli.Fail(info.status(), "BuildBasis");
  }
  JsonWriter j;
  WriteBasisInfo(j, *info);
  cli.Emit(j);
  return 0;
}

int Bases(Cli& cli, const CommandLine& a) {
  v1::ListBasesRequest request;
  request.set_mesh_id(GetString(a, "mesh"));
  absl::StatusOr<v1::ListBasesResponse> response = cli.client().ListBases(request);
  if (!response.ok()) return cli.Fail(response.status(), "ListBases");
  JsonWriter j;
  j.BeginObject().Key("bases").BeginArray();
  for (const v1::BasisInfo& b : response->bases()) WriteBasisInfo(j, b);
  j.EndArray().EndObject();
  cli.Emit(j);
  return 0;
}

int Basis(Cli& cli, const CommandLine& a) {
  v1::GetBasisRequest request;
  request.set_basis_id(a.positional()[0]);
  absl::StatusOr<v1::BasisInfo> info = cli.client().GetBasis(request);
  if (!info.ok()) return cli.Fail(info.status(), "GetBasis");
  JsonWriter j;
  WriteBasisInfo(j, *info);
  cli.Emit(j);
  return 0;
}

int DeleteBasis(Cli& cli, const CommandLine& a) {
  v1::DeleteBasisRequest request;
  request.set_basis_id(a.positional()[0]);
  if (absl::StatusOr<v1::DeleteBasisResponse> r = cli.client().DeleteBasis(request); !r.ok()) {
    return cli.Fail(r.status(), "DeleteBasis");
  }
  JsonWriter j;
  j.BeginObject().Key("deleted").String(request.basis_id()).EndObject();
  cli.Emit(j);
  return 0;
}

int Cancel(Cli& cli, const CommandLine& a) {
  v1::CancelBuildRequest request;
  request.set_basis_id(a.positional()[0]);
  if (absl::StatusOr<v1::CancelBuildResponse> r = cli.client().CancelBuild(request); !r.ok()) {
    return cli.Fail(r.status(), "CancelBuild");
  }
  JsonWriter j;
  j.BeginObject().Key("cancelled").String(request.basis_id()).EndObject();
  cli.Emit(j);
  return 0;
}

}  // namespace fieldspace::client::cli
