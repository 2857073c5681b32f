#ifndef FIELDSPACE_SERVER_RPC_UTIL_H_
#define FIELDSPACE_SERVER_RPC_UTIL_H_

// Building blocks of the RPC layer: how a call ends (FinishWith: the one place a reactor turns
// an absl::Status into the call's grpc::Status), how exceptions from core are contained
// (Guarded), unary calls on the compute pool (RunUnary, RunHandler), server-streaming calls whose
// chunks a handler produces on the pool (ChunkWriter), and the
// parsing and serializing of messages on raw (grpc::ByteBuffer) streams.

#include <atomic>
#include <cstdint>
#include <exception>
#include <memory>
#include <new>
#include <utility>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/strings/str_cat.h"
#include "core/common/status_macros.h"
#include "grpcpp/grpcpp.h"
#include "server/clock.h"
#include "server/compute_pool.h"
#include "server/field_service.h"
#include "server/handlers.h"
#include "server/status_util.h"

namespace fieldspace::server {

namespace v1 = ::fieldspace::v1;

// Ends a call of any reactor type with `status`.
template <typename Reactor>
void FinishWith(Reactor* reactor, const absl::Status& status) {
  reactor->Finish(ToGrpcStatus(status));
}

// Runs `fn` (returning absl::Status) and turns exceptions escaping core code into statuses, so
// that no request can take the server down.
template <typename Fn>
absl::Status Guarded(Fn&& fn) {
  try {
    return fn();
  } catch (const std::bad_alloc&) {
    return absl::ResourceExhaustedError("out of memory");
  } catch (const std::exception& e) {
    return absl::InternalError(absl::StrCat("internal error: ", e.what()));
  }
}

// Raw streams (UploadMesh, Design) parse their messages themselves: on a typed stream gRPC reports
// a message that does not parse exactly like the end of the stream (OnReadDone(false)), so a
// corrupt upload or design session would pass for a complete one. `index` counts the stream's
// messages from 1.
template <typename Message>
absl::Status ParseStreamMessage(grpc::ByteBuffer* buffer, const char* rpc, int64_t index,
                                Message* message) {
  if (!grpc::SerializationTraits<Message>::Deserialize(buffer, message).ok()) {
    return absl::InvalidArgumentError(absl::StrCat("message ", index, " of the ", rpc,
                                                   " stream is not a valid ",
                                                   Message::descriptor()->full_name()));
  }
  return absl::OkStatus();
}

// Replaces `buffer` (which may still hold the previous message) with `message`.
template <typename Message>
absl::Status SerializeToBuffer(const Message& message, grpc::ByteBuffer* buffer) {
  buffer->Clear();  // gRPC's serializer asserts an empty buffer for messages beyond a few bytes
  bool own_buffer;
  const grpc::Status status =
      grpc::SerializationTraits<Message>::Serialize(message, buffer, &own_buffer);
  if (!status.ok()) {
    return absl::InternalError(absl::StrCat("cannot serialize ", Message::descriptor()->full_name(),
                                            ": ", status.error_message()));
  }
  return absl::OkStatus();
}

inline absl::Status ShuttingDown() { return absl::UnavailableError("server is shutting down"); }

// Unary calls: the work runs on the compute pool and finishes the call from there.
class UnaryCall final : public grpc::ServerUnaryReactor {
 public:
  void OnCancel() override { cancelled_.store(true); }
  void OnDone() override { delete this; }
  const std::atomic<bool>* cancelled() const { return &cancelled_; }

 private:
  std::atomic<bool> cancelled_{false};
};

// `work(const std::atomic<bool>* cancel) -> absl::Status` runs on the pool (heavy work) or inline
// on the gRPC thread (bookkeeping that only takes a lock and copies a little).
enum class Where { kPool, kInline };
template <typename Work>
grpc::ServerUnaryReactor* RunUnary(FieldService* service, Where where, Work work) {
  auto* call = new UnaryCall();
  if (absl::Status admit = service->Admit(); !admit.ok()) {
    FinishWith(call, admit);
    return call;
  }
  if (where == Where::kInline) {
    FinishWith(call, Guarded([&] { return work(call->cancelled()); }));
    return call;
  }
  const bool submitted = service->pool()->Submit(
      ComputePool::Lane::kInteractive, [call, work = std::move(work)]() mutable {
        FinishWith(call, call->cancelled()->load()
                             ? absl::CancelledError("the call was cancelled before it started")
                             : Guarded([&] { return work(call->cancelled()); }));
      });
  if (!submitted) FinishWith(call, ShuttingDown());
  return call;
}

// Unary calls whose work is a handler (handlers.h).
template <typename Request, typename Response>
grpc::ServerUnaryReactor* RunHandler(FieldService* service, Where where,
                                     absl::Status (*handler)(const HandlerContext&, const Request&,
                                                             Response*),
                                     const Request* request, Response* response) {
  return RunUnary(service, where,
                  [service, handler, request, response](const std::atomic<bool>* cancel) {
                    return handler(service->Context(cancel), *request, response);
                  });
}

// Server-streaming calls whose chunks a handler's ChunkStream produces on the pool, one write at
// a time: `open` (e.g. OpenLift) runs once, then Next for each chunk.
template <typename Message, typename Request>
class ChunkWriter final : public grpc::ServerWriteReactor<Message> {
 public:
  using OpenFn = absl::StatusOr<std::unique_ptr<ChunkStream<Message>>> (*)(const HandlerContext&,
                                                                           const Request&);
  ChunkWriter(FieldService* service, const Request& request, OpenFn open)
      : service_(service), request_(request), open_(open) {
    if (absl::Status admitted = service->Admit(); !admitted.ok()) {
      FinishWith(this, admitted);
      return;
    }
    Schedule(true);
  }

  void OnWriteDone(bool ok) override {
    if (!ok) {
      FinishWith(this, absl::CancelledError("the client went away"));
      return;
    }
    Schedule(false);
  }
  void OnCancel() override { cancelled_.store(true); }
  void OnDone() override { delete this; }

 private:
  void Schedule(bool first) {
    const bool submitted = service_->pool()->Submit(ComputePool::Lane::kInteractive, [this, first] {
      bool has_chunk = false;
      absl::Status status = Guarded([&]() -> absl::Status {
        if (cancelled_.load()) return absl::CancelledError("cancelled");
        if (first) {
          ASSIGN_OR_RETURN(stream_, open_(service_->Context(&cancelled_), request_));
        }
        chunk_.Clear();
        ASSIGN_OR_RETURN(has_chunk, stream_->Next(&chunk_));
        return absl::OkStatus();
      });
      if (!status.ok() || !has_chunk) {
        FinishWith(this, status);
      } else {
        this->StartWrite(&chunk_);
      }
    });
    if (!submitted) FinishWith(this, ShuttingDown());
  }

  FieldService* const service_;
  const Request request_;
  const OpenFn open_;
  std::unique_ptr<ChunkStream<Message>> stream_;
  std::atomic<bool> cancelled_{false};
  Message chunk_;
};

}  // namespace fieldspace::server

#endif  // FIELDSPACE_SERVER_RPC_UTIL_H_
