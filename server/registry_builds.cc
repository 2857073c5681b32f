// Registry: basis builds (ids, starting, running, cancelling). The rest of the registry is in
// registry.cc.

#include <algorithm>
#include <chrono>
#include <deque>
#include <iostream>
#include <string>
#include <string_view>
#include <thread>
#include <utility>
#include <vector>

#include "absl/strings/str_cat.h"
#include "core/basis/basis_io.h"
#include "core/common/status_macros.h"
#include "core/subspace/reduced_system.h"
#include "server/hash.h"
#include "server/registry.h"
#include "server/shown_text.h"
#include "tbb/task_arena.h"

namespace fieldspace::server {
namespace {

// What building the served basis's reduced system (ServedBasis) adds to EstimateBuildPeakBytes,
// which counts 8 d^2 bytes for the reduced matrices: the product pass's dense band accumulators,
// 3 x 8 d bytes per output column and thread up to ReducedSystemOptions::accumulator_budget_bytes
// (768 MiB: d = 4096 on 2 threads fills it), and, with more than 8 fields per region, what the
// regions' wider column blocks add: 20 d^2 more, an envelope of the peaks measured at d = 4096 and
// 8192, m = 16..64, on 20k to 269k faces (within 11% on bunny_70k at m = 64; bench/RESULTS.md,
// Session 16).
int64_t ReducedAssemblyBytes(int64_t d, int32_t fields_per_region, int32_t threads) {
  const int64_t resolved = threads > 0 ? threads : tbb::this_task_arena::max_concurrency();
  const int64_t accumulators =
      std::min<int64_t>(ReducedSystemOptions().accumulator_budget_bytes, 24 * resolved * d * d);
  return accumulators + (fields_per_region > 8 ? 20 * d * d : 0);
}

}  // namespace

std::string Registry::BasisIdFor(const BasisKey& key) {
  Hasher hasher;
  hasher.UpdateString("fieldspace-basis-v1");
  hasher.UpdateString(key.mesh_id);
  hasher.UpdateValue<uint8_t>(static_cast<uint8_t>(key.field.kind));
  hasher.UpdateValue<int32_t>(key.field.kind == FieldKind::kNField ? key.field.n : 0);
  hasher.UpdateValue<int32_t>(key.dimension);
  hasher.UpdateValue<double>(key.sigma);
  hasher.UpdateValue<int32_t>(key.fields_per_region);
  hasher.UpdateValue<uint64_t>(key.seed);
  hasher.UpdateValue<uint64_t>(key.weights_hash);
  // Only two-level bases hash C, so the ids of one-level bases stay what they were before C
  // existed.
  if (key.coarse_dimension != 0) hasher.UpdateValue<int32_t>(key.coarse_dimension);
  // Likewise kernel columns: bases without them (the paper's construction) keep their old ids.
  if (key.kernel_columns) hasher.UpdateString("kernel-columns");
  // And quality levels: the paper's keeps the ids of before.
  if (key.quality != BasisQuality::kPaper) {
    hasher.UpdateString("quality");
    hasher.UpdateValue<uint8_t>(static_cast<uint8_t>(key.quality));
  }
  return "b-" + Hex64(hasher.Digest());
}

absl::StatusOr<Registry::StartedBuild> Registry::StartBuild(BuildRequest request) {
  BasisKey& key = request.key;
  ASSIGN_OR_RETURN(MeshRecord mesh, GetMeshRecord(key.mesh_id));
  if (key.field.kind != FieldKind::kVector && key.field.kind != FieldKind::kNField &&
      key.field.kind != FieldKind::kTensor) {
    return absl::InvalidArgumentError("field type must be vector, nfield or tensor");
  }
  if (key.field.kind != FieldKind::kNField) key.field.n = 1;
  RETURN_IF_ERROR(key.field.Validate());
  const int64_t dofs = int64_t{key.field.dofs_per_face()} * mesh.num_faces;
  if (key.dimension > options_.max_dimension) {
    return absl::ResourceExhaustedError(absl::StrCat(
        "dimension ", key.dimension, " exceeds this server's limit of ", options_.max_dimension));
  }
  if (key.fields_per_region == 0) key.fields_per_region = key.field.default_fields_per_region();
  {
    // The core's bounds (d, sigma, m, weights), on the parameters as the build will see them.
    BasisParams params;
    params.dimension = key.dimension;
    params.sigma = key.sigma;
    params.fields_per_region = key.fields_per_region;
    params.face_weights = std::move(request.face_weights);
    const absl::Status valid = ValidateBasisParams(params, key.field, mesh.num_faces);
    request.face_weights = std::move(params.face_weights);
    RETURN_IF_ERROR(valid);
  }
  RETURN_IF_ERROR(
      QualityLevels(key.quality, key.dimension, key.sigma, key.coarse_dimension).status());
  // A vector field's kernel is the harmonic fields: none on a genus-0 mesh (with or without
  // boundary), so the option would not change the basis and must not change its id.
  if (key.field.kind == FieldKind::kVector && mesh.genus == 0) key.kernel_columns = false;
  key.weights_hash = 0;
  if (request.face_weights.size() > 0) {
    // Salted with the construction's revision for weighted bases (2: eq. 12's radius from the
    // weighted area), so that bases built by the earlier rule keep their ids and new requests get
    // new ones. Never 0, which means uniform.
    constexpr uint64_t kWeightedConstructionRevision = 2;
    key.weights_hash =
        (Hash64(request.face_weights.data(), sizeof(double) * request.face_weights.size()) ^
         (kWeightedConstructionRevision * 0x9E3779B97F4A7C15ull)) |
        1;
  }
  BasisRecord pending;
  pending.id = BasisIdFor(key);
  pending.key = key;
  pending.dofs = static_cast<int32_t>(dofs);

  SyncBasis(pending.id);
  std::lock_guard<std::mutex> lock(mu_);
  StartedBuild out;
  if (auto it = bases_.find(pending.id); it != bases_.end() && it->second.damaged.ok()) {
    out.existing = it->second.record;
    return out;
  }
  if (auto it = builds_.find(pending.id); it != builds_.end()) {
    out.job = it->second;
    out.joined = true;
    return out;
  }
  if (static_cast<int64_t>(builds_.size()) >= options_.max_queued_builds) {
    return absl::ResourceExhaustedError(
        absl::StrCat("the server has ", builds_.size(),
                     " basis builds running or queued, its maximum (--max-queued-builds); retry "
                     "when one has finished"));
  }
  ASSIGN_OR_RETURN(
      WorkGrant grant,
      AdmitWorkLocked(
          EstimateBuildPeakBytes(mesh.num_faces, key.field, key.dimension, key.sigma,
                                 key.kernel_columns, key.quality, key.coarse_dimension,
                                 options_.build_threads) +
              ReducedAssemblyBytes(key.dimension, key.fields_per_region, options_.build_threads),
          "this basis build"));
  auto job = std::make_shared<BuildJob>(pending);
  const bool submitted = pool_->Submit(
      ComputePool::Lane::kBuild, [this, job, request = std::move(request),
                                  grant = std::make_shared<WorkGrant>(std::move(grant))]() mutable {
        RunBuild(job, std::move(request), std::move(*grant));
      });
  if (!submitted) return absl::UnavailableError("server is shutting down");
  builds_[pending.id] = job;
  out.job = std::move(job);
  return out;
}

void Registry::RunBuild(const std::shared_ptr<BuildJob>& job, BuildRequest request,
                        WorkGrant grant) {
  const auto start = std::chrono::steady_clock::now();
  BasisRecord record = job->pending_record();
  BuildContext context;
  context.cancel = job->cancel_flag();
  context.threads = options_.build_threads;
  context.progress = [job](BuildStage stage, double fraction) { job->SetStage(stage, fraction); };

  std::unique_ptr<Lease> lease;          // shared store: held from before the build to the save
  std::optional<BasisRecord> elsewhere;  // shared store: another daemon built it
  auto build = [&]() -> absl::StatusOr<std::shared_ptr<const ServedBasis>> {
    if (job->cancel_flag()->load()) return absl::CancelledError("build cancelled");
    if (options_.shared_store) {
      BasisRecord built;
      ASSIGN_OR_RETURN(lease, AwaitBuildLease(*job, &built));
      if (lease == nullptr) {
        elsewhere = std::move(built);
        return nullptr;
      }
      std::cerr << "fieldspaced: building basis " << record.id << " (mesh " << record.key.mesh_id
                << ", d " << record.key.dimension << ") as " << me_.ToString() << ", lease "
                << lease->path() << std::endl;
    }
    job->SetStage(BuildStage::kOperator, 0);
    ASSIGN_OR_RETURN(std::shared_ptr<const TriangleMesh> mesh, GetMesh(record.key.mesh_id));
    ASSIGN_OR_RETURN(BuiltBasis built,
                     BuildBasisForKey(*mesh, record.key, request.face_weights, context));
    const Basis& basis = *built.basis;
    if (job->cancel_flag()->load()) return absl::CancelledError("build cancelled");
    job->SetStage(BuildStage::kPrecompute, 0);
    ASSIGN_OR_RETURN(std::shared_ptr<const ServedBasis> served,
                     ServeBasis(record, mesh, built.basis, built.op.get(), context));
    built.op.reset();  // S is no longer needed: free it before saving
    if (job->cancel_flag()->load()) return absl::CancelledError("build cancelled");
    job->SetStage(BuildStage::kSaving, 0);
    record.columns = basis.dimension();
    record.num_regions = basis.num_regions();
    record.dofs = static_cast<int32_t>(basis.U.rows());
    record.radius = basis.radius;
    record.nnz = basis.U.nonZeros();
    record.created_unix_ms = NowUnixMs();
    record.build_seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    // U's arrays are written from where they are, not from a copy beside them.
    std::deque<std::string> payload_storage;
    ASSIGN_OR_RETURN(std::vector<std::string_view> payload,
                     EncodeBasisPieces(basis, record.key.mesh_id, &payload_storage));
    uint64_t payload_hash = 0;
    RETURN_IF_ERROR(store_->SaveBasis(record, payload, &payload_hash));
    SaveReducedMatrices(record.id, payload_hash, *served->system);
    builds_run_.fetch_add(1);
    auto published = std::make_shared<ServedBasis>(*served);
    published->record = record;  // with the figures known only now
    return std::shared_ptr<const ServedBasis>(std::move(published));
  };
  absl::StatusOr<std::shared_ptr<const ServedBasis>> result;
  try {
    result = build();
  } catch (const std::bad_alloc&) {
    result = absl::ResourceExhaustedError("out of memory while building the basis");
  } catch (const std::exception& e) {
    result = absl::InternalError(absl::StrCat("basis build failed: ", e.what()));
  }
  if (!result.ok() && result.status().code() == absl::StatusCode::kCancelled &&
      shutting_down_.load()) {
    result = absl::UnavailableError(
        "the server shut down before the build finished; request it again after the restart");
  }
  if (elsewhere) record = *elsewhere;
  grant = WorkGrant();  // the working memory is free; the basis is counted as loaded from now on
  if (options_.shared_store) SyncMesh(record.key.mesh_id);
  bool orphaned = false;
  {
    std::lock_guard<std::mutex> lock(mu_);
    builds_.erase(record.id);
    if (result.ok() && elsewhere) {
      // Built by another daemon: known from now on, loaded on first use.
      BasisEntry& e = bases_[record.id];
      if (e.loaded == nullptr) {
        e.record = record;
        e.damaged = absl::OkStatus();
      }
    } else if (result.ok()) {
      if (meshes_.count(record.key.mesh_id) == 0) {
        orphaned = true;  // the mesh was deleted while we were building
        result = absl::CancelledError("the basis's mesh was deleted during the build");
      } else {
        BasisEntry& e = bases_[record.id];
        if (e.loaded != nullptr) memory_in_use_ -= e.bytes;
        e.record = record;
        e.damaged = absl::OkStatus();
        e.loaded = *result;
        e.bytes = (*result)->memory_bytes;
        e.last_used = ++clock_;
        memory_in_use_ += e.bytes;
        EvictLocked();
      }
    }
  }
  if (orphaned) (void)store_->DeleteBasis(record.id);
  lease.reset();  // after the file is in place: waiters look for the file before the lease
  job->Finish(result.status(), record);
}

absl::Status Registry::CancelBuild(const std::string& basis_id) {
  std::lock_guard<std::mutex> lock(mu_);
  auto it = builds_.find(basis_id);
  if (it == builds_.end()) {
    if (bases_.count(basis_id) > 0) {
      return absl::FailedPreconditionError(
          absl::StrCat("basis ", basis_id, " is already built; nothing to cancel"));
    }
    return absl::NotFoundError(absl::StrCat("no running build for basis ", ShownId(basis_id)));
  }
  it->second->Cancel();
  return absl::OkStatus();
}

void Registry::CancelAllBuilds(std::chrono::milliseconds timeout) {
  shutting_down_.store(true);
  std::vector<std::shared_ptr<BuildJob>> jobs;
  {
    std::lock_guard<std::mutex> lock(mu_);
    for (auto& [id, job] : builds_) jobs.push_back(job);
  }
  for (auto& job : jobs) job->Cancel();
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  for (auto& job : jobs) {
    while (!job->progress().finished && std::chrono::steady_clock::now() < deadline) {
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
  }
}

}  // namespace fieldspace::server
