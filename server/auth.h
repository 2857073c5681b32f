#ifndef FIELDSPACE_SERVER_AUTH_H_
#define FIELDSPACE_SERVER_AUTH_H_

// The daemon's token check (--auth-token-file). It runs on a call's initial metadata inside gRPC,
// as the listening port's auth metadata processor, before the call reaches the service: a call
// without the token is answered UNAUTHENTICATED and its request body is never received in full
// (the stream is reset after the flow-control window) or parsed. Before, the check ran in the
// handlers, after gRPC had read and parsed up to --max-message-mb of request.

#include <atomic>
#include <cstdint>
#include <memory>
#include <string>
#include <string_view>

#include "absl/status/status.h"
#include "grpcpp/support/server_interceptor.h"

namespace grpc {
class ServerCredentials;
}  // namespace grpc

namespace fieldspace::server {

// Whether a call to `path` ("/package.Service/Method") is let through without a token: health
// checks and server reflection, so that probes and reflection-based tools need none.
bool IsOpenMethod(std::string_view path);

// The check of one call: OK when `authorization` (nullptr: the header is missing) is
// "Bearer <expected>", the scheme in any case (RFC 7235, section 2.1) and the token exactly;
// otherwise Unauthenticated saying what was wrong. The comparison takes the same time however
// much of the token matches.
absl::Status CheckBearerToken(std::string_view expected, const std::string_view* authorization);

// Credentials for a plaintext port that, unlike grpc::InsecureServerCredentials(), accept an
// auth metadata processor (which RequireBearerToken installs).
std::shared_ptr<grpc::ServerCredentials> PlaintextServerCredentials();

// The number of open grpc.health.v1.Health/Watch streams, which need no token: each holds memory
// for as long as its client likes (5,000 of them took 90 MB), so RequireBearerToken refuses new
// ones beyond `max_open` with RESOURCE_EXHAUSTED. Counted by the interceptor of
// NewWatchCounterFactory (a stream counts from its dispatch to its end).
struct OpenWatches {
  explicit OpenWatches(int32_t max) : max_open(max) {}
  const int32_t max_open;
  std::atomic<int32_t> open{0};
};

// Makes every call on ports with `credentials` (PlaintextServerCredentials() or TLS credentials)
// pass CheckBearerToken(token, ...) on its metadata, except the open methods, and refuses
// Health/Watch streams beyond `watches`' maximum. Before the server is built; `token` must not be
// empty.
void RequireBearerToken(grpc::ServerCredentials& credentials, std::string token,
                        std::shared_ptr<OpenWatches> watches);

// For ServerBuilder::experimental().SetInterceptorCreators: counts the open Health/Watch streams
// in `watches`.
std::unique_ptr<grpc::experimental::ServerInterceptorFactoryInterface> NewWatchCounterFactory(
    std::shared_ptr<OpenWatches> watches);

}  // namespace fieldspace::server

#endif  // FIELDSPACE_SERVER_AUTH_H_
