#ifndef FIELDSPACE_CORE_BASIS_BASIS_H_
#define FIELDSPACE_CORE_BASIS_BASIS_H_

#include <atomic>
#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "Eigen/Core"
#include "Eigen/SparseCore"
#include "absl/status/statusor.h"
#include "core/mesh/triangle_mesh.h"
#include "core/operators/field_operator.h"

namespace fieldspace {

enum class BasisPhase : uint8_t { kSampling = 0, kRegions = 1, kEigensolve = 2, kAssembly = 3 };

// Parameters of the locally supported basis construction (paper section 4, DESIGN.md section 3).
struct BasisParams {
  int32_t dimension = 0;                     // d: target number of columns of U (>= 1)
  double sigma = 40.0;                       // overlap factor of eq. 12 (> 0)
  std::optional<int32_t> fields_per_region;  // m; default: FieldType::default_fields_per_region()
  uint64_t seed = 0;                         // picks the first farthest-point sample per component
  // Per-face adaptivity weights (#F, each finite and > 0); empty means uniform. A dual arc's
  // length is multiplied by the mean of its two faces' weights.
  Eigen::VectorXd face_weights;
};

struct BasisOptions {
  BasisParams params;
  int32_t threads = 0;  // 0: all available cores
  // Called from any thread, at least every 100 ms while building; fraction in [0, 1].
  std::function<void(BasisPhase phase, double fraction)> progress;
  // Checked at least every 100 ms; when it becomes true the build returns Cancelled.
  const std::atomic<bool>* cancel = nullptr;
};

struct BasisTimings {
  double sampling_seconds = 0;
  double regions_seconds = 0;
  double eigensolve_seconds = 0;
  double total_seconds = 0;
};

// A subspace basis U (k x d) of locally supported fields.
struct Basis {
  FieldType type;
  BasisParams params;
  double radius = 0;  // r of eq. 12 actually used (in dual-graph distance units)
  // k x d, DOF order of DESIGN.md section 2; column j = region j / m, field j % m, M-orthonormal
  // within a region. Row-major float storage: lifting (U x) walks rows in parallel.
  Eigen::SparseMatrix<float, Eigen::RowMajor> U;
  std::vector<int32_t> sample_faces;      // sample (center) face of each region
  std::vector<double> local_eigenvalues;  // d: eigenvalue of each column's local problem (eq. 7)
  BasisTimings timings;

  int32_t dimension() const { return static_cast<int32_t>(U.cols()); }
  int32_t num_regions() const { return static_cast<int32_t>(sample_faces.size()); }
};

// Builds the basis (section 4) for `op` on `mesh`. InvalidArgument for bad parameters, Cancelled
// when options.cancel fires, ResourceExhausted when the estimated nnz(U) is beyond memory.
absl::StatusOr<Basis> BuildBasis(const TriangleMesh& mesh, const FieldOperator& op,
                                 const BasisOptions& options);

}  // namespace fieldspace

#endif  // FIELDSPACE_CORE_BASIS_BASIS_H_
