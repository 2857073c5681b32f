#include "core/subspace/lift_plan.h"

#include <algorithm>
#include <atomic>
#include <cmath>

#include "core/subspace/subspace_util.h"
#include "oneapi/tbb/blocked_range.h"
#include "oneapi/tbb/parallel_for.h"

namespace fieldspace {

LiftPlan LiftPlan::Build(const BasisMatrix& U, int32_t dofs_per_face) {
  LiftPlan plan;
  plan.p_ = dofs_per_face;
  const int64_t p = dofs_per_face;
  const int64_t num_faces = U.rows() / p;
  // Pass 1: the size of each face's column union (merging its p sorted rows).
  std::vector<int64_t> count(num_faces + 1, 0);
  const auto for_union = [&](int64_t f, auto&& visit) {
    BasisRow rows[8];
    int64_t pos[8] = {0, 0, 0, 0, 0, 0, 0, 0};
    for (int64_t c = 0; c < p; ++c) rows[c] = GetBasisRow(U, f * p + c);
    while (true) {
      int32_t next = -1;
      for (int64_t c = 0; c < p; ++c) {
        if (pos[c] < rows[c].size && (next < 0 || rows[c].cols[pos[c]] < next)) {
          next = rows[c].cols[pos[c]];
        }
      }
      if (next < 0) return;
      float vals[8] = {0, 0, 0, 0, 0, 0, 0, 0};
      for (int64_t c = 0; c < p; ++c) {
        if (pos[c] < rows[c].size && rows[c].cols[pos[c]] == next) vals[c] = rows[c].vals[pos[c]++];
      }
      visit(next, vals);
    }
  };
  tbb::parallel_for(tbb::blocked_range<int64_t>(0, num_faces, 4096),
                    [&](const tbb::blocked_range<int64_t>& r) {
                      for (int64_t f = r.begin(); f < r.end(); ++f) {
                        int64_t n = 0;
                        for_union(f, [&](int32_t, const float*) { ++n; });
                        count[f + 1] = n;
                      }
                    });
  for (int64_t f = 0; f < num_faces; ++f) count[f + 1] += count[f];
  plan.begin_ = std::move(count);
  const int64_t total = plan.begin_[num_faces];
  const bool narrow = U.cols() <= 65536;
  if (narrow) {
    plan.cols16_.resize(total);
  } else {
    plan.cols32_.resize(total);
  }
  plan.vals_.resize(total * p);
  tbb::parallel_for(tbb::blocked_range<int64_t>(0, num_faces, 4096),
                    [&](const tbb::blocked_range<int64_t>& r) {
                      for (int64_t f = r.begin(); f < r.end(); ++f) {
                        int64_t j = plan.begin_[f];
                        for_union(f, [&](int32_t col, const float* vals) {
                          if (narrow) {
                            plan.cols16_[j] = static_cast<uint16_t>(col);
                          } else {
                            plan.cols32_[j] = col;
                          }
                          std::copy(vals, vals + p, plan.vals_.data() + j * p);
                          ++j;
                        });
                      }
                    });
  return plan;
}

void LiftPlan::AppendRow(int64_t face, int32_t c, std::vector<int>* cols,
                         std::vector<float>* vals) const {
  ForEachEntry(face, [&](int col, const float* v) {
    if (v[c] == 0.0f) return;
    cols->push_back(col);
    vals->push_back(v[c]);
  });
}

void LiftPlan::LiftAll(const double* x, double* out) const {
  tbb::parallel_for(tbb::blocked_range<int64_t>(0, num_faces(), 4096),
                    [&](const tbb::blocked_range<int64_t>& r) {
                      for (int64_t f = r.begin(); f < r.end(); ++f) LiftFace(x, f, out + f * p_);
                    });
}

bool LiftPlan::LiftAllToFloat(const double* x, float* out) const {
  std::atomic<bool> finite{true};
  tbb::parallel_for(tbb::blocked_range<int64_t>(0, num_faces(), 4096),
                    [&](const tbb::blocked_range<int64_t>& r) {
                      bool ok = true;
                      double face[8];
                      for (int64_t f = r.begin(); f < r.end(); ++f) {
                        LiftFace(x, f, face);
                        float* o = out + f * p_;
                        for (int32_t c = 0; c < p_; ++c) {
                          o[c] = static_cast<float>(face[c]);
                          ok &= std::isfinite(o[c]);
                        }
                      }
                      if (!ok) finite.store(false, std::memory_order_relaxed);
                    });
  return finite.load();
}

int64_t LiftPlan::memory_bytes() const {
  return static_cast<int64_t>(begin_.size() * sizeof(int64_t) + cols16_.size() * 2 +
                              cols32_.size() * 4 + vals_.size() * sizeof(float));
}

}  // namespace fieldspace
