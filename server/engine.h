#ifndef FIELDSPACE_SERVER_ENGINE_H_
#define FIELDSPACE_SERVER_ENGINE_H_

// The server's bridge to core/: everything that calls core/operators, core/basis and
// core/subspace goes through this narrow interface (core types only, no wire format), so that the
// registry and the RPC layer stay independent of the numerics' details.

#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "Eigen/Core"
#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/types/span.h"
#include "core/basis/basis.h"
#include "core/mesh/triangle_mesh.h"
#include "core/operators/field_operator.h"
#include "core/operators/field_type.h"
#include "server/records.h"

namespace fieldspace::server {

// Build progress as the server reports it (wraps core's BasisPhase with the server's own steps).
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

// Per-basis precomputation of the subspace methods (reduced S, B, M and what the solvers keep);
// defined where core/subspace is called.
class SubspaceModel;

// A basis in memory with everything the subspace methods need. Immutable once published; shared
// by the requests that use it (each holds it only for the request or session).
struct ServedBasis {
  BasisRecord record;
  std::shared_ptr<const TriangleMesh> mesh;
  std::shared_ptr<const Basis> basis;
  std::shared_ptr<const SubspaceModel> model;
  int64_t memory_bytes = 0;
};

// How per-face values travel (mirrors fieldspace.v1.FieldEncoding).
enum class ValueEncoding : uint8_t {
  kDof = 0,      // DESIGN.md section 2: 2 (vector, n-field) or 3 (tensor) frame values per face
  kAmbient = 1,  // 3 (vector; one of the n directions for n-fields) or 6 (tensor xx yy zz xy yz zx)
};

int32_t ValuesPerFace(const FieldType& type, ValueEncoding encoding);

// --- Basis lifecycle -------------------------------------------------------------------------

struct BuildContext {
  std::function<void(BuildStage stage, double fraction)> progress;  // any thread
  const std::atomic<bool>* cancel = nullptr;
  int32_t threads = 0;  // 0: all
};

// Assembles the operator and builds the basis (core/basis) for `key` on `mesh`.
// `face_weights`: #F positive adaptivity weights or empty.
struct BuiltBasis {
  std::shared_ptr<const Basis> basis;
  std::shared_ptr<const FieldOperator> op;  // S and M the basis was built for
};
absl::StatusOr<BuiltBasis> BuildBasisForKey(const TriangleMesh& mesh, const BasisKey& key,
                                            const Eigen::VectorXd& face_weights,
                                            const BuildContext& context);

// The per-basis precomputation for the subspace methods. `op`: the basis's operator, or null to
// assemble it here (after a load from the store).
absl::StatusOr<std::shared_ptr<const SubspaceModel>> PrepareModel(
    const TriangleMesh& mesh, std::shared_ptr<const Basis> basis, const FieldOperator* op,
    const BuildContext& context);

// Bytes of memory held by a model (for the memory budget).
int64_t ModelBytes(const SubspaceModel& model);
int64_t BasisBytes(const Basis& basis);
int64_t MeshBytes(const TriangleMesh& mesh);

// Store payload of a basis (core/basis/basis_io's format, with its own checksums), tagged with
// the id of its mesh.
absl::StatusOr<std::string> SerializeBasis(const Basis& basis, const std::string& mesh_id);
struct DeserializedBasis {
  std::shared_ptr<const Basis> basis;
  std::string mesh_id;
};
absl::StatusOr<DeserializedBasis> DeserializeBasis(std::string_view bytes);

// --- Fields ----------------------------------------------------------------------------------

// Converts values in `encoding` for `faces` (values: faces.size() * ValuesPerFace) to DOFs
// written at dofs[i * dofs_per_face + c] (i the position in `faces`, not the face index).
// Ambient inputs are projected to the face's tangent plane. InvalidArgument for non-finite values,
// bad face indices or sizes.
absl::Status ValuesToDofs(const TriangleMesh& mesh, const FieldType& type, ValueEncoding encoding,
                          absl::Span<const int32_t> faces, absl::Span<const double> values,
                          absl::Span<double> dofs);

// The inverse: `dofs` (faces.size() * dofs_per_face) to `out` (faces.size() * ValuesPerFace).
absl::Status DofsToValues(const TriangleMesh& mesh, const FieldType& type, ValueEncoding encoding,
                          absl::Span<const int32_t> faces, absl::Span<const double> dofs,
                          absl::Span<float> out);

// --- Subspace methods --------------------------------------------------------------------------

struct ProjectResult {
  Eigen::VectorXd coefficients;  // d
  double relative_error = 0;     // ||X - U x||_M / ||X||_M
};
// X: k DOFs (DESIGN.md layout). Eq. 13.
absl::StatusOr<ProjectResult> ProjectField(const ServedBasis& basis, const Eigen::VectorXd& X,
                                           const std::atomic<bool>* cancel);

struct ModelWeights {
  double mu_s = 0;
  double mu_b = 0;
  double mu_c = 0;
};

struct ConstraintSpec {
  int32_t face = 0;
  Eigen::Vector3d dofs = Eigen::Vector3d::Zero();  // first dofs_per_face entries used
  double weight = 1.0;                             // soft constraints only
  bool hard = false;
};

struct SolveResult {
  Eigen::VectorXd coefficients;
  double solve_ms = 0;  // reduced factorization + solve
};
// The reduced model problem (eq. 8, 11) with soft and hard constraints.
absl::StatusOr<SolveResult> SolveModel(const ServedBasis& basis, const ModelWeights& weights,
                                       const std::vector<ConstraintSpec>& constraints,
                                       const std::atomic<bool>* cancel);

// X_f = (U x) at `faces` (any order): dofs_per_face values per listed face into `out`.
absl::Status LiftFaces(const ServedBasis& basis, const Eigen::VectorXd& coefficients,
                       absl::Span<const int32_t> faces, absl::Span<double> out);

struct ReducedEigenfieldsResult {
  Eigen::VectorXd eigenvalues;   // count, ascending
  Eigen::MatrixXd coefficients;  // d x count, M-orthonormal columns
};
absl::StatusOr<ReducedEigenfieldsResult> ReducedEigenfields(const ServedBasis& basis, int32_t count,
                                                            const std::atomic<bool>* cancel);

// An interactive design session (DESIGN.md section 4): constraint edits never refactorize the
// reduced system; only changes of mu_s or mu_b do.
class InteractiveSession {
 public:
  virtual ~InteractiveSession() = default;
  struct EditResult {
    double edit_ms = 0;  // the whole edit, including the reduced solve
    bool refactorized = false;
  };
  // AlreadyExists for an id in use; InvalidArgument for bad values; FailedPrecondition for a hard
  // constraint that depends on the others.
  virtual absl::StatusOr<EditResult> Add(int32_t id, const ConstraintSpec& constraint) = 0;
  // Keeps the constraint's weight and hardness. NotFound for an unknown id.
  virtual absl::StatusOr<EditResult> Move(int32_t id, int32_t face,
                                          const Eigen::Vector3d& dofs) = 0;
  virtual absl::StatusOr<EditResult> Remove(int32_t id) = 0;
  virtual absl::StatusOr<EditResult> SetWeights(const ModelWeights& weights) = 0;
  virtual const Eigen::VectorXd& coefficients() const = 0;
  virtual int32_t num_constraints() const = 0;
  virtual int32_t num_hard_constraints() const = 0;
};

struct OpenSessionResult {
  std::unique_ptr<InteractiveSession> session;
  InteractiveSession::EditResult timings;
};
// verify_interval: DesignSessionOptions::verify_interval.
absl::StatusOr<OpenSessionResult> OpenDesignSession(std::shared_ptr<const ServedBasis> basis,
                                                    const ModelWeights& weights,
                                                    int32_t verify_interval = 1);

// Validates weights: finite, >= 0, mu_s + mu_b > 0 (otherwise the energy does not determine the
// field away from the constraints). Shared by Solve and Design (which also needs mu_c > 0).
absl::Status ValidateWeights(const ModelWeights& weights);

}  // namespace fieldspace::server

#endif  // FIELDSPACE_SERVER_ENGINE_H_
