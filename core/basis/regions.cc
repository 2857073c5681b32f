#include "core/basis/regions.h"

#include <algorithm>
#include <atomic>
#include <utility>

#include "tbb/blocked_range.h"
#include "tbb/enumerable_thread_specific.h"
#include "tbb/parallel_for.h"

namespace fieldspace {

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
  };
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
          std::sort(faces.begin(), faces.end());
        }
      });
  if (cancelled.load()) return absl::CancelledError("basis construction cancelled");
  return regions;
}

}  // namespace fieldspace
