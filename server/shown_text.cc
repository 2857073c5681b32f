#include "server/shown_text.h"

#include "absl/strings/str_cat.h"

namespace fieldspace::server {

namespace {
constexpr size_t kMaxIdShown = 64;
}  // namespace

std::string CutText(std::string_view text, size_t max) {
  if (text.size() <= max) return std::string(text);
  size_t end = max;
  while (end > 0 && (static_cast<unsigned char>(text[end]) & 0xC0) == 0x80) --end;
  return std::string(text.substr(0, end)) + "\u2026";
}

std::string ShownId(std::string_view id) {
  if (id.size() <= kMaxIdShown) return "'" + std::string(id) + "'";
  return absl::StrCat("'", CutText(id, kMaxIdShown), "' (", id.size(), " bytes)");
}

}  // namespace fieldspace::server
