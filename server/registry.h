#ifndef FIELDSPACE_SERVER_REGISTRY_H_
#define FIELDSPACE_SERVER_REGISTRY_H_

#include <atomic>
#include <chrono>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "Eigen/Core"
#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "core/mesh/triangle_mesh.h"
#include "server/build_job.h"
#include "server/compute_pool.h"
#include "server/lease.h"
#include "server/records.h"
#include "server/served_basis.h"
#include "server/store.h"
#include "server/work_grant.h"

namespace fieldspace::server {

struct RegistryOptions {
  // Memory for loaded meshes and bases and for the working memory of requests (AdmitWork). Idle
  // artifacts (no request or session holds them) are evicted least recently used first and reload
  // from the store on demand; loading an artifact in use may exceed it (a soft limit), admitting
  // work may not.
  int64_t memory_budget_bytes = int64_t{4} << 30;
  int32_t build_threads = 0;     // passed to the basis construction; 0: all
  int32_t max_dimension = 8192;  // larger d is ResourceExhausted (dense reduced matrices are d x d)
  // Builds running or queued at once (each holds its admitted memory while queued): a new build
  // beyond them is ResourceExhausted (joining an identical running build is not).
  int32_t max_queued_builds = 32;
  // Several daemons share the store (--shared-store; docs/scale-out.md): ids missing from memory
  // are looked up in the store, requests naming an id check that its file still exists (deletes
  // by other daemons), listings read the store, and a basis is built once across the daemons
  // (a lease per build in DIR/leases; the others wait for its file).
  bool shared_store = false;
  std::string daemon_id;  // in lease files and logs; random when empty
  Lease::Options lease;
  std::chrono::milliseconds lease_poll{250};  // how often a waiting build looks again
};

// A request for a basis: the key (mesh id, field type, d, sigma, m, seed) plus adaptivity weights.
struct BuildRequest {
  BasisKey key;                  // key.weights_hash is computed by the registry
  Eigen::VectorXd face_weights;  // #F or empty
};

struct BasisStatus {
  BasisRecord record;  // for a running build: key and id only
  bool ready = false;
  bool loaded = false;
  int64_t memory_bytes = 0;
  BuildJob::Progress progress;  // running builds
};

// All server state: meshes, bases, running builds. The RPC layer is stateless and asks the
// registry for handles (shared_ptr<const T>) that it holds only for one request or session.
// Thread-safe.
class Registry final : public WorkAccount {
 public:
  // Reads the store's index (headers only; payloads load lazily).
  static absl::StatusOr<std::unique_ptr<Registry>> Create(Store* store, ComputePool* pool,
                                                          const RegistryOptions& options);
  ~Registry();

  // --- Meshes. Ids: "m-" + XXH64 of the canonical vertex (float64) and face (int32) arrays.
  // Validates (TriangleMesh::Create), stores (if new) and returns the record; adding a mesh that
  // exists returns the existing record (uploads are idempotent).
  absl::StatusOr<MeshRecord> AddMesh(MeshArrays arrays, const std::string& name,
                                     int32_t polygons_triangulated);
  absl::StatusOr<MeshRecord> GetMeshRecord(const std::string& id) const;
  std::vector<MeshRecord> ListMeshes() const;
  bool IsMeshLoaded(const std::string& id) const;
  // FailedPrecondition if the mesh has bases or builds and !cascade. Returns deleted basis ids.
  absl::StatusOr<std::vector<std::string>> DeleteMesh(const std::string& id, bool cascade);
  // Loads lazily. NotFound, DataLoss.
  absl::StatusOr<std::shared_ptr<const TriangleMesh>> GetMesh(const std::string& id);

  // --- Bases. Ids: "b-" + XXH64 of the BasisKey.
  static std::string BasisIdFor(const BasisKey& key);
  struct StartedBuild {
    std::shared_ptr<BuildJob> job;        // null if the basis already exists
    std::optional<BasisRecord> existing;  // set if it does
    bool joined = false;                  // attached to a running build
  };
  // Validates the request (InvalidArgument, NotFound for the mesh, ResourceExhausted for limits),
  // then returns the stored basis, joins the running build or starts one.
  absl::StatusOr<StartedBuild> StartBuild(BuildRequest request);
  absl::Status CancelBuild(const std::string& basis_id);
  absl::StatusOr<BasisStatus> GetBasisStatus(const std::string& id) const;
  std::vector<BasisStatus> ListBases(const std::string& mesh_id_filter) const;
  // FailedPrecondition while it is being built.
  absl::Status DeleteBasis(const std::string& id);
  // Loads lazily (NotFound, DataLoss; FailedPrecondition while building).
  absl::StatusOr<std::shared_ptr<const ServedBasis>> GetBasis(const std::string& id);

  // Cancels all running builds and waits (up to `timeout`) for them to finish (shutdown).
  void CancelAllBuilds(std::chrono::milliseconds timeout);

  int64_t memory_in_use() const;

  // --- Working memory of requests.
  // Admits `bytes` for `what` ("this Solve"): idle artifacts are evicted to make room, and
  // ResourceExhausted (naming `what`, the bytes and --memory-budget-mb) when the artifacts in use
  // and the work already admitted leave less. Requests under kSmallWorkBytes are always admitted
  // (and counted): the daemon's own baseline is larger.
  static constexpr int64_t kSmallWorkBytes = int64_t{4} << 20;
  absl::StatusOr<WorkGrant> AdmitWork(int64_t bytes, absl::string_view what);
  int64_t work_in_use() const;
  void ReleaseWork(int64_t bytes) override;
  // How many basis builds this registry ran to the end (not joined, not found built elsewhere).
  int64_t builds_run() const { return builds_run_.load(); }
  // "HOST/PID/DAEMON_ID" as written into lease files.
  std::string owner_name() const { return me_.ToString(); }

 private:
  // A stored artifact (mesh or basis) and its in-memory copy, if loaded.
  template <typename Record, typename Value>
  struct Entry {
    using ValueType = Value;
    Record record;
    absl::Status damaged;  // DataLoss: the file exists but is unusable
    std::shared_ptr<const Value> loaded;
    std::shared_ptr<std::mutex> load_mu = std::make_shared<std::mutex>();
    int64_t bytes = 0;
    uint64_t last_used = 0;
  };
  using MeshEntry = Entry<MeshRecord, TriangleMesh>;
  using BasisEntry = Entry<BasisRecord, ServedBasis>;

  // The loaded artifact `id` of `entries`, loading it with `load` (outside mu_, one loader per
  // artifact; others wait and then find it) and counting `bytes` of it against the budget.
  // `missing` gives the status for an unknown id (called with mu_ held). A DataLoss from `load`
  // marks the entry damaged.
  template <typename E>
  absl::StatusOr<std::shared_ptr<const typename E::ValueType>> GetOrLoad(
      std::map<std::string, E>& entries, const std::string& id,
      const std::function<absl::Status()>& missing,
      const std::function<absl::StatusOr<std::shared_ptr<const typename E::ValueType>>()>& load,
      const std::function<int64_t(const typename E::ValueType&)>& bytes);

  Registry(Store* store, ComputePool* pool, const RegistryOptions& options)
      : store_(store), pool_(pool), options_(options), me_(LocalLeaseOwner(options.daemon_id)) {}

  // Shared store only (no-ops otherwise), called without mu_: brings the entry of `id` in line
  // with its store file (one stat; the header on first sight); Rescan does it for all files.
  void SyncMesh(const std::string& id) const;
  void SyncBasis(const std::string& id) const;
  // Both: drops the entry of `id` in `entries` when its file is gone (`on_disk` false), else reads
  // its record with `read` unless it is known and sound.
  template <typename E, typename Record>
  void SyncEntry(std::map<std::string, E>& entries, const std::string& id, bool on_disk,
                 const std::function<absl::StatusOr<Record>()>& read) const;
  void Rescan() const;
  // Removes an entry that a delete elsewhere made stale. Requires mu_.
  template <typename E>
  void DropLocked(std::map<std::string, E>& entries,
                  typename std::map<std::string, E>::iterator it) const;
  // Shared store: waits until this daemon holds the build lease of the job's basis (returned), or
  // until another daemon stored the basis (nullptr, `*built` set).
  absl::StatusOr<std::unique_ptr<Lease>> AwaitBuildLease(BuildJob& job, BasisRecord* built);

  // `grant`: the build's admitted working memory, released when the basis is published.
  void RunBuild(const std::shared_ptr<BuildJob>& job, BuildRequest request, WorkGrant grant);
  absl::StatusOr<std::shared_ptr<const ServedBasis>> LoadBasis(const std::string& id);
  // Stores the reduced matrices of basis `id` beside its file (Store::SaveReduced), which a later
  // LoadBasis uses instead of the product pass; a failure is only logged.
  void SaveReducedMatrices(const std::string& id, uint64_t basis_payload_hash,
                           const ReducedSystem& system) const;
  // Stops counting a loaded artifact of `bytes` leaving the index, once nothing holds it any
  // more (at once if nothing does now). Requires mu_.
  void ReleaseLocked(std::shared_ptr<const void> loaded, int64_t bytes) const;
  // Uncounts the released artifacts that nothing holds any more. Requires mu_.
  void SweepReleasedLocked() const;
  // Drops idle loaded artifacts until memory_in_use_ + work_in_use_ <= budget. Requires mu_.
  void EvictLocked();
  absl::StatusOr<WorkGrant> AdmitWorkLocked(int64_t bytes, absl::string_view what);

  Store* const store_;
  ComputePool* const pool_;
  const RegistryOptions options_;
  const LeaseOwner me_;

  mutable std::mutex mu_;
  // Mutable: lookups in a shared store bring them in line with the store.
  mutable std::map<std::string, MeshEntry> meshes_;
  mutable std::map<std::string, BasisEntry> bases_;
  std::map<std::string, std::shared_ptr<BuildJob>> builds_;
  std::atomic<bool> shutting_down_{false};
  std::atomic<int64_t> builds_run_{0};
  mutable int64_t memory_in_use_ = 0;
  // Loaded meshes and bases dropped from the index (deleted) while requests or design sessions
  // still held them: counted in memory_in_use_ until the last holder lets go (ReleaseLocked,
  // SweepReleasedLocked).
  mutable std::vector<std::pair<std::weak_ptr<const void>, int64_t>> released_in_use_;
  int64_t work_in_use_ = 0;  // admitted working memory of requests
  uint64_t clock_ = 0;       // LRU clock
};

}  // namespace fieldspace::server

#endif  // FIELDSPACE_SERVER_REGISTRY_H_
