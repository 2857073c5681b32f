// UploadMesh (client streaming).

#include <algorithm>
#include <atomic>
#include <cstdint>
#include <cstring>
#include <memory>
#include <mutex>
#include <string>

#include "absl/strings/str_cat.h"
#include "absl/time/time.h"
#include "core/common/status_macros.h"
#include "core/mesh/mesh_io.h"
#include "grpcpp/alarm.h"
#include "server/mesh_intake.h"
#include "server/proto_convert.h"
#include "server/reactors.h"
#include "server/record_convert.h"
#include "server/rpc_util.h"

// gRPC (1.51) hands a message whose compressed flag is set, on a call that declared no message
// encoding, to the application as if it were not compressed, where the gRPC protocol calls it an
// error; only this accessor of the call's last message flags tells. It is exported by libgrpc but
// declared in a header gRPC does not install (src/core/lib/surface/call_test_only.h).
uint32_t grpc_call_test_only_get_message_flags(grpc_call* call);

namespace fieldspace::server {
namespace {

// The flag bit gRPC sets on a received message whose compressed flag was set
// (GRPC_WRITE_INTERNAL_COMPRESS of src/core/lib/transport/transport.h).
constexpr uint32_t kMessageCompressedFlag = 0x80000000u;

// UploadMesh: accumulates in-order chunks, then parses and registers on the pool. Raw: a message
// that does not parse ends the upload with INVALID_ARGUMENT (a typed stream would see it as the
// end of the upload and store what came before). Only a clean half-close after well-formed
// messages commits: a cancelled call, a reset stream or a closed connection stores nothing (End),
// and neither does one whose size was never announced and whose last message was not marked
// `last` (gRPC drops a truncated final message silently, so nothing else tells it from a whole
// upload).
//
// An upload idle for options().upload_idle_timeout (no message, before the client has closed its
// side) is ended with DEADLINE_EXCEEDED: its memory reservation is released and nothing is stored.
// The idle alarm holds a reference (RefCounted): OnDone cancels it, and the reactor is deleted
// once both gRPC and the alarm are done with it. Every end of the call goes through FinishOnce,
// since the alarm may end it while a read is in flight.
class UploadReactor final : public grpc::ServerReadReactor<grpc::ByteBuffer>, public RefCounted {
 public:
  UploadReactor(FieldService* service, grpc::CallbackServerContext* context,
                grpc::ByteBuffer* response)
      : service_(service),
        context_(context),
        response_(response),
        idle_timeout_(service->options().upload_idle_timeout) {
    if (absl::Status admit = service->Admit(); !admit.ok()) {
      FinishOnce(admit);
      return;
    }
    if (idle_timeout_ > Clock::duration::zero()) {
      std::lock_guard<std::mutex> lock(mu_);
      last_message_ = Clock::now();
      ArmIdleAlarmLocked(last_message_ + idle_timeout_);
    }
    StartRead(&message_);
  }

  void OnReadDone(bool ok) override {
    {
      std::lock_guard<std::mutex> lock(mu_);
      if (finished_) return;  // the idle alarm ended the call while this read was in flight
      last_message_ = Clock::now();
      if (!ok) input_done_ = true;
    }
    if (!ok) {
      End();
      return;
    }
    // Guarded: a header whose announced size cannot be reserved (bad_alloc, length_error) used
    // to throw out of this callback, which left the call unfinished and blocked shutdown.
    if (absl::Status st = Guarded([this]() -> absl::Status {
          ++messages_;
          if ((grpc_call_test_only_get_message_flags(context_->c_call()) &
               kMessageCompressedFlag) != 0 &&
              context_->client_metadata().count("grpc-encoding") == 0) {
            return absl::InvalidArgumentError(absl::StrCat(
                "message ", messages_,
                " of the UploadMesh stream is flagged compressed, but the call declared no "
                "grpc-encoding"));
          }
          RETURN_IF_ERROR(ParseStreamMessage(&message_, "UploadMesh", messages_, &request_));
          return Accept();
        });
        !st.ok()) {
      FinishOnce(st);
      return;
    }
    StartRead(&message_);
  }
  void OnCancel() override { cancelled_.store(true); }
  void OnDone() override {
    // Released now, not at deletion (which may wait for the alarm's callback, after the server
    // and its registry are gone).
    grant_ = WorkGrant();
    std::string().swap(data_);
    {
      std::lock_guard<std::mutex> lock(mu_);
      done_ = true;
      if (idle_alarm_ != nullptr) idle_alarm_->Cancel();  // its callback drops its reference
    }
    DropRef();
  }

 private:
  // Ends the call with `status` unless it has been ended already.
  void FinishOnce(const absl::Status& status) {
    {
      std::lock_guard<std::mutex> lock(mu_);
      if (finished_) return;
      finished_ = true;
    }
    FinishWith(this, status);
  }

  void ArmIdleAlarmLocked(Clock::time_point due) {
    AddRef();
    // A new alarm each time: one cannot be set again from its own callback. Replacing the one
    // whose callback runs is safe (gRPC holds the running alarm until its callback returns).
    idle_alarm_ = std::make_unique<grpc::Alarm>();
    idle_alarm_->Set(
        std::chrono::system_clock::now() +
            std::chrono::duration_cast<std::chrono::system_clock::duration>(due - Clock::now()),
        [this](bool fired) { OnIdleAlarm(fired); });
  }

  void OnIdleAlarm(bool fired) {
    bool expired = false;
    {
      std::lock_guard<std::mutex> lock(mu_);
      if (fired && !done_ && !finished_ && !input_done_) {
        const Clock::time_point due = last_message_ + idle_timeout_;
        if (Clock::now() >= due) {
          expired = true;
        } else {
          ArmIdleAlarmLocked(due);
        }
      }
    }
    if (expired) {
      FinishOnce(absl::DeadlineExceededError(absl::StrCat(
          "no UploadMesh message for ", absl::FormatDuration(absl::FromChrono(idle_timeout_)),
          " (the server's --upload-idle-seconds): the upload was abandoned and nothing stored")));
    }
    DropRef();
  }

 private:
  absl::Status Accept() {
    const int64_t limit = service_->options().max_upload_bytes;
    if (!have_header_) {
      if (!request_.has_header()) {
        return absl::InvalidArgumentError("the first UploadMeshRequest must carry the header");
      }
      header_ = request_.header();
      have_header_ = true;
      if (header_.format() == v1::MESH_FORMAT_UNSPECIFIED) {
        absl::StatusOr<MeshFormat> f = MeshFormatFromPath(header_.name());
        if (!f.ok()) {
          return absl::InvalidArgumentError(
              absl::StrCat("header.format is unspecified and the name '", header_.name(),
                           "' has no .obj, .off or .ply extension"));
        }
        header_.set_format(*f == MeshFormat::kObj   ? v1::MESH_FORMAT_OBJ
                           : *f == MeshFormat::kOff ? v1::MESH_FORMAT_OFF
                                                    : v1::MESH_FORMAT_PLY);
      }
      if (header_.format() < v1::MESH_FORMAT_OBJ || header_.format() > v1::MESH_FORMAT_RAW) {
        return absl::InvalidArgumentError(
            absl::StrCat("unknown mesh format ", static_cast<int>(header_.format())));
      }
      if (header_.format() == v1::MESH_FORMAT_RAW) {
        constexpr int64_t kMaxElements = int64_t{1} << 27;
        if (header_.num_vertices() <= 0 || header_.num_faces() <= 0 ||
            header_.num_vertices() > kMaxElements || header_.num_faces() > kMaxElements) {
          return absl::InvalidArgumentError(
              absl::StrCat("raw upload needs 0 < num_vertices, num_faces <= ", kMaxElements,
                           "; got ", header_.num_vertices(), " and ", header_.num_faces()));
        }
        const int64_t expected = 24 * header_.num_vertices() + 12 * header_.num_faces();
        if (expected > limit) {
          return absl::ResourceExhaustedError(absl::StrCat(
              "raw mesh of ", expected, " bytes exceeds the upload limit of ", limit, " bytes"));
        }
      }
      if (header_.total_bytes() > static_cast<uint64_t>(limit)) {
        return absl::ResourceExhaustedError(absl::StrCat(
            "upload of ", header_.total_bytes(), " bytes exceeds the limit of ", limit, " bytes"));
      }
      if (header_.format() == v1::MESH_FORMAT_RAW) {
        RETURN_IF_ERROR(Admit(24 * header_.num_vertices() + 12 * header_.num_faces()));
      } else {
        RETURN_IF_ERROR(Admit(static_cast<int64_t>(header_.total_bytes())));
      }
      // Reserve up front only what is cheap to hold; larger uploads grow as chunks arrive.
      constexpr uint64_t kMaxReserve = uint64_t{256} << 20;
      if (header_.total_bytes() > 0) data_.reserve(std::min(header_.total_bytes(), kMaxReserve));
    } else if (request_.has_header()) {
      return absl::InvalidArgumentError("only the first UploadMeshRequest may carry a header");
    } else if (saw_last_) {
      return absl::InvalidArgumentError(absl::StrCat(
          "message ", messages_, " of the UploadMesh stream follows the one marked last"));
    }
    saw_last_ = request_.last();
    if (request_.offset() != data_.size()) {
      return absl::InvalidArgumentError(
          absl::StrCat("out-of-order chunk: offset ", request_.offset(), ", expected ",
                       data_.size(), " (chunks must arrive in order, without gaps)"));
    }
    if (static_cast<int64_t>(data_.size() + request_.data().size()) > limit) {
      return absl::ResourceExhaustedError(
          absl::StrCat("upload exceeds the limit of ", limit, " bytes"));
    }
    RETURN_IF_ERROR(Admit(static_cast<int64_t>(data_.size() + request_.data().size())));
    data_.append(request_.data());
    request_.Clear();
    return absl::OkStatus();
  }

  // Admits the memory of an upload of `bytes` against the memory budget: twice its size (parsing
  // holds the bytes and the arrays they become). Beyond the size the registry always admits, in
  // steps of kAdmitStep as unannounced uploads grow (each step is checked).
  absl::Status Admit(int64_t bytes) {
    constexpr int64_t kAdmitStep = int64_t{16} << 20;
    if (2 * bytes <= grant_.bytes()) return absl::OkStatus();
    const int64_t want = 2 * bytes <= Registry::kSmallWorkBytes
                             ? 2 * bytes
                             : (2 * bytes + kAdmitStep - 1) / kAdmitStep * kAdmitStep;
    ASSIGN_OR_RETURN(WorkGrant more,
                     service_->registry()->AdmitWork(want - grant_.bytes(), "this upload"));
    grant_.Merge(std::move(more));
    return absl::OkStatus();
  }

  void End() {
    if (!have_header_) {
      FinishOnce(absl::InvalidArgumentError("empty upload: no header was sent"));
      return;
    }
    if (header_.total_bytes() == 0 && header_.format() != v1::MESH_FORMAT_RAW && !saw_last_) {
      FinishOnce(absl::InvalidArgumentError(absl::StrCat(
          "the upload ended after ", data_.size(),
          " bytes without a message marked last, and its header announced no total_bytes: an "
          "upload cut short looks the same, so nothing was stored (announce total_bytes or mark "
          "the last message)")));
      return;
    }
    if (header_.total_bytes() > 0 && header_.total_bytes() != data_.size()) {
      FinishOnce(absl::InvalidArgumentError(absl::StrCat("upload ended after ", data_.size(),
                                                         " bytes; the header announced ",
                                                         header_.total_bytes())));
      return;
    }
    // A failed read is also what a reset stream, a closed connection or a message gRPC refused
    // (say, a compressed one on a call without compression) look like: only a stream that is
    // still open towards the client was half-closed cleanly. Sending the response headers tells:
    // the transport fails them on a stream it has closed (it closes the stream in the same step
    // that fails the read, so this answer is not racy).
    StartSendInitialMetadata();
  }

  void OnSendInitialMetadataDone(bool ok) override {
    if (!ok || cancelled_.load()) {
      FinishOnce(Aborted());
      return;
    }
    const bool submitted = service_->pool()->Submit(ComputePool::Lane::kInteractive, [this] {
      FinishOnce(Guarded([this] { return Register(); }));
    });
    if (!submitted) FinishOnce(ShuttingDown());
  }

  static absl::Status Aborted() {
    return absl::CancelledError(
        "the upload was cancelled or its stream reset before the client finished it; nothing was "
        "stored");
  }

  absl::Status Register() {
    // The received bytes' grant goes on to cover their parse and validation.
    MeshIntake intake(service_->registry(), "this upload", std::move(grant_));
    const int64_t text_bytes = static_cast<int64_t>(data_.capacity());
    MeshReadResult parsed;
    if (header_.format() == v1::MESH_FORMAT_RAW) {
      const int64_t nv = header_.num_vertices(), nf = header_.num_faces();
      if (static_cast<int64_t>(data_.size()) != 24 * nv + 12 * nf) {
        return absl::InvalidArgumentError(absl::StrCat("raw upload has ", data_.size(), " bytes; ",
                                                       nv, " vertices and ", nf, " faces need ",
                                                       24 * nv + 12 * nf));
      }
      RETURN_IF_ERROR(intake.HoldAtLeast(text_bytes + 24 * nv + 12 * nf));
      parsed.arrays.vertices.resize(nv, 3);
      parsed.arrays.faces.resize(nf, 3);
      std::memcpy(parsed.arrays.vertices.data(), data_.data(), 24 * nv);
      std::memcpy(parsed.arrays.faces.data(), data_.data() + 24 * nv, 12 * nf);
    } else {
      const MeshFormat format = header_.format() == v1::MESH_FORMAT_OBJ   ? MeshFormat::kObj
                                : header_.format() == v1::MESH_FORMAT_OFF ? MeshFormat::kOff
                                                                          : MeshFormat::kPly;
      MeshReadOptions read;
      intake.AdmitArraysOf(&read, text_bytes);
      ASSIGN_OR_RETURN(parsed, ReadMesh(data_, format, read));
    }
    std::string().swap(data_);  // the parsed arrays replace the bytes
    // The last point where a cancelled upload can be dropped.
    if (cancelled_.load()) return Aborted();
    ASSIGN_OR_RETURN(MeshRecord record, intake.Add(std::move(parsed), header_.name()));
    v1::MeshInfo info;
    MeshInfoFromRecord(record, service_->registry()->IsMeshLoaded(record.id), &info);
    return SerializeToBuffer(info, response_);
  }

  FieldService* const service_;
  grpc::CallbackServerContext* const context_;
  grpc::ByteBuffer* const response_;
  grpc::ByteBuffer message_;
  int64_t messages_ = 0;  // read so far
  v1::UploadMeshRequest request_;
  v1::UploadMeshHeader header_;
  bool have_header_ = false;
  bool saw_last_ = false;  // a message marked last has come
  std::string data_;
  WorkGrant grant_;  // the upload's admitted memory (Admit)
  std::atomic<bool> cancelled_{false};
  const Clock::duration idle_timeout_;  // zero: none
  std::mutex mu_;                       // guards the members below
  Clock::time_point last_message_;      // when the last message (or the end of input) came
  bool input_done_ = false;             // the last read has completed (the client's side ended)
  bool finished_ = false;               // FinishOnce has been called
  bool done_ = false;                   // OnDone has run
  std::unique_ptr<grpc::Alarm> idle_alarm_;
};

}  // namespace

grpc::ServerReadReactor<grpc::ByteBuffer>* NewUploadReactor(FieldService* service,
                                                            grpc::CallbackServerContext* context,
                                                            grpc::ByteBuffer* response) {
  return new UploadReactor(service, context, response);
}

}  // namespace fieldspace::server
