#include "server/status_util.h"

#include <string>

namespace fieldspace::server {

grpc::Status ToGrpcStatus(const absl::Status& status) {
  if (status.ok()) return grpc::Status::OK;
  auto code = static_cast<grpc::StatusCode>(status.code());
  std::string message(status.message());
  if (status.code() == absl::StatusCode::kUnknown ||
      static_cast<int>(status.code()) > static_cast<int>(absl::StatusCode::kUnauthenticated)) {
    code = grpc::StatusCode::INTERNAL;
    message = "internal error (unclassified): " + message;
  }
  if (message.empty()) message = absl::StatusCodeToString(status.code());
  return grpc::Status(code, message);
}

absl::Status FromGrpcStatus(const grpc::Status& status) {
  if (status.ok()) return absl::OkStatus();
  return absl::Status(static_cast<absl::StatusCode>(status.error_code()), status.error_message());
}

}  // namespace fieldspace::server
