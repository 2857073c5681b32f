#include "server/auth.h"

#include <utility>

#include "absl/strings/match.h"  // EqualsIgnoreCase
#include "absl/strings/str_cat.h"
#include "grpc/grpc_security.h"
#include "grpcpp/security/auth_metadata_processor.h"
#include "grpcpp/security/server_credentials.h"

namespace fieldspace::server {
namespace {

// Checks the token of every call but the open methods; runs inline on gRPC's thread (it neither
// blocks nor allocates much).
constexpr char kWatchMethod[] = "/grpc.health.v1.Health/Watch";

class BearerTokenProcessor final : public grpc::AuthMetadataProcessor {
 public:
  BearerTokenProcessor(std::string token, std::shared_ptr<OpenWatches> watches)
      : token_(std::move(token)), watches_(std::move(watches)) {}

  bool IsBlocking() const override { return false; }

  grpc::Status Process(const InputMetadata& metadata, grpc::AuthContext*, OutputMetadata*,
                       OutputMetadata*) override {
    const auto path = metadata.find(":path");
    const std::string_view method =
        path == metadata.end() ? std::string_view()
                               : std::string_view(path->second.data(), path->second.size());
    if (method == kWatchMethod && watches_ != nullptr &&
        watches_->open.load() >= watches_->max_open) {
      return grpc::Status(grpc::StatusCode::RESOURCE_EXHAUSTED,
                          absl::StrCat("the server has its maximum of ", watches_->max_open,
                                       " open health watches (--max-open-watches); use Check, or "
                                       "retry later"));
    }
    if (IsOpenMethod(method)) return grpc::Status::OK;
    const auto header = metadata.find("authorization");
    std::string_view value;
    if (header != metadata.end())
      value = std::string_view(header->second.data(), header->second.size());
    const absl::Status status =
        CheckBearerToken(token_, header == metadata.end() ? nullptr : &value);
    if (status.ok()) return grpc::Status::OK;
    return grpc::Status(grpc::StatusCode::UNAUTHENTICATED, std::string(status.message()));
  }

 private:
  const std::string token_;
  const std::shared_ptr<OpenWatches> watches_;
};

// Counts a Health/Watch stream from its dispatch until gRPC destroys the call's interceptors.
class WatchCounter final : public grpc::experimental::Interceptor {
 public:
  explicit WatchCounter(std::shared_ptr<OpenWatches> watches) : watches_(std::move(watches)) {
    watches_->open.fetch_add(1);
  }
  ~WatchCounter() override { watches_->open.fetch_sub(1); }
  void Intercept(grpc::experimental::InterceptorBatchMethods* methods) override {
    methods->Proceed();
  }

 private:
  const std::shared_ptr<OpenWatches> watches_;
};

class WatchCounterFactory final : public grpc::experimental::ServerInterceptorFactoryInterface {
 public:
  explicit WatchCounterFactory(std::shared_ptr<OpenWatches> watches)
      : watches_(std::move(watches)) {}
  grpc::experimental::Interceptor* CreateServerInterceptor(
      grpc::experimental::ServerRpcInfo* info) override {
    if (std::string_view(info->method()) != kWatchMethod) return nullptr;
    return new WatchCounter(watches_);
  }

 private:
  const std::shared_ptr<OpenWatches> watches_;
};

// grpc::InsecureServerCredentials() refuses a processor (it asserts), but the C core's insecure
// credentials run one in the server's auth filter like TLS credentials do.
class PlaintextCredentials final : public grpc::ServerCredentials {
 public:
  PlaintextCredentials() : credentials_(grpc_insecure_server_credentials_create()) {}
  ~PlaintextCredentials() override { grpc_server_credentials_release(credentials_); }
  PlaintextCredentials(const PlaintextCredentials&) = delete;
  PlaintextCredentials& operator=(const PlaintextCredentials&) = delete;

  // Processors that block are run inline too, and get no AuthContext; metadata they consume stays
  // on the call. BearerTokenProcessor needs none of these.
  void SetAuthMetadataProcessor(
      const std::shared_ptr<grpc::AuthMetadataProcessor>& processor) override {
    // The core owns a heap copy of the shared_ptr and frees it in Destroy.
    grpc_server_credentials_set_auth_metadata_processor(
        credentials_,
        {&Process, &Destroy, new std::shared_ptr<grpc::AuthMetadataProcessor>(processor)});
  }

 private:
  int AddPortToServer(const std::string& address, grpc_server* server) override {
    return grpc_server_add_http2_port(server, address.c_str(), credentials_);
  }

  static void Process(void* state, grpc_auth_context*, const grpc_metadata* md, size_t num_md,
                      grpc_process_auth_metadata_done_cb done, void* user_data) {
    auto& processor = *static_cast<std::shared_ptr<grpc::AuthMetadataProcessor>*>(state);
    grpc::AuthMetadataProcessor::InputMetadata metadata;
    for (size_t i = 0; i < num_md; ++i) {
      metadata.emplace(
          grpc::string_ref(reinterpret_cast<const char*>(GRPC_SLICE_START_PTR(md[i].key)),
                           GRPC_SLICE_LENGTH(md[i].key)),
          grpc::string_ref(reinterpret_cast<const char*>(GRPC_SLICE_START_PTR(md[i].value)),
                           GRPC_SLICE_LENGTH(md[i].value)));
    }
    grpc::AuthMetadataProcessor::OutputMetadata consumed, response;
    const grpc::Status status = processor->Process(metadata, nullptr, &consumed, &response);
    done(user_data, nullptr, 0, nullptr, 0, static_cast<grpc_status_code>(status.error_code()),
         status.ok() ? nullptr : status.error_message().c_str());
  }

  static void Destroy(void* state) {
    delete static_cast<std::shared_ptr<grpc::AuthMetadataProcessor>*>(state);
  }

  grpc_server_credentials* const credentials_;
};

}  // namespace

bool IsOpenMethod(std::string_view path) {
  return path.starts_with("/grpc.health.v1.Health/") ||
         path.starts_with("/grpc.reflection.v1.ServerReflection/") ||
         path.starts_with("/grpc.reflection.v1alpha.ServerReflection/");
}

absl::Status CheckBearerToken(std::string_view expected, const std::string_view* authorization) {
  if (authorization == nullptr) {
    return absl::UnauthenticatedError("missing 'authorization: Bearer <token>' metadata");
  }
  const std::string_view value = *authorization;
  // The scheme is case-insensitive (RFC 7235, section 2.1); the token is not.
  constexpr std::string_view kScheme = "bearer ";
  if (value.size() < kScheme.size() ||
      !absl::EqualsIgnoreCase(absl::string_view(value.data(), kScheme.size()),
                              absl::string_view(kScheme.data(), kScheme.size()))) {
    return absl::UnauthenticatedError("expected 'authorization: Bearer <token>'");
  }
  const std::string_view token = value.substr(kScheme.size());
  // Constant-time comparison: the time taken must not reveal how much of the token matched.
  unsigned char diff = token.size() == expected.size() ? 0 : 1;
  for (size_t i = 0; i < expected.size(); ++i) {
    diff |= static_cast<unsigned char>(expected[i] ^ (i < token.size() ? token[i] : 0));
  }
  if (diff != 0) return absl::UnauthenticatedError("invalid token");
  return absl::OkStatus();
}

std::shared_ptr<grpc::ServerCredentials> PlaintextServerCredentials() {
  return std::make_shared<PlaintextCredentials>();
}

void RequireBearerToken(grpc::ServerCredentials& credentials, std::string token,
                        std::shared_ptr<OpenWatches> watches) {
  credentials.SetAuthMetadataProcessor(
      std::make_shared<BearerTokenProcessor>(std::move(token), std::move(watches)));
}

std::unique_ptr<grpc::experimental::ServerInterceptorFactoryInterface> NewWatchCounterFactory(
    std::shared_ptr<OpenWatches> watches) {
  return std::make_unique<WatchCounterFactory>(std::move(watches));
}

}  // namespace fieldspace::server
