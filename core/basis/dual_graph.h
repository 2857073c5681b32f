#ifndef FIELDSPACE_CORE_BASIS_DUAL_GRAPH_H_
#define FIELDSPACE_CORE_BASIS_DUAL_GRAPH_H_

#include <algorithm>
#include <cstdint>
#include <limits>
#include <utility>
#include <vector>

#include "Eigen/Core"
#include "absl/status/statusor.h"
#include "core/common/cancel.h"
#include "core/mesh/triangle_mesh.h"

namespace fieldspace {

// One arc of the dual graph; target -1 marks a missing neighbor (boundary edge).
struct DualArc {
  double length = 0.0;
  int32_t target = -1;
  int32_t unused = 0;
};

// The dual graph of a triangle mesh (paper section 4; docs/conventions.md, Basis construction): one
// node per face, an arc in both directions between two faces sharing an edge, of length
// |barycenter_f - barycenter_g| * (w_f + w_g) / 2 with the per-face adaptivity weights w.
//
// Nodes are the faces renumbered along a Morton (Z-order) curve of their barycenters, and each
// node's (at most 3) arcs are stored together: Dijkstra then touches one cache line per node and
// neighbors are mostly nearby in memory. Input meshes often list faces in an order with little
// spatial locality (e.g. subdivided meshes), which made the searches memory-bound before.
// Distances do not depend on the numbering.
struct DualGraph {
  int32_t num_nodes = 0;
  std::vector<DualArc> arcs;       // 3 per node: arcs[3 v + k]
  std::vector<int32_t> node_face;  // node -> face
  std::vector<int32_t> face_node;  // face -> node
};

// Builds the dual graph in O(#F log #F) from mesh.face_neighbors(). `face_weights` is empty
// (uniform, all weights 1) or has one finite positive weight per face; InvalidArgument otherwise.
absl::StatusOr<DualGraph> BuildDualGraph(const TriangleMesh& mesh,
                                         const Eigen::VectorXd& face_weights);

// Reusable Dijkstra state for one thread: a distance per node (+infinity when untouched) and the
// list of touched nodes, so that resetting costs O(touched), never O(#nodes).
class DijkstraScratch {
 public:
  static constexpr double kInfinity = std::numeric_limits<double>::infinity();

  explicit DijkstraScratch(int32_t num_nodes) : dist_(num_nodes, kInfinity) {}

  // The nodes within graph distance `radius` of node `source` (inclusive), in order of
  // increasing distance, each with its distance. If fewer than `min_nodes` nodes are that close,
  // the growth continues past the radius until `min_nodes` nodes (or the whole component) are
  // reached. `cancel` is checked every few thousand steps; once it is set the growth stops
  // early and the function returns false.
  bool Grow(const DualGraph& graph, int32_t source, double radius, int32_t min_nodes,
            std::vector<std::pair<int32_t, double>>* visited, const CancelToken& cancel);

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

inline bool DijkstraScratch::Grow(const DualGraph& graph, int32_t source, double radius,
                                  int32_t min_nodes,
                                  std::vector<std::pair<int32_t, double>>* visited,
                                  const CancelToken& cancel) {
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
    const DualArc* arcs = &graph.arcs[3 * static_cast<size_t>(u)];
    for (int k = 0; k < 3; ++k) {
      const int32_t v = arcs[k].target;
      if (v < 0) continue;
      const double nd = d + arcs[k].length;
      if (nd < dist_[v]) {
        if (dist_[v] == kInfinity) touched_.push_back(v);
        dist_[v] = nd;
        heap_.emplace_back(nd, v);
        std::push_heap(heap_.begin(), heap_.end(), greater);
      }
    }
    if ((++steps & 4095) == 0 && cancel.Check()) {
      completed = false;
      break;
    }
  }
  Reset();
  return completed;
}

}  // namespace fieldspace

#endif  // FIELDSPACE_CORE_BASIS_DUAL_GRAPH_H_
