#ifndef FIELDSPACE_CORE_SUBSPACE_LIFT_PLAN_H_
#define FIELDSPACE_CORE_SUBSPACE_LIFT_PLAN_H_

#include <cstdint>
#include <vector>

#include "Eigen/SparseCore"
#include "absl/status/statusor.h"
#include "core/basis/basis_io.h"

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

namespace fieldspace {

// A face-major copy of a basis U (k x d) laid out for lifting X = U x. Lifting is a sparse
// matrix-vector product whose cost is reading U (tens of millions of nonzeros on large meshes),
// so the layout minimizes bytes per nonzero: the dofs_per_face rows of one face share a single
// column list (the union of theirs; an entry a row lacks is stored as 0, which for local bases
// practically never happens), with 16-bit column indices when d <= 65536. For vector fields that
// is 5 bytes per nonzero instead of the 8 of U's CSR storage. Immutable; thread-safe to share.
class LiftPlan {
 public:
  LiftPlan() = default;
  // U: k x d row-major, k a multiple of dofs_per_face. Parallel.
  static LiftPlan Build(const Eigen::SparseMatrix<float, Eigen::RowMajor>& U,
                        int32_t dofs_per_face);

  int64_t num_faces() const { return static_cast<int64_t>(begin_.size()) - 1; }
  int32_t dofs_per_face() const { return p_; }
  // Builds a plan from U's CSR arrays as a basis file streams them by (DecodeBasisFrom with a
  // BasisRowsSink), equal to Build's from the decoded U: U itself is never held, only the plan,
  // the row pointers and, for faces whose rows differ in their columns (practically none), each
  // entry's place in the face's column list. Sequential: the file's read is the bound.
  class StreamBuilder;

  // out[0 .. p) = (U x) at the DOFs of `face`; x has d entries. No bounds checks.
  void LiftFace(const double* x, int64_t face, double* out) const {
    if (cols16_.empty()) {
      LiftFaceImpl(cols32_.data(), x, face, out);
    } else {
      LiftFaceImpl(cols16_.data(), x, face, out);
    }
  }
  // Row c of `face` (row p face + c of U, c < p) appended to cols / vals: ascending columns,
  // without the zeros the face's shared column list holds for columns the row lacks. What a
  // served ReducedSystem reads once it released U (ReducedSystemOptions::release_basis_rows).
  void AppendRow(int64_t face, int32_t c, std::vector<int>* cols, std::vector<float>* vals) const;
  // Calls fn(column, values) for each entry of `face`'s column list, ascending: values points to
  // its p values, one per row of the face (0 where a row lacks the column).
  template <typename Fn>
  void ForEachEntry(int64_t face, Fn&& fn) const {
    const int64_t b = begin_[face], e = begin_[face + 1];
    for (int64_t j = b; j < e; ++j) {
      fn(cols16_.empty() ? cols32_[j] : static_cast<int>(cols16_[j]), vals_.data() + j * p_);
    }
  }
  // All faces into out (k values), parallel over faces.
  void LiftAll(const double* x, double* out) const;
  // The same narrowed to float in the same pass (half the bytes written: what the wire sends).
  // False when a value is not finite as a float (beyond 3.4e38 or NaN); out is filled anyway.
  bool LiftAllToFloat(const double* x, float* out) const;
  int64_t memory_bytes() const;

 private:
  template <typename Index>
  void LiftFaceImpl(const Index* cols, const double* x, int64_t face, double* out) const {
    const int64_t b = begin_[face], e = begin_[face + 1];
    const float* v = vals_.data() + b * p_;
    if (p_ == 2) {
#if defined(__SSE2__)
      // Both DOFs of the face in one SSE2 register (baseline x86-64, no -march needed): the
      // float pair converts with one instruction. One accumulator keeps the summation order of
      // the scalar loop, so results are bit-identical to U's CSR product.
      __m128d acc = _mm_setzero_pd();
      int64_t j = b;
      for (; j + 1 < e; j += 2, v += 4) {
        const __m128 pair = _mm_loadu_ps(v);
        acc = _mm_add_pd(acc, _mm_mul_pd(_mm_cvtps_pd(pair), _mm_set1_pd(x[cols[j]])));
        acc = _mm_add_pd(
            acc, _mm_mul_pd(_mm_cvtps_pd(_mm_movehl_ps(pair, pair)), _mm_set1_pd(x[cols[j + 1]])));
      }
      if (j < e) {
        const __m128 pair = _mm_castpd_ps(_mm_load_sd(reinterpret_cast<const double*>(v)));
        acc = _mm_add_pd(acc, _mm_mul_pd(_mm_cvtps_pd(pair), _mm_set1_pd(x[cols[j]])));
      }
      _mm_storeu_pd(out, acc);
#else
      double a0 = 0, a1 = 0;
      for (int64_t j = b; j < e; ++j, v += 2) {
        const double xj = x[cols[j]];
        a0 += static_cast<double>(v[0]) * xj;
        a1 += static_cast<double>(v[1]) * xj;
      }
      out[0] = a0;
      out[1] = a1;
#endif
      return;
    }
    double acc[8] = {0, 0, 0, 0, 0, 0, 0, 0};
    for (int64_t j = b; j < e; ++j, v += p_) {
      const double xj = x[cols[j]];
      for (int32_t c = 0; c < p_; ++c) acc[c] += static_cast<double>(v[c]) * xj;
    }
    for (int32_t c = 0; c < p_; ++c) out[c] = acc[c];
  }

  friend class StreamBuilder;

  int32_t p_ = 1;
  std::vector<int64_t> begin_{0};  // num_faces + 1 offsets into the column lists
  std::vector<uint16_t> cols16_;   // used when d <= 65536
  std::vector<int32_t> cols32_;    // otherwise
  std::vector<float> vals_;        // per column entry, p values (one per row of the face)
};

class LiftPlan::StreamBuilder final : public BasisRowsSink {
 public:
  void Begin(int64_t rows, int64_t cols, int32_t dofs_per_face,
             const std::vector<int32_t>& row_pointers) override;
  void AddColumns(const int32_t* cols, int64_t n) override;
  void AddValues(const float* vals, int64_t n) override;
  // The plan, once every column and value came; FailedPrecondition before that.
  absl::StatusOr<LiftPlan> Finish() &&;

 private:
  // Appends the column lists of faces [next_face_, ...) whose entries have all come.
  void CloseFaces();

  LiftPlan plan_;
  int64_t num_faces_ = 0;
  int64_t cols_ = 0;
  std::vector<int32_t> outer_;         // U's row pointers
  int64_t columns_seen_ = 0;           // column indices come so far
  int64_t values_seen_ = 0;            // values come so far
  int64_t next_face_ = 0;              // the first face whose column list is not made
  std::vector<int32_t> face_columns_;  // the columns of next_face_'s rows come so far
  // Faces whose rows differ in their columns, ascending, where their entries' places in the
  // face's column list start in `places_`, and those places (entry order).
  std::vector<int64_t> irregular_faces_, irregular_start_;
  std::vector<int32_t> places_;
  // While values come: the current entry's row, and the next irregular face.
  int64_t value_row_ = 0;
  size_t next_irregular_ = 0;
};

}  // namespace fieldspace

#endif  // FIELDSPACE_CORE_SUBSPACE_LIFT_PLAN_H_
