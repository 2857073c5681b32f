#include "server/status_util.h"

#include <algorithm>
#include <mutex>
#include <string>
#include <utility>
#include <vector>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_replace.h"
#include "server/shown_text.h"

namespace fieldspace::server {

namespace {

std::mutex redaction_mu;
std::vector<std::pair<std::string, std::string>>& Redactions() {
  static auto* redactions = new std::vector<std::pair<std::string, std::string>>();
  return *redactions;
}

std::string Redacted(std::string message) {
  std::lock_guard<std::mutex> lock(redaction_mu);
  // Longest first, so that a path inside another registered one is not half replaced.
  for (const auto& [path, shown] : Redactions()) {
    if (message.find(path) != std::string::npos) {
      message = absl::StrReplaceAll(message, {{path, shown}});
    }
  }
  return message;
}

constexpr size_t kMaxMessageBytes = 4096;

}  // namespace

void RedactPathOnTheWire(const std::string& path, const std::string& shown) {
  if (path.empty()) return;
  std::lock_guard<std::mutex> lock(redaction_mu);
  auto& r = Redactions();
  if (std::find(r.begin(), r.end(), std::make_pair(path, shown)) != r.end()) return;
  r.emplace_back(path, shown);
  std::stable_sort(r.begin(), r.end(),
                   [](const auto& a, const auto& b) { return a.first.size() > b.first.size(); });
}

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
  message = Redacted(std::move(message));
  if (message.size() > kMaxMessageBytes) {
    message = absl::StrCat(CutText(message, kMaxMessageBytes), " (", message.size(), " bytes)");
  }
  return grpc::Status(code, std::move(message));
}

absl::Status FromGrpcStatus(const grpc::Status& status) {
  if (status.ok()) return absl::OkStatus();
  return absl::Status(static_cast<absl::StatusCode>(status.error_code()), status.error_message());
}

}  // namespace fieldspace::server
