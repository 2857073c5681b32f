#include "core/subspace/problem.h"

#include <cmath>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "core/common/index_check.h"
#include "core/common/status_macros.h"

namespace fieldspace {

absl::Status ValidateWeights(const EnergyWeights& w) {
  const auto check = [](double v, const char* name) -> absl::Status {
    if (!std::isfinite(v) || v < 0.0) {
      return absl::InvalidArgumentError(
          absl::StrFormat("energy weight %s = %g is invalid: must be finite and >= 0", name, v));
    }
    return absl::OkStatus();
  };
  RETURN_IF_ERROR(check(w.mu_s, "mu_s"));
  RETURN_IF_ERROR(check(w.mu_b, "mu_b"));
  RETURN_IF_ERROR(check(w.mu_c, "mu_c"));
  RETURN_IF_ERROR(check(w.mu_a, "mu_a"));
  if (w.mu_s + w.mu_b <= 0.0) {
    return absl::InvalidArgumentError(
        "energy weights mu_s and mu_b are both 0; at least one must be > 0 (otherwise the energy "
        "does not determine the field away from the constraints)");
  }
  return absl::OkStatus();
}

absl::Status ValidateWeightsWithoutDataTerm(const EnergyWeights& w) {
  RETURN_IF_ERROR(ValidateWeights(w));
  if (w.mu_a != 0.0) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "energy weight mu_a = %g has no term to weigh: only a design session opened with a data "
        "(alignment) term has one",
        w.mu_a));
  }
  return absl::OkStatus();
}

absl::Status ValidateSessionWeights(const EnergyWeights& weights, bool data_term) {
  RETURN_IF_ERROR(data_term ? ValidateWeights(weights) : ValidateWeightsWithoutDataTerm(weights));
  if (!(weights.mu_c > 0)) {
    return absl::InvalidArgumentError(
        absl::StrCat("energy weight mu_c = ", weights.mu_c,
                     " is invalid for a design session: must be > 0 (it scales every soft "
                     "constraint)"));
  }
  return absl::OkStatus();
}

absl::Status ValidateConstraint(const FieldConstraint& c, int64_t num_faces,
                                const FieldType& type) {
  RETURN_IF_ERROR(CheckFace(c.face, num_faces, "constraint"));
  if (c.value.size() != type.dofs_per_face()) {
    return absl::InvalidArgumentError(
        absl::StrCat("constraint on face ", c.face, " has ", c.value.size(), " values; a ",
                     type.ToString(), " field has ", type.dofs_per_face(), " per face"));
  }
  if (!c.value.allFinite()) {
    return absl::InvalidArgumentError(
        absl::StrCat("constraint on face ", c.face, " has a non-finite value"));
  }
  if (!c.hard() && (!std::isfinite(c.weight) || c.weight <= 0)) {
    return absl::InvalidArgumentError(absl::StrCat(
        "soft constraint on face ", c.face, " has weight ", c.weight, "; must be finite and > 0"));
  }
  return absl::OkStatus();
}

}  // namespace fieldspace
