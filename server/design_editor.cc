#include "server/design_editor.h"

#include <algorithm>

#include "absl/strings/str_cat.h"
#include "core/common/index_check.h"
#include "core/common/status_macros.h"
#include "core/subspace/projection.h"
#include "server/clock.h"
#include "server/curvature_alignment.h"
#include "server/design_tools_convert.h"
#include "server/field_answers.h"
#include "server/proto_convert.h"

namespace fieldspace::server {

absl::Status DesignEditor::Apply(const v1::DesignRequest& r, v1::DesignUpdate* update) {
  update->set_seq(r.seq());
  refactorized_ = false;
  edit_start_ = Clock::now();
  if (r.edit_case() == v1::DesignRequest::EDIT_NOT_SET) {
    return absl::InvalidArgumentError("a DesignRequest must carry one edit");
  }
  // What undoes the edit when its answer cannot be made (e.g. a constraint of 1e39 whose lifted
  // values overflow float): a failed request leaves the session as it was.
  const EnergyWeights weights = is_open() ? session_->weights() : EnergyWeights{};
  std::vector<int32_t> watch;
  if (r.has_watch()) watch = watch_;
  const FieldEncoding watch_encoding = watch_encoding_;
  // The answer before the edit: the inverse edit re-solves, which agrees with it only to rounding.
  const Eigen::VectorXd coefficients = is_open() ? session_->coefficients() : Eigen::VectorXd();
  // A moved or removed constraint (or group) as it was.
  absl::StatusOr<std::vector<FieldConstraint>> previous = absl::NotFoundError("no such id");
  const int64_t edited = r.has_move() ? r.move().id() : r.remove().id();
  const bool group = is_open() && session_->IsConstraintGroup(edited);
  if (is_open() && (r.has_move() || r.has_remove())) {
    previous = session_->GetConstraintGroup(edited);
  }
  RETURN_IF_ERROR(r.has_open() ? Open(r.open()) : Edit(r));
  absl::Status status = Answer(update);
  if (status.ok()) return status;
  absl::Status undone = absl::OkStatus();
  switch (r.edit_case()) {
    case v1::DesignRequest::kOpen:
      session_.reset();
      basis_.reset();
      watch_.clear();
      break;
    case v1::DesignRequest::kAdd:
      undone = session_->RemoveConstraint(r.add().id());
      break;
    case v1::DesignRequest::kMove:
      undone = group ? session_->MoveConstraintGroup(edited, *previous)
                     : session_->MoveConstraint(edited, previous->front());
      break;
    case v1::DesignRequest::kRemove:
      undone = group ? session_->AddConstraintGroup(edited, *previous)
                     : session_->AddConstraint(edited, previous->front());
      break;
    case v1::DesignRequest::kAddStroke:
    case v1::DesignRequest::kPlaceSingularity:
    case v1::DesignRequest::kAlignBoundary:
    case v1::DesignRequest::kAlignFeatures:
      undone = session_->RemoveConstraint(ToolEditId(r));
      break;
    case v1::DesignRequest::kSetWeights:
      undone = session_->SetWeights(weights);
      break;
    case v1::DesignRequest::kWatch:
      watch_ = std::move(watch);
      watch_encoding_ = watch_encoding;
      break;
    case v1::DesignRequest::EDIT_NOT_SET:
      break;
  }
  if (undone.ok() && r.edit_case() != v1::DesignRequest::kOpen &&
      r.edit_case() != v1::DesignRequest::kWatch) {
    undone = session_->RestoreCoefficients(coefficients);
  }
  if (!undone.ok()) {
    return absl::InternalError(
        absl::StrCat("could not undo a failed edit (", status.message(), "): ", undone.message()));
  }
  return status;
}

void DesignEditor::ErrorUpdate(uint64_t seq, const absl::Status& status, v1::DesignUpdate* update) {
  update->Clear();
  update->set_seq(seq);
  update->mutable_error()->set_code(static_cast<int32_t>(status.code()));
  update->mutable_error()->set_message(std::string(status.message()));
}

absl::Status DesignEditor::Answer(v1::DesignUpdate* update) {
  const double edit_ms = MsSince(edit_start_);
  const Eigen::VectorXd& x = session_->coefficients();
  RETURN_IF_ERROR(CheckSolutionFinite(x));
  update->mutable_coefficients()->Add(x.data(), x.data() + x.size());
  const auto lift_start = Clock::now();
  update->mutable_watched()->set_encoding(EncodingToProto(watch_encoding_));
  update->mutable_watched()->mutable_faces()->Add(watch_.begin(), watch_.end());
  RETURN_IF_ERROR(LiftToValues(*basis_, x, watch_, watch_encoding_,
                               update->mutable_watched()->mutable_values()));
  v1::DesignTimings* t = update->mutable_timings();
  t->set_edit_ms(edit_ms);
  t->set_lift_ms(MsSince(lift_start));
  t->set_refactorized(refactorized_);
  update->set_num_constraints(session_->num_constraints());
  update->set_num_hard_constraints(session_->num_hard_constraints());
  update->set_basis_id(basis_->record.id);
  update->set_backward_error(session_->last_backward_error());
  update->set_iterations(session_->last_refinement_steps());
  if (singularities_) RETURN_IF_ERROR(SingularityChanges(x, update->mutable_singularities()));
  return absl::OkStatus();
}

absl::Status DesignEditor::SingularityChanges(const Eigen::VectorXd& x,
                                              v1::SingularityChanges* changes) {
  ASSIGN_OR_RETURN(Eigen::VectorXd dofs, fieldspace::Lift(*basis_->system, x));
  v1::SingularitiesResponse now;
  RETURN_IF_ERROR(SingularitiesToProto(*basis_, dofs, 0, &now));
  absl::flat_hash_map<int32_t, int32_t> current;
  current.reserve(now.singularities_size());
  for (v1::Singularity& s : *now.mutable_singularities()) {
    current[s.vertex()] = s.index();
    auto it = last_singularities_.find(s.vertex());
    if (it == last_singularities_.end() || it->second != s.index()) {
      *changes->add_appeared() = std::move(s);
    }
  }
  for (const auto& [vertex, index] : last_singularities_) {
    if (!current.contains(vertex)) changes->add_vanished(vertex);
  }
  std::sort(changes->mutable_vanished()->begin(), changes->mutable_vanished()->end());
  changes->set_n(now.n());
  changes->set_index_sum(now.index_sum());
  changes->set_count(static_cast<int32_t>(current.size()));
  last_singularities_ = std::move(current);
  return absl::OkStatus();
}

absl::Status DesignEditor::Open(const v1::OpenDesign& open) {
  if (session_ != nullptr) return absl::FailedPreconditionError("the session is already open");
  ASSIGN_OR_RETURN(std::shared_ptr<const ServedBasis> basis, lookup_(open.basis_id()));
  edit_start_ = Clock::now();  // a basis loaded from the store is not part of the edit
  const bool data_term = open.has_data();
  const EnergyWeights weights = WeightsFromProto(
      open.weights(), data_term ? kDefaultDataTermSessionWeights : EnergyWeights{});
  RETURN_IF_ERROR(ValidateSessionWeights(weights, data_term));
  ASSIGN_OR_RETURN(const BiharmonicForm biharmonic, BiharmonicFormFromProto(open.biharmonic()));
  if (open.singularities()) RETURN_IF_ERROR(CheckHasSingularities(*basis));
  WorkGrant grant;
  if (options_.admit_work) {
    ASSIGN_OR_RETURN(
        grant, options_.admit_work(DesignSessionOpenBytes(*basis->system), "this design session"));
  }
  basis_ = std::move(basis);
  if (absl::Status st = SetWatch(open.watch_faces(), open.watch_encoding()); !st.ok()) {
    basis_.reset();
    return st;
  }
  DesignSessionOptions options;
  options.energy_cache = basis_->energy_cache;
  options.verify_interval = options_.verify_interval;
  options.scale_free = !open.raw_weights();
  options.biharmonic = biharmonic;
  if (data_term) {
    absl::StatusOr<std::shared_ptr<const ReducedSmoother>> data = DataTerm(open.data());
    if (!data.ok()) {
      basis_.reset();
      watch_.clear();
      return data.status();
    }
    options.data_term = std::move(*data);
  }
  absl::StatusOr<std::unique_ptr<DesignSession>> session =
      DesignSession::Create(basis_->system, weights, options);
  if (!session.ok()) {
    basis_.reset();
    watch_.clear();
    return session.status();
  }
  session_ = std::move(*session);
  grant_ = std::move(grant);
  refactorized_ = session_->last_factorized();
  singularities_ = open.singularities();
  last_singularities_.clear();
  return absl::OkStatus();
}

absl::StatusOr<std::shared_ptr<const ReducedSmoother>> DesignEditor::DataTerm(
    const v1::DataTerm& data) {
  Eigen::VectorXd X0;
  Eigen::VectorXd face_weights;
  switch (data.target_case()) {
    case v1::DataTerm::kCurvature: {
      if (data.face_weights_size() > 0) {
        return absl::InvalidArgumentError(
            "data.face_weights go with data.field; a curvature target is weighted by its "
            "anisotropy");
      }
      ASSIGN_OR_RETURN(CurvatureEstimator estimator,
                       EstimatorFromProto(data.curvature().estimator()));
      // Shared by the sessions of this basis (and with it their energy factorizations).
      return CurvatureAlignmentDataTerm(*basis_, estimator);
    }
    case v1::DataTerm::kField: {
      ASSIGN_OR_RETURN(X0, FieldFromProto(data.field(), *basis_));
      face_weights =
          Eigen::Map<const Eigen::VectorXd>(data.face_weights().data(), data.face_weights_size());
      break;
    }
    case v1::DataTerm::TARGET_NOT_SET:
      return absl::InvalidArgumentError("data needs a target: curvature or field");
  }
  ASSIGN_OR_RETURN(
      ReducedSmoother smoother,
      ReducedSmoother::Create(basis_->system, X0,
                              absl::MakeConstSpan(face_weights.data(), face_weights.size())));
  return std::make_shared<const ReducedSmoother>(std::move(smoother));
}

absl::Status DesignEditor::AdmitConstraints(int64_t constraints) {
  if (!options_.admit_work) return absl::OkStatus();
  const int64_t bytes = DesignSessionConstraintBytes(*basis_->system, constraints);
  const int64_t held = constraints_grant_.bytes();
  if (bytes <= held) return absl::OkStatus();
  ASSIGN_OR_RETURN(WorkGrant more, options_.admit_work(std::max(bytes, 2 * held) - held,
                                                       absl::StrCat("this design session's ",
                                                                    constraints, " constraints")));
  constraints_grant_.Merge(std::move(more));
  return absl::OkStatus();
}

absl::Status DesignEditor::AdmitGroup(int64_t size) {
  if (int64_t{session_->num_constraints()} + size > options_.max_constraints) {
    return absl::ResourceExhaustedError("too many constraints in this session");
  }
  return AdmitConstraints(int64_t{session_->num_constraints()} + size);
}

absl::Status DesignEditor::Edit(const v1::DesignRequest& r) {
  if (session_ == nullptr) {
    return absl::FailedPreconditionError("the first message of a session must be 'open'");
  }
  switch (r.edit_case()) {
    case v1::DesignRequest::kAdd: {
      if (session_->num_constraints() >= options_.max_constraints) {
        return absl::ResourceExhaustedError("too many constraints in this session");
      }
      RETURN_IF_ERROR(AdmitConstraints(int64_t{session_->num_constraints()} + 1));
      ASSIGN_OR_RETURN(FieldConstraint c,
                       ConstraintFromProto(*basis_, r.add().constraint(),
                                           absl::StrCat("add id ", r.add().id())));
      return session_->AddConstraint(r.add().id(), c);
    }
    case v1::DesignRequest::kAddStroke:
    case v1::DesignRequest::kPlaceSingularity:
    case v1::DesignRequest::kAlignBoundary:
    case v1::DesignRequest::kAlignFeatures: {
      ASSIGN_OR_RETURN(ToolEdit edit, ToolEditFromProto(*basis_, r));
      RETURN_IF_ERROR(AdmitGroup(static_cast<int64_t>(edit.constraints.size())));
      return session_->AddConstraintGroup(edit.id, edit.constraints);
    }
    case v1::DesignRequest::kMove: {
      if (r.move().has_group()) {
        ASSIGN_OR_RETURN(std::vector<FieldConstraint> constraints,
                         ConstraintGroupFromProto(*basis_, r.move().group(),
                                                  absl::StrCat("move id ", r.move().id())));
        RETURN_IF_ERROR(AdmitGroup(static_cast<int64_t>(constraints.size())));
        return session_->MoveConstraintGroup(r.move().id(), constraints);
      }
      ASSIGN_OR_RETURN(
          Eigen::VectorXd value,
          ConstraintValueFromProto(*basis_, r.move().face(), r.move().value(), r.move().encoding(),
                                   absl::StrCat("move id ", r.move().id())));
      return session_->MoveConstraint(r.move().id(), r.move().face(), std::move(value));
    }
    case v1::DesignRequest::kRemove:
      return session_->RemoveConstraint(r.remove().id());
    case v1::DesignRequest::kSetWeights: {
      const EnergyWeights weights = WeightsFromProto(r.set_weights(), session_->weights());
      RETURN_IF_ERROR(session_->SetWeights(weights));
      refactorized_ = session_->last_factorized();
      return absl::OkStatus();
    }
    case v1::DesignRequest::kWatch:
      return SetWatch(r.watch().faces(), r.watch().encoding());
    case v1::DesignRequest::kOpen:
    case v1::DesignRequest::EDIT_NOT_SET:
      break;
  }
  return absl::InternalError("unreachable: open and empty requests are handled by Apply");
}

absl::Status DesignEditor::SetWatch(absl::Span<const int32_t> faces, int encoding) {
  RETURN_IF_ERROR(CheckFaces(faces, basis_->mesh->num_faces(), "watch"));
  ASSIGN_OR_RETURN(FieldEncoding watch_encoding, EncodingFromProto(encoding));
  const int64_t bytes =
      static_cast<int64_t>(faces.size()) * ValuesPerFace(basis_->basis->type, watch_encoding) * 4;
  if (bytes > options_.max_message_bytes / 2) {
    return absl::ResourceExhaustedError(
        absl::StrCat("watching ", faces.size(), " faces exceeds the message size limit"));
  }
  watch_encoding_ = watch_encoding;
  watch_.assign(faces.begin(), faces.end());
  return absl::OkStatus();
}

}  // namespace fieldspace::server
