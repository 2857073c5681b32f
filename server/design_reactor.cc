// Design (bidirectional streaming): one DesignEditor per stream. Strictly sequential: read an
// edit, apply it on the pool, write the answer (an update, or the edit's error), read the next.

#include <atomic>
#include <cstdint>
#include <mutex>
#include <string>

#include "server/design_editor.h"
#include "server/reactors.h"
#include "server/rpc_util.h"

namespace fieldspace::server {
namespace {

// How a draining server ends a session: UNAVAILABLE with a retry hint (message and the trailing
// metadata `x-fieldspace-retry: reopen`), so that clients reopen it, through a router on another
// replica, and replay their edits (the client library does; docs/scale-out.md).
constexpr char kRetryHintKey[] = "x-fieldspace-retry";
absl::Status DrainedSession() {
  return absl::UnavailableError(
      "server is shutting down: reopen the design session (on another replica) and replay its "
      "constraints and weights");
}

DesignEditorOptions EditorOptions(FieldService* service) {
  DesignEditorOptions options;
  options.verify_interval = service->options().design_verify_interval;
  options.max_message_bytes = service->options().max_message_bytes;
  options.admit_work = [registry = service->registry()](int64_t bytes, absl::string_view what) {
    return registry->AdmitWork(bytes, what);
  };
  return options;
}

// Design: one session per stream. Strictly sequential: read an edit, process it on the pool,
// write the answer, read the next one. Raw: a message that does not parse ends the session with
// INVALID_ARGUMENT (a typed stream would see it as the client closing the session).
class DesignReactor final : public grpc::ServerBidiReactor<grpc::ByteBuffer, grpc::ByteBuffer>,
                            public DrainableStream {
 public:
  DesignReactor(FieldService* service, grpc::CallbackServerContext* context)
      : service_(service),
        context_(context),
        editor_([registry =
                     service->registry()](const std::string& id) { return registry->GetBasis(id); },
                EditorOptions(service)) {
    if (absl::Status admit = service->Admit(); !admit.ok()) {
      finish_sent_ = true;
      FinishWith(this, (admit));
      return;
    }
    if (!service->AcquireDesignSession()) {
      finish_sent_ = true;
      FinishWith(this, absl::ResourceExhaustedError(absl::StrCat(
                           "the server has its maximum of ", service->options().max_design_sessions,
                           " open design sessions (--max-design-sessions); close one or retry "
                           "later")));
      return;
    }
    holds_session_ = true;
    service_->RegisterStream(this);
    registered_ = true;
    reading_ = true;
    StartRead(&in_);
  }

  void OnReadDone(bool ok) override {
    received_ = Clock::now();
    enum { kWork, kFinish, kNothing } next;
    {
      std::lock_guard<std::mutex> lock(mu_);
      reading_ = false;
      if (finish_sent_) {
        // Drain() finished the stream while this read was in flight: the message (or the end of
        // the client's side) is dropped, and no work may be queued for a finishing reactor. (A
        // failed read used to fall through to Work() here and write to a finished call.)
        next = kNothing;
      } else if (!ok) {
        // The client closed its side (or went away): end the session.
        finish_sent_ = true;
        next = kFinish;
      } else {
        working_ = true;
        next = kWork;
      }
    }
    if (next == kNothing) return;
    if (next == kFinish) {
      FinishWith(this, absl::OkStatus());
      return;
    }
    // The queued task holds a reference: OnDone (and deletion) cannot overtake it.
    AddRef();
    const bool submitted = service_->pool()->Submit(ComputePool::Lane::kInteractive, [this] {
      Work();
      DropRef();
    });
    if (!submitted) {
      {
        std::lock_guard<std::mutex> lock(mu_);
        working_ = false;
        finish_sent_ = true;
      }
      FinishWith(this, (ShuttingDown()));
      DropRef();
    }
  }

  void OnWriteDone(bool ok) override {
    enum { kRead, kFinishCancelled, kFinishDrain, kNothing } next = kNothing;
    {
      std::lock_guard<std::mutex> lock(mu_);
      writing_ = false;
      if (finish_sent_) {
        next = kNothing;
      } else if (!ok) {
        next = kFinishCancelled;
        finish_sent_ = true;
      } else if (drain_requested_) {
        next = kFinishDrain;
        finish_sent_ = true;
      } else {
        next = kRead;
        reading_ = true;
      }
    }
    switch (next) {
      case kRead:
        StartRead(&in_);
        break;
      case kFinishCancelled:
        FinishWith(this, (absl::CancelledError("the client went away")));
        break;
      case kFinishDrain:
        FinishDrained();
        break;
      case kNothing:
        break;
    }
  }

  void OnCancel() override { cancelled_.store(true); }

  void OnDone() override {
    if (holds_session_) service_->ReleaseDesignSession();
    if (registered_) service_->UnregisterStream(this);
    DropRef();
  }

  void Drain() override {
    bool finish = false;
    {
      std::lock_guard<std::mutex> lock(mu_);
      drain_requested_ = true;
      if (!working_ && !writing_ && !finish_sent_) {
        finish = true;
        finish_sent_ = true;
      }
    }
    if (finish) FinishDrained();
  }

 private:
  void FinishDrained() {
    context_->AddTrailingMetadata(kRetryHintKey, "reopen");
    FinishWith(this, DrainedSession());
  }

  void Work() {
    update_.Clear();
    // Whether the editor answered (an exception inside it leaves the session in doubt: the
    // stream ends).
    bool applied = false;
    absl::Status status =
        cancelled_.load() ? absl::CancelledError("cancelled") : Guarded([this, &applied] {
          RETURN_IF_ERROR(ParseStreamMessage(&in_, "Design", ++messages_, &request_));
          absl::Status s = editor_.Apply(request_, &update_);
          applied = true;
          return s;
        });
    if (applied && !status.ok() && !editor_.EndsSession(status)) {
      // A refused edit costs that edit, not the session: answer it and read the next one.
      DesignEditor::ErrorUpdate(request_.seq(), status, &update_);
      status = absl::OkStatus();
    }
    if (status.ok()) {
      status = Guarded([this] {
        if (!update_.has_error()) update_.mutable_timings()->set_total_ms(MsSince(received_));
        return SerializeToBuffer(update_, &out_);
      });
    }
    bool finish = false;
    {
      std::lock_guard<std::mutex> lock(mu_);
      working_ = false;
      if (!status.ok()) {
        finish = !finish_sent_;
        finish_sent_ = true;
      } else {
        writing_ = true;
      }
    }
    if (!status.ok()) {
      if (finish) FinishWith(this, (status));
      return;
    }
    StartWrite(&out_);
  }

  FieldService* const service_;
  grpc::CallbackServerContext* const context_;
  bool registered_ = false;
  std::atomic<bool> cancelled_{false};
  std::mutex mu_;
  bool reading_ = false;
  bool working_ = false;
  bool writing_ = false;
  bool finish_sent_ = false;
  bool drain_requested_ = false;
  Clock::time_point received_;
  grpc::ByteBuffer in_;   // the message read, parsed into request_ on the pool
  grpc::ByteBuffer out_;  // update_ serialized
  int64_t messages_ = 0;  // read so far
  v1::DesignRequest request_;
  v1::DesignUpdate update_;
  DesignEditor editor_;
  bool holds_session_ = false;  // one of the service's max_design_sessions places
};

}  // namespace

grpc::ServerBidiReactor<grpc::ByteBuffer, grpc::ByteBuffer>* NewDesignReactor(
    FieldService* service, grpc::CallbackServerContext* context) {
  return new DesignReactor(service, context);
}

}  // namespace fieldspace::server
