#include "core/operators/field_type.h"

#include "absl/strings/match.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"

namespace fieldspace {

absl::Status FieldType::Validate() const {
  switch (kind) {
    case FieldKind::kVector:
    case FieldKind::kTensor:
      return absl::OkStatus();
    case FieldKind::kNField:
      if (n < 1 || n > 64) {
        return absl::InvalidArgumentError(
            absl::StrFormat("n-field symmetry order n = %d outside [1, 64]", n));
      }
      return absl::OkStatus();
  }
  return absl::InvalidArgumentError(
      absl::StrFormat("unknown field kind %d", static_cast<int>(kind)));
}

std::string FieldType::ToString() const {
  switch (kind) {
    case FieldKind::kVector:
      return "vector";
    case FieldKind::kNField:
      return absl::StrCat("nfield", n);
    case FieldKind::kTensor:
      return "tensor";
  }
  return absl::StrCat("invalid", static_cast<int>(kind));
}

absl::StatusOr<FieldType> ParseFieldType(absl::string_view name, std::optional<int32_t> n) {
  if (name == "vector" || name == "tensor") {
    if (n.has_value()) {
      return absl::InvalidArgumentError(
          absl::StrCat("field type '", name, "' takes no symmetry order n"));
    }
    return name == "vector" ? FieldType::Vector() : FieldType::Tensor();
  }
  if (absl::StartsWith(name, "nfield")) {
    absl::string_view digits = name.substr(6);
    std::optional<int32_t> order = n;
    if (!digits.empty()) {
      int32_t parsed = 0;
      if (!absl::SimpleAtoi(digits, &parsed)) {
        return absl::InvalidArgumentError(absl::StrCat("unknown field type '", name, "'"));
      }
      if (n.has_value() && *n != parsed) {
        return absl::InvalidArgumentError(
            absl::StrFormat("field type '%s' conflicts with n = %d", name, *n));
      }
      order = parsed;
    }
    if (!order.has_value()) {
      return absl::InvalidArgumentError("n-fields need a symmetry order n");
    }
    const FieldType type = FieldType::NField(*order);
    if (absl::Status status = type.Validate(); !status.ok()) return status;
    return type;
  }
  return absl::InvalidArgumentError(
      absl::StrCat("unknown field type '", name, "' (expected vector, nfield or tensor)"));
}

}  // namespace fieldspace
