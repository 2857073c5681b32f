#include "core/basis/sampling.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <utility>

#include "absl/strings/str_format.h"
#include "core/common/random.h"

namespace fieldspace {

absl::StatusOr<std::vector<int32_t>> AllocateSamplesPerComponent(const TriangleMesh& mesh,
                                                                 int32_t num_regions) {
  const std::vector<MeshComponent>& comps = mesh.components();
  const int32_t nc = static_cast<int32_t>(comps.size());
  if (num_regions < nc) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "%d regions cannot give each of the mesh's %d connected components a sample; increase "
        "the dimension",
        num_regions, nc));
  }
  if (num_regions > mesh.num_faces()) {
    return absl::InvalidArgumentError(
        absl::StrFormat("%d regions exceed the mesh's %d faces (one sample face per region)",
                        num_regions, mesh.num_faces()));
  }
  double total = 0.0;
  for (const MeshComponent& c : comps) total += c.area;
  std::vector<double> quota(nc);
  std::vector<int32_t> count(nc);
  int64_t sum = 0;
  for (int32_t c = 0; c < nc; ++c) {
    quota[c] = total > 0 ? num_regions * comps[c].area / total : 1.0;
    count[c] = static_cast<int32_t>(
        std::clamp<double>(std::floor(quota[c]), 1.0, static_cast<double>(comps[c].num_faces)));
    sum += count[c];
  }
  std::vector<int32_t> order(nc);
  std::iota(order.begin(), order.end(), 0);
  if (sum < num_regions) {
    // Largest remainders first (ties: lower component index), cycling while there is room.
    std::stable_sort(order.begin(), order.end(), [&](int32_t a, int32_t b) {
      return quota[a] - count[a] > quota[b] - count[b];
    });
    while (sum < num_regions) {
      bool progressed = false;
      for (int32_t c : order) {
        if (sum == num_regions) break;
        if (count[c] < comps[c].num_faces) {
          ++count[c];
          ++sum;
          progressed = true;
        }
      }
      if (!progressed) break;  // impossible: num_regions <= #faces
    }
  } else if (sum > num_regions) {
    // Only the minimum of one sample per component can overshoot: take back from the components
    // with the most samples beyond their quota.
    std::stable_sort(order.begin(), order.end(), [&](int32_t a, int32_t b) {
      return count[a] - quota[a] > count[b] - quota[b];
    });
    while (sum > num_regions) {
      bool progressed = false;
      for (int32_t c : order) {
        if (sum == num_regions) break;
        if (count[c] > 1) {
          --count[c];
          --sum;
          progressed = true;
        }
      }
      if (!progressed) break;  // impossible: num_regions >= #components
    }
  }
  if (sum != num_regions) {
    return absl::InternalError("sample allocation over components did not add up");
  }
  return count;
}

absl::StatusOr<SamplingResult> FarthestPointSampling(const TriangleMesh& mesh,
                                                     const DualGraph& graph,
                                                     const std::vector<int32_t>& per_component,
                                                     uint64_t seed, const CancelToken& cancel) {
  const int32_t nf = mesh.num_faces();
  const int32_t nc = mesh.num_components();
  if (static_cast<int32_t>(per_component.size()) != nc) {
    return absl::InvalidArgumentError("per_component must have one count per component");
  }
  if (graph.num_nodes != nf) return absl::InvalidArgumentError("dual graph of another mesh");
  // Faces grouped by component (counting sort keeps each group ascending).
  std::vector<int32_t> comp_offset(static_cast<size_t>(nc) + 1, 0);
  const Eigen::VectorXi& fc = mesh.face_component();
  for (int32_t f = 0; f < nf; ++f) ++comp_offset[fc[f] + 1];
  std::partial_sum(comp_offset.begin(), comp_offset.end(), comp_offset.begin());
  std::vector<int32_t> comp_faces(nf);
  {
    std::vector<int32_t> cursor(comp_offset.begin(), comp_offset.end() - 1);
    for (int32_t f = 0; f < nf; ++f) comp_faces[cursor[fc[f]]++] = f;
  }

  constexpr double kInf = std::numeric_limits<double>::infinity();
  std::vector<double> dist(nf, kInf);            // per node
  std::vector<std::pair<double, int32_t>> heap;  // Dijkstra min-heap
  const auto greater = [](const std::pair<double, int32_t>& a,
                          const std::pair<double, int32_t>& b) { return a > b; };
  int64_t steps = 0;
  bool cancelled = false;

  // The farthest node is found with a bucket queue over distances: distances only decrease, so
  // each node is re-filed (lazily: old entries are dropped when their bucket is scanned) only
  // when it moves to a lower bucket, and the maximum is in the highest non-empty bucket. A
  // global max-heap was several times slower here (every decrease costs a heap operation on a
  // heap of #F entries with poor locality).
  int32_t num_buckets = 1;
  double bucket_scale = 0.0;
  std::vector<std::vector<int32_t>> buckets;
  std::vector<int32_t> node_bucket;
  bool bucketing = false;
  auto bucket_of = [&](double d) {
    return std::min(num_buckets - 1, static_cast<int32_t>(d * bucket_scale));
  };

  // Lowers dist[] by a Dijkstra from `source`, touching only nodes that get closer.
  auto relax_from = [&](int32_t source) {
    heap.clear();
    dist[source] = 0.0;
    if (bucketing && node_bucket[source] != 0) {
      node_bucket[source] = 0;
      buckets[0].push_back(source);
    }
    heap.emplace_back(0.0, source);
    while (!heap.empty()) {
      std::pop_heap(heap.begin(), heap.end(), greater);
      const auto [d, u] = heap.back();
      heap.pop_back();
      if (d > dist[u]) continue;
      const DualArc* arcs = &graph.arcs[3 * static_cast<size_t>(u)];
      for (int k = 0; k < 3; ++k) {
        const int32_t v = arcs[k].target;
        if (v < 0) continue;
        const double nd = d + arcs[k].length;
        if (nd < dist[v]) {
          dist[v] = nd;
          heap.emplace_back(nd, v);
          std::push_heap(heap.begin(), heap.end(), greater);
          if (bucketing) {
            const int32_t b = bucket_of(nd);
            if (b != node_bucket[v]) {
              node_bucket[v] = b;
              buckets[b].push_back(v);
            }
          }
        }
      }
      if ((++steps & 4095) == 0 && cancel.Check()) {
        cancelled = true;
        return;
      }
    }
  };

  SamplingResult result;
  int64_t total = 0;
  for (int32_t n : per_component) total += n;
  result.samples.reserve(total);
  for (int32_t c = 0; c < nc; ++c) {
    const int32_t begin = comp_offset[c];
    const int32_t size = comp_offset[c + 1] - begin;
    const int32_t want = per_component[c];
    if (want < 1 || want > size) {
      return absl::InvalidArgumentError(
          absl::StrFormat("component %d: %d samples for %d faces", c, want, size));
    }
    const int32_t first =
        comp_faces[begin +
                   static_cast<int32_t>(SplitMix64::Hash(seed ^ SplitMix64::Hash(c)) % size)];
    result.samples.push_back(first);
    bucketing = false;
    relax_from(graph.face_node[first]);
    if (cancelled) return absl::CancelledError("basis construction cancelled");
    if (want > 1) {
      double far = 0.0;
      for (int32_t i = 0; i < size; ++i) {
        far = std::max(far, dist[graph.face_node[comp_faces[begin + i]]]);
      }
      num_buckets = std::clamp(size, 1, 1 << 16);
      bucket_scale = far > 0 ? num_buckets / far : 0.0;
      buckets.assign(num_buckets, {});
      if (node_bucket.empty()) node_bucket.assign(nf, -1);
      for (int32_t i = 0; i < size; ++i) {
        const int32_t v = graph.face_node[comp_faces[begin + i]];
        node_bucket[v] = bucket_of(dist[v]);
        buckets[node_bucket[v]].push_back(v);
      }
      bucketing = true;
      int32_t top = num_buckets - 1;
      for (int32_t s = 1; s < want; ++s) {
        int32_t best = -1;
        while (best < 0) {
          while (top > 0 && buckets[top].empty()) --top;
          std::vector<int32_t>& bucket = buckets[top];
          size_t kept = 0;
          for (int32_t v : bucket) {
            if (node_bucket[v] != top) continue;  // moved to a lower bucket
            bucket[kept++] = v;
            // The maximum distance; ties go to the larger face index (independent of the
            // graph's node numbering).
            if (best < 0 || dist[v] > dist[best] ||
                (dist[v] == dist[best] && graph.node_face[v] > graph.node_face[best])) {
              best = v;
            }
          }
          bucket.resize(kept);
          if (best < 0 && top == 0) return absl::InternalError("farthest point sampling ran dry");
        }
        result.samples.push_back(graph.node_face[best]);
        relax_from(best);
        if (cancelled) return absl::CancelledError("basis construction cancelled");
      }
      bucketing = false;
    }
    for (int32_t i = 0; i < size; ++i) {
      result.coverage_radius =
          std::max(result.coverage_radius, dist[graph.face_node[comp_faces[begin + i]]]);
    }
  }
  return result;
}

}  // namespace fieldspace
