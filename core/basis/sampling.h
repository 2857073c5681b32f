#ifndef FIELDSPACE_CORE_BASIS_SAMPLING_H_
#define FIELDSPACE_CORE_BASIS_SAMPLING_H_

#include <cstdint>
#include <vector>

#include "absl/status/statusor.h"
#include "core/basis/dual_graph.h"
#include "core/common/cancel.h"
#include "core/mesh/triangle_mesh.h"

namespace fieldspace {

// How many of `num_regions` samples each connected component gets: proportional to its area
// (largest remainders), at least one each and at most its face count. InvalidArgument when there
// are more components than regions or more regions than faces.
absl::StatusOr<std::vector<int32_t>> AllocateSamplesPerComponent(const TriangleMesh& mesh,
                                                                 int32_t num_regions);

struct SamplingResult {
  // Sample faces, component by component (component 0's first), each component's in the order
  // farthest point sampling picked them.
  std::vector<int32_t> samples;
  // max over faces of the dual-graph distance to the nearest sample: regions of a larger radius
  // cover the mesh (paper section 4, "rho").
  double coverage_radius = 0.0;
};

// Farthest point sampling on the dual graph (paper section 4): per component, the first sample is
// a face chosen by `seed`, every next one the face farthest (in dual-graph distance) from the
// samples so far (ties: the larger face index). Incremental: after each new sample a Dijkstra
// from it relaxes only the faces whose distance decreases, and a bucket queue over distances
// yields the farthest face without scanning all faces. `cancel` is checked every few
// thousand steps; Cancelled once it is set.
absl::StatusOr<SamplingResult> FarthestPointSampling(const TriangleMesh& mesh,
                                                     const DualGraph& graph,
                                                     const std::vector<int32_t>& per_component,
                                                     uint64_t seed, const CancelToken& cancel);

}  // namespace fieldspace

#endif  // FIELDSPACE_CORE_BASIS_SAMPLING_H_
