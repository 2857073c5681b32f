#ifndef FIELDSPACE_CORE_BASIS_REGIONS_H_
#define FIELDSPACE_CORE_BASIS_REGIONS_H_

#include <cstdint>
#include <vector>

#include "absl/status/statusor.h"
#include "core/basis/dual_graph.h"
#include "core/common/cancel.h"

namespace fieldspace {

struct RegionOptions {
  double radius = 0.0;    // dual-graph distance r (eq. 12)
  int32_t min_faces = 1;  // regions smaller than this grow past r to this size
};

// The support region of each sample (paper section 4): the faces within dual-graph distance
// `radius` of the sample (Dijkstra truncated at r), as ascending face indices. Regions are grown
// in parallel (run inside the caller's task arena) with per-thread scratch, O(region size) each.
// `cancel` is checked regularly from worker threads; Cancelled once it is set.
absl::StatusOr<std::vector<std::vector<int32_t>>> GrowRegions(const DualGraph& graph,
                                                              const std::vector<int32_t>& samples,
                                                              const RegionOptions& options,
                                                              const CancelToken& cancel);

}  // namespace fieldspace

#endif  // FIELDSPACE_CORE_BASIS_REGIONS_H_
