// BuildBasis (server streaming): watches a (possibly shared) build job and streams its progress.

#include <cmath>
#include <memory>
#include <mutex>

#include "core/common/status_macros.h"
#include "server/handlers.h"
#include "server/reactors.h"
#include "server/record_convert.h"
#include "server/rpc_util.h"

namespace fieldspace::server {
namespace {

// BuildBasis: watches a (possibly shared) build job and streams its progress. The job lives on
// if this stream goes away.
class BuildWatcher final : public grpc::ServerWriteReactor<v1::BuildBasisProgress>,
                           public RefCounted {
 public:
  BuildWatcher(FieldService* service, const v1::BuildBasisRequest& request)
      : context_(service->Context(nullptr)) {
    absl::Status st = service->Admit();
    absl::StatusOr<Registry::StartedBuild> started =
        st.ok() ? StartBuild(context_, request) : absl::StatusOr<Registry::StartedBuild>(st);
    if (!started.ok()) {
      finished_ = true;
      FinishWith(this, (started.status()));
      return;
    }
    if (started->existing.has_value()) {
      finished_ = true;
      BuiltBasisToProto(context_, *started->existing, &msg_);
      StartWriteAndFinish(&msg_, grpc::WriteOptions(), grpc::Status::OK);
      return;
    }
    job_ = started->job;
    joined_ = started->joined;
    // The job calls the listener from its own thread, possibly after this stream is done: the
    // gate tells it whether the watcher still exists, and a reference keeps it alive meanwhile.
    gate_ = std::make_shared<Gate>();
    gate_->watcher = this;
    token_ = job_->Subscribe([gate = gate_] {
      BuildWatcher* watcher;
      {
        std::lock_guard<std::mutex> lock(gate->mu);
        watcher = gate->watcher;
        if (watcher == nullptr) return;
        watcher->AddRef();
      }
      watcher->Pump();
      watcher->DropRef();
    });
    Pump();  // the current state (often QUEUED) right away, with the basis id
  }

  void OnWriteDone(bool ok) override {
    bool again = false, finish = false;
    {
      std::lock_guard<std::mutex> lock(mu_);
      writing_ = false;
      if (!ok || cancelled_) {
        finish = !finished_;
        finished_ = true;
      } else {
        again = pending_;
        pending_ = false;
      }
    }
    if (finish) FinishWith(this, (absl::CancelledError("the client went away")));
    if (again) Pump();
  }

  void OnCancel() override {
    bool finish = false;
    {
      std::lock_guard<std::mutex> lock(mu_);
      cancelled_ = true;
      // With a write in flight, OnWriteDone finishes instead.
      if (!finished_ && !writing_) {
        finished_ = true;
        finish = true;
      }
    }
    if (finish) FinishWith(this, (absl::CancelledError("cancelled by the client")));
  }

  void OnDone() override {
    if (job_ != nullptr) {
      job_->Unsubscribe(token_);
      std::lock_guard<std::mutex> lock(gate_->mu);
      gate_->watcher = nullptr;
    }
    DropRef();
  }

 private:
  struct Gate {
    std::mutex mu;
    BuildWatcher* watcher = nullptr;
  };

  // Sends the job's current state unless a write is in flight (then once it completes).
  void Pump() {
    BuildJob::Progress progress = job_->progress();
    bool final_ok = false, final_error = false;
    {
      std::lock_guard<std::mutex> lock(mu_);
      if (finished_ || cancelled_) return;
      if (writing_) {
        pending_ = true;
        return;
      }
      const v1::BuildPhase phase = PhaseToProto(progress.stage);
      if (!progress.finished && sent_any_ && phase == msg_.phase() &&
          progress.waiting_for == msg_.waiting_for() &&
          std::abs(progress.fraction - msg_.fraction()) < 0.005) {
        return;
      }
      sent_any_ = true;
      if (progress.finished) {
        finished_ = true;
        final_ok = progress.status.ok();
        final_error = !final_ok;
      }
      BuildProgressToProto(context_, *job_, progress, joined_, &msg_);
      writing_ = !final_error;
    }
    if (final_ok) {
      StartWriteAndFinish(&msg_, grpc::WriteOptions(), grpc::Status::OK);
    } else if (final_error) {
      FinishWith(this, (progress.status));
    } else {
      StartWrite(&msg_);
    }
  }

  const HandlerContext context_;
  std::shared_ptr<BuildJob> job_;
  std::shared_ptr<Gate> gate_;
  uint64_t token_ = 0;
  bool joined_ = false;
  std::mutex mu_;
  bool writing_ = false;
  bool pending_ = false;
  bool finished_ = false;
  bool cancelled_ = false;
  bool sent_any_ = false;
  v1::BuildBasisProgress msg_;
};

}  // namespace

grpc::ServerWriteReactor<v1::BuildBasisProgress>* NewBuildWatcher(
    FieldService* service, const v1::BuildBasisRequest& request) {
  return new BuildWatcher(service, request);
}

}  // namespace fieldspace::server
