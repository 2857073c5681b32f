#ifndef FIELDSPACE_SERVER_DESIGN_EDITOR_H_
#define FIELDSPACE_SERVER_DESIGN_EDITOR_H_

#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "absl/container/flat_hash_map.h"
#include "absl/status/statusor.h"
#include "core/operators/conversions.h"
#include "core/subspace/design_session.h"
#include "fieldspace/v1/fieldspace.pb.h"
#include "server/served_basis.h"
#include "server/work_grant.h"

namespace fieldspace::server {

struct DesignEditorOptions {
  // DesignSessionOptions::verify_interval of the sessions.
  int32_t verify_interval = 16;
  // Watched faces must fit in half of a message of this size.
  int64_t max_message_bytes = int64_t{64} << 20;
  int32_t max_constraints = 1 << 20;
  // Admits an opening session's memory (DesignSessionOpenBytes) for the session's lifetime, and
  // its constraints' (DesignSessionConstraintBytes) as they are added; none when empty.
  AdmitWorkFn admit_work;
};

// What a Design stream does with its messages, without gRPC: the first request opens a
// core DesignSession on a basis (weights, watched faces), every later one is an edit
// (add / move / remove / set_weights / watch), and each is answered by one DesignUpdate with the
// coefficients, the watched faces' lifted values (through the basis's LiftPlan) and timings.
// A request that fails leaves the session exactly as it was: the stream answers it with
// ErrorUpdate and goes on, unless EndsSession. Thread-compatible (one stream).
class DesignEditor {
 public:
  DesignEditor(BasisLookup lookup, const DesignEditorOptions& options)
      : lookup_(std::move(lookup)), options_(options) {}

  // Fills `update` (everything but timings.total_ms, which the transport adds). Errors: those
  // of the session (InvalidArgument, NotFound, AlreadyExists, FailedPrecondition), of the basis
  // lookup, FailedPrecondition for an edit before `open` or a second `open`,
  // ResourceExhausted for too many constraints or watched faces.
  absl::Status Apply(const fieldspace::v1::DesignRequest& request,
                     fieldspace::v1::DesignUpdate* update);

  // Whether the stream must end after `status`, an error of Apply: no session is open (the
  // request was an edit before `open`, or an `open` that failed), or the session may not be as
  // it was (Internal: a failed edit could not be undone). Any other error is the edit's alone:
  // the session is as it was, and the answer is ErrorUpdate.
  bool EndsSession(const absl::Status& status) const {
    return !is_open() || status.code() == absl::StatusCode::kInternal;
  }
  // The answer to the refused request `seq`: only its seq and the error (code and message).
  static void ErrorUpdate(uint64_t seq, const absl::Status& status,
                          fieldspace::v1::DesignUpdate* update);

  bool is_open() const { return session_ != nullptr; }
  const DesignSession* session() const { return session_.get(); }

 private:
  // The smoother of an OpenDesign.data term on basis_.
  absl::StatusOr<std::shared_ptr<const ReducedSmoother>> DataTerm(const v1::DataTerm& data);
  absl::Status Open(const fieldspace::v1::OpenDesign& open);
  absl::Status Edit(const fieldspace::v1::DesignRequest& request);
  absl::Status SetWatch(absl::Span<const int32_t> faces, int encoding);
  // Fills `update` from the session after an edit: coefficients, watched values, singularities.
  absl::Status Answer(fieldspace::v1::DesignUpdate* update);
  // The singularities of the field with coefficients `x` compared with the previous update's.
  absl::Status SingularityChanges(const Eigen::VectorXd& x,
                                  fieldspace::v1::SingularityChanges* changes);

  BasisLookup lookup_;
  DesignEditorOptions options_;
  std::shared_ptr<const ServedBasis> basis_;
  std::unique_ptr<DesignSession> session_;
  // Admits the memory of `constraints` constraints into constraints_grant_, which grows by at
  // least doubling (as the session's own capacity does) and never shrinks (nor does that).
  absl::Status AdmitConstraints(int64_t constraints);
  // max_constraints and AdmitConstraints for `size` more constraints (a tool's group).
  absl::Status AdmitGroup(int64_t size);

  WorkGrant grant_;              // the open session's admitted memory
  WorkGrant constraints_grant_;  // its constraints' (AdmitConstraints)
  std::vector<int32_t> watch_;
  FieldEncoding watch_encoding_ = FieldEncoding::kDof;
  bool refactorized_ = false;                                 // by the request being applied
  bool singularities_ = false;                                // updates carry SingularityChanges
  absl::flat_hash_map<int32_t, int32_t> last_singularities_;  // vertex -> index (1/n turns)
  std::chrono::steady_clock::time_point edit_start_;
};

}  // namespace fieldspace::server

#endif  // FIELDSPACE_SERVER_DESIGN_EDITOR_H_
