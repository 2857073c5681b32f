// --shared-store: several daemons (here: registries and servers in one process) on one store
// directory. Lookups on a miss, listings and deletes seen by all, one build per basis across the
// daemons (a lease with a heartbeat, taken over when its holder stops renewing it), and temporary
// files of other daemons' saves left alone.

#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <memory>
#include <mutex>
#include <string>
#include <thread>

#include "absl/strings/str_cat.h"
#include "client/field_client.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "server/build_job.h"
#include "server/compute_pool.h"
#include "server/field_server.h"
#include "server/lease.h"
#include "server/registry.h"
#include "server/store.h"
#include "server/store_lock.h"
#include "tests/testing/server_fixture.h"
#include "tests/testing/test_meshes.h"

namespace fieldspace::server {
namespace {

namespace fs = std::filesystem;
namespace v1 = ::fieldspace::v1;
using ::testing::HasSubstr;
using namespace std::chrono_literals;

// One daemon's state on the shared store (the pool outlives the registry).
struct Daemon {
  std::unique_ptr<Store> store;
  std::unique_ptr<ComputePool> pool;
  std::unique_ptr<Registry> registry;
};

MeshArrays ArraysOf(const TriangleMesh& mesh) {
  MeshArrays arrays;
  arrays.vertices = mesh.vertices();
  arrays.faces = mesh.faces();
  return arrays;
}

BuildRequest VectorBasis(const std::string& mesh_id, int32_t d) {
  BuildRequest request;
  request.key.mesh_id = mesh_id;
  request.key.field = FieldType::Vector();
  request.key.dimension = d;
  return request;
}

// Waits for the job to finish (at most 120 s); its final progress.
BuildJob::Progress Wait(const std::shared_ptr<BuildJob>& job) {
  const auto deadline = std::chrono::steady_clock::now() + 120s;
  while (!job->progress().finished && std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(5ms);
  }
  return job->progress();
}

// The holder a build job waits for, recorded from construction on. A job's listeners hear only
// changes made after they subscribe, so the state at subscription is read too. The listener owns
// what it writes: the job may still be calling it when the recorder goes.
class WaitingRecorder {
 public:
  explicit WaitingRecorder(std::shared_ptr<BuildJob> job) : job_(std::move(job)) {
    token_ = job_->Subscribe(
        [state = state_, job = std::weak_ptr<BuildJob>(job_)] { Note(job.lock(), *state); });
    Note(job_, *state_);
  }
  ~WaitingRecorder() { job_->Unsubscribe(token_); }
  std::string waiting_for() {
    std::lock_guard<std::mutex> lock(state_->mu);
    return state_->waiting_for;
  }

 private:
  struct State {
    std::mutex mu;
    std::string waiting_for;
  };
  static void Note(const std::shared_ptr<BuildJob>& job, State& state) {
    if (job == nullptr) return;
    BuildJob::Progress p = job->progress();
    std::lock_guard<std::mutex> lock(state.mu);
    if (!p.waiting_for.empty()) state.waiting_for = p.waiting_for;
  }

  std::shared_ptr<BuildJob> job_;
  std::shared_ptr<State> state_ = std::make_shared<State>();
  uint64_t token_ = 0;
};

class SharedStoreTest : public ::testing::Test {
 protected:
  void SetUp() override { store_dir_ = (root_ / "store").string(); }

  Daemon Open(const std::string& daemon_id, int32_t save_pause_ms = 0) {
    Daemon d;
    StoreOptions store_options;
    store_options.shared = true;
    store_options.save_pause_ms = save_pause_ms;
    absl::StatusOr<std::unique_ptr<Store>> store = Store::Open(store_dir_, store_options);
    EXPECT_TRUE(store.ok()) << store.status();
    if (!store.ok()) return d;
    d.store = *std::move(store);
    d.pool = std::make_unique<ComputePool>(ComputePool::Options{1, 1});
    RegistryOptions options;
    options.shared_store = true;
    options.daemon_id = daemon_id;
    options.build_threads = 1;
    options.lease.heartbeat = 100ms;
    options.lease.stale_after = 400ms;
    options.lease_poll = 20ms;
    absl::StatusOr<std::unique_ptr<Registry>> registry =
        Registry::Create(d.store.get(), d.pool.get(), options);
    EXPECT_TRUE(registry.ok()) << registry.status();
    if (registry.ok()) d.registry = *std::move(registry);
    return d;
  }

  ::fieldspace::testing::TempDir root_{"shared_store"};
  std::string store_dir_;
};

TEST_F(SharedStoreTest, AMeshUploadedByOneDaemonIsFoundByTheOtherOnFirstRequest) {
  Daemon a = Open("a");
  Daemon b = Open("b");
  ASSERT_NE(a.registry, nullptr);
  ASSERT_NE(b.registry, nullptr);
  absl::StatusOr<MeshRecord> added = a.registry->AddMesh(ArraysOf(testing::Icosphere(1)), "ico", 0);
  ASSERT_TRUE(added.ok()) << added.status();
  absl::StatusOr<MeshRecord> seen = b.registry->GetMeshRecord(added->id);
  ASSERT_TRUE(seen.ok()) << seen.status();
  EXPECT_EQ(seen->name, "ico");
  EXPECT_EQ(seen->num_faces, added->num_faces);
  absl::StatusOr<std::shared_ptr<const TriangleMesh>> mesh = b.registry->GetMesh(added->id);
  ASSERT_TRUE(mesh.ok()) << mesh.status();
  EXPECT_EQ((*mesh)->num_faces(), added->num_faces);
  // Listings are the store's content.
  Daemon c = Open("c");
  absl::StatusOr<MeshRecord> other =
      c.registry->AddMesh(ArraysOf(testing::Icosphere(2)), "ico2", 0);
  ASSERT_TRUE(other.ok()) << other.status();
  EXPECT_EQ(a.registry->ListMeshes().size(), 2u);
  EXPECT_EQ(b.registry->ListMeshes().size(), 2u);
}

TEST_F(SharedStoreTest, DeletesAreSeenByAllDaemons) {
  Daemon a = Open("a");
  Daemon b = Open("b");
  ASSERT_NE(a.registry, nullptr);
  ASSERT_NE(b.registry, nullptr);
  absl::StatusOr<MeshRecord> added = a.registry->AddMesh(ArraysOf(testing::Icosphere(2)), "ico", 0);
  ASSERT_TRUE(added.ok()) << added.status();
  absl::StatusOr<Registry::StartedBuild> started =
      a.registry->StartBuild(VectorBasis(added->id, 8));
  ASSERT_TRUE(started.ok()) << started.status();
  ASSERT_NE(started->job, nullptr);
  BuildJob::Progress done = Wait(started->job);
  ASSERT_TRUE(done.status.ok()) << done.status;
  const std::string basis_id = started->job->basis_id();
  // b loads both (they stay in its memory).
  ASSERT_TRUE(b.registry->GetBasis(basis_id).ok());
  ASSERT_EQ(b.registry->ListBases("").size(), 1u);

  // A cascade delete on b removes what a built; a sees it on the next request and listing.
  absl::StatusOr<std::vector<std::string>> deleted = b.registry->DeleteMesh(added->id, true);
  ASSERT_TRUE(deleted.ok()) << deleted.status();
  EXPECT_THAT(*deleted, ::testing::ElementsAre(basis_id));
  EXPECT_EQ(a.registry->GetBasis(basis_id).status().code(), absl::StatusCode::kNotFound);
  EXPECT_EQ(a.registry->GetMeshRecord(added->id).status().code(), absl::StatusCode::kNotFound);
  EXPECT_TRUE(a.registry->ListMeshes().empty());
  EXPECT_TRUE(a.registry->ListBases("").empty());
  EXPECT_EQ(a.registry->memory_in_use(), 0);
}

TEST_F(SharedStoreTest, ABasisIsBuiltOnceAcrossDaemonsAndTheOthersWaitForIt) {
  // a's save pauses, so b surely asks while a holds the lease.
  Daemon a = Open("a", /*save_pause_ms=*/600);
  Daemon b = Open("b");
  ASSERT_NE(a.registry, nullptr);
  ASSERT_NE(b.registry, nullptr);
  absl::StatusOr<MeshRecord> mesh = a.registry->AddMesh(ArraysOf(testing::Icosphere(3)), "ico", 0);
  ASSERT_TRUE(mesh.ok()) << mesh.status();
  absl::StatusOr<Registry::StartedBuild> first = a.registry->StartBuild(VectorBasis(mesh->id, 24));
  ASSERT_TRUE(first.ok()) << first.status();
  ASSERT_NE(first->job, nullptr);
  // Wait until a holds the lease.
  const std::string lease_dir = a.store->LeaseDir();
  const auto deadline = std::chrono::steady_clock::now() + 30s;
  while (!Lease::Read(lease_dir, first->job->basis_id()).ok() &&
         std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(1ms);
  }
  absl::StatusOr<Lease::State> lease = Lease::Read(lease_dir, first->job->basis_id());
  ASSERT_TRUE(lease.ok()) << lease.status();
  EXPECT_EQ(lease->owner.daemon_id, "a");
  EXPECT_EQ(lease->owner.pid, ::getpid());

  absl::StatusOr<Registry::StartedBuild> second = b.registry->StartBuild(VectorBasis(mesh->id, 24));
  ASSERT_TRUE(second.ok()) << second.status();
  ASSERT_NE(second->job, nullptr) << "b found the basis before a saved it";
  EXPECT_EQ(second->job->basis_id(), first->job->basis_id());
  WaitingRecorder waiting(second->job);
  BuildJob::Progress a_done = Wait(first->job);
  BuildJob::Progress b_done = Wait(second->job);
  ASSERT_TRUE(a_done.status.ok()) << a_done.status;
  ASSERT_TRUE(b_done.status.ok()) << b_done.status;
  EXPECT_EQ(b_done.stage, BuildStage::kDone);
  EXPECT_EQ(waiting.waiting_for(), a.registry->owner_name());
  EXPECT_EQ(a.registry->builds_run(), 1);
  EXPECT_EQ(b.registry->builds_run(), 0);
  EXPECT_EQ(b_done.record.created_unix_ms, a_done.record.created_unix_ms);  // the same file
  EXPECT_FALSE(Lease::Read(lease_dir, first->job->basis_id()).ok()) << "the lease was not released";
  absl::StatusOr<std::shared_ptr<const ServedBasis>> loaded =
      b.registry->GetBasis(first->job->basis_id());
  ASSERT_TRUE(loaded.ok()) << loaded.status();
  EXPECT_EQ((*loaded)->record.columns, 24);
  // Asked again, both find it stored.
  absl::StatusOr<Registry::StartedBuild> again = b.registry->StartBuild(VectorBasis(mesh->id, 24));
  ASSERT_TRUE(again.ok());
  EXPECT_TRUE(again->existing.has_value());
}

TEST_F(SharedStoreTest, AStaleLeaseOfADeadDaemonIsTakenOver) {
  Daemon b = Open("b");
  ASSERT_NE(b.registry, nullptr);
  absl::StatusOr<MeshRecord> mesh = b.registry->AddMesh(ArraysOf(testing::Icosphere(2)), "ico", 0);
  ASSERT_TRUE(mesh.ok()) << mesh.status();
  const std::string basis_id = [&] {
    BasisKey key = VectorBasis(mesh->id, 8).key;
    key.fields_per_region = 2;
    return Registry::BasisIdFor(key);
  }();
  // A lease left by a daemon that died (no heartbeat any more).
  {
    std::ofstream out(fs::path(b.store->LeaseDir()) / (basis_id + ".lease"));
    out << "deadhost 4242 gone\n";
  }
  const auto start = std::chrono::steady_clock::now();
  absl::StatusOr<Registry::StartedBuild> started = b.registry->StartBuild(VectorBasis(mesh->id, 8));
  ASSERT_TRUE(started.ok()) << started.status();
  ASSERT_NE(started->job, nullptr);
  ASSERT_EQ(started->job->basis_id(), basis_id);
  WaitingRecorder waiting(started->job);
  BuildJob::Progress done = Wait(started->job);
  ASSERT_TRUE(done.status.ok()) << done.status;
  EXPECT_GE(std::chrono::steady_clock::now() - start, 400ms) << "took over before stale_after";
  EXPECT_EQ(b.registry->builds_run(), 1);
  EXPECT_EQ(waiting.waiting_for(), "deadhost/4242/gone");
}

TEST_F(SharedStoreTest, ALiveLeaseIsRenewedAndNotBroken) {
  ASSERT_TRUE(fs::create_directories(root_ / "leases"));
  const std::string dir = (root_ / "leases").string();
  Lease::Options options;
  options.heartbeat = 50ms;
  LeaseOwner me = LocalLeaseOwner("me");
  LeaseOwner holder;
  absl::StatusOr<std::unique_ptr<Lease>> lease = Lease::TryAcquire(dir, "x", me, options, &holder);
  ASSERT_TRUE(lease.ok()) << lease.status();
  ASSERT_NE(*lease, nullptr);
  absl::StatusOr<Lease::State> before = Lease::Read(dir, "x");
  ASSERT_TRUE(before.ok());
  std::this_thread::sleep_for(200ms);
  absl::StatusOr<Lease::State> after = Lease::Read(dir, "x");
  ASSERT_TRUE(after.ok());
  EXPECT_GT(after->mtime_ns, before->mtime_ns) << "no heartbeat";
  // A second owner is refused and told who holds it.
  absl::StatusOr<std::unique_ptr<Lease>> other =
      Lease::TryAcquire(dir, "x", LocalLeaseOwner("other"), options, &holder);
  ASSERT_TRUE(other.ok()) << other.status();
  EXPECT_EQ(*other, nullptr);
  EXPECT_EQ(holder.daemon_id, "me");
  // Breaking it with a state that is no longer current (it was renewed) leaves it in place.
  ASSERT_TRUE(Lease::BreakStale(dir, "x", before->owner, before->mtime_ns).ok());
  EXPECT_TRUE(Lease::Read(dir, "x").ok());
  EXPECT_TRUE((*lease)->held());
  lease->reset();
  EXPECT_EQ(Lease::Read(dir, "x").status().code(), absl::StatusCode::kNotFound);
  // Free again; no temporary files left behind.
  absl::StatusOr<std::unique_ptr<Lease>> again =
      Lease::TryAcquire(dir, "x", LocalLeaseOwner("other"), options, &holder);
  ASSERT_TRUE(again.ok());
  EXPECT_NE(*again, nullptr);
  again->reset();
  EXPECT_TRUE(fs::is_empty(dir));
}

TEST_F(SharedStoreTest, OpeningASharedStoreLeavesOtherDaemonsSavesInProgressAlone) {
  StoreOptions shared;
  shared.shared = true;
  ASSERT_TRUE(Store::Open(store_dir_, shared).ok());
  // What a save in progress looks like (file_util's temporary names).
  const fs::path fresh = fs::path(store_dir_) / "bases" / ".b-0123456789abcdef.fsbasis.tmp-x";
  { std::ofstream(fresh) << "partial"; }
  ASSERT_TRUE(Store::Open(store_dir_, shared).ok());
  EXPECT_TRUE(fs::exists(fresh)) << "a shared store removed another daemon's save in progress";
  shared.stale_temp_age = std::chrono::seconds(0);
  std::this_thread::sleep_for(10ms);
  ASSERT_TRUE(Store::Open(store_dir_, shared).ok());
  EXPECT_FALSE(fs::exists(fresh)) << "an old temporary file was kept";
}

TEST_F(SharedStoreTest, SharedServersStartOnOneStoreAndAnExclusiveOneIsRefused) {
  FieldServerOptions options;
  options.listen = "127.0.0.1:0";
  options.store_dir = store_dir_;
  options.threads = 1;
  options.store_lock = StoreLockMode::kShared;
  options.daemon_id = "one";
  auto one = FieldServer::Start(options);
  ASSERT_TRUE(one.ok()) << one.status();
  options.daemon_id = "two";
  auto two = FieldServer::Start(options);
  ASSERT_TRUE(two.ok()) << two.status();
  EXPECT_TRUE(fs::is_directory(fs::path(store_dir_) / "leases"));
  // Still one daemon per port.
  options.listen = (*one)->address();
  auto same_port = FieldServer::Start(options);
  ASSERT_FALSE(same_port.ok());
  EXPECT_EQ(same_port.status().code(), absl::StatusCode::kUnavailable);
  options.listen = "127.0.0.1:0";
  options.store_lock = StoreLockMode::kExclusive;
  options.daemon_id.clear();
  auto exclusive = FieldServer::Start(options);
  ASSERT_FALSE(exclusive.ok());
  EXPECT_EQ(exclusive.status().code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_THAT(exclusive.status().message(), HasSubstr("shared mode"));
}

// Over the wire: a BuildBasis stream on the daemon that waits reports QUEUED with waiting_for (the
// holder of the lease) and then DONE with the basis the other daemon stored.
TEST_F(SharedStoreTest, AWaitingDaemonStreamsQueuedWaitingForTheHolderThenDone) {
  FieldServerOptions options;
  options.listen = "127.0.0.1:0";
  options.store_dir = store_dir_;
  options.threads = 1;
  options.store_lock = StoreLockMode::kShared;
  options.daemon_id = "builder";
  options.debug_save_pause_ms = 800;  // holds the lease long enough
  auto builder = FieldServer::Start(options);
  ASSERT_TRUE(builder.ok()) << builder.status();
  options.daemon_id = "waiter";
  options.debug_save_pause_ms = 0;
  auto waiter = FieldServer::Start(options);
  ASSERT_TRUE(waiter.ok()) << waiter.status();
  auto client_of = [](const FieldServer& server) {
    client::FieldClientOptions o;
    o.address = server.address();
    return client::FieldClient::Create(o);
  };
  auto a = client_of(**builder);
  auto b = client_of(**waiter);
  ASSERT_TRUE(a.ok() && b.ok());
  absl::StatusOr<v1::MeshInfo> mesh =
      (*a)->UploadMeshArrays(ArraysOf(testing::Icosphere(3)), "ico");
  ASSERT_TRUE(mesh.ok()) << mesh.status();
  v1::BuildBasisRequest request;
  request.set_mesh_id(mesh->id());
  request.mutable_field()->set_kind(v1::FIELD_KIND_VECTOR);
  request.set_dimension(24);

  absl::StatusOr<v1::BasisInfo> built;
  std::thread first([&] { built = (*a)->BuildBasis(request); });
  // The lease itself (BASIS.lease), not the temporary file it is linked from: before the link,
  // the waiter could still take the lease and build itself.
  const fs::path lease_dir = fs::path(store_dir_) / "leases";
  const auto leased = [&] {
    std::error_code ec;
    for (const auto& entry : fs::directory_iterator(lease_dir, ec)) {
      const std::string name = entry.path().filename().string();
      if (name[0] != '.' && entry.path().extension() == ".lease") return true;
    }
    return false;
  };
  const auto deadline = std::chrono::steady_clock::now() + 30s;
  while (!leased() && std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(1ms);
  }
  ASSERT_TRUE(leased()) << "the builder never took the lease";
  std::vector<v1::BuildBasisProgress> seen;
  absl::StatusOr<v1::BasisInfo> waited =
      (*b)->BuildBasis(request, [&](const v1::BuildBasisProgress& p) { seen.push_back(p); });
  first.join();
  ASSERT_TRUE(built.ok()) << built.status();
  ASSERT_TRUE(waited.ok()) << waited.status();
  EXPECT_EQ(waited->id(), built->id());
  EXPECT_EQ(waited->created_unix_ms(), built->created_unix_ms());
  ASSERT_GE(seen.size(), 2u);
  // QUEUED at once, then QUEUED naming the daemon that builds it, then DONE.
  EXPECT_EQ(seen.front().phase(), v1::BUILD_PHASE_QUEUED);
  const auto waiting = std::find_if(seen.begin(), seen.end(),
                                    [](const auto& p) { return !p.waiting_for().empty(); });
  ASSERT_NE(waiting, seen.end()) << "no message named the replica it waited for";
  EXPECT_EQ(waiting->phase(), v1::BUILD_PHASE_QUEUED);
  EXPECT_THAT(waiting->waiting_for(), ::testing::EndsWith("/builder"));
  EXPECT_EQ(seen.back().phase(), v1::BUILD_PHASE_DONE);
  EXPECT_TRUE(seen.back().waiting_for().empty());
  EXPECT_TRUE(seen.back().has_basis());
  EXPECT_EQ((*waiter)->registry()->builds_run(), 0);
  EXPECT_EQ((*builder)->registry()->builds_run(), 1);
}

}  // namespace
}  // namespace fieldspace::server
