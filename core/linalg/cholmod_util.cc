#include "core/linalg/cholmod_util.h"

#include <cstring>

#include "absl/strings/str_format.h"

namespace fieldspace::linalg_internal {

cholmod_sparse UpperView(int64_t n, const int32_t* outer, const int32_t* inner,
                         const double* values, bool sorted) {
  cholmod_sparse s;
  std::memset(&s, 0, sizeof(s));
  s.nrow = static_cast<size_t>(n);
  s.ncol = static_cast<size_t>(n);
  s.nzmax = static_cast<size_t>(outer[n]);
  s.p = const_cast<int32_t*>(outer);
  s.i = const_cast<int32_t*>(inner);
  s.x = const_cast<double*>(values);
  s.stype = 1;
  s.itype = CHOLMOD_INT;
  s.xtype = values != nullptr ? CHOLMOD_REAL : CHOLMOD_PATTERN;
  s.dtype = CHOLMOD_DOUBLE;
  s.sorted = sorted ? 1 : 0;
  s.packed = 1;
  return s;
}

absl::Status StatusFromCholmod(const cholmod_common& c, const char* context, const char* during) {
  switch (c.status) {
    case CHOLMOD_OK:
      return absl::OkStatus();
    case CHOLMOD_OUT_OF_MEMORY:
      return absl::ResourceExhaustedError(
          absl::StrFormat("%s: CHOLMOD %s: out of memory", context, during));
    case CHOLMOD_TOO_LARGE:
      return absl::ResourceExhaustedError(
          absl::StrFormat("%s: CHOLMOD %s: problem too large for 32-bit indices", context, during));
    case CHOLMOD_NOT_POSDEF:
      return absl::FailedPreconditionError(
          absl::StrFormat("%s: CHOLMOD %s: matrix is not positive definite", context, during));
    default:
      if (c.status > 0) return absl::OkStatus();  // other warnings (e.g. tiny diagonal) are benign
      return absl::InternalError(
          absl::StrFormat("%s: CHOLMOD %s failed (status %d)", context, during, c.status));
  }
}

absl::StatusOr<cholmod_factor*> Analyze(cholmod_sparse* A, cholmod_common* c, const char* context) {
  cholmod_factor* L = cholmod_analyze(A, c);
  if (L != nullptr && c->status >= CHOLMOD_OK) return L;
  if (L != nullptr) cholmod_free_factor(&L, c);
  absl::Status status = StatusFromCholmod(*c, context, "analyze");
  if (status.ok()) {
    status =
        absl::InternalError(absl::StrFormat("%s: CHOLMOD analyze returned no factor", context));
  }
  return status;
}

}  // namespace fieldspace::linalg_internal
