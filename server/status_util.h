#ifndef FIELDSPACE_SERVER_STATUS_UTIL_H_
#define FIELDSPACE_SERVER_STATUS_UTIL_H_

#include "absl/status/status.h"
#include "grpcpp/support/status.h"

namespace fieldspace::server {

// The one place where absl::Status becomes grpc::Status. Codes map one to one (they share their
// numbering), except that UNKNOWN never leaves the server: an absl::UnknownError is a bug in our
// error handling and becomes INTERNAL, so clients can rely on every failure being classified.
grpc::Status ToGrpcStatus(const absl::Status& status);

// And back, for clients and tests that use absl::Status APIs.
absl::Status FromGrpcStatus(const grpc::Status& status);

}  // namespace fieldspace::server

#endif  // FIELDSPACE_SERVER_STATUS_UTIL_H_
