#include "core/operators/vector_laplacian.h"

#include <algorithm>
#include <array>
#include <cstdint>
#include <limits>
#include <new>
#include <numeric>
#include <vector>

#include "Eigen/Core"
#include "absl/strings/str_format.h"
#include "core/operators/face_block_assembly.h"
#include "tbb/blocked_range.h"
#include "tbb/parallel_for.h"

namespace fieldspace {
namespace {

using operators_internal::AssembleFaceBlocks;
using operators_internal::FaceRowWriter;
using operators_internal::kFaceGrain;
using vector_laplacian_internal::VertexStars;

// Doubles per face in the edge-vector table (6 used, padded to a cache line).
constexpr size_t kStride = 8;

VertexStars BuildVertexStars(const TriangleMesh& mesh) {
  const FaceMatrix& F = mesh.faces();
  const int32_t nf = mesh.num_faces();
  VertexStars s;
  s.offset.assign(static_cast<size_t>(mesh.num_vertices()) + 1, 0);
  for (int32_t f = 0; f < nf; ++f) {
    for (int k = 0; k < 3; ++k) ++s.offset[F(f, k) + 1];
  }
  std::partial_sum(s.offset.begin(), s.offset.end(), s.offset.begin());
  s.corners.resize(3 * static_cast<size_t>(nf));
  std::vector<int64_t> cursor(s.offset.begin(), s.offset.end() - 1);
  for (int32_t f = 0; f < nf; ++f) {
    for (int k = 0; k < 3; ++k) s.corners[cursor[F(f, k)]++] = 4 * f + k;
  }
  return s;
}

// One contribution of a shared vertex to block (f, g): vertex v is corner kf of f, corner kg of g.
struct SharedVertex {
  int32_t v;
  int32_t kf;
  int32_t kg;
};

// Walks the faces sharing a vertex with face f in ascending order: a 3-way merge of the (sorted)
// stars of f's vertices. For each distinct face g calls visit(g, shared, count), shared[0..count)
// the vertices f and g share, sorted by vertex index. prefetch(g) is called first for every
// neighbor.
template <typename Prefetch, typename Visit>
inline void ForEachVertexNeighbor(const VertexStars& stars, const FaceMatrix& F, int32_t f,
                                  Prefetch prefetch, Visit visit) {
  const int32_t* head[3];
  const int32_t* end[3];
  int32_t vertex[3];
  for (int k = 0; k < 3; ++k) {
    vertex[k] = F(f, k);
    head[k] = stars.corners.data() + stars.offset[vertex[k]];
    end[k] = stars.corners.data() + stars.offset[vertex[k] + 1];
  }
  // The per-face data of the neighbors is scattered in memory: request all of it up front so the
  // cache misses overlap instead of following one another through the merge.
  for (int k = 0; k < 3; ++k) {
    for (const int32_t* c = head[k]; c != end[k]; ++c) prefetch(*c >> 2);
  }
  constexpr int32_t kDone = std::numeric_limits<int32_t>::max();
  while (true) {
    int32_t next[3];
    for (int k = 0; k < 3; ++k) next[k] = head[k] != end[k] ? (*head[k] >> 2) : kDone;
    const int32_t g = std::min(next[0], std::min(next[1], next[2]));
    if (g == kDone) return;
    SharedVertex shared[3];
    int count = 0;
    for (int k = 0; k < 3; ++k) {
      if (next[k] == g) {
        shared[count++] = {vertex[k], k, *head[k] & 3};
        ++head[k];
      }
    }
    // Sum in a canonical order (by vertex index) so that block (g, f) computed from g's side is
    // bitwise the transpose of block (f, g): S is exactly symmetric.
    operators_internal::SmallSort(
        shared, count, [](const SharedVertex& a, const SharedVertex& b) { return a.v < b.v; });
    visit(g, shared, count);
  }
}

}  // namespace

HodgeInverseMasses BuildHodgeInverseMasses(const TriangleMesh& mesh) {
  const FaceMatrix& F = mesh.faces();
  const FaceMatrix& FE = mesh.face_edges();
  const Eigen::VectorXd& area = mesh.face_areas();
  HodgeInverseMasses inv;
  inv.vertex.assign(mesh.num_vertices(), 0.0);
  inv.edge.assign(mesh.num_edges(), 0.0);
  for (int32_t f = 0; f < mesh.num_faces(); ++f) {
    for (int k = 0; k < 3; ++k) {
      inv.vertex[F(f, k)] += area[f];
      inv.edge[FE(f, k)] += area[f];
    }
  }
  for (double& m : inv.vertex) m = 3.0 / m;
  for (double& m : inv.edge) m = 3.0 / m;
  return inv;
}

absl::StatusOr<VectorHodgeRows> VectorHodgeRows::Create(const TriangleMesh& mesh) {
  const int32_t nf = mesh.num_faces();
  if (4 * static_cast<int64_t>(nf) > std::numeric_limits<int32_t>::max()) {
    return absl::ResourceExhaustedError(
        absl::StrFormat("vector Laplacian: %d faces is beyond 32-bit corner indices", nf));
  }
  VectorHodgeRows rows(mesh);
  rows.stars_ = BuildVertexStars(mesh);

  // Edge vectors t_fk = p_{k+2} - p_{k+1} (counter-clockwise, opposite corner k) in face f's frame.
  // They give both terms: area_f grad phi_k|f = J t_fk / 2 and area_f J grad psi_e|f = t_fk.
  // Rows padded to one 64-byte cache line: the neighbor loop reads whole rows of random faces.
  std::vector<double, vector_laplacian_internal::CacheAlignedAllocator<double>>& t = rows.t_;
  t.resize(kStride * static_cast<size_t>(nf));
  tbb::parallel_for(tbb::blocked_range<int32_t>(0, nf, kFaceGrain),
                    [&](const tbb::blocked_range<int32_t>& r) {
                      for (int32_t f = r.begin(); f != r.end(); ++f) {
                        for (int k = 0; k < 3; ++k) {
                          const Eigen::Vector2d tk = mesh.EdgeVectorInFrame(f, k);
                          t[kStride * f + 2 * k] = tk[0];
                          t[kStride * f + 2 * k + 1] = tk[1];
                        }
                      }
                    });
  rows.inv_mass_ = BuildHodgeInverseMasses(mesh);
  return rows;
}

// Distinct faces sharing a vertex with f: the star sizes summed, minus the repeats. A face
// sharing m >= 1 edges with f shares min(m + 1, 3) vertices (two vertices of a triangle always
// span one of its edges, and an edge has at most two faces), f itself shares 3.
int32_t VectorHodgeRows::CountBlocks(int32_t f) const {
  const FaceMatrix& F = mesh_->faces();
  const FaceMatrix& FN = mesh_->face_neighbors();
  int64_t n = -2;
  for (int k = 0; k < 3; ++k) n += stars_.offset[F(f, k) + 1] - stars_.offset[F(f, k)];
  for (int k = 0; k < 3; ++k) {
    const int32_t g = FN(f, k);
    if (g == kNoFace) continue;
    int m = 0, first = 3;
    for (int j = 0; j < 3; ++j) {
      if (FN(f, j) == g) {
        ++m;
        first = std::min(first, j);
      }
    }
    if (first == k) n -= std::min(m + 1, 3) - 1;  // count each neighbor once
  }
  return static_cast<int32_t>(n);
}

void VectorHodgeRows::ForEachBlock(
    int32_t f, absl::FunctionRef<void(int32_t g, const double* block)> visit) const {
  const FaceMatrix& F = mesh_->faces();
  const FaceMatrix& FE = mesh_->face_edges();
  const FaceMatrix& FN = mesh_->face_neighbors();
  const double* t = t_.data();
  const double* inv_mv = inv_mass_.vertex.data();
  const double* inv_me = inv_mass_.edge.data();
  const double* tf = &t[kStride * f];
  auto prefetch = [&](int32_t g) { __builtin_prefetch(&t[kStride * g]); };
  ForEachVertexNeighbor(stars_, F, f, prefetch, [&](int32_t g, const SharedVertex* shared, int n) {
    const double* tg = &t[kStride * g];
    double block[4] = {0.0, 0.0, 0.0, 0.0};
    // Vertex (divergence) term: q = J t / 2 = (-t_y / 2, t_x / 2).
    for (int i = 0; i < n; ++i) {
      const double w = inv_mv[shared[i].v];
      const double a[2] = {-0.5 * tf[2 * shared[i].kf + 1], 0.5 * tf[2 * shared[i].kf]};
      const double b[2] = {-0.5 * tg[2 * shared[i].kg + 1], 0.5 * tg[2 * shared[i].kg]};
      for (int c = 0; c < 2; ++c) {
        for (int d = 0; d < 2; ++d) block[2 * c + d] += w * (a[c] * b[d]);
      }
    }
    // Edge (curl) term over the edges f and g share, in ascending edge order.
    std::array<std::array<int32_t, 3>, 3> edges;  // (edge, kf, kg)
    int m = 0;
    if (g == f) {
      for (int k = 0; k < 3; ++k) edges[m++] = {FE(f, k), k, k};
    } else if (n == 2) {
      // The usual case: one shared edge, opposite the corners that are not shared.
      const int kf = 3 - shared[0].kf - shared[1].kf;
      const int kg = 3 - shared[0].kg - shared[1].kg;
      edges[m++] = {FE(f, kf), kf, kg};
    } else if (n == 3) {
      // f and g share all three vertices (a closed two-triangle "pillow"): every common edge.
      for (int k = 0; k < 3; ++k) {
        if (FN(f, k) != g) continue;
        const int32_t e = FE(f, k);
        int l = 0;
        while (l < 2 && FE(g, l) != e) ++l;
        edges[m++] = {e, k, l};
      }
      operators_internal::SmallSort(edges.data(), m,
                                    [](const auto& a, const auto& b) { return a[0] < b[0]; });
    }
    for (int i = 0; i < m; ++i) {
      const double w = inv_me[edges[i][0]];
      const double* a = tf + 2 * edges[i][1];
      const double* b = tg + 2 * edges[i][2];
      for (int c = 0; c < 2; ++c) {
        for (int d = 0; d < 2; ++d) block[2 * c + d] += w * (a[c] * b[d]);
      }
    }
    visit(g, block);
  });
}

double VectorHodgeRows::Trace() const {
  double trace = 0.0;
  for (int32_t f = 0; f < num_faces(); ++f) {
    ForEachBlock(f, [&](int32_t g, const double* block) {
      if (g == f) trace += block[0] + block[3];
    });
  }
  return trace;
}

absl::StatusOr<Eigen::SparseMatrix<double>> BuildVectorHodgeStiffness(const TriangleMesh& mesh) {
  absl::StatusOr<VectorHodgeRows> rows = VectorHodgeRows::Create(mesh);
  if (!rows.ok()) return rows.status();
  return AssembleFaceBlocks<2>(
      mesh.num_faces(), [&](int32_t f) { return rows->CountBlocks(f); },
      [&](int32_t f, FaceRowWriter<2>& writer) {
        rows->ForEachBlock(f, [&](int32_t g, const double* block) { writer.Add(g, block); });
      });
}
}  // namespace fieldspace
