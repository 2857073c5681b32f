#ifndef FIELDSPACE_SERVER_FIELD_SERVER_H_
#define FIELDSPACE_SERVER_FIELD_SERVER_H_

#include <chrono>
#include <cstdint>
#include <memory>
#include <mutex>
#include <optional>
#include <string>

#include "absl/status/statusor.h"
#include "server/lease.h"
#include "server/store_lock.h"
#include "server/tls.h"

namespace grpc {
class Server;
}  // namespace grpc

namespace fieldspace::server {

class ComputePool;
class FieldService;
class Registry;
class Store;

struct FieldServerOptions {
  std::string listen = "127.0.0.1:0";  // HOST:PORT; port 0 picks a free port
  std::string store_dir;               // required
  std::string data_root;               // LoadMesh root; empty disables LoadMesh
  int32_t threads = 0;                 // compute threads; 0: hardware concurrency
  int64_t memory_budget_mb = 4096;
  int64_t max_message_mb = 64;
  int64_t max_upload_mb = 2048;
  int32_t max_dimension = 8192;
  int32_t design_verify_interval = 16;  // see DesignSessionOptions::verify_interval
  int32_t max_design_sessions = 256;    // open Design streams at once; more: RESOURCE_EXHAUSTED
  int32_t max_queued_builds = 32;       // builds running or queued; more: RESOURCE_EXHAUSTED
  int32_t upload_idle_seconds = 60;     // an upload silent this long is ended; 0: never
  // Open Health/Watch streams at once when a token is required (they need none); more:
  // RESOURCE_EXHAUSTED.
  int32_t max_open_watches = 64;
  std::string auth_token;  // required from clients when not empty
  TlsFiles tls;            // --tls-cert, --tls-key, --tls-client-ca; none: plaintext
  // Listening on a non-loopback address needs an auth token or client certificates
  // (tls.client_ca_file), or this explicit opt-out.
  bool insecure = false;
  int32_t debug_save_pause_ms = 0;  // testing only (see StoreOptions)
  // Whether other daemons may use the same store (see StoreLock): kShared is --shared-store
  // (RegistryOptions::shared_store; docs/scale-out.md).
  StoreLockMode store_lock = StoreLockMode::kExclusive;
  std::string daemon_id;  // shared store: names this daemon in leases and logs; random if empty
  Lease::Options lease;   // shared store: build lease heartbeat and staleness
};

// The gRPC transport's share of --memory-budget-mb (a resource quota: its read buffers and the
// request messages it holds before a handler runs): a quarter, at least 32 MiB. The registry
// admits the rest.
int64_t TransportQuotaBytes(int64_t memory_budget_mb);

// The daemon: store + registry + compute pool + gRPC server with FieldSpace, server reflection and
// grpc.health.v1.Health.
class FieldServer {
 public:
  // Checks the TLS files, locks and opens the store, binds, starts serving. InvalidArgument for
  // bad options (TLS files: see MakeServerCredentials), FailedPrecondition for a non-loopback
  // address without a token, client certificates or --insecure, or for a store
  // that another daemon holds (the message names its pid), Unavailable if the address cannot be
  // bound ("address already in use" when another process listens on it: the port is never
  // shared, SO_REUSEPORT is off).
  static absl::StatusOr<std::unique_ptr<FieldServer>> Start(const FieldServerOptions& options);

  // Shutdown(default drain).
  ~FieldServer();

  int port() const { return port_; }
  // HOST:PORT with the port actually bound.
  const std::string& address() const { return address_; }
  Registry* registry() const { return registry_.get(); }
  // The store the daemon writes (for tests and tools that read its files; Store's reads are
  // const and safe beside the daemon's writes).
  const Store* store() const { return store_.get(); }

  // Graceful shutdown: health NOT_SERVING, new RPCs refused, open design sessions ended, running
  // builds cancelled, in-flight RPCs drained for at most `drain` (then cancelled), compute pool
  // joined. Idempotent; thread-safe.
  void Shutdown(std::chrono::milliseconds drain = std::chrono::seconds(10));

  // Blocks until Shutdown() has completed.
  void Wait();

 private:
  FieldServer() = default;

  FieldServerOptions options_;
  int port_ = 0;
  std::string address_;
  std::optional<StoreLock> store_lock_;
  std::unique_ptr<Store> store_;
  std::unique_ptr<ComputePool> pool_;
  std::unique_ptr<Registry> registry_;
  std::unique_ptr<FieldService> service_;
  std::unique_ptr<grpc::Server> server_;
  std::shared_ptr<void> tbb_limit_;  // oneTBB global_control (type-erased: keeps TBB out of here)
  std::mutex shutdown_mu_;
  bool shut_down_ = false;
};

// Whether HOST of HOST:PORT is a loopback address (localhost, 127.0.0.0/8, ::1).
bool IsLoopbackListenAddress(const std::string& listen);

}  // namespace fieldspace::server

#endif  // FIELDSPACE_SERVER_FIELD_SERVER_H_
