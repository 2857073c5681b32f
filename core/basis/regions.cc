#include "core/basis/regions.h"

#include <algorithm>
#include <atomic>
#include <utility>

#include "tbb/blocked_range.h"
#include "tbb/enumerable_thread_specific.h"
#include "tbb/parallel_for.h"

namespace fieldspace {
namespace {

// Sorts `v` (values in [0, 2^bits)) ascending: least significant digit first, in as few passes
// of at most 11 bits as cover `bits` (the region phase of the 1.38M-face build: 1.0-1.1 s against
// 1.6 s with std::sort; bench/RESULTS.md, Session 32).
void RadixSort(int bits, std::vector<int32_t>& v, std::vector<int32_t>& buffer,
               std::vector<int32_t>& count) {
  const int passes = std::max(1, (bits + 10) / 11);
  const int digit = (bits + passes - 1) / passes;
  const int32_t mask = (int32_t{1} << digit) - 1;
  buffer.resize(v.size());
  int32_t* from = v.data();
  int32_t* to = buffer.data();
  const size_t n = v.size();
  for (int pass = 0; pass < passes; ++pass) {
    const int shift = pass * digit;
    count.assign(static_cast<size_t>(mask) + 2, 0);
    for (size_t i = 0; i < n; ++i) ++count[((from[i] >> shift) & mask) + 1];
    for (int32_t b = 0; b <= mask; ++b) count[b + 1] += count[b];
    for (size_t i = 0; i < n; ++i) to[count[(from[i] >> shift) & mask]++] = from[i];
    std::swap(from, to);
  }
  if (from != v.data()) std::copy(from, from + n, v.data());
}

}  // namespace

absl::StatusOr<std::vector<std::vector<int32_t>>> GrowRegions(const DualGraph& graph,
                                                              const std::vector<int32_t>& samples,
                                                              const RegionOptions& options,
                                                              const CancelToken& cancel) {
  const int32_t nr = static_cast<int32_t>(samples.size());
  std::vector<std::vector<int32_t>> regions(nr);
  struct Scratch {
    explicit Scratch(int32_t n) : dijkstra(n) {}
    DijkstraScratch dijkstra;
    std::vector<std::pair<int32_t, double>> visited;
    std::vector<int32_t> sort_buffer, sort_count;
  };
  int bits = 1;
  while (bits < 31 && (int64_t{1} << bits) < graph.num_nodes) ++bits;
  tbb::enumerable_thread_specific<Scratch> scratch(graph.num_nodes);
  std::atomic<bool> cancelled{false};
  // Regions in the order of their samples along the graph's Morton numbering: consecutive
  // regions overlap, so each thread finds most of the graph's arcs still in cache.
  std::vector<int32_t> order(nr);
  for (int32_t i = 0; i < nr; ++i) order[i] = i;
  std::sort(order.begin(), order.end(), [&](int32_t a, int32_t b) {
    return graph.face_node[samples[a]] < graph.face_node[samples[b]];
  });
  tbb::parallel_for(
      tbb::blocked_range<int32_t>(0, nr, 1), [&](const tbb::blocked_range<int32_t>& r) {
        Scratch& s = scratch.local();
        for (int32_t oi = r.begin(); oi != r.end(); ++oi) {
          const int32_t i = order[oi];
          if (cancelled.load(std::memory_order_relaxed)) return;
          const bool done = s.dijkstra.Grow(graph, graph.face_node[samples[i]], options.radius,
                                            options.min_faces, &s.visited, cancel);
          if (!done || cancel.Check()) {
            cancelled.store(true, std::memory_order_relaxed);
            return;
          }
          std::vector<int32_t>& faces = regions[i];
          faces.resize(s.visited.size());
          for (size_t k = 0; k < s.visited.size(); ++k) {
            faces[k] = graph.node_face[s.visited[k].first];
          }
          RadixSort(bits, faces, s.sort_buffer, s.sort_count);
        }
      });
  if (cancelled.load()) return absl::CancelledError("basis construction cancelled");
  return regions;
}

}  // namespace fieldspace
