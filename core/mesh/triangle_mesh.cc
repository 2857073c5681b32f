#include "core/mesh/triangle_mesh.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <numeric>
#include <string>
#include <utility>
#include <vector>

#include "Eigen/Geometry"
#include "absl/status/status.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/synchronization/mutex.h"
#include "core/common/status_macros.h"
#include "tbb/blocked_range.h"
#include "tbb/combinable.h"
#include "tbb/parallel_for.h"

namespace fieldspace {
namespace {

constexpr int64_t kGrain = 4096;

// A face whose doubled area is below this fraction of its longest squared edge is degenerate:
// its normal, and so its frame, is numerically meaningless.
constexpr double kDegenerateRatio = 1e-14;

// Half-edges grouped by their lower vertex (counting sort): bucket v holds the half-edges
// (face, corner) of every edge whose smaller endpoint is v. Building edges from these buckets is
// O(F) and needs no global sort or hash map.
struct HalfEdgeBuckets {
  std::vector<int64_t> offsets;  // #V + 1
  std::vector<int64_t> items;    // 3F entries: face * 3 + corner (corner opposite the half-edge)
};

HalfEdgeBuckets BucketHalfEdges(const FaceMatrix& F, int32_t num_vertices) {
  HalfEdgeBuckets b;
  b.offsets.assign(num_vertices + 1, 0);
  const int64_t nf = F.rows();
  for (int64_t f = 0; f < nf; ++f) {
    for (int k = 0; k < 3; ++k) {
      const int32_t a = F(f, (k + 1) % 3), c = F(f, (k + 2) % 3);
      ++b.offsets[std::min(a, c) + 1];
    }
  }
  std::partial_sum(b.offsets.begin(), b.offsets.end(), b.offsets.begin());
  b.items.resize(3 * nf);
  std::vector<int64_t> cursor(b.offsets.begin(), b.offsets.end() - 1);
  for (int64_t f = 0; f < nf; ++f) {
    for (int k = 0; k < 3; ++k) {
      const int32_t a = F(f, (k + 1) % 3), c = F(f, (k + 2) % 3);
      b.items[cursor[std::min(a, c)]++] = f * 3 + k;
    }
  }
  return b;
}

// Keeps the error found at the smallest key, so parallel checks report deterministically.
class FirstError {
 public:
  void Record(int64_t key, std::string message) {
    absl::MutexLock lock(&mu_);
    if (key < key_) {
      key_ = key;
      message_ = std::move(message);
    }
  }
  absl::Status status() const {
    absl::MutexLock lock(&mu_);
    return message_.empty() ? absl::OkStatus() : absl::InvalidArgumentError(message_);
  }

 private:
  mutable absl::Mutex mu_;
  int64_t key_ = INT64_MAX;
  std::string message_;
};

}  // namespace

absl::StatusOr<TriangleMesh> TriangleMesh::Create(MeshArrays arrays) {
  const int64_t nv_in = arrays.vertices.rows();
  const int64_t nf = arrays.faces.rows();
  if (nf == 0) return absl::InvalidArgumentError("mesh has no faces");
  if (nf > (int64_t{1} << 30) || nv_in > (int64_t{1} << 30)) {
    return absl::ResourceExhaustedError(
        absl::StrFormat("mesh too large: %d vertices, %d faces", nv_in, nf));
  }

  // Index range, repeated indices, referenced vertices.
  std::vector<int32_t> new_index(nv_in, -1);
  for (int64_t f = 0; f < nf; ++f) {
    for (int k = 0; k < 3; ++k) {
      const int32_t v = arrays.faces(f, k);
      if (v < 0 || v >= nv_in) {
        return absl::InvalidArgumentError(
            absl::StrFormat("face %d: vertex index %d out of range [0, %d)", f, v, nv_in));
      }
      new_index[v] = 0;
    }
    const int32_t a = arrays.faces(f, 0), b = arrays.faces(f, 1), c = arrays.faces(f, 2);
    if (a == b || b == c || a == c) {
      return absl::InvalidArgumentError(
          absl::StrFormat("face %d: repeated vertex index (%d, %d, %d)", f, a, b, c));
    }
  }
  std::vector<int32_t> original_index;
  original_index.reserve(nv_in);
  for (int64_t v = 0; v < nv_in; ++v) {
    if (new_index[v] < 0) continue;
    const auto p = arrays.vertices.row(v);
    if (!p.allFinite()) {
      return absl::InvalidArgumentError(
          absl::StrFormat("vertex %d: non-finite coordinate (%g, %g, %g)", v, p(0), p(1), p(2)));
    }
    new_index[v] = static_cast<int32_t>(original_index.size());
    original_index.push_back(static_cast<int32_t>(v));
  }

  TriangleMesh mesh;
  const int32_t nv = static_cast<int32_t>(original_index.size());
  mesh.dropped_unreferenced_vertices_ = static_cast<int32_t>(nv_in - nv);
  if (nv == nv_in) {
    mesh.vertices_ = std::move(arrays.vertices);
  } else {
    mesh.vertices_.resize(nv, 3);
    for (int32_t v = 0; v < nv; ++v) mesh.vertices_.row(v) = arrays.vertices.row(original_index[v]);
    arrays.vertices = VertexMatrix();
  }
  mesh.faces_ = std::move(arrays.faces);
  FaceMatrix& F = mesh.faces_;
  if (nv != nv_in) {
    tbb::parallel_for(tbb::blocked_range<int64_t>(0, nf, kGrain), [&](const auto& r) {
      for (int64_t f = r.begin(); f < r.end(); ++f) {
        for (int k = 0; k < 3; ++k) F(f, k) = new_index[F(f, k)];
      }
    });
  }
  std::vector<int32_t>().swap(new_index);
  const VertexMatrix& V = mesh.vertices_;

  // Per-face geometry, with the degenerate-face check.
  mesh.face_areas_.resize(nf);
  mesh.face_normals_.resize(nf, 3);
  mesh.face_barycenters_.resize(nf, 3);
  mesh.frame_x_.resize(nf, 3);
  mesh.frame_y_.resize(nf, 3);
  std::vector<uint8_t> degenerate(nf, 0);
  tbb::combinable<double> radius2([] { return 0.0; });
  tbb::parallel_for(tbb::blocked_range<int64_t>(0, nf, kGrain), [&](const auto& r) {
    double& local_radius2 = radius2.local();
    for (int64_t f = r.begin(); f < r.end(); ++f) {
      const Eigen::Vector3d p0 = V.row(F(f, 0)), p1 = V.row(F(f, 1)), p2 = V.row(F(f, 2));
      const Eigen::Vector3d e1 = p1 - p0, e2 = p2 - p0;
      const Eigen::Vector3d cross = e1.cross(e2);
      const double twice_area = cross.norm();
      const double longest =
          std::max({e1.squaredNorm(), e2.squaredNorm(), (p2 - p1).squaredNorm()});
      if (!(twice_area > kDegenerateRatio * longest) || !(longest > 0)) {
        degenerate[f] = 1;
        continue;
      }
      const Eigen::Vector3d n = cross / twice_area;
      const Eigen::Vector3d x = e1.normalized();
      mesh.face_areas_(f) = 0.5 * twice_area;
      mesh.face_normals_.row(f) = n;
      const Eigen::Vector3d b = (p0 + p1 + p2) / 3.0;
      mesh.face_barycenters_.row(f) = b;
      local_radius2 = std::max(
          {local_radius2, (p0 - b).squaredNorm(), (p1 - b).squaredNorm(), (p2 - b).squaredNorm()});
      mesh.frame_x_.row(f) = x;
      mesh.frame_y_.row(f) = n.cross(x);
    }
  });
  for (int64_t f = 0; f < nf; ++f) {
    if (degenerate[f]) {
      return absl::InvalidArgumentError(
          absl::StrFormat("face %d: zero area (vertices %d, %d, %d)", f, original_index[F(f, 0)],
                          original_index[F(f, 1)], original_index[F(f, 2)]));
    }
  }
  std::vector<uint8_t>().swap(degenerate);
  mesh.max_face_radius_ =
      std::sqrt(radius2.combine([](double a, double b) { return std::max(a, b); }));

  // Edges, edge-face incidence, face adjacency; non-manifold edges and orientation. Buckets are
  // independent, so both passes run in parallel; edge ids follow (lower, upper) vertex order.
  {
    HalfEdgeBuckets buckets = BucketHalfEdges(F, nv);
    // Pack each half-edge as (upper vertex << 32 | face * 3 + corner) so sorting a bucket needs
    // no lookups into F.
    std::vector<int32_t> edges_in_bucket(nv + 1, 0);
    FirstError first_error;
    tbb::parallel_for(tbb::blocked_range<int32_t>(0, nv, kGrain), [&](const auto& r) {
      for (int32_t lo = r.begin(); lo < r.end(); ++lo) {
        const int64_t begin = buckets.offsets[lo], end = buckets.offsets[lo + 1];
        for (int64_t i = begin; i < end; ++i) {
          const int64_t he = buckets.items[i];
          const int64_t f = he / 3;
          const int k = static_cast<int>(he % 3);
          const uint64_t upper = std::max(F(f, (k + 1) % 3), F(f, (k + 2) % 3));
          buckets.items[i] = static_cast<int64_t>((upper << 32) | static_cast<uint64_t>(he));
        }
        std::sort(buckets.items.begin() + begin, buckets.items.begin() + end);
        int32_t count = 0;
        for (int64_t i = begin; i < end;) {
          int64_t j = i + 1;
          while (j < end && (buckets.items[j] >> 32) == (buckets.items[i] >> 32)) ++j;
          if (j - i > 2) {
            std::string faces;
            for (int64_t t = i; t < j && t < i + 6; ++t) {
              absl::StrAppend(&faces, t > i ? ", " : "", (buckets.items[t] & 0xffffffff) / 3);
            }
            first_error.Record(
                lo, absl::StrFormat("edge (%d, %d): non-manifold, shared by %d faces (%s)",
                                    original_index[lo], original_index[buckets.items[i] >> 32],
                                    j - i, faces));
          }
          ++count;
          i = j;
        }
        edges_in_bucket[lo + 1] = count;
      }
    });
    RETURN_IF_ERROR(first_error.status());
    std::partial_sum(edges_in_bucket.begin(), edges_in_bucket.end(), edges_in_bucket.begin());
    const int32_t ne = edges_in_bucket[nv];
    mesh.edges_.resize(ne, 2);
    mesh.edge_faces_.resize(ne, 2);
    mesh.face_edges_.resize(nf, 3);
    mesh.face_neighbors_.resize(nf, 3);
    tbb::parallel_for(tbb::blocked_range<int32_t>(0, nv, kGrain), [&](const auto& r) {
      for (int32_t lo = r.begin(); lo < r.end(); ++lo) {
        const int64_t begin = buckets.offsets[lo], end = buckets.offsets[lo + 1];
        int32_t e = edges_in_bucket[lo];
        for (int64_t i = begin; i < end; ++e) {
          const int32_t hi = static_cast<int32_t>(buckets.items[i] >> 32);
          const int64_t h0 = buckets.items[i] & 0xffffffff;
          const int32_t f0 = static_cast<int32_t>(h0 / 3);
          const int k0 = static_cast<int>(h0 % 3);
          mesh.edges_(e, 0) = lo;
          mesh.edges_(e, 1) = hi;
          mesh.face_edges_(f0, k0) = e;
          mesh.face_neighbors_(f0, k0) = kNoFace;
          mesh.edge_faces_(e, 0) = f0;
          mesh.edge_faces_(e, 1) = kNoFace;
          if (i + 1 < end && (buckets.items[i + 1] >> 32) == hi) {
            const int64_t h1 = buckets.items[i + 1] & 0xffffffff;
            const int32_t f1 = static_cast<int32_t>(h1 / 3);
            const int k1 = static_cast<int>(h1 % 3);
            // Consistent orientation: the two faces run the shared edge in opposite directions.
            if (F(f0, (k0 + 1) % 3) == F(f1, (k1 + 1) % 3)) {
              first_error.Record(
                  lo, absl::StrFormat("edge (%d, %d): inconsistent orientation between faces "
                                      "%d and %d",
                                      original_index[lo], original_index[hi], f0, f1));
            }
            mesh.face_edges_(f1, k1) = e;
            mesh.face_neighbors_(f0, k0) = f1;
            mesh.face_neighbors_(f1, k1) = f0;
            mesh.edge_faces_(e, 0) = std::min(f0, f1);
            mesh.edge_faces_(e, 1) = std::max(f0, f1);
            i += 2;
          } else {
            i += 1;
          }
        }
      }
    });
    RETURN_IF_ERROR(first_error.status());
  }

  // Non-manifold vertices: the faces around a vertex must form one fan. Walk the fan from one
  // incident face in both directions and compare with the vertex's face count.
  {
    std::vector<int32_t> incident(nv, 0);
    std::vector<int32_t> some_face(nv, -1);
    for (int32_t f = 0; f < nf; ++f) {
      for (int k = 0; k < 3; ++k) {
        ++incident[F(f, k)];
        some_face[F(f, k)] = f;
      }
    }
    const FaceMatrix& FE = mesh.face_edges_;
    const FaceMatrix& FN = mesh.face_neighbors_;
    auto corner_of = [&](int32_t f, int32_t v) {
      return F(f, 0) == v ? 0 : (F(f, 1) == v ? 1 : 2);
    };
    // Walks from `start` across the vertex-incident edge `first_edge_slot`; returns faces visited
    // (excluding start) and whether it came back to start.
    auto walk = [&](int32_t v, int32_t start, int first_slot, bool* closed) {
      int32_t count = 0;
      int32_t f = start;
      int slot = first_slot;
      *closed = false;
      while (true) {
        const int32_t edge = FE(f, slot);
        const int32_t g = FN(f, slot);
        if (g == kNoFace) return count;
        if (g == start) {
          *closed = true;
          return count;
        }
        if (++count > incident[v]) return count;  // cannot happen on valid input; bounds the loop
        const int j = corner_of(g, v);
        const int s1 = (j + 1) % 3, s2 = (j + 2) % 3;
        slot = FE(g, s1) == edge ? s2 : s1;
        f = g;
      }
    };
    FirstError first_error;
    tbb::parallel_for(tbb::blocked_range<int32_t>(0, nv, kGrain), [&](const auto& r) {
      for (int32_t v = r.begin(); v < r.end(); ++v) {
        const int32_t start = some_face[v];
        const int k = corner_of(start, v);
        bool closed = false;
        int32_t visited = 1 + walk(v, start, (k + 1) % 3, &closed);
        if (!closed) {
          bool closed2 = false;
          visited += walk(v, start, (k + 2) % 3, &closed2);
        }
        if (visited != incident[v]) {
          first_error.Record(
              v, absl::StrFormat(
                     "vertex %d: non-manifold (its %d faces do not form a single fan; one fan "
                     "has %d)",
                     original_index[v], incident[v], visited));
        }
      }
    });
    RETURN_IF_ERROR(first_error.status());
  }

  // Connected components (breadth-first over face adjacency).
  {
    mesh.face_component_.setConstant(nf, -1);
    std::vector<int32_t> queue(nf);
    int32_t num_components = 0;
    for (int32_t seed = 0; seed < nf; ++seed) {
      if (mesh.face_component_(seed) >= 0) continue;
      int64_t head = 0, tail = 0;
      queue[tail++] = seed;
      mesh.face_component_(seed) = num_components;
      while (head < tail) {
        const int32_t f = queue[head++];
        for (int k = 0; k < 3; ++k) {
          const int32_t g = mesh.face_neighbors_(f, k);
          if (g != kNoFace && mesh.face_component_(g) < 0) {
            mesh.face_component_(g) = num_components;
            queue[tail++] = g;
          }
        }
      }
      ++num_components;
    }
    mesh.components_.assign(num_components, MeshComponent{});
    std::vector<int32_t> vertex_component(nv, -1);
    for (int32_t f = 0; f < nf; ++f) {
      MeshComponent& c = mesh.components_[mesh.face_component_(f)];
      ++c.num_faces;
      c.area += mesh.face_areas_(f);
      for (int k = 0; k < 3; ++k) vertex_component[F(f, k)] = mesh.face_component_(f);
    }
    for (int32_t v = 0; v < nv; ++v) ++mesh.components_[vertex_component[v]].num_vertices;
    for (int32_t e = 0; e < mesh.num_edges(); ++e) {
      ++mesh.components_[mesh.face_component_(mesh.edge_faces_(e, 0))].num_edges;
    }

    // Boundary loops: each boundary vertex of a manifold mesh has exactly one outgoing boundary
    // half-edge (in its face's orientation); follow them.
    std::vector<int32_t> next(nv, -1);
    for (int32_t e = 0; e < mesh.num_edges(); ++e) {
      if (mesh.edge_faces_(e, 1) != kNoFace) continue;
      const int32_t f = mesh.edge_faces_(e, 0);
      for (int k = 0; k < 3; ++k) {
        if (mesh.face_edges_(f, k) == e) next[F(f, (k + 1) % 3)] = F(f, (k + 2) % 3);
      }
    }
    std::vector<uint8_t> seen(nv, 0);
    for (int32_t v = 0; v < nv; ++v) {
      if (next[v] < 0 || seen[v]) continue;
      std::vector<int32_t> loop;
      for (int32_t u = v; !seen[u]; u = next[u]) {
        seen[u] = 1;
        loop.push_back(u);
      }
      ++mesh.components_[vertex_component[v]].num_boundary_loops;
      mesh.boundary_loops_.push_back(std::move(loop));
    }
    for (MeshComponent& c : mesh.components_) {
      c.euler_characteristic = c.num_vertices - c.num_edges + c.num_faces;
      c.genus = (2 - c.num_boundary_loops - c.euler_characteristic) / 2;
    }
  }
  mesh.total_area_ = mesh.face_areas_.sum();
  return mesh;
}

int32_t TriangleMesh::euler_characteristic() const {
  return num_vertices() - num_edges() + num_faces();
}

int32_t TriangleMesh::genus() const {
  int32_t g = 0;
  for (const MeshComponent& c : components_) g += c.genus;
  return g;
}

int64_t TriangleMesh::MemoryBytes() const {
  int64_t bytes = 0;
  for (const VertexMatrix* m :
       {&vertices_, &face_normals_, &face_barycenters_, &frame_x_, &frame_y_}) {
    bytes += m->size() * static_cast<int64_t>(sizeof(double));
  }
  for (const FaceMatrix* m : {&faces_, &face_edges_, &face_neighbors_}) {
    bytes += m->size() * static_cast<int64_t>(sizeof(int32_t));
  }
  for (const PairMatrix* m : {&edges_, &edge_faces_}) {
    bytes += m->size() * static_cast<int64_t>(sizeof(int32_t));
  }
  bytes += face_areas_.size() * static_cast<int64_t>(sizeof(double)) +
           face_component_.size() * static_cast<int64_t>(sizeof(int));
  for (const std::vector<int32_t>& loop : boundary_loops_) {
    bytes += static_cast<int64_t>(loop.size() * sizeof(int32_t));
  }
  return bytes;
}

}  // namespace fieldspace
