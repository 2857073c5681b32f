#include "server/registry.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <iostream>
#include <set>
#include <thread>
#include <utility>

#include "absl/strings/str_cat.h"
#include "core/basis/basis_io.h"
#include "core/common/status_macros.h"
#include "server/hash.h"
#include "server/shown_text.h"

namespace fieldspace::server {
namespace {

std::string MeshIdFor(const TriangleMesh& mesh) {
  Hasher hasher;
  hasher.UpdateString("fieldspace-mesh-v1");
  hasher.UpdateValue<int64_t>(mesh.num_vertices());
  hasher.UpdateValue<int64_t>(mesh.num_faces());
  hasher.Update(mesh.vertices().data(), sizeof(double) * mesh.vertices().size());
  hasher.Update(mesh.faces().data(), sizeof(int32_t) * mesh.faces().size());
  return "m-" + Hex64(hasher.Digest());
}

MeshRecord RecordFor(const TriangleMesh& mesh) {
  MeshRecord r;
  r.id = MeshIdFor(mesh);
  r.num_vertices = mesh.num_vertices();
  r.num_faces = mesh.num_faces();
  r.num_edges = mesh.num_edges();
  r.num_components = mesh.num_components();
  r.num_boundary_loops = static_cast<int32_t>(mesh.boundary_loops().size());
  r.euler_characteristic = mesh.euler_characteristic();
  r.genus = mesh.genus();
  r.total_area = mesh.total_area();
  r.dropped_unreferenced_vertices = mesh.dropped_unreferenced_vertices();
  return r;
}

}  // namespace

// --- BuildJob ----------------------------------------------------------------------------------

absl::StatusOr<std::unique_ptr<Registry>> Registry::Create(Store* store, ComputePool* pool,
                                                           const RegistryOptions& options) {
  if (store == nullptr || pool == nullptr) {
    return absl::InvalidArgumentError("registry needs a store and a compute pool");
  }
  std::unique_ptr<Registry> registry(new Registry(store, pool, options));
  StoreContents contents = store->Scan();
  for (MeshRecord& r : contents.meshes) {
    MeshEntry& e = registry->meshes_[r.id];
    e.record = std::move(r);
  }
  for (BasisRecord& r : contents.bases) {
    BasisEntry& e = registry->bases_[r.id];
    e.record = std::move(r);
  }
  for (DamagedEntry& d : contents.damaged) {
    if (d.is_basis) {
      BasisEntry& e = registry->bases_[d.id];
      e.record.id = d.id;
      e.damaged = d.status;
    } else {
      MeshEntry& e = registry->meshes_[d.id];
      e.record.id = d.id;
      e.damaged = d.status;
    }
  }
  return registry;
}

Registry::~Registry() { CancelAllBuilds(std::chrono::milliseconds(0)); }

// --- Shared store -------------------------------------------------------------------------------

template <typename E>
void Registry::DropLocked(std::map<std::string, E>& entries,
                          typename std::map<std::string, E>::iterator it) const {
  // Sessions and requests that hold the loaded copy keep it until they let go.
  if (it->second.loaded != nullptr) ReleaseLocked(it->second.loaded, it->second.bytes);
  entries.erase(it);
}

template <typename E, typename Record>
void Registry::SyncEntry(std::map<std::string, E>& entries, const std::string& id, bool on_disk,
                         const std::function<absl::StatusOr<Record>()>& read) const {
  {
    std::lock_guard<std::mutex> lock(mu_);
    auto it = entries.find(id);
    if (!on_disk) {
      if (it != entries.end()) DropLocked(entries, it);
      return;
    }
    if (it != entries.end() && it->second.damaged.ok()) return;
  }
  absl::StatusOr<Record> record = read();
  if (!record.ok() && record.status().code() != absl::StatusCode::kDataLoss) return;
  std::lock_guard<std::mutex> lock(mu_);
  E& e = entries[id];
  if (e.loaded != nullptr) return;  // an upload or build here won the race
  e.record.id = id;
  e.damaged = record.status();
  if (record.ok()) e.record = *std::move(record);
}

void Registry::SyncMesh(const std::string& id) const {
  if (!options_.shared_store) return;
  SyncEntry<MeshEntry, MeshRecord>(meshes_, id, store_->HasMesh(id),
                                   [&] { return store_->ReadMeshRecord(id); });
}

void Registry::SyncBasis(const std::string& id) const {
  if (!options_.shared_store) return;
  SyncEntry<BasisEntry, BasisRecord>(bases_, id, store_->HasBasis(id),
                                     [&] { return store_->ReadBasisRecord(id); });
}

void Registry::Rescan() const {
  if (!options_.shared_store) return;
  StoreContents contents = store_->Scan();
  std::set<std::string> mesh_ids, basis_ids;
  std::lock_guard<std::mutex> lock(mu_);
  for (MeshRecord& r : contents.meshes) {
    mesh_ids.insert(r.id);
    MeshEntry& e = meshes_[r.id];
    if (e.loaded != nullptr && e.damaged.ok()) continue;
    e.damaged = absl::OkStatus();
    e.record = std::move(r);
  }
  for (BasisRecord& r : contents.bases) {
    basis_ids.insert(r.id);
    BasisEntry& e = bases_[r.id];
    if (e.loaded != nullptr && e.damaged.ok()) continue;
    e.damaged = absl::OkStatus();
    e.record = std::move(r);
  }
  for (DamagedEntry& d : contents.damaged) {
    (d.is_basis ? basis_ids : mesh_ids).insert(d.id);
    auto mark = [&d](auto& e) {
      if (e.loaded != nullptr) return;  // in use: the copy in memory was checked when loaded
      e.record.id = d.id;
      e.damaged = d.status;
    };
    if (d.is_basis) {
      mark(bases_[d.id]);
    } else {
      mark(meshes_[d.id]);
    }
  }
  for (auto it = meshes_.begin(); it != meshes_.end();) {
    auto next = std::next(it);
    if (mesh_ids.count(it->first) == 0) DropLocked(meshes_, it);
    it = next;
  }
  for (auto it = bases_.begin(); it != bases_.end();) {
    auto next = std::next(it);
    if (basis_ids.count(it->first) == 0) DropLocked(bases_, it);
    it = next;
  }
}

absl::StatusOr<std::unique_ptr<Lease>> Registry::AwaitBuildLease(BuildJob& job,
                                                                 BasisRecord* built) {
  const std::string& id = job.basis_id();
  const std::string dir = store_->LeaseDir();
  Lease::State watched;
  watched.mtime_ns = -1;
  auto unchanged_since = std::chrono::steady_clock::now();
  std::string announced;
  while (true) {
    if (job.cancel_flag()->load()) return absl::CancelledError("build cancelled");
    if (absl::StatusOr<BasisRecord> r = store_->ReadBasisRecord(id); r.ok()) {
      *built = *std::move(r);
      return nullptr;
    }
    LeaseOwner holder;
    ASSIGN_OR_RETURN(std::unique_ptr<Lease> lease,
                     Lease::TryAcquire(dir, id, me_, options_.lease, &holder));
    if (lease != nullptr) {
      // The holder may have saved and released between our two looks.
      if (absl::StatusOr<BasisRecord> r = store_->ReadBasisRecord(id); r.ok()) {
        *built = *std::move(r);
        return nullptr;
      }
      return lease;
    }
    if (holder.ToString() != announced) {
      announced = holder.ToString();
      std::cerr << "fieldspaced: basis " << id << ": waiting for replica " << announced
                << " (it holds the build lease)" << std::endl;
    }
    job.SetWaitingFor(announced);
    const auto now = std::chrono::steady_clock::now();
    if (absl::StatusOr<Lease::State> state = Lease::Read(dir, id); state.ok()) {
      if (!(state->owner == watched.owner) || state->mtime_ns != watched.mtime_ns) {
        watched = *state;
        unchanged_since = now;
      } else if (now - unchanged_since > options_.lease.stale_after) {
        std::cerr << "fieldspaced: basis " << id << ": the lease of " << announced
                  << " has had no heartbeat for "
                  << std::chrono::duration<double>(now - unchanged_since).count()
                  << " s: taking it over" << std::endl;
        RETURN_IF_ERROR(Lease::BreakStale(dir, id, watched.owner, watched.mtime_ns));
        continue;
      }
    }
    std::this_thread::sleep_for(options_.lease_poll);
  }
}

int64_t Registry::memory_in_use() const {
  std::lock_guard<std::mutex> lock(mu_);
  SweepReleasedLocked();
  return memory_in_use_;
}

void Registry::ReleaseLocked(std::shared_ptr<const void> loaded, int64_t bytes) const {
  if (loaded.use_count() > 1) {
    released_in_use_.emplace_back(loaded, bytes);
  } else {
    memory_in_use_ -= bytes;
  }
}

void Registry::SweepReleasedLocked() const {
  auto gone =
      std::remove_if(released_in_use_.begin(), released_in_use_.end(), [this](const auto& held) {
        if (!held.first.expired()) return false;
        memory_in_use_ -= held.second;
        return true;
      });
  released_in_use_.erase(gone, released_in_use_.end());
}

void Registry::EvictLocked() {
  SweepReleasedLocked();
  while (memory_in_use_ + work_in_use_ > options_.memory_budget_bytes) {
    // Least recently used idle artifact: bases first among equals, as a loaded basis pins its
    // mesh (so the mesh becomes idle only after its bases went).
    uint64_t best = UINT64_MAX;
    BasisEntry* best_basis = nullptr;
    MeshEntry* best_mesh = nullptr;
    for (auto& [id, e] : bases_) {
      if (e.loaded != nullptr && e.loaded.use_count() == 1 && e.last_used < best) {
        best = e.last_used;
        best_basis = &e;
      }
    }
    for (auto& [id, e] : meshes_) {
      if (e.loaded != nullptr && e.loaded.use_count() == 1 && e.last_used < best) {
        best = e.last_used;
        best_basis = nullptr;
        best_mesh = &e;
      }
    }
    if (best_basis != nullptr) {
      best_basis->loaded.reset();
      memory_in_use_ -= best_basis->bytes;
      best_basis->bytes = 0;
    } else if (best_mesh != nullptr) {
      best_mesh->loaded.reset();
      memory_in_use_ -= best_mesh->bytes;
      best_mesh->bytes = 0;
    } else {
      return;  // everything in memory is in use: the budget is soft
    }
  }
}

absl::StatusOr<WorkGrant> Registry::AdmitWork(int64_t bytes, absl::string_view what) {
  std::lock_guard<std::mutex> lock(mu_);
  return AdmitWorkLocked(bytes, what);
}

absl::StatusOr<WorkGrant> Registry::AdmitWorkLocked(int64_t bytes, absl::string_view what) {
  bytes = std::max<int64_t>(bytes, 0);
  const int64_t budget = options_.memory_budget_bytes;
  auto mib = [](int64_t b) { return (b + (int64_t{1} << 20) - 1) >> 20; };
  if (bytes > kSmallWorkBytes && bytes > budget) {
    return absl::ResourceExhaustedError(
        absl::StrCat(what, " needs about ", mib(bytes),
                     " MiB of working memory, more than the whole memory "
                     "budget of ",
                     mib(budget), " MiB (--memory-budget-mb)"));
  }
  work_in_use_ += bytes;
  EvictLocked();
  if (bytes > kSmallWorkBytes && memory_in_use_ + work_in_use_ > budget) {
    work_in_use_ -= bytes;
    return absl::ResourceExhaustedError(absl::StrCat(
        what, " needs about ", mib(bytes), " MiB of working memory; of the memory budget of ",
        mib(budget), " MiB (--memory-budget-mb), ", mib(memory_in_use_),
        " MiB are held by meshes and bases in use and ", mib(work_in_use_),
        " MiB by other requests. Retry when they are done, or raise the budget"));
  }
  return WorkGrant(this, bytes);
}

int64_t Registry::work_in_use() const {
  std::lock_guard<std::mutex> lock(mu_);
  return work_in_use_;
}

void Registry::ReleaseWork(int64_t bytes) {
  std::lock_guard<std::mutex> lock(mu_);
  work_in_use_ -= bytes;
}

absl::StatusOr<MeshRecord> Registry::AddMesh(MeshArrays arrays, const std::string& name,
                                             int32_t polygons_triangulated) {
  ASSIGN_OR_RETURN(TriangleMesh mesh, TriangleMesh::Create(std::move(arrays)));
  MeshRecord record = RecordFor(mesh);
  record.name = name;
  record.polygons_triangulated = polygons_triangulated;
  record.created_unix_ms = NowUnixMs();
  SyncMesh(record.id);
  std::optional<MeshRecord> listed;  // known from its file's header alone
  {
    std::lock_guard<std::mutex> lock(mu_);
    auto it = meshes_.find(record.id);
    if (it != meshes_.end() && it->second.damaged.ok()) {
      it->second.last_used = ++clock_;
      if (it->second.loaded != nullptr) return it->second.record;
      listed = it->second.record;
    }
  }
  // A listed file that was never loaded may still have a damaged payload: check it and rewrite it
  // unless it holds this mesh. Not known, or damaged (which this upload repairs): persist first,
  // then publish, so that a listed mesh always survives a restart.
  if (listed && store_->VerifyMesh(record.id, mesh.vertices(), mesh.faces()).ok()) {
    record = *std::move(listed);
  } else {
    RETURN_IF_ERROR(store_->SaveMesh(record, mesh.vertices(), mesh.faces()));
  }
  auto shared = std::make_shared<const TriangleMesh>(std::move(mesh));
  const int64_t bytes = shared->MemoryBytes();
  std::lock_guard<std::mutex> lock(mu_);
  auto [it, inserted] = meshes_.try_emplace(record.id);
  MeshEntry& e = it->second;
  if (!inserted && e.damaged.ok() && e.loaded != nullptr) return e.record;  // lost a race
  if (e.loaded != nullptr) memory_in_use_ -= e.bytes;
  // A repair: bases that failed to load because this mesh was damaged load again (a basis whose
  // own file is damaged fails again on its next load).
  if (!inserted) {
    for (auto& [bid, b] : bases_) {
      if (b.record.key.mesh_id == record.id) b.damaged = absl::OkStatus();
    }
  }
  e.record = record;
  e.damaged = absl::OkStatus();
  e.loaded = std::move(shared);
  e.bytes = bytes;
  e.last_used = ++clock_;
  memory_in_use_ += bytes;
  EvictLocked();
  return record;
}

absl::StatusOr<MeshRecord> Registry::GetMeshRecord(const std::string& id) const {
  SyncMesh(id);
  std::lock_guard<std::mutex> lock(mu_);
  auto it = meshes_.find(id);
  if (it == meshes_.end())
    return absl::NotFoundError(absl::StrCat("no mesh with id ", ShownId(id)));
  if (!it->second.damaged.ok()) return it->second.damaged;
  return it->second.record;
}

std::vector<MeshRecord> Registry::ListMeshes() const {
  Rescan();
  std::lock_guard<std::mutex> lock(mu_);
  std::vector<MeshRecord> out;
  for (const auto& [id, e] : meshes_) {
    if (e.damaged.ok()) out.push_back(e.record);
  }
  return out;
}

bool Registry::IsMeshLoaded(const std::string& id) const {
  std::lock_guard<std::mutex> lock(mu_);
  auto it = meshes_.find(id);
  return it != meshes_.end() && it->second.loaded != nullptr;
}

absl::StatusOr<std::vector<std::string>> Registry::DeleteMesh(const std::string& id, bool cascade) {
  std::vector<std::string> basis_ids;
  std::vector<std::shared_ptr<BuildJob>> jobs;
  Rescan();  // shared store: the bases other daemons built on this mesh
  {
    std::lock_guard<std::mutex> lock(mu_);
    auto it = meshes_.find(id);
    if (it == meshes_.end())
      return absl::NotFoundError(absl::StrCat("no mesh with id ", ShownId(id)));
    for (const auto& [bid, e] : bases_) {
      if (e.record.key.mesh_id == id) basis_ids.push_back(bid);
    }
    for (const auto& [bid, job] : builds_) {
      if (job->pending_record().key.mesh_id == id) jobs.push_back(job);
    }
    if (!cascade && (!basis_ids.empty() || !jobs.empty())) {
      return absl::FailedPreconditionError(
          absl::StrCat("mesh ", id, " has ", basis_ids.size(), " basis(es) and ", jobs.size(),
                       " running build(s); delete them first or set cascade"));
    }
    for (const std::string& bid : basis_ids) {
      BasisEntry& e = bases_[bid];
      if (e.loaded != nullptr) ReleaseLocked(e.loaded, e.bytes);
      bases_.erase(bid);
    }
    if (it->second.loaded != nullptr) ReleaseLocked(it->second.loaded, it->second.bytes);
    meshes_.erase(it);
  }
  for (auto& job : jobs) job->Cancel();
  // Files go after the index: a crash in between leaves files that the next start lists again,
  // which is safe (nothing is lost that was not asked to be deleted).
  for (const std::string& bid : basis_ids) RETURN_IF_ERROR(store_->DeleteBasis(bid));
  RETURN_IF_ERROR(store_->DeleteMesh(id));
  return basis_ids;
}

template <typename E>
absl::StatusOr<std::shared_ptr<const typename E::ValueType>> Registry::GetOrLoad(
    std::map<std::string, E>& entries, const std::string& id,
    const std::function<absl::Status()>& missing,
    const std::function<absl::StatusOr<std::shared_ptr<const typename E::ValueType>>()>& load,
    const std::function<int64_t(const typename E::ValueType&)>& bytes) {
  std::shared_ptr<std::mutex> load_mu;
  {
    std::lock_guard<std::mutex> lock(mu_);
    auto it = entries.find(id);
    if (it == entries.end()) return missing();
    if (!it->second.damaged.ok()) return it->second.damaged;
    it->second.last_used = ++clock_;
    if (it->second.loaded != nullptr) {
      // Held before evicting, so that this entry counts as in use. Memory over budget (artifacts
      // that were busy when the last load happened) is trimmed on every hit, not only on loads.
      std::shared_ptr<const typename E::ValueType> handle = it->second.loaded;
      EvictLocked();
      return handle;
    }
    load_mu = it->second.load_mu;
  }
  // One loader per artifact; others wait here and then find it loaded.
  std::lock_guard<std::mutex> load_lock(*load_mu);
  {
    std::lock_guard<std::mutex> lock(mu_);
    auto it = entries.find(id);
    if (it == entries.end()) return missing();
    if (it->second.loaded != nullptr) return it->second.loaded;
  }
  absl::StatusOr<std::shared_ptr<const typename E::ValueType>> loaded = load();
  std::lock_guard<std::mutex> lock(mu_);
  auto it = entries.find(id);
  if (!loaded.ok()) {
    if (it != entries.end() && loaded.status().code() == absl::StatusCode::kDataLoss) {
      it->second.damaged = loaded.status();
    }
    return loaded.status();
  }
  if (it != entries.end()) {
    it->second.loaded = *loaded;
    it->second.bytes = bytes(**loaded);
    it->second.last_used = ++clock_;
    memory_in_use_ += it->second.bytes;
    EvictLocked();
  }
  return loaded;
}

absl::StatusOr<std::shared_ptr<const TriangleMesh>> Registry::GetMesh(const std::string& id) {
  SyncMesh(id);
  return GetOrLoad<MeshEntry>(
      meshes_, id,
      [&] { return absl::NotFoundError(absl::StrCat("no mesh with id ", ShownId(id))); },
      [&]() -> absl::StatusOr<std::shared_ptr<const TriangleMesh>> {
        absl::StatusOr<MeshArrays> arrays = store_->LoadMesh(id);
        absl::StatusOr<TriangleMesh> mesh =
            arrays.ok() ? TriangleMesh::Create(*std::move(arrays)) : arrays.status();
        if (mesh.ok() && MeshIdFor(*mesh) != id) {
          return absl::DataLossError(absl::StrCat("stored mesh ", id, " does not match its id"));
        }
        if (!mesh.ok() && arrays.ok()) {
          // Checksums passed but validation failed: the file was written by something else.
          return absl::DataLossError(
              absl::StrCat("stored mesh ", id, " is invalid: ", mesh.status().message()));
        }
        if (!mesh.ok()) return mesh.status();
        return std::make_shared<const TriangleMesh>(*std::move(mesh));
      },
      [](const TriangleMesh& mesh) { return mesh.MemoryBytes(); });
}

absl::StatusOr<BasisStatus> Registry::GetBasisStatus(const std::string& id) const {
  SyncBasis(id);
  std::lock_guard<std::mutex> lock(mu_);
  if (auto it = bases_.find(id); it != bases_.end()) {
    if (!it->second.damaged.ok()) return it->second.damaged;
    BasisStatus s;
    s.record = it->second.record;
    s.ready = true;
    s.loaded = it->second.loaded != nullptr;
    s.memory_bytes = it->second.bytes;
    return s;
  }
  if (auto it = builds_.find(id); it != builds_.end()) {
    BasisStatus s;
    s.record = it->second->pending_record();
    s.progress = it->second->progress();
    return s;
  }
  return absl::NotFoundError(absl::StrCat("no basis with id ", ShownId(id)));
}

std::vector<BasisStatus> Registry::ListBases(const std::string& mesh_id_filter) const {
  Rescan();
  std::lock_guard<std::mutex> lock(mu_);
  std::vector<BasisStatus> out;
  for (const auto& [id, e] : bases_) {
    if (!e.damaged.ok()) continue;
    if (!mesh_id_filter.empty() && e.record.key.mesh_id != mesh_id_filter) continue;
    BasisStatus s;
    s.record = e.record;
    s.ready = true;
    s.loaded = e.loaded != nullptr;
    s.memory_bytes = e.bytes;
    out.push_back(std::move(s));
  }
  for (const auto& [id, job] : builds_) {
    if (!mesh_id_filter.empty() && job->pending_record().key.mesh_id != mesh_id_filter) continue;
    if (bases_.count(id) > 0) continue;
    BasisStatus s;
    s.record = job->pending_record();
    s.progress = job->progress();
    out.push_back(std::move(s));
  }
  return out;
}

absl::Status Registry::DeleteBasis(const std::string& id) {
  SyncBasis(id);
  {
    std::lock_guard<std::mutex> lock(mu_);
    if (builds_.count(id) > 0) {
      return absl::FailedPreconditionError(
          absl::StrCat("basis ", id, " is being built; cancel the build first (CancelBuild)"));
    }
    auto it = bases_.find(id);
    if (it == bases_.end())
      return absl::NotFoundError(absl::StrCat("no basis with id ", ShownId(id)));
    if (it->second.loaded != nullptr) ReleaseLocked(it->second.loaded, it->second.bytes);
    bases_.erase(it);
  }
  return store_->DeleteBasis(id);
}

absl::StatusOr<std::shared_ptr<const ServedBasis>> Registry::GetBasis(const std::string& id) {
  SyncBasis(id);
  return GetOrLoad<BasisEntry>(
      bases_, id,
      [&] {
        if (builds_.count(id) > 0) {
          return absl::FailedPreconditionError(absl::StrCat("basis ", id, " is still being built"));
        }
        return absl::NotFoundError(absl::StrCat("no basis with id ", ShownId(id)));
      },
      [&] { return LoadBasis(id); }, [](const ServedBasis& basis) { return basis.memory_bytes; });
}

absl::StatusOr<std::shared_ptr<const ServedBasis>> Registry::LoadBasis(const std::string& id) {
  // Straight from the file, the store's checksum taken on the way.
  ASSIGN_OR_RETURN(std::unique_ptr<Store::BasisPayloadReader> reader, store_->OpenBasisPayload(id));
  // The reduced matrices kept beside the basis, if any and sound: a cache, so any problem with
  // it only means computing them (and writing them again).
  std::optional<ReducedMatrices> matrices;
  absl::StatusOr<std::string> reduced = store_->LoadReduced(id, reader->expected_payload_hash());
  if (reduced.ok()) {
    absl::StatusOr<ReducedMatrices> m = DecodeReducedMatrices(*reduced);
    std::string().swap(*reduced);
    if (m.ok()) {
      matrices = *std::move(m);
    } else {
      reduced = m.status();
    }
  }
  if (!reduced.ok() && !absl::IsNotFound(reduced.status())) {
    std::cerr << "fieldspaced: not using the stored reduced matrices of basis " << id << " ("
              << reduced.status().message() << "); computing them" << std::endl;
  }
  // What was decoded, checked against its record and mesh.
  struct Checked {
    BasisRecord record;
    std::shared_ptr<const TriangleMesh> mesh;
    std::shared_ptr<const Basis> basis;
    uint64_t payload_hash = 0;
  };
  const auto checked = [&](absl::StatusOr<LoadedBasis> decoded,
                           Store::BasisPayloadReader& in) -> absl::StatusOr<Checked> {
    if (!decoded.ok()) {
      if (absl::IsDataLoss(decoded.status()) || absl::IsInvalidArgument(decoded.status())) {
        return absl::DataLossError(
            absl::StrCat("stored basis ", id, " is unreadable: ", decoded.status().message()));
      }
      return decoded.status();  // e.g. a read error of the file system
    }
    Checked out;
    absl::StatusOr<uint64_t> payload_hash = in.Finish();
    if (!payload_hash.ok()) {
      return absl::DataLossError(
          absl::StrCat("stored basis ", id, " is unreadable: ", payload_hash.status().message()));
    }
    out.payload_hash = *payload_hash;
    out.record = in.record();
    if (decoded->mesh_id != out.record.key.mesh_id) {
      return absl::DataLossError(absl::StrCat("stored basis ", id, " names mesh ", decoded->mesh_id,
                                              ", its record ", out.record.key.mesh_id));
    }
    out.basis = std::make_shared<const Basis>(std::move(decoded->basis));
    ASSIGN_OR_RETURN(out.mesh, GetMesh(out.record.key.mesh_id));
    const int64_t dofs = int64_t{out.record.key.field.dofs_per_face()} * out.mesh->num_faces();
    if (out.basis->U.rows() != dofs || !(out.basis->type == out.record.key.field)) {
      return absl::DataLossError(
          absl::StrCat("stored basis ", id, " does not match its mesh or field type"));
    }
    return out;
  };
  BuildContext context;
  context.threads = options_.build_threads;
  if (matrices.has_value()) {
    // U straight into its LiftPlan, the only copy of U a served basis keeps: the load never holds
    // U's CSR arrays beside it (bench/RESULTS.md, Session 24).
    LiftPlan::StreamBuilder rows;
    absl::StatusOr<LoadedBasis> decoded = DecodeBasisFrom(*reader, rows);
    ASSIGN_OR_RETURN(Checked c, checked(std::move(decoded), *reader));
    ASSIGN_OR_RETURN(LiftPlan plan, std::move(rows).Finish());
    absl::StatusOr<std::shared_ptr<const ServedBasis>> served =
        ServeBasis(c.record, std::move(c.mesh), std::move(c.basis), nullptr, context,
                   std::move(matrices), std::move(plan));
    // Matrices that do not fit the basis after all (ServeBasis said why): U is read again whole
    // below for the product pass.
    if (served.ok() || absl::IsCancelled(served.status())) return served;
    ASSIGN_OR_RETURN(reader, store_->OpenBasisPayload(id));
  }
  absl::StatusOr<LoadedBasis> decoded = DecodeBasisFrom(*reader);
  ASSIGN_OR_RETURN(Checked c, checked(std::move(decoded), *reader));
  reader.reset();
  ASSIGN_OR_RETURN(
      std::shared_ptr<const ServedBasis> served,
      ServeBasis(c.record, std::move(c.mesh), std::move(c.basis), nullptr, context, std::nullopt));
  SaveReducedMatrices(id, c.payload_hash, *served->system);
  return served;
}

void Registry::SaveReducedMatrices(const std::string& id, uint64_t basis_payload_hash,
                                   const ReducedSystem& system) const {
  const absl::Status saved =
      store_->SaveReduced(id, basis_payload_hash, EncodeReducedMatrices(system));
  if (!saved.ok()) {
    std::cerr << "fieldspaced: could not store the reduced matrices of basis " << id << " ("
              << saved.message() << "); they are computed again when it is next loaded"
              << std::endl;
  }
}

}  // namespace fieldspace::server
