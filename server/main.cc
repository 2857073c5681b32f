// fieldspaced: the fieldspace gRPC daemon.
//
//   fieldspaced --listen HOST:PORT --store DIR [--data-root DIR] [--threads N]
//               [--memory-budget-mb N] [--max-message-mb N] [--max-upload-mb N]
//               [--max-dimension N] [--design-verify-every K] [--max-queued-builds N]
//               [--upload-idle-seconds S] [--max-open-watches N] [--auth-token-file FILE]
//               [--tls-cert PEM --tls-key PEM [--tls-client-ca PEM]] [--insecure]
//               [--drain-seconds S] [--shared-store [--daemon-id ID]] [--demo]
//
// Prints "listening on HOST:PORT" as the first line on stdout once serving (port 0 picks a free
// port). SIGTERM / SIGINT drain and exit 0.

#include <signal.h>

#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <iostream>
#include <map>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "absl/strings/ascii.h"
#include "absl/strings/str_cat.h"
#include "core/common/command_line.h"
#include "core/common/huge_pages.h"
#include "server/demo.h"
#include "server/field_server.h"

namespace {

constexpr char kUsage[] =
    "usage: fieldspaced --listen HOST:PORT --store DIR [--data-root DIR] [--threads N]\n"
    "                   [--memory-budget-mb N] [--max-message-mb N] [--max-upload-mb N]\n"
    "                   [--max-dimension N] [--design-verify-every K] [--max-design-sessions N]\n"
    "                   [--max-queued-builds N] [--upload-idle-seconds S] [--max-open-watches N]\n"
    "                   [--auth-token-file FILE] [--tls-cert PEM --tls-key PEM\n"
    "                   [--tls-client-ca PEM]] [--insecure]\n"
    "                   [--drain-seconds S] [--shared-store [--daemon-id ID]] [--demo]\n"
    "\n"
    "  --listen HOST:PORT      address to serve on (default 127.0.0.1:50051; port 0 = any free\n"
    "                          port). Non-loopback needs --auth-token-file, --tls-client-ca or\n"
    "                          --insecure.\n"
    "  --store DIR             where meshes and bases persist (required)\n"
    "  --data-root DIR         LoadMesh reads mesh files below DIR only (default: disabled)\n"
    "  --threads N             compute threads (default: all cores)\n"
    "  --memory-budget-mb N    memory for loaded meshes and bases; idle ones are evicted (4096)\n"
    "  --max-message-mb N      largest gRPC message either way (64)\n"
    "  --max-upload-mb N       largest mesh upload (2048)\n"
    "  --max-dimension N       largest basis dimension d (8192)\n"
    "  --design-verify-every K check every K-th design edit's solution against the true\n"
    "                          system, and risky ones always (16; 1: every edit)\n"
    "  --max-design-sessions N open Design streams at once (256)\n"
    "  --max-queued-builds N   basis builds running or queued at once (32)\n"
    "  --upload-idle-seconds S end an upload that sends nothing for S seconds, releasing its\n"
    "                          memory (60; 0: never)\n"
    "  --max-open-watches N    open health Watch streams at once with --auth-token-file (64)\n"
    "  --auth-token-file FILE  clients must send 'authorization: Bearer <token>'\n"
    "  --tls-cert PEM          serve TLS with this certificate (chain: leaf first) ...\n"
    "  --tls-key PEM           ... and its private key (unencrypted)\n"
    "  --tls-client-ca PEM     mutual TLS: clients need a certificate signed by this CA\n"
    "  --insecure              allow a non-loopback address without a token or client CA\n"
    "  --drain-seconds S       how long shutdown waits for in-flight RPCs (10)\n"
    "  --shared-store          several daemons use --store (e.g. replicas behind a router on a\n"
    "                          shared file system): lookups on a miss, a build lease per basis\n"
    "                          (docs/scale-out.md). Every daemon on the store needs it.\n"
    "  --daemon-id ID          this daemon's name in build leases and logs (default: random)\n"
    "  --demo                  store the demo mesh and build its vector basis in the background\n";

int Fail(const std::string& message) {
  std::cerr << "fieldspaced: " << message << "\n";
  return 2;
}

}  // namespace

int main(int argc, char** argv) {
  fieldspace::ReexecWithHugePageMalloc(argv);
  using fieldspace::server::FieldServer;
  fieldspace::server::FieldServerOptions options;
  options.listen = "127.0.0.1:50051";
  bool demo = false;
  double drain_seconds = 10;
  std::string token_file;

  std::map<std::string, std::string*> string_flags = {
      {"listen", &options.listen},        {"store", &options.store_dir},
      {"data-root", &options.data_root},  {"auth-token-file", &token_file},
      {"daemon-id", &options.daemon_id},  {"tls-cert", &options.tls.cert_file},
      {"tls-key", &options.tls.key_file}, {"tls-client-ca", &options.tls.client_ca_file}};
  std::map<std::string, int64_t*> int64_flags = {{"memory-budget-mb", &options.memory_budget_mb},
                                                 {"max-message-mb", &options.max_message_mb},
                                                 {"max-upload-mb", &options.max_upload_mb}};
  std::map<std::string, int32_t*> int32_flags = {
      {"threads", &options.threads},
      {"max-dimension", &options.max_dimension},
      {"design-verify-every", &options.design_verify_interval},
      {"max-design-sessions", &options.max_design_sessions},
      {"max-queued-builds", &options.max_queued_builds},
      {"upload-idle-seconds", &options.upload_idle_seconds},
      {"max-open-watches", &options.max_open_watches},
      {"debug-save-pause-ms", &options.debug_save_pause_ms}};
  fieldspace::FlagSpec spec;
  spec.switches = {"help", "demo", "insecure", "shared-store"};
  spec.value_flags = {"drain-seconds"};
  for (const auto& flag : string_flags) spec.value_flags.push_back(flag.first);
  for (const auto& flag : int64_flags) spec.value_flags.push_back(flag.first);
  for (const auto& flag : int32_flags) spec.value_flags.push_back(flag.first);
  absl::StatusOr<fieldspace::CommandLine> args =
      fieldspace::CommandLine::Parse(std::vector<std::string>(argv + 1, argv + argc), spec);
  if (!args.ok()) {
    std::cerr << kUsage;
    return Fail(std::string(args.status().message()));
  }
  const std::vector<std::string>& positional = args->positional();
  if (args->Has("help") || (!positional.empty() && positional[0] == "-h")) {
    std::cout << kUsage;
    return 0;
  }
  if (!positional.empty()) {
    std::cerr << kUsage;
    return Fail("unknown argument '" + positional[0] + "'");
  }
  demo = args->Has("demo");
  options.insecure = args->Has("insecure");
  if (args->Has("shared-store")) options.store_lock = fieldspace::server::StoreLockMode::kShared;
  for (const auto& [name, target] : string_flags) *target = args->Get(name).value_or(*target);
  for (const auto& [name, target] : int64_flags) {
    absl::StatusOr<int64_t> value = args->GetInt(name, *target);
    if (!value.ok()) return Fail(std::string(value.status().message()));
    *target = *value;
  }
  for (const auto& [name, target] : int32_flags) {
    absl::StatusOr<int32_t> value = args->GetInt32(name, *target);
    if (!value.ok()) return Fail(std::string(value.status().message()));
    *target = *value;
  }
  absl::StatusOr<double> drain = args->GetDouble("drain-seconds", drain_seconds);
  if (!drain.ok() || *drain < 0) return Fail("--drain-seconds needs a non-negative number");
  drain_seconds = *drain;
  if (!options.daemon_id.empty() &&
      options.store_lock != fieldspace::server::StoreLockMode::kShared) {
    return Fail("--daemon-id needs --shared-store");
  }
  if (options.store_dir.empty()) {
    std::cerr << kUsage;
    return Fail("--store DIR is required");
  }
  if (!token_file.empty()) {
    std::ifstream in(token_file);
    if (!in) return Fail("cannot read --auth-token-file " + token_file);
    std::stringstream ss;
    ss << in.rdbuf();
    options.auth_token = std::string(absl::StripAsciiWhitespace(ss.str()));
    if (options.auth_token.empty()) return Fail("--auth-token-file " + token_file + " is empty");
  }

  // Signals are taken by one thread with sigwait: block them before any thread starts, so gRPC's
  // and oneTBB's threads inherit the mask.
  sigset_t signals;
  sigemptyset(&signals);
  sigaddset(&signals, SIGTERM);
  sigaddset(&signals, SIGINT);
  pthread_sigmask(SIG_BLOCK, &signals, nullptr);
  signal(SIGPIPE, SIG_IGN);

  absl::StatusOr<std::unique_ptr<FieldServer>> server = FieldServer::Start(options);
  if (!server.ok()) return Fail(std::string(server.status().message()));
  std::cout << "listening on " << (*server)->address() << std::endl;

  std::unique_ptr<fieldspace::server::DemoLoader> demo_loader;
  if (demo) demo_loader = fieldspace::server::StartDemo((*server)->registry());

  int sig = 0;
  sigwait(&signals, &sig);
  std::cerr << "fieldspaced: " << (sig == SIGTERM ? "SIGTERM" : "SIGINT") << ", draining\n";
  // A second signal during the drain exits at once.
  std::thread second([&signals] {
    int again = 0;
    sigwait(&signals, &again);
    std::cerr << "fieldspaced: second signal, exiting without draining\n";
    std::_Exit(1);
  });
  second.detach();
  if (demo_loader != nullptr) demo_loader->Stop();
  (*server)->Shutdown(std::chrono::milliseconds(static_cast<int64_t>(drain_seconds * 1000)));
  demo_loader.reset();
  server->reset();
  std::cerr << "fieldspaced: stopped\n";
  return 0;
}
