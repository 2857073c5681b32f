#ifndef FIELDSPACE_CORE_OPERATORS_FACE_BLOCK_ASSEMBLY_H_
#define FIELDSPACE_CORE_OPERATORS_FACE_BLOCK_ASSEMBLY_H_

// Internal to core/operators: direct CSC construction of symmetric per-face block matrices.
// Triplets + setFromTriplets would need ~3x the final memory and a global sort; here every face
// writes its own columns in place, so assembly is O(nnz), parallel and allocation-free per face.

#include <atomic>
#include <cstdint>
#include <limits>
#include <vector>

#include "Eigen/SparseCore"
#include "absl/status/statusor.h"
#include "absl/strings/str_format.h"
#include "core/mesh/triangle_mesh.h"
#include "core/operators/edge_transport.h"
#include "tbb/blocked_range.h"
#include "tbb/parallel_for.h"

namespace fieldspace::operators_internal {

inline constexpr int64_t kFaceGrain = 2048;

// Insertion sort for the tiny per-face lists (at most a handful of items): faster than std::sort
// there, and free of GCC 12's false -Warray-bounds reports on std::sort of small arrays.
template <typename T, typename Less>
inline void SmallSort(T* items, int count, Less less) {
  for (int i = 1; i < count; ++i) {
    T item = items[i];
    int j = i;
    for (; j > 0 && less(item, items[j - 1]); --j) items[j] = items[j - 1];
    items[j] = item;
  }
}

// Receives the blocks of one face row in ascending neighbor order.
template <int P>
class FaceRowWriter {
 public:
  FaceRowWriter(int* inner, double* values, int64_t base, int32_t count)
      : inner_(inner), values_(values), base_(base), count_(count) {}

  // block[c * P + d] = S(P f + c, P g + d). Must be called exactly count(f) times, g ascending.
  void Add(int32_t g, const double* block) {
    if (written_ < count_) {
      for (int c = 0; c < P; ++c) {
        const int64_t at = base_ + static_cast<int64_t>(c) * P * count_ + P * written_;
        for (int d = 0; d < P; ++d) {
          inner_[at + d] = P * g + d;
          values_[at + d] = block[c * P + d];
        }
      }
    }
    ++written_;
  }
  int32_t written() const { return written_; }

 private:
  int* inner_;
  double* values_;
  int64_t base_;
  int32_t count_;
  int32_t written_ = 0;
};

// Builds the k x k matrix (k = P * num_faces, DOF P f + c) whose nonzero P x P blocks are those
// reported by `fill`. The matrix must be symmetric: column P f + c is filled from row P f + c of
// face f's blocks, so the caller guarantees block(f, g) = block(g, f)^T.
//   count(f) -> int32_t: number of distinct faces g (including f) with a block in row f.
//   fill(f, FaceRowWriter<P>& writer): writer.Add(g, block) for those g in ascending order.
// ResourceExhausted when nnz exceeds Eigen's 32-bit indices.
template <int P, typename CountFn, typename FillFn>
absl::StatusOr<Eigen::SparseMatrix<double>> AssembleFaceBlocks(int32_t num_faces, CountFn count,
                                                               FillFn fill) {
  std::vector<int64_t> offset(static_cast<size_t>(num_faces) + 1, 0);
  std::vector<int32_t> counts(num_faces);
  tbb::parallel_for(tbb::blocked_range<int32_t>(0, num_faces, kFaceGrain),
                    [&](const tbb::blocked_range<int32_t>& r) {
                      for (int32_t f = r.begin(); f != r.end(); ++f) counts[f] = count(f);
                    });
  for (int32_t f = 0; f < num_faces; ++f) {
    offset[f + 1] = offset[f] + int64_t{P} * P * counts[f];
  }
  const int64_t nnz = offset[num_faces];
  const int64_t k = int64_t{P} * num_faces;
  // Built inside the StatusOr and returned by name from every return statement (so NRVO
  // applies): Eigen sparse matrices have no move operations, and a copy of S would double the
  // peak memory.
  absl::StatusOr<Eigen::SparseMatrix<double>> result(absl::in_place);
  if (nnz > std::numeric_limits<int>::max() || k > std::numeric_limits<int>::max()) {
    result = absl::ResourceExhaustedError(
        absl::StrFormat("operator has %d nonzeros, beyond 32-bit sparse indices", nnz));
    return result;
  }
  Eigen::SparseMatrix<double>& S = *result;
  S.resize(k, k);
  S.resizeNonZeros(nnz);
  int* outer = S.outerIndexPtr();
  int* inner = S.innerIndexPtr();
  double* values = S.valuePtr();
  std::atomic<bool> mismatch{false};
  tbb::parallel_for(tbb::blocked_range<int32_t>(0, num_faces, kFaceGrain),
                    [&](const tbb::blocked_range<int32_t>& r) {
                      for (int32_t f = r.begin(); f != r.end(); ++f) {
                        for (int c = 0; c < P; ++c) {
                          outer[P * f + c] =
                              static_cast<int>(offset[f] + int64_t{c} * P * counts[f]);
                        }
                        FaceRowWriter<P> writer(inner, values, offset[f], counts[f]);
                        fill(f, writer);
                        if (writer.written() != counts[f]) mismatch = true;
                      }
                    });
  outer[k] = static_cast<int>(nnz);
  if (mismatch) result = absl::InternalError("operator assembly: block count mismatch (bug)");
  return result;
}

// Connection Laplacian on P DOFs per face with the edge weights of `transport`:
//   x^T S x = sum over interior e = (f0, f1) of weight_e |x_f0 - T_e x_f1|^2, T_e orthogonal,
// so S_ff = (sum of weights around f) I, S_f0f1 = -w T_e, S_f1f0 = -w T_e^T.
// edge_transport(e, double* T) writes T_e (P x P, row-major), the transport from face
// edge_faces(e, 1) to face edge_faces(e, 0); it is called once per side and must be deterministic,
// so the two sides are bitwise transposes.
template <int P, typename EdgeTransportFn>
absl::StatusOr<Eigen::SparseMatrix<double>> AssembleConnectionLaplacian(
    const TriangleMesh& mesh, const EdgeTransport& transport, EdgeTransportFn edge_transport) {
  const FaceMatrix& FE = mesh.face_edges();
  const FaceMatrix& FN = mesh.face_neighbors();
  struct Item {
    int32_t g;
    int32_t e;  // shared edge; -1 for the diagonal entry
  };
  // Neighbors of f (and f itself) sorted by face, then edge: a canonical summation order.
  auto items_of = [&](int32_t f, Item* items) {
    int m = 0;
    items[m++] = {f, -1};
    for (int k = 0; k < 3; ++k) {
      if (FN(f, k) != kNoFace) items[m++] = {FN(f, k), FE(f, k)};
    }
    SmallSort(items, m,
              [](const Item& a, const Item& b) { return a.g != b.g ? a.g < b.g : a.e < b.e; });
    return m;
  };
  auto count = [&](int32_t f) {
    Item items[4];
    const int m = items_of(f, items);
    int32_t distinct = 0;
    for (int i = 0; i < m; ++i) distinct += (i == 0 || items[i].g != items[i - 1].g);
    return distinct;
  };
  auto fill = [&](int32_t f, FaceRowWriter<P>& writer) {
    // Edge records sit at random places: fetch them for a face a few rows ahead.
    if (f + 4 < mesh.num_faces()) {
      for (int k = 0; k < 3; ++k) __builtin_prefetch(&transport.edges[FE(f + 4, k)]);
    }
    Item items[4];
    const int m = items_of(f, items);
    for (int i = 0; i < m;) {
      const int32_t g = items[i].g;
      double block[P * P] = {};
      for (; i < m && items[i].g == g; ++i) {
        if (g == f) {
          double diagonal = 0.0;
          for (int k = 0; k < 3; ++k) {
            if (FN(f, k) != kNoFace) diagonal += transport.edges[FE(f, k)].weight;
          }
          for (int c = 0; c < P; ++c) block[c * P + c] += diagonal;
          continue;
        }
        const int32_t e = items[i].e;
        double T[P * P];
        edge_transport(e, T);
        const double w = transport.edges[e].weight;
        // edge_faces() lists the lower face index first.
        const bool first_side = f < g;
        for (int c = 0; c < P; ++c) {
          for (int d = 0; d < P; ++d) {
            block[c * P + d] -= w * (first_side ? T[c * P + d] : T[d * P + c]);
          }
        }
      }
      writer.Add(g, block);
    }
  };
  return AssembleFaceBlocks<P>(mesh.num_faces(), count, fill);
}

}  // namespace fieldspace::operators_internal

#endif  // FIELDSPACE_CORE_OPERATORS_FACE_BLOCK_ASSEMBLY_H_
