#include "core/basis/sampling.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <utility>

#include "absl/strings/str_format.h"

namespace fieldspace {
namespace {

// SplitMix64: a tiny, well-mixed deterministic generator (the sample choice must not depend on
// the platform's std::hash or distribution implementations).
uint64_t SplitMix64(uint64_t x) {
  x += 0x9e3779b97f4a7c15ull;
  x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ull;
  x = (x ^ (x >> 27)) * 0x94d049bb133111ebull;
  return x ^ (x >> 31);
}

}  // namespace

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
                                                     uint64_t seed,
                                                     const std::function<bool()>& poll) {
  const int32_t nf = mesh.num_faces();
  const int32_t nc = mesh.num_components();
  if (static_cast<int32_t>(per_component.size()) != nc) {
    return absl::InvalidArgumentError("per_component must have one count per component");
  }
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
  std::vector<double> dist(nf, kInf);
  std::vector<std::pair<double, int32_t>> heap;  // Dijkstra min-heap
  const auto greater = [](const std::pair<double, int32_t>& a,
                          const std::pair<double, int32_t>& b) { return a > b; };
  int64_t steps = 0;
  bool cancelled = false;
  // Lowers dist[] by a Dijkstra from `source`, touching only faces that get closer.
  auto relax_from = [&](int32_t source) {
    heap.clear();
    dist[source] = 0.0;
    heap.emplace_back(0.0, source);
    while (!heap.empty()) {
      std::pop_heap(heap.begin(), heap.end(), greater);
      const auto [d, u] = heap.back();
      heap.pop_back();
      if (d > dist[u]) continue;
      for (int32_t a = graph.offsets[u]; a < graph.offsets[u + 1]; ++a) {
        const int32_t v = graph.targets[a];
        const double nd = d + graph.lengths[a];
        if (nd < dist[v]) {
          dist[v] = nd;
          heap.emplace_back(nd, v);
          std::push_heap(heap.begin(), heap.end(), greater);
        }
      }
      if ((++steps & 4095) == 0 && poll && poll()) {
        cancelled = true;
        return;
      }
    }
  };

  SamplingResult result;
  int64_t total = 0;
  for (int32_t n : per_component) total += n;
  result.samples.reserve(total);
  std::vector<std::pair<double, int32_t>> far;  // lazy max-heap of (distance, face)
  for (int32_t c = 0; c < nc; ++c) {
    const int32_t begin = comp_offset[c];
    const int32_t size = comp_offset[c + 1] - begin;
    const int32_t want = per_component[c];
    if (want < 1 || want > size) {
      return absl::InvalidArgumentError(
          absl::StrFormat("component %d: %d samples for %d faces", c, want, size));
    }
    const int32_t first =
        comp_faces[begin + static_cast<int32_t>(SplitMix64(seed ^ SplitMix64(c)) % size)];
    result.samples.push_back(first);
    relax_from(first);
    if (cancelled) return absl::CancelledError("basis construction cancelled");
    // Every face keeps exactly one heap entry whose key is >= its current distance (distances
    // only decrease). A popped entry whose key is stale is re-pushed with the current distance;
    // a fresh one is the true maximum.
    far.clear();
    far.reserve(size);
    for (int32_t i = 0; i < size; ++i) {
      const int32_t f = comp_faces[begin + i];
      far.emplace_back(dist[f], f);
    }
    std::make_heap(far.begin(), far.end());
    for (int32_t s = 1; s < want; ++s) {
      while (true) {
        std::pop_heap(far.begin(), far.end());
        auto [d, f] = far.back();
        if (d == dist[f]) {
          far.back().first = 0.0;  // f becomes a sample: distance 0
          std::push_heap(far.begin(), far.end());
          result.samples.push_back(f);
          relax_from(f);
          break;
        }
        far.back().first = dist[f];
        std::push_heap(far.begin(), far.end());
      }
      if (cancelled) return absl::CancelledError("basis construction cancelled");
    }
    for (int32_t i = 0; i < size; ++i) {
      result.coverage_radius = std::max(result.coverage_radius, dist[comp_faces[begin + i]]);
    }
  }
  return result;
}

}  // namespace fieldspace
