#ifndef FIELDSPACE_SERVER_STATUS_UTIL_H_
#define FIELDSPACE_SERVER_STATUS_UTIL_H_

#include <string>
#include <string_view>

#include "absl/status/status.h"
#include "grpcpp/support/status.h"

namespace fieldspace::server {

// The one place where absl::Status becomes grpc::Status. Codes map one to one (they share their
// numbering), except that UNKNOWN never leaves the server: an absl::UnknownError is a bug in our
// error handling and becomes INTERNAL, so clients can rely on every failure being classified.
// Messages are also redacted: every occurrence of a path registered with RedactPathOnTheWire is
// replaced by its shown name, so that clients never see where the server keeps its files. Messages
// longer than 4 KiB are cut there (a header that large is refused or stalls on the way).
grpc::Status ToGrpcStatus(const absl::Status& status);

// Registers `path` (e.g. the store directory, as given and absolute) to be shown as `shown`
// (e.g. "<store>") in every status sent to clients. Process-wide and additive (each server in a
// process registers its own store); thread-safe.
void RedactPathOnTheWire(const std::string& path, const std::string& shown);

// And back, for clients and tests that use absl::Status APIs.
absl::Status FromGrpcStatus(const grpc::Status& status);

}  // namespace fieldspace::server

#endif  // FIELDSPACE_SERVER_STATUS_UTIL_H_
