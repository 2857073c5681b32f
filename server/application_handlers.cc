// The handlers of the applications: Singularities, Smooth, Align, Curvature (handlers.h).

#include <algorithm>
#include <numeric>
#include <utility>
#include <vector>

#include "absl/strings/str_cat.h"
#include "core/common/status_macros.h"
#include "core/operators/curvature.h"
#include "core/subspace/projection.h"
#include "core/subspace/smoothing.h"
#include "server/clock.h"
#include "server/curvature_alignment.h"
#include "server/field_answers.h"
#include "server/handlers.h"
#include "server/proto_convert.h"

namespace fieldspace::server {

absl::Status Singularities(const HandlerContext& ctx, const v1::SingularitiesRequest& request,
                           v1::SingularitiesResponse* response) {
  ASSIGN_OR_RETURN(std::shared_ptr<const ServedBasis> basis, ctx.GetBasis(request.basis_id()));
  RETURN_IF_ERROR(CheckHasSingularities(*basis));
  // The field in double and the per-vertex indices.
  ASSIGN_OR_RETURN(WorkGrant grant,
                   ctx.AdmitWork(8 * basis->system->dofs() + 32 * int64_t{basis->mesh->num_faces()},
                                 "this Singularities call"));
  const bool has_field = !request.field().values().empty();
  if (has_field == !request.coefficients().empty()) {
    return absl::InvalidArgumentError(
        "give the field either as coefficients or as values on all faces (field)");
  }
  Eigen::VectorXd dofs;
  if (has_field) {
    ASSIGN_OR_RETURN(dofs, FieldFromProto(request.field(), *basis));
  } else {
    ASSIGN_OR_RETURN(Eigen::VectorXd x, CoefficientsFromProto(request.coefficients(), *basis));
    ASSIGN_OR_RETURN(dofs, fieldspace::Lift(*basis->system, x));
  }
  return SingularitiesToProto(*basis, dofs, request.zero_tolerance(), response);
}

namespace {

// What Smooth and Align share: the field to smooth and how to answer.
struct SmoothJob {
  Eigen::VectorXd X0;
  EnergyWeights weights;
  absl::Span<const double> face_weights;  // empty for 1
  bool scale_free = true;
  bool return_field = false;
  int field_encoding = 0;
  bool singularities = false;
};

// Smooths `job.X0` in `basis` and fills `response`: the coefficients, the lifted field and the
// singularities on request, and the timings (total since `start`).
absl::Status SmoothInto(const HandlerContext& ctx, const ServedBasis& basis, const SmoothJob& job,
                        Clock::time_point start, v1::SmoothResponse* response) {
  RETURN_IF_ERROR(ValidateWeightsWithoutDataTerm(job.weights));
  ASSIGN_OR_RETURN(FieldEncoding encoding, EncodingFromProto(job.field_encoding));
  if (job.return_field) {
    RETURN_IF_ERROR(CheckFieldFits(basis, encoding, ctx.options->message_room()));
  }
  // The smoother, and the lifted field (double and float) on request.
  ASSIGN_OR_RETURN(
      WorkGrant grant,
      ctx.AdmitWork((job.return_field || job.singularities ? 12 : 0) * basis.system->dofs() +
                        SmoothWorkingBytes(*basis.system, HardwareThreads()),
                    "this smoothing"));
  SmoothingOptions options;
  options.scale_free = job.scale_free;
  options.cancel = ctx.cancel;
  ASSIGN_OR_RETURN(SmoothingResult result,
                   SmoothReduced(*basis.system, job.X0, job.weights, job.face_weights, options));
  RETURN_IF_ERROR(CheckSolutionFinite(result.coefficients));
  response->mutable_coefficients()->Add(result.coefficients.data(),
                                        result.coefficients.data() + result.coefficients.size());
  ASSIGN_OR_RETURN(const double lift_ms,
                   AnswerField(basis, result.coefficients, encoding,
                               job.return_field ? response->mutable_field() : nullptr,
                               job.singularities ? response->mutable_singularities() : nullptr));
  v1::SmoothTimings* t = response->mutable_timings();
  t->set_rhs_ms(result.timings.rhs_ms);
  t->set_weighted_mass_ms(result.timings.weighted_mass_ms);
  t->set_factorize_ms(result.timings.factorize_ms);
  t->set_solve_ms(result.timings.solve_ms);
  t->set_lift_ms(lift_ms);
  t->set_total_ms(MsSince(start));
  response->set_backward_error(result.backward_error);
  return absl::OkStatus();
}

}  // namespace

absl::Status Smooth(const HandlerContext& ctx, const v1::SmoothRequest& request,
                    v1::SmoothResponse* response) {
  const auto start = Clock::now();
  ASSIGN_OR_RETURN(std::shared_ptr<const ServedBasis> basis, ctx.GetBasis(request.basis_id()));
  SmoothJob job;
  ASSIGN_OR_RETURN(job.X0, FieldFromProto(request.field(), *basis));
  job.weights = WeightsFromProto(request.weights(), kDefaultSmoothingWeights);
  job.face_weights = request.face_weights();
  job.scale_free = request.scale_free();
  job.return_field = request.return_field();
  job.field_encoding = request.field_encoding();
  job.singularities = request.singularities();
  return SmoothInto(ctx, *basis, job, start, response);
}

absl::Status Align(const HandlerContext& ctx, const v1::AlignRequest& request,
                   v1::SmoothResponse* response) {
  const auto start = Clock::now();
  ASSIGN_OR_RETURN(std::shared_ptr<const ServedBasis> basis, ctx.GetBasis(request.basis_id()));
  ASSIGN_OR_RETURN(CurvatureEstimator estimator, EstimatorFromProto(request.estimator()));
  // The curvature target while it is computed (the smoothing is admitted in SmoothInto).
  ASSIGN_OR_RETURN(
      WorkGrant grant,
      ctx.AdmitWork(8 * basis->system->dofs() + CurvatureWorkingBytes(basis->mesh->num_faces()),
                    "this Align"));
  ASSIGN_OR_RETURN(AlignmentTarget target, CurvatureAlignmentTarget(*basis, estimator));
  SmoothJob job;
  job.X0 = std::move(target.dofs);
  job.weights = WeightsFromProto(request.weights(), kDefaultSmoothingWeights);
  job.face_weights = absl::MakeConstSpan(target.face_weights.data(), target.face_weights.size());
  job.scale_free = true;
  job.return_field = request.return_field();
  job.field_encoding = request.field_encoding();
  job.singularities = request.singularities();
  return SmoothInto(ctx, *basis, job, start, response);
}

namespace {

// The shape operator (and principal curvatures) computed once when the stream opens, then sent
// in chunks of faces.
class CurvatureStream final : public ChunkStream<v1::CurvatureChunk> {
 public:
  absl::Status Open(const HandlerContext& ctx, const v1::CurvatureRequest& request) {
    const auto start = Clock::now();
    principal_wanted_ = request.principal();
    ASSIGN_OR_RETURN(encoding_, EncodingFromProto(request.encoding()));
    if (request.chunk_faces() < 0) {
      return absl::InvalidArgumentError("chunk_faces must not be negative");
    }
    // Per face: the tensor (6 or 3 floats) and, on request, k1, k2, d1, d2 (8 floats).
    chunk_ = ctx.options->ChunkFaces(
        request.chunk_faces(),
        4 * (ValuesPerFace(FieldType::Tensor(), encoding_) + (principal_wanted_ ? 8 : 0)));
    ShapeOperatorOptions options;
    options.cancel = ctx.cancel;
    ASSIGN_OR_RETURN(options.estimator, EstimatorFromProto(request.estimator()));
    ASSIGN_OR_RETURN(mesh_, ctx.GetMesh(request.mesh_id()));
    ASSIGN_OR_RETURN(
        grant_, ctx.AdmitWork(CurvatureWorkingBytes(mesh_->num_faces()), "this Curvature call"));
    ASSIGN_OR_RETURN(dofs_, ComputeShapeOperator(*mesh_, options));
    if (principal_wanted_) {
      ASSIGN_OR_RETURN(principal_, ComputePrincipalCurvatures(*mesh_, dofs_));
    }
    server_ms_ = MsSince(start);
    return absl::OkStatus();
  }

  absl::StatusOr<bool> Next(v1::CurvatureChunk* out) override {
    const int32_t total = mesh_->num_faces();
    if (next_ >= total) return false;
    const auto start = Clock::now();
    const int32_t count = std::min(chunk_, total - next_);
    faces_.resize(count);
    std::iota(faces_.begin(), faces_.end(), next_);
    out->set_start_face(next_);
    out->set_total_faces(total);
    const FieldType type = FieldType::Tensor();
    const int32_t vpf = ValuesPerFace(type, encoding_);
    v1::FieldValues* tensor = out->mutable_tensor();
    tensor->set_encoding(EncodingToProto(encoding_));
    tensor->mutable_values()->Resize(count * vpf, 0.0f);
    RETURN_IF_ERROR(
        DofsToValues(*mesh_, type, encoding_, faces_,
                     absl::MakeConstSpan(dofs_.data() + int64_t{3} * next_, int64_t{3} * count),
                     absl::MakeSpan(tensor->mutable_values()->mutable_data(), count * vpf)));
    if (principal_wanted_) {
      for (int32_t f = next_; f < next_ + count; ++f) {
        out->add_k1(static_cast<float>(principal_.k1[f]));
        out->add_k2(static_cast<float>(principal_.k2[f]));
        for (int c = 0; c < 3; ++c) {
          out->add_d1(static_cast<float>(principal_.d1(f, c)));
          out->add_d2(static_cast<float>(principal_.d2(f, c)));
        }
      }
    }
    next_ += count;
    server_ms_ += MsSince(start);
    out->set_server_ms(server_ms_);
    return true;
  }

 private:
  std::shared_ptr<const TriangleMesh> mesh_;
  Eigen::VectorXd dofs_;
  PrincipalCurvatures principal_;
  bool principal_wanted_ = false;
  WorkGrant grant_;  // the memory of the curvature computations
  FieldEncoding encoding_ = FieldEncoding::kDof;
  std::vector<int32_t> faces_;
  int32_t chunk_ = 0;
  int32_t next_ = 0;
  double server_ms_ = 0;
};

}  // namespace

absl::StatusOr<std::unique_ptr<ChunkStream<v1::CurvatureChunk>>> OpenCurvature(
    const HandlerContext& ctx, const v1::CurvatureRequest& request) {
  auto stream = std::make_unique<CurvatureStream>();
  RETURN_IF_ERROR(stream->Open(ctx, request));
  return stream;
}

}  // namespace fieldspace::server
