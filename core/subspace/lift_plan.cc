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

void LiftPlan::StreamBuilder::Begin(int64_t rows, int64_t cols, int32_t dofs_per_face,
                                    const std::vector<int32_t>& row_pointers) {
  plan_.p_ = dofs_per_face;
  num_faces_ = rows / dofs_per_face;
  cols_ = cols;
  outer_ = row_pointers;
  const int64_t nnz = outer_.back();
  plan_.begin_.reserve(num_faces_ + 1);
  // Exact when every face's rows share their columns (the union of p rows of n entries has n).
  const int64_t expected = nnz / dofs_per_face;
  if (cols <= 65536) {
    plan_.cols16_.reserve(expected);
  } else {
    plan_.cols32_.reserve(expected);
  }
  CloseFaces();  // faces without entries before the first column
}

void LiftPlan::StreamBuilder::AddColumns(const int32_t* cols, int64_t n) {
  const int64_t p = plan_.p_;
  while (n > 0 && next_face_ < num_faces_) {
    const int64_t take = std::min<int64_t>(n, outer_[p * (next_face_ + 1)] - columns_seen_);
    face_columns_.insert(face_columns_.end(), cols, cols + take);
    cols += take;
    n -= take;
    columns_seen_ += take;
    CloseFaces();
  }
}

void LiftPlan::StreamBuilder::CloseFaces() {
  const int64_t p = plan_.p_;
  std::vector<int32_t> merged;
  while (next_face_ < num_faces_ && outer_[p * (next_face_ + 1)] <= columns_seen_) {
    const int64_t f = next_face_;
    const int32_t* face = face_columns_.data();
    const int64_t first = outer_[p * f];
    const auto row_begin = [&](int64_t c) { return face + (outer_[p * f + c] - first); };
    const auto row_size = [&](int64_t c) { return outer_[p * f + c + 1] - outer_[p * f + c]; };
    bool regular = true;
    for (int64_t c = 1; c < p && regular; ++c) {
      regular = row_size(c) == row_size(0) &&
                std::equal(row_begin(c), row_begin(c) + row_size(c), row_begin(0));
    }
    const int32_t* list = row_begin(0);
    int64_t size = row_size(0);
    if (!regular) {
      merged.clear();
      for (int64_t c = 0; c < p; ++c) {
        merged.insert(merged.end(), row_begin(c), row_begin(c) + row_size(c));
      }
      std::sort(merged.begin(), merged.end());
      merged.erase(std::unique(merged.begin(), merged.end()), merged.end());
      irregular_faces_.push_back(f);
      irregular_start_.push_back(static_cast<int64_t>(places_.size()));
      for (int64_t c = 0; c < p; ++c) {
        for (const int32_t* e = row_begin(c); e != row_begin(c) + row_size(c); ++e) {
          places_.push_back(static_cast<int32_t>(
              std::lower_bound(merged.begin(), merged.end(), *e) - merged.begin()));
        }
      }
      list = merged.data();
      size = static_cast<int64_t>(merged.size());
    }
    if (cols_ <= 65536) {
      plan_.cols16_.insert(plan_.cols16_.end(), list, list + size);
    } else {
      plan_.cols32_.insert(plan_.cols32_.end(), list, list + size);
    }
    plan_.begin_.push_back(plan_.begin_.back() + size);
    face_columns_.clear();
    ++next_face_;
  }
}

void LiftPlan::StreamBuilder::AddValues(const float* vals, int64_t n) {
  const int64_t p = plan_.p_;
  if (plan_.vals_.empty()) plan_.vals_.assign(plan_.begin_.back() * p, 0.0f);
  for (int64_t i = 0; i < n; ++i, ++values_seen_) {
    const int64_t q = values_seen_;
    while (outer_[value_row_ + 1] <= q) ++value_row_;
    const int64_t f = value_row_ / p;
    const int64_t c = value_row_ % p;
    while (next_irregular_ < irregular_faces_.size() && irregular_faces_[next_irregular_] < f) {
      ++next_irregular_;
    }
    const int64_t place =
        next_irregular_ < irregular_faces_.size() && irregular_faces_[next_irregular_] == f
            ? places_[irregular_start_[next_irregular_] + (q - outer_[p * f])]
            : q - outer_[value_row_];
    plan_.vals_[(plan_.begin_[f] + place) * p + c] = vals[i];
  }
}

absl::StatusOr<LiftPlan> LiftPlan::StreamBuilder::Finish() && {
  const int64_t nnz = outer_.empty() ? 0 : outer_.back();
  if (outer_.empty() || next_face_ != num_faces_ || columns_seen_ != nnz || values_seen_ != nnz) {
    return absl::FailedPreconditionError("LiftPlan::StreamBuilder: U did not come whole");
  }
  if (plan_.vals_.empty()) plan_.vals_.assign(plan_.begin_.back() * plan_.p_, 0.0f);
  return std::move(plan_);
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
