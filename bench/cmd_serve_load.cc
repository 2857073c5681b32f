// `fieldspace-bench serve-load MESH --dim D [--field vector|nfield|tensor] [--n N] [--sessions S]
//  [--edits E] [--watch W] [--threads T] [--rate HZ] [--server HOST:PORT]`: load on fieldspaced's
// interactive
// path. Without --server it starts an in-process server on 127.0.0.1:0 with a temporary store.
// Uploads MESH, builds (or finds) the basis, then runs S concurrent design sessions of E edits each
// (add / move / remove constraints on random faces, W watched faces) and prints the latency
// distribution of the server-side edit time and of the client round trip, and the throughput.
// --rate HZ paces each session like a user dragging a constraint: one edit every 1/HZ seconds
// (start times staggered), the round trip measured from the send; 0 (default) sends each edit as
// soon as the previous answer arrives (closed loop, a saturation test). RSS is sampled before and
// after the sessions ("rss_mb") to show that memory stays bounded. Then --lifts L (default 5) Lift
// calls of all faces (DOF encoding, random coefficients) report the daemon's server-side lift time
// (FieldChunk.server_ms) and the client's round trip; an in-process server also reports the same
// lift through the basis's LiftPlan called directly ("liftplan_ms"), the bench path it is
// compared with (daemon and LiftPlan lifts alternate, so load changes hit both alike).

#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"
#include "bench/bench_util.h"
#include "bench/commands.h"
#include "client/field_client.h"
#include "core/mesh/mesh_io.h"
#include "core/subspace/projection.h"
#include "server/field_server.h"
#include "server/registry.h"

namespace fieldspace::bench {
namespace {

namespace v1 = ::fieldspace::v1;

struct Percentiles {
  double p50 = 0, p90 = 0, p99 = 0, max = 0, mean = 0;
};

Percentiles Summarize(std::vector<double> v) {
  Percentiles p;
  if (v.empty()) return p;
  std::sort(v.begin(), v.end());
  auto at = [&](double q) { return v[std::min(v.size() - 1, static_cast<size_t>(q * v.size()))]; };
  p.p50 = at(0.5);
  p.p90 = at(0.9);
  p.p99 = at(0.99);
  p.max = v.back();
  double sum = 0;
  for (double x : v) sum += x;
  p.mean = sum / v.size();
  return p;
}

void WritePercentiles(JsonWriter& j, const std::string& key, const Percentiles& p) {
  j.BeginObject(key);
  j.Double("p50", p.p50).Double("p90", p.p90).Double("p99", p.p99).Double("max", p.max);
  j.Double("mean", p.mean);
  j.EndObject();
}

// `status` with "<what>: " before its message.
absl::Status Prefixed(const absl::Status& status, const std::string& what) {
  if (status.ok()) return status;
  return absl::Status(status.code(), absl::StrCat(what, ": ", status.message()));
}

struct SessionResult {
  absl::Status status;
  double open_ms = 0;
  std::vector<double> server_ms;
  std::vector<double> round_trip_ms;
  int refactorizations = 0;
};

SessionResult RunSession(const client::FieldClient& field_client, const std::string& basis_id,
                         int32_t num_faces, int32_t values_per_face, int edits, int watch,
                         uint32_t seed, double rate) {
  SessionResult out;
  std::mt19937 rng(seed);
  std::uniform_int_distribution<int32_t> face(0, num_faces - 1);
  std::normal_distribution<double> value(0.0, 1.0);
  std::unique_ptr<client::DesignStream> stream = field_client.Design(basis_id);
  v1::OpenDesign open;
  open.set_basis_id(basis_id);
  open.mutable_weights()->set_mu_s(1.0);
  open.mutable_weights()->set_mu_b(0.0);
  open.mutable_weights()->set_mu_c(1.0);
  for (int i = 0; i < watch; ++i) open.add_watch_faces(face(rng));
  open.set_watch_encoding(v1::FIELD_ENCODING_AMBIENT);
  auto t0 = std::chrono::steady_clock::now();
  if (absl::StatusOr<v1::DesignUpdate> opened = stream->Open(open); !opened.ok()) {
    out.status = Prefixed(opened.status(), "Design open");
    return out;
  }
  out.open_ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  std::vector<int32_t> live;  // constraint ids in the session
  int32_t next_id = 1;
  const auto paced_start =
      std::chrono::steady_clock::now() +
      std::chrono::duration_cast<std::chrono::steady_clock::duration>(std::chrono::duration<double>(
          rate > 0 ? static_cast<double>(seed % 1000) / 1000.0 / rate : 0.0));
  for (int e = 0; e < edits; ++e) {
    if (rate > 0) {
      std::this_thread::sleep_until(paced_start +
                                    std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                                        std::chrono::duration<double>(e / rate)));
    }
    v1::DesignRequest r;
    r.set_seq(e + 1);
    const int kind = live.size() < 4 ? 0 : (live.size() > 24 ? 2 : static_cast<int>(rng() % 3));
    auto fill = [&](google::protobuf::RepeatedField<double>* v) {
      for (int c = 0; c < values_per_face; ++c) v->Add(value(rng));
    };
    if (kind == 0) {
      v1::Constraint* c = r.mutable_add()->mutable_constraint();
      r.mutable_add()->set_id(next_id);
      c->set_face(face(rng));
      fill(c->mutable_value());
      c->set_encoding(v1::FIELD_ENCODING_AMBIENT);
      live.push_back(next_id++);
    } else if (kind == 1) {
      r.mutable_move()->set_id(live[rng() % live.size()]);
      r.mutable_move()->set_face(face(rng));
      fill(r.mutable_move()->mutable_value());
      r.mutable_move()->set_encoding(v1::FIELD_ENCODING_AMBIENT);
    } else {
      const size_t k = rng() % live.size();
      r.mutable_remove()->set_id(live[k]);
      live.erase(live.begin() + static_cast<std::ptrdiff_t>(k));
    }
    t0 = std::chrono::steady_clock::now();
    absl::StatusOr<v1::DesignUpdate> update = stream->Edit(r);
    if (!update.ok()) break;  // Close gives the session's status
    out.round_trip_ms.push_back(
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
    out.server_ms.push_back(update->timings().total_ms());
    out.refactorizations += update->timings().refactorized() ? 1 : 0;
  }
  out.status = Prefixed(stream->Close(), "Design");
  return out;
}

}  // namespace

int RunServeLoad(const Args& args) {
  auto dim = args.GetInt("dim", 0);
  auto sessions = args.GetInt("sessions", 4);
  auto edits = args.GetInt("edits", 200);
  auto watch = args.GetInt("watch", 16);
  auto threads = args.GetInt("threads", 0);
  auto n = args.GetInt("n", 4);
  auto lifts = args.GetInt("lifts", 5);
  for (const auto* v : {&dim, &sessions, &edits, &watch, &threads, &n, &lifts}) {
    if (!v->ok()) return ReportError(v->status());
  }
  auto rate = args.GetDouble("rate", 0.0);
  if (!rate.ok()) return ReportError(rate.status());
  if (!(*rate >= 0.0 && *rate <= 1e4)) {
    return ReportError(absl::InvalidArgumentError("--rate must be in [0, 10000] edits/s"));
  }
  if (*dim < 1 || *sessions < 1 || *edits < 1 || *watch < 0 || *lifts < 0) {
    return ReportError(absl::InvalidArgumentError(
        "need --dim >= 1, --sessions >= 1, --edits >= 1, --watch >= 0, --lifts >= 0"));
  }
  const std::string field = args.Get("field").value_or("vector");
  v1::FieldType type;
  int32_t values_per_face = 3;
  if (field == "vector") {
    type.set_kind(v1::FIELD_KIND_VECTOR);
  } else if (field == "nfield") {
    type.set_kind(v1::FIELD_KIND_NFIELD);
    type.set_n(static_cast<int32_t>(*n));
  } else if (field == "tensor") {
    type.set_kind(v1::FIELD_KIND_TENSOR);
    values_per_face = 6;
  } else {
    return ReportError(absl::InvalidArgumentError("--field must be vector, nfield or tensor"));
  }

  auto mesh = ReadMeshFile(args.positional()[0]);
  if (!mesh.ok()) return ReportError(mesh.status());

  std::unique_ptr<server::FieldServer> local;
  std::filesystem::path store;
  std::string address = args.Get("server").value_or("");
  if (address.empty()) {
    store =
        std::filesystem::temp_directory_path() / absl::StrCat("fieldspace_serve_load_", ::getpid());
    server::FieldServerOptions options;
    options.store_dir = store.string();
    options.threads = static_cast<int32_t>(*threads);
    auto started = server::FieldServer::Start(options);
    if (!started.ok()) return ReportError(started.status());
    local = std::move(*started);
    address = local->address();
  }
  auto cleanup = [&] {
    local.reset();
    if (!store.empty()) std::filesystem::remove_all(store);
  };
  client::FieldClientOptions client_options;
  client_options.address = address;
  client_options.upload_chunk_bytes = 4 << 20;
  absl::StatusOr<std::unique_ptr<client::FieldClient>> field_client =
      client::FieldClient::Create(client_options);
  if (!field_client.ok()) {
    cleanup();
    return ReportError(field_client.status());
  }

  // Upload as raw arrays, in 4 MiB chunks.
  Stopwatch upload_watch;
  absl::StatusOr<v1::MeshInfo> info =
      (*field_client)
          ->UploadMeshArrays(mesh->arrays,
                             std::filesystem::path(args.positional()[0]).filename().string());
  if (!info.ok()) {
    cleanup();
    return ReportError(Prefixed(info.status(), "UploadMesh"));
  }
  const double upload_seconds = upload_watch.Seconds();

  Stopwatch build_watch;
  v1::BuildBasisRequest build;
  build.set_mesh_id(info->id());
  *build.mutable_field() = type;
  build.set_dimension(static_cast<int32_t>(*dim));
  absl::StatusOr<v1::BasisInfo> basis = (*field_client)->BuildBasis(build);
  if (!basis.ok()) {
    cleanup();
    return ReportError(Prefixed(basis.status(), "BuildBasis"));
  }
  const double build_seconds = build_watch.Seconds();

  const double rss_before_mb = CurrentRssMb();
  Stopwatch load_watch;
  std::vector<SessionResult> results(static_cast<size_t>(*sessions));
  std::vector<std::thread> workers;
  for (int64_t s = 0; s < *sessions; ++s) {
    workers.emplace_back([&, s] {
      results[s] = RunSession(**field_client, basis->id(), info->num_faces(), values_per_face,
                              static_cast<int>(*edits), static_cast<int>(*watch),
                              static_cast<uint32_t>(1000 + s), *rate);
    });
  }
  for (auto& w : workers) w.join();
  const double load_seconds = load_watch.Seconds();
  const double rss_after_mb = CurrentRssMb();
  std::vector<double> server_ms, round_trip_ms, open_ms;
  int refactorizations = 0;
  for (const SessionResult& r : results) {
    if (!r.status.ok()) {
      cleanup();
      return ReportError(r.status);
    }
    server_ms.insert(server_ms.end(), r.server_ms.begin(), r.server_ms.end());
    round_trip_ms.insert(round_trip_ms.end(), r.round_trip_ms.begin(), r.round_trip_ms.end());
    open_ms.push_back(r.open_ms);
    refactorizations += r.refactorizations;
  }
  // All-faces lifts through the daemon (and, in process, through the LiftPlan directly).
  std::vector<double> lift_server_ms, lift_round_trip_ms, liftplan_ms;
  {
    std::mt19937 rng(7);
    std::normal_distribution<double> value(0.0, 1.0);
    v1::LiftRequest lift;
    lift.set_basis_id(basis->id());
    lift.set_encoding(v1::FIELD_ENCODING_DOF);
    for (int32_t i = 0; i < basis->columns(); ++i) lift.add_coefficients(value(rng));
    // The same served basis, for the LiftPlan called directly (in-process servers only).
    std::shared_ptr<const server::ServedBasis> served;
    if (local != nullptr) {
      auto found = local->registry()->GetBasis(basis->id());
      if (!found.ok()) {
        cleanup();
        return ReportError(found.status());
      }
      served = *std::move(found);
    }
    const Eigen::Map<const Eigen::VectorXd> x(lift.coefficients().data(),
                                              lift.coefficients().size());
    std::vector<double> out(served != nullptr ? served->system->dofs() : 0);
    // Daemon and LiftPlan lifts alternate, so that a change in machine load hits both alike.
    for (int64_t l = 0; l < *lifts; ++l) {
      Stopwatch watch;
      absl::StatusOr<std::vector<v1::FieldChunk>> chunks = (*field_client)->Lift(lift);
      if (!chunks.ok() || chunks->empty()) {
        cleanup();
        return ReportError(
            Prefixed(chunks.ok() ? absl::InternalError("no chunks") : chunks.status(), "Lift"));
      }
      lift_round_trip_ms.push_back(watch.Seconds() * 1e3);
      lift_server_ms.push_back(chunks->back().server_ms());
      if (served == nullptr) continue;
      Stopwatch plan_watch;
      if (absl::Status st = LiftInto(*served->system, x, absl::MakeSpan(out)); !st.ok()) {
        cleanup();
        return ReportError(st);
      }
      liftplan_ms.push_back(plan_watch.Seconds() * 1e3);
    }
  }

  JsonWriter j;
  j.BeginObject();
  j.String("command", "serve-load");
  j.String("mesh", args.positional()[0]);
  j.Int("faces", info->num_faces());
  j.String("field", field);
  j.Int("dimension", basis->columns());
  j.String("server", local != nullptr ? "in-process" : address);
  j.Double("upload_seconds", upload_seconds);
  j.Double("build_seconds", build_seconds);
  j.Int("sessions", *sessions);
  j.Int("edits", static_cast<int64_t>(server_ms.size()));
  j.Int("watched_faces", *watch);
  j.Double("rate_hz", *rate);
  j.Int("refactorizations", refactorizations);
  j.Double("edits_per_second", static_cast<double>(server_ms.size()) / load_seconds);
  WritePercentiles(j, "open_ms", Summarize(open_ms));
  WritePercentiles(j, "server_edit_ms", Summarize(server_ms));
  WritePercentiles(j, "round_trip_ms", Summarize(round_trip_ms));
  j.BeginObject("lift_all_faces").Int("lifts", *lifts);
  WritePercentiles(j, "server_ms", Summarize(lift_server_ms));
  WritePercentiles(j, "round_trip_ms", Summarize(lift_round_trip_ms));
  if (!liftplan_ms.empty()) WritePercentiles(j, "liftplan_ms", Summarize(liftplan_ms));
  j.EndObject();
  j.BeginObject("rss_mb").Double("before", rss_before_mb).Double("after", rss_after_mb).EndObject();
  j.Double("peak_rss_mb", PeakRssMb());
  j.EndObject();
  std::printf("%s\n", j.str().c_str());
  cleanup();
  return 0;
}

}  // namespace fieldspace::bench
