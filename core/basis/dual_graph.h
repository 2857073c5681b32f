#ifndef FIELDSPACE_CORE_BASIS_DUAL_GRAPH_H_
#define FIELDSPACE_CORE_BASIS_DUAL_GRAPH_H_

#include <algorithm>
#include <cstdint>
#include <limits>
#include <utility>
#include <vector>

#include "Eigen/Core"
#include "absl/status/statusor.h"
#include "core/mesh/triangle_mesh.h"

namespace fieldspace {

// The dual graph of a triangle mesh (paper section 4, DESIGN.md section 3): one node per face,
// an arc in both directions between two faces sharing an edge, of length
// |barycenter_f - barycenter_g| * (w_f + w_g) / 2 with the per-face adaptivity weights w.
// Compressed sparse rows: the arcs leaving node f are [offsets[f], offsets[f + 1]).
struct DualGraph {
  int32_t num_nodes = 0;
  std::vector<int32_t> offsets;  // num_nodes + 1
  std::vector<int32_t> targets;  // 2 * #interior edges
  std::vector<double> lengths;   // same size as targets, finite and >= 0
};

// Builds the dual graph in O(#F) from mesh.face_neighbors(). `face_weights` is empty (uniform,
// all weights 1) or has one finite positive weight per face; InvalidArgument otherwise.
absl::StatusOr<DualGraph> BuildDualGraph(const TriangleMesh& mesh,
                                         const Eigen::VectorXd& face_weights);

// Reusable Dijkstra state for one thread: a distance per node (+infinity when untouched) and the
// list of touched nodes, so that resetting costs O(touched), never O(#nodes).
class DijkstraScratch {
 public:
  static constexpr double kInfinity = std::numeric_limits<double>::infinity();

  explicit DijkstraScratch(int32_t num_nodes) : dist_(num_nodes, kInfinity) {}

  // The faces within graph distance `radius` of `source` (inclusive), in order of increasing
  // distance, each with its distance. If fewer than `min_nodes` faces are that close, the growth
  // continues past the radius until `min_nodes` faces (or the whole component) are reached.
  // `poll` is called every few thousand steps; when it returns true the growth stops early and
  // the function returns false.
  template <typename Poll>
  bool Grow(const DualGraph& graph, int32_t source, double radius, int32_t min_nodes,
            std::vector<std::pair<int32_t, double>>* visited, Poll&& poll);

  // Restores all distances to +infinity.
  void Reset() {
    for (int32_t v : touched_) dist_[v] = kInfinity;
    touched_.clear();
  }

 private:
  std::vector<double> dist_;
  std::vector<int32_t> touched_;
  std::vector<std::pair<double, int32_t>> heap_;  // min-heap via std::greater
};

template <typename Poll>
bool DijkstraScratch::Grow(const DualGraph& graph, int32_t source, double radius,
                           int32_t min_nodes, std::vector<std::pair<int32_t, double>>* visited,
                           Poll&& poll) {
  visited->clear();
  heap_.clear();
  dist_[source] = 0.0;
  touched_.push_back(source);
  heap_.emplace_back(0.0, source);
  const auto greater = [](const std::pair<double, int32_t>& a,
                          const std::pair<double, int32_t>& b) { return a > b; };
  int64_t steps = 0;
  bool completed = true;
  while (!heap_.empty()) {
    std::pop_heap(heap_.begin(), heap_.end(), greater);
    const auto [d, u] = heap_.back();
    heap_.pop_back();
    if (d > dist_[u]) continue;  // stale entry
    if (d > radius && static_cast<int32_t>(visited->size()) >= min_nodes) break;
    visited->emplace_back(u, d);
    for (int32_t a = graph.offsets[u]; a < graph.offsets[u + 1]; ++a) {
      const int32_t v = graph.targets[a];
      const double nd = d + graph.lengths[a];
      if (nd < dist_[v]) {
        if (dist_[v] == kInfinity) touched_.push_back(v);
        dist_[v] = nd;
        heap_.emplace_back(nd, v);
        std::push_heap(heap_.begin(), heap_.end(), greater);
      }
    }
    if ((++steps & 4095) == 0 && poll()) {
      completed = false;
      break;
    }
  }
  Reset();
  return completed;
}

}  // namespace fieldspace

#endif  // FIELDSPACE_CORE_BASIS_DUAL_GRAPH_H_
