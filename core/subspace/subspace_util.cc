#include "core/subspace/subspace_util.h"

#include <atomic>
#include <cmath>
#include <string>

#include "absl/strings/str_cat.h"
#include "oneapi/tbb/blocked_range.h"
#include "oneapi/tbb/parallel_for.h"

namespace fieldspace {

absl::Status CheckBasisMatrix(const BasisMatrix& U, std::string_view what) {
  std::atomic<int64_t> bad_row{-1};
  tbb::parallel_for(tbb::blocked_range<int64_t>(0, U.rows(), 4096),
                    [&](const tbb::blocked_range<int64_t>& r) {
                      for (int64_t i = r.begin(); i < r.end(); ++i) {
                        const BasisRow row = GetBasisRow(U, i);
                        for (int64_t q = 0; q < row.size; ++q) {
                          if (!std::isfinite(row.vals[q])) {
                            bad_row.store(i);
                            return;
                          }
                        }
                      }
                    });
  if (bad_row.load() >= 0) {
    return absl::InvalidArgumentError(absl::StrCat(
        std::string(what), ": basis U has a non-finite value in row ", bad_row.load()));
  }
  return absl::OkStatus();
}

}  // namespace fieldspace
