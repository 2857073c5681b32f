#ifndef FIELDSPACE_CORE_OPERATORS_FIELD_TYPE_H_
#define FIELDSPACE_CORE_OPERATORS_FIELD_TYPE_H_

#include <cstdint>
#include <optional>
#include <string>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"

namespace fieldspace {

enum class FieldKind : uint8_t { kVector = 0, kNField = 1, kTensor = 2 };

// What a per-face field is, and so its DOF layout (docs/conventions.md, DOF layout): vector and
// n-fields have 2 DOFs per face at 2f + c (frame coordinates; for n-fields the representation
// vector), symmetric (1,1)-tensors 3 DOFs per face at 3f + c (Mandel-Voigt (a11, a22,
// sqrt(2) a12)).
struct FieldType {
  FieldKind kind = FieldKind::kVector;
  int32_t n = 1;  // rotational symmetry order; meaningful for kNField only

  static FieldType Vector() { return {FieldKind::kVector, 1}; }
  static FieldType NField(int32_t n) { return {FieldKind::kNField, n}; }
  static FieldType Tensor() { return {FieldKind::kTensor, 1}; }

  int32_t dofs_per_face() const { return kind == FieldKind::kTensor ? 3 : 2; }
  // Eigenfields per region in the basis construction (section 4): 2 for vector and n-fields,
  // 3 for tensors (the multiplicity of the lowest eigenvalue).
  int32_t default_fields_per_region() const { return dofs_per_face(); }

  // InvalidArgument for n < 1 or n > 64 on n-fields.
  absl::Status Validate() const;
  // "vector", "nfield4", "tensor".
  std::string ToString() const;

  friend bool operator==(const FieldType& a, const FieldType& b) {
    return a.kind == b.kind && (a.kind != FieldKind::kNField || a.n == b.n);
  }
};

// Parses a field type name: "vector", "tensor", "nfield" (symmetry order from `n`, required) or
// "nfieldN" (`n`, if given, must agree). `n` is rejected for vector and tensor fields.
// InvalidArgument for anything else, including n outside [1, 64].
absl::StatusOr<FieldType> ParseFieldType(absl::string_view name,
                                         std::optional<int32_t> n = std::nullopt);

}  // namespace fieldspace

#endif  // FIELDSPACE_CORE_OPERATORS_FIELD_TYPE_H_
