#ifndef FIELDSPACE_CORE_LINALG_CHOLMOD_UTIL_H_
#define FIELDSPACE_CORE_LINALG_CHOLMOD_UTIL_H_

#include <cstdint>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "cholmod.h"

// What the two Cholesky implementations of core/linalg that use CHOLMOD (SparseCholesky,
// SupernodalSymbolic) share in talking to CHOLMOD. Included only by core/linalg sources.
namespace fieldspace::linalg_internal {

// A cholmod_common configured for silence: CHOLMOD reports through status only (no printing, no
// error handler). Callers adjust the analysis settings before use.
class CholmodCommon {
 public:
  CholmodCommon() {
    cholmod_start(&common_);
    common_.print = 0;
    common_.error_handler = nullptr;
  }
  ~CholmodCommon() { cholmod_finish(&common_); }
  CholmodCommon(const CholmodCommon&) = delete;
  CholmodCommon& operator=(const CholmodCommon&) = delete;

  cholmod_common* get() { return &common_; }
  cholmod_common& operator*() { return common_; }
  cholmod_common* operator->() { return &common_; }

 private:
  cholmod_common common_;
};

// Non-owning CHOLMOD view of an n x n symmetric matrix in compressed columns with int32 indices
// (CHOLMOD_INT, as Eigen's default StorageIndex), of which CHOLMOD reads only the upper triangle
// (stype = 1). `values` null: a pattern-only matrix (CHOLMOD_PATTERN, enough for the analysis).
cholmod_sparse UpperView(int64_t n, const int32_t* outer, const int32_t* inner,
                         const double* values, bool sorted);

// The Status of CHOLMOD's last call `during` ("analyze", "factorize", "solve"), prefixed by
// `context`: ResourceExhausted for out of memory or too large for 32-bit indices,
// FailedPrecondition for not positive definite, Internal for other errors, OK for success and
// warnings.
absl::Status StatusFromCholmod(const cholmod_common& c, const char* context, const char* during);

// cholmod_analyze of `A` with the settings in `c`: the symbolic factor (the caller frees it with
// cholmod_free_factor), or the error as StatusFromCholmod says (Internal if CHOLMOD returned no
// factor without one).
absl::StatusOr<cholmod_factor*> Analyze(cholmod_sparse* A, cholmod_common* c, const char* context);

}  // namespace fieldspace::linalg_internal

#endif  // FIELDSPACE_CORE_LINALG_CHOLMOD_UTIL_H_
