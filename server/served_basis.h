#ifndef FIELDSPACE_SERVER_SERVED_BASIS_H_
#define FIELDSPACE_SERVER_SERVED_BASIS_H_

// Server state around a basis: the basis in memory with its per-basis precomputation, and how a
// build reports progress. Every numeric step is a core/ call; the RPC layer works on core's own
// types (EnergyWeights, FieldConstraint, ModelProblem, DesignSession, ...).

#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>

#include "Eigen/Core"
#include "absl/status/statusor.h"
#include "core/basis/basis.h"
#include "core/mesh/triangle_mesh.h"
#include "core/operators/field_operator.h"
#include "core/subspace/design_session.h"
#include "core/subspace/reduced_system.h"
#include "server/records.h"

namespace fieldspace::server {

// Build progress as the server reports it (core's BasisPhase plus the server's own steps).
enum class BuildStage : uint8_t {
  kQueued = 0,
  kOperator = 1,
  kSampling = 2,
  kRegions = 3,
  kEigensolve = 4,
  kAssembly = 5,
  kPrecompute = 6,
  kSaving = 7,
  kDone = 8,
};

// The estimated fraction of a whole build done at `stage` with `fraction` of that stage done:
// the stages weighted by their typical share of a build's wall time (served_basis.cc says where
// the weights come from). In [0, 1], non-decreasing in (stage, fraction).
double OverallFraction(BuildStage stage, double fraction);

// A basis in memory with everything the subspace methods need. Immutable once published; shared
// by the requests that use it (each holds it only for the request or session).
struct ServedBasis {
  BasisRecord record;
  std::shared_ptr<const TriangleMesh> mesh;
  std::shared_ptr<const Basis> basis;  // system->shared_basis(): its metadata, U without rows
  std::shared_ptr<const ReducedSystem> system;      // U^T S U, U^T B U, U^T M U, LiftPlan, ...
  std::shared_ptr<EnergyFactorCache> energy_cache;  // shared by this basis's design sessions
  int64_t memory_bytes = 0;  // basis + system, as core counts them (for the memory budget)
  // The curvature-aligned data terms of design sessions, per estimator, shared while any session
  // holds one (so that sessions with the same weights also share their energy factorization):
  // curvature_alignment.h.
  std::shared_ptr<struct AlignmentCache> alignment_cache;
};

// Where a request finds the basis it names (Registry::GetBasis in the daemon).
using BasisLookup =
    std::function<absl::StatusOr<std::shared_ptr<const ServedBasis>>(const std::string& id)>;

struct BuildContext {
  std::function<void(BuildStage stage, double fraction)> progress;  // any thread
  const std::atomic<bool>* cancel = nullptr;
  int32_t threads = 0;  // 0: all
};

// Builds the basis (core/basis) for `key` on `mesh`, with S assembled only if the build reads it.
// `face_weights`: #F positive adaptivity weights or empty.
struct BuiltBasis {
  std::shared_ptr<const Basis> basis;
  // S and M the basis was built for; null when the build did not read S (BuildReadsStiffness:
  // vector fields), whose reduced system ServeBasis then computes from the mesh without S.
  std::shared_ptr<const FieldOperator> op;
};
absl::StatusOr<BuiltBasis> BuildBasisForKey(const TriangleMesh& mesh, const BasisKey& key,
                                            const Eigen::VectorXd& face_weights,
                                            const BuildContext& context);

// The per-basis precomputation (core's ReducedSystem) and the served handle. `op`: the basis's
// operator, or null for the mesh's own (after a load from the store, or a vector build:
// ReducedSystem::Build from the mesh, which never assembles a vector field's S). `matrices`: the
// reduced matrices kept in the store for this basis (Store::LoadReduced), which spare the product
// pass; should they not fit the basis, the pass runs after all (and says so on stderr). `plan`: U
// read from the store as a LiftPlan (LiftPlan::StreamBuilder), `basis` then without rows; needs
// `matrices`, and should they not fit, the error is returned (the pass needs U's rows: the
// caller reads them).
absl::StatusOr<std::shared_ptr<const ServedBasis>> ServeBasis(
    BasisRecord record, std::shared_ptr<const TriangleMesh> mesh,
    std::shared_ptr<const Basis> basis, const FieldOperator* op, const BuildContext& context,
    std::optional<ReducedMatrices> matrices = std::nullopt,
    std::optional<LiftPlan> plan = std::nullopt);

}  // namespace fieldspace::server

#endif  // FIELDSPACE_SERVER_SERVED_BASIS_H_
