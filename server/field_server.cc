#include "server/field_server.h"

#include <arpa/inet.h>
#include <netdb.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "core/common/file_util.h"
#include "core/common/status_macros.h"
#include "grpc/grpc.h"
#include "grpc/health/v1/health.pb.h"
#include "grpcpp/ext/proto_server_reflection_plugin.h"
#include "grpcpp/health_check_service_interface.h"
#include "grpcpp/resource_quota.h"
#include "grpcpp/security/server_credentials.h"
#include "grpcpp/server.h"
#include "grpcpp/server_builder.h"
#include "oneapi/tbb/global_control.h"
#include "server/auth.h"
#include "server/compute_pool.h"
#include "server/field_service.h"
#include "server/parse_failure_interceptor.h"
#include "server/reflection_v1.h"
#include "server/registry.h"
#include "server/status_util.h"
#include "server/store.h"
#include "server/tls.h"

namespace fieldspace::server {
namespace {

constexpr char kServiceName[] = "fieldspace.v1.FieldSpace";

// Splits HOST:PORT ([v6]:PORT allowed). Returns false if malformed.
bool SplitHostPort(const std::string& listen, std::string* host, int* port) {
  const size_t colon = listen.rfind(':');
  if (colon == std::string::npos || colon == 0) return false;
  *host = listen.substr(0, colon);
  if (host->size() >= 2 && host->front() == '[' && host->back() == ']') {
    *host = host->substr(1, host->size() - 2);
  }
  return absl::SimpleAtoi(listen.substr(colon + 1), port) && *port >= 0 && *port <= 65535;
}

// Why binding HOST:PORT failed, as far as a probe can tell (gRPC only logs it).
std::string ListenFailureReason(const std::string& host, int port) {
  if (port == 0) return "";
  addrinfo hints{};
  hints.ai_socktype = SOCK_STREAM;
  hints.ai_flags = AI_PASSIVE;
  addrinfo* found = nullptr;
  if (::getaddrinfo(host.c_str(), std::to_string(port).c_str(), &hints, &found) != 0) {
    return absl::StrCat(": cannot resolve '", host, "'");
  }
  std::string reason;
  for (addrinfo* a = found; a != nullptr && reason.empty(); a = a->ai_next) {
    const ScopedFd fd(::socket(a->ai_family, a->ai_socktype | SOCK_CLOEXEC, a->ai_protocol));
    if (!fd.is_open()) continue;
    const int one = 1;
    ::setsockopt(fd.get(), SOL_SOCKET, SO_REUSEADDR, &one, sizeof(one));  // as gRPC does
    if (::bind(fd.get(), a->ai_addr, a->ai_addrlen) != 0) {
      reason = errno == EADDRINUSE ? ": address already in use"
                                   : absl::StrCat(": ", std::strerror(errno));
    }
  }
  ::freeaddrinfo(found);
  return reason;
}

}  // namespace

bool IsLoopbackListenAddress(const std::string& listen) {
  std::string host;
  int port;
  if (!SplitHostPort(listen, &host, &port)) return false;
  if (host == "localhost") return true;
  // Literal addresses only, parsed in full: a host name such as "127.example.com" is not one
  // (inet_pton takes exactly the dotted-quad form, so "127.1" or "127.0.0.1.nip.io" fail too).
  in_addr v4;
  if (::inet_pton(AF_INET, host.c_str(), &v4) == 1) return (ntohl(v4.s_addr) >> 24) == 127;
  in6_addr v6;
  if (::inet_pton(AF_INET6, host.c_str(), &v6) == 1) {
    if (IN6_IS_ADDR_LOOPBACK(&v6)) return true;
    // ::ffff:127.x.y.z, an IPv4 loopback address in IPv6 form.
    return IN6_IS_ADDR_V4MAPPED(&v6) && v6.s6_addr[12] == 127;
  }
  return false;
}

int64_t TransportQuotaBytes(int64_t memory_budget_mb) {
  return std::max<int64_t>((memory_budget_mb << 20) / 4, int64_t{32} << 20);
}

absl::StatusOr<std::unique_ptr<FieldServer>> FieldServer::Start(const FieldServerOptions& options) {
  std::string host;
  int requested_port;
  if (!SplitHostPort(options.listen, &host, &requested_port)) {
    return absl::InvalidArgumentError(
        absl::StrCat("--listen must be HOST:PORT, got '", options.listen, "'"));
  }
  if (!IsLoopbackListenAddress(options.listen) && options.auth_token.empty() &&
      !options.tls.verifies_clients() && !options.insecure) {
    return absl::FailedPreconditionError(absl::StrCat(
        "refusing to listen on non-loopback address ", options.listen,
        " without --auth-token-file or --tls-client-ca (or say --insecure explicitly)"));
  }
  if (options.store_dir.empty()) return absl::InvalidArgumentError("--store DIR is required");
  if (options.threads < 0 || options.memory_budget_mb < 0 || options.max_message_mb < 1 ||
      options.max_message_mb > 2047 || options.max_upload_mb < 1 || options.max_dimension < 1 ||
      options.design_verify_interval < 1 || options.max_design_sessions < 1 ||
      options.max_queued_builds < 1 || options.upload_idle_seconds < 0 ||
      options.max_open_watches < 1) {
    return absl::InvalidArgumentError(
        "bad limits: --threads >= 0, --memory-budget-mb >= 0, 1 <= --max-message-mb <= 2047, "
        "--max-upload-mb >= 1, --max-dimension >= 1, --design-verify-every >= 1, "
        "--max-design-sessions >= 1, --max-queued-builds >= 1, --upload-idle-seconds >= 0, "
        "--max-open-watches >= 1");
  }
  // Before the store and the port: a bad certificate must not leave a half-started daemon.
  ASSIGN_OR_RETURN(const std::shared_ptr<grpc::ServerCredentials> credentials,
                   MakeServerCredentials(options.tls));
  auto watches = std::make_shared<OpenWatches>(options.max_open_watches);
  if (!options.auth_token.empty()) RequireBearerToken(*credentials, options.auth_token, watches);

  std::unique_ptr<FieldServer> s(new FieldServer());
  s->options_ = options;
  const int threads = options.threads > 0
                          ? options.threads
                          : std::max(1, static_cast<int>(std::thread::hardware_concurrency()));
  s->tbb_limit_ = std::make_shared<tbb::global_control>(
      tbb::global_control::max_allowed_parallelism, static_cast<size_t>(threads));

  // The lock comes first: Store::Open removes temporary files, which would be another daemon's
  // saves in progress.
  // Clients see "<store>" where messages would name the store directory.
  RedactPathOnTheWire(options.store_dir, "<store>");
  {
    std::error_code ec;
    const std::filesystem::path absolute = std::filesystem::absolute(options.store_dir, ec);
    if (!ec) RedactPathOnTheWire(absolute.lexically_normal().string(), "<store>");
    const std::filesystem::path canonical =
        std::filesystem::weakly_canonical(options.store_dir, ec);
    if (!ec) RedactPathOnTheWire(canonical.string(), "<store>");
  }
  ASSIGN_OR_RETURN(StoreLock lock, StoreLock::Acquire(options.store_dir, options.store_lock));
  s->store_lock_.emplace(std::move(lock));
  StoreOptions store_options;
  store_options.save_pause_ms = options.debug_save_pause_ms;
  store_options.shared = options.store_lock == StoreLockMode::kShared;
  ASSIGN_OR_RETURN(s->store_, Store::Open(options.store_dir, store_options));
  ComputePool::Options pool_options;
  pool_options.interactive_threads = threads;
  pool_options.build_threads = 1;
  s->pool_ = std::make_unique<ComputePool>(pool_options);
  RegistryOptions registry_options;
  registry_options.memory_budget_bytes = options.memory_budget_mb << 20;
  registry_options.build_threads = threads;
  registry_options.max_dimension = options.max_dimension;
  registry_options.max_queued_builds = options.max_queued_builds;
  registry_options.shared_store = options.store_lock == StoreLockMode::kShared;
  registry_options.daemon_id = options.daemon_id;
  registry_options.lease = options.lease;
  ASSIGN_OR_RETURN(s->registry_,
                   Registry::Create(s->store_.get(), s->pool_.get(), registry_options));

  ServiceOptions service_options;
  service_options.data_root = options.data_root;
  service_options.max_upload_bytes = options.max_upload_mb << 20;
  service_options.max_message_bytes = options.max_message_mb << 20;
  service_options.design_verify_interval = options.design_verify_interval;
  service_options.max_design_sessions = options.max_design_sessions;
  service_options.upload_idle_timeout = std::chrono::seconds(options.upload_idle_seconds);
  s->service_ = std::make_unique<FieldService>(s->registry_.get(), s->pool_.get(), service_options);

  // Link the health proto's descriptors into the generated pool so that reflection can describe
  // grpc.health.v1.Health (the built-in health service itself does not register them).
  (void)grpc::health::v1::HealthCheckRequest::descriptor();
  grpc::EnableDefaultHealthCheckService(true);
  grpc::reflection::InitProtoReflectionServerBuilderPlugin();

  grpc::ServerBuilder builder;
  builder.SetOption(ReflectionV1Option());  // v1alpha comes from the plugin above
  // gRPC sets SO_REUSEPORT by default: a second daemon on the same port would then start
  // silently and take half of the connections.
  builder.AddChannelArgument(GRPC_ARG_ALLOW_REUSEPORT, 0);
  builder.AddListeningPort(options.listen, credentials, &s->port_);
  builder.RegisterService(s->service_.get());
  {
    std::vector<std::unique_ptr<grpc::experimental::ServerInterceptorFactoryInterface>>
        interceptors;
    interceptors.push_back(NewParseFailureInterceptorFactory());
    interceptors.push_back(NewWatchCounterFactory(watches));
    builder.experimental().SetInterceptorCreators(std::move(interceptors));
  }
  // The transport's memory (its read buffers and the request messages it assembles before a
  // handler runs, and so before any admission) comes from a resource quota of
  // TransportQuotaBytes; when it runs short, gRPC shrinks its windows and stops reading.
  grpc::ResourceQuota transport_quota("fieldspaced transport");
  transport_quota.Resize(static_cast<size_t>(TransportQuotaBytes(options.memory_budget_mb)));
  builder.SetResourceQuota(transport_quota);
  builder.SetMaxReceiveMessageSize(static_cast<int>(options.max_message_mb << 20));
  builder.SetMaxSendMessageSize(static_cast<int>(options.max_message_mb << 20));
  s->server_ = builder.BuildAndStart();
  if (s->server_ == nullptr || s->port_ == 0) {
    s->pool_->Shutdown();
    return absl::UnavailableError(absl::StrCat("cannot listen on ", options.listen,
                                               ListenFailureReason(host, requested_port)));
  }
  if (grpc::HealthCheckServiceInterface* health = s->server_->GetHealthCheckService()) {
    health->SetServingStatus(true);
    health->SetServingStatus(kServiceName, true);
  }
  const bool bracket = host.find(':') != std::string::npos;
  s->address_ =
      bracket ? absl::StrCat("[", host, "]:", s->port_) : absl::StrCat(host, ":", s->port_);
  return s;
}

FieldServer::~FieldServer() { Shutdown(); }

void FieldServer::Shutdown(std::chrono::milliseconds drain) {
  std::lock_guard<std::mutex> lock(shutdown_mu_);
  if (shut_down_) return;
  shut_down_ = true;
  if (server_ != nullptr) {
    if (grpc::HealthCheckServiceInterface* health = server_->GetHealthCheckService()) {
      // NOT_SERVING for every service, then frozen.
      health->Shutdown();
    }
  }
  if (service_ != nullptr) service_->BeginDrain();
  const auto deadline = std::chrono::system_clock::now() + drain;
  // Builds would not finish within any reasonable drain: stop them (clients see UNAVAILABLE or
  // CANCELLED and can ask again after the restart).
  if (registry_ != nullptr)
    registry_->CancelAllBuilds(std::min(drain, std::chrono::milliseconds(2000)));
  if (server_ != nullptr) {
    server_->Shutdown(deadline);  // stops accepting; waits for in-flight RPCs until the deadline
    server_->Wait();
  }
  if (pool_ != nullptr) pool_->Shutdown();
}

void FieldServer::Wait() {
  if (server_ != nullptr) server_->Wait();
}

}  // namespace fieldspace::server
