#include "server/proto_convert.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <numeric>

#include "absl/strings/str_cat.h"
#include "core/common/status_macros.h"
#include "core/operators/singularities.h"
#include "core/subspace/projection.h"
#include "oneapi/tbb/blocked_range.h"
#include "oneapi/tbb/parallel_for.h"

namespace fieldspace::server {

absl::StatusOr<FieldType> FieldTypeFromProto(const v1::FieldType& p) {
  switch (p.kind()) {
    case v1::FIELD_KIND_VECTOR:
      return FieldType::Vector();
    case v1::FIELD_KIND_NFIELD: {
      FieldType t = FieldType::NField(p.n());
      RETURN_IF_ERROR(t.Validate());
      return t;
    }
    case v1::FIELD_KIND_TENSOR:
      return FieldType::Tensor();
    default:
      return absl::InvalidArgumentError(
          "field.kind must be FIELD_KIND_VECTOR, FIELD_KIND_NFIELD or FIELD_KIND_TENSOR");
  }
}

void FieldTypeToProto(const FieldType& t, v1::FieldType* p) {
  switch (t.kind) {
    case FieldKind::kVector:
      p->set_kind(v1::FIELD_KIND_VECTOR);
      break;
    case FieldKind::kNField:
      p->set_kind(v1::FIELD_KIND_NFIELD);
      p->set_n(t.n);
      break;
    case FieldKind::kTensor:
      p->set_kind(v1::FIELD_KIND_TENSOR);
      break;
  }
}

absl::StatusOr<FieldEncoding> EncodingFromProto(int encoding) {
  switch (encoding) {
    case v1::FIELD_ENCODING_DOF:
      return FieldEncoding::kDof;
    case v1::FIELD_ENCODING_AMBIENT:
      return FieldEncoding::kAmbient;
    default:
      return absl::InvalidArgumentError(absl::StrCat("unknown field encoding ", encoding));
  }
}

v1::FieldEncoding EncodingToProto(FieldEncoding e) {
  return e == FieldEncoding::kAmbient ? v1::FIELD_ENCODING_AMBIENT : v1::FIELD_ENCODING_DOF;
}

v1::BuildPhase PhaseToProto(BuildStage stage) {
  switch (stage) {
    case BuildStage::kQueued:
      return v1::BUILD_PHASE_QUEUED;
    case BuildStage::kOperator:
      return v1::BUILD_PHASE_OPERATOR;
    case BuildStage::kSampling:
      return v1::BUILD_PHASE_SAMPLING;
    case BuildStage::kRegions:
      return v1::BUILD_PHASE_REGIONS;
    case BuildStage::kEigensolve:
      return v1::BUILD_PHASE_EIGENSOLVE;
    case BuildStage::kAssembly:
      return v1::BUILD_PHASE_ASSEMBLY;
    case BuildStage::kPrecompute:
      return v1::BUILD_PHASE_PRECOMPUTE;
    case BuildStage::kSaving:
      return v1::BUILD_PHASE_SAVING;
    case BuildStage::kDone:
      return v1::BUILD_PHASE_DONE;
  }
  return v1::BUILD_PHASE_UNSPECIFIED;
}

void MeshInfoFromRecord(const MeshRecord& r, bool loaded, v1::MeshInfo* p) {
  p->set_id(r.id);
  p->set_name(r.name);
  p->set_num_vertices(r.num_vertices);
  p->set_num_faces(r.num_faces);
  p->set_num_edges(r.num_edges);
  p->set_num_components(r.num_components);
  p->set_num_boundary_loops(r.num_boundary_loops);
  p->set_euler_characteristic(r.euler_characteristic);
  p->set_genus(r.genus);
  p->set_total_area(r.total_area);
  p->set_dropped_unreferenced_vertices(r.dropped_unreferenced_vertices);
  p->set_polygons_triangulated(r.polygons_triangulated);
  p->set_loaded(loaded);
  p->set_created_unix_ms(r.created_unix_ms);
}

void BasisInfoFromStatus(const BasisStatus& s, v1::BasisInfo* p) {
  const BasisRecord& r = s.record;
  p->set_id(r.id);
  p->set_mesh_id(r.key.mesh_id);
  FieldTypeToProto(r.key.field, p->mutable_field());
  p->set_dimension(r.key.dimension);
  p->set_sigma(r.key.sigma);
  p->set_fields_per_region(r.key.fields_per_region);
  p->set_seed(r.key.seed);
  p->set_coarse_dimension(r.key.coarse_dimension);
  p->set_kernel_columns(r.key.kernel_columns);
  p->set_quality(static_cast<v1::BasisQuality>(r.key.quality));
  p->set_adaptive(r.key.weights_hash != 0);
  p->set_dofs(r.dofs);
  if (s.ready) {
    p->set_state(v1::BASIS_STATE_READY);
    p->set_columns(r.columns);
    p->set_num_regions(r.num_regions);
    p->set_radius(r.radius);
    p->set_nnz(r.nnz);
    p->set_build_seconds(r.build_seconds);
    p->set_loaded(s.loaded);
    p->set_memory_bytes(s.memory_bytes);
    p->set_created_unix_ms(r.created_unix_ms);
    p->set_phase(v1::BUILD_PHASE_DONE);
    p->set_fraction(1.0);
  } else {
    p->set_state(v1::BASIS_STATE_BUILDING);
    p->set_phase(PhaseToProto(s.progress.stage));
    p->set_fraction(s.progress.fraction);
    p->set_overall_fraction(OverallFraction(s.progress.stage, s.progress.fraction));
  }
}

void BasisInfoFromRecord(const BasisRecord& r, v1::BasisInfo* p) {
  BasisStatus s;
  s.record = r;
  s.ready = true;
  BasisInfoFromStatus(s, p);
}

absl::StatusOr<BuildRequest> BuildRequestFromProto(const v1::BuildBasisRequest& p) {
  BuildRequest build;
  build.key.mesh_id = p.mesh_id();
  ASSIGN_OR_RETURN(build.key.field, FieldTypeFromProto(p.field()));
  build.key.dimension = p.dimension();
  build.key.sigma = p.has_sigma() ? p.sigma() : 40.0;
  build.key.fields_per_region = p.fields_per_region();
  build.key.seed = p.seed();
  build.key.coarse_dimension = p.coarse_dimension();
  build.key.kernel_columns = !p.has_kernel_columns() || p.kernel_columns();
  switch (p.quality()) {
    case v1::BASIS_QUALITY_PAPER:
      build.key.quality = BasisQuality::kPaper;
      break;
    case v1::BASIS_QUALITY_LOW_MODES:
      build.key.quality = BasisQuality::kLowModes;
      break;
    case v1::BASIS_QUALITY_SMOOTH:
      build.key.quality = BasisQuality::kSmooth;
      break;
    default:
      return absl::InvalidArgumentError(
          absl::StrCat("unknown basis quality ", static_cast<int>(p.quality())));
  }
  build.face_weights =
      Eigen::Map<const Eigen::VectorXd>(p.face_weights().data(), p.face_weights().size());
  return build;
}

absl::StatusOr<CurvatureEstimator> EstimatorFromProto(int estimator) {
  switch (estimator) {
    case v1::CURVATURE_ESTIMATOR_JET:
      return CurvatureEstimator::kJetFit;
    case v1::CURVATURE_ESTIMATOR_NORMAL_DIFFERENCES:
      return CurvatureEstimator::kNormalDifferences;
    default:
      return absl::InvalidArgumentError(absl::StrCat("unknown curvature estimator ", estimator));
  }
}

absl::StatusOr<BiharmonicForm> BiharmonicFormFromProto(int form) {
  switch (form) {
    case v1::BIHARMONIC_FORM_EXACT:
      return BiharmonicForm::kExact;
    case v1::BIHARMONIC_FORM_UNSPECIFIED:  // the default
    case v1::BIHARMONIC_FORM_MIXED:
      return BiharmonicForm::kMixed;
    default:
      return absl::InvalidArgumentError(absl::StrCat("unknown biharmonic form ", form));
  }
}

EnergyWeights WeightsFromProto(const v1::Weights& w, const EnergyWeights& defaults) {
  return {.mu_s = w.has_mu_s() ? w.mu_s() : defaults.mu_s,
          .mu_b = w.has_mu_b() ? w.mu_b() : defaults.mu_b,
          .mu_c = w.has_mu_c() ? w.mu_c() : defaults.mu_c,
          .mu_a = w.has_mu_a() ? w.mu_a() : defaults.mu_a};
}

absl::Status SingularitiesToProto(const ServedBasis& basis, const Eigen::VectorXd& dofs,
                                  double zero_tolerance, v1::SingularitiesResponse* out) {
  const TriangleMesh& mesh = *basis.mesh;
  const FieldType& type = basis.basis->type;
  if (type.kind == FieldKind::kTensor) {
    return absl::InvalidArgumentError(
        "singularities are defined for vector and n-field bases, not tensor bases");
  }
  SingularityOptions options;
  options.n = type.kind == FieldKind::kNField ? type.n : 1;
  options.zero_tolerance = zero_tolerance;
  ASSIGN_OR_RETURN(Singularities found, ComputeSingularities(mesh, dofs, options));
  const auto position = [&mesh](int32_t v, v1::Singularity* s) {
    for (int c = 0; c < 3; ++c) s->add_position(mesh.vertices()(v, c));
  };
  out->set_n(found.n);
  for (const Singularity& s : found.singularities) {
    v1::Singularity* p = out->add_singularities();
    p->set_vertex(s.vertex);
    p->set_index(s.index);
    p->set_turns(s.turns);
    position(s.vertex, p);
  }
  for (const BoundaryIndex& b : found.boundary) {
    v1::Singularity* p = out->add_boundary();
    p->set_vertex(b.vertex);
    p->set_turns(b.turns);
    position(b.vertex, p);
  }
  out->mutable_undefined_vertices()->Add(found.undefined_vertices.begin(),
                                         found.undefined_vertices.end());
  out->set_index_sum(static_cast<double>(found.index_sum) / found.n);
  out->set_euler_characteristic(mesh.num_vertices() - mesh.num_edges() + mesh.num_faces());
  return absl::OkStatus();
}

absl::Status CheckFaces(absl::Span<const int32_t> faces, int32_t num_faces,
                        absl::string_view what) {
  for (int32_t f : faces) {
    if (f < 0 || f >= num_faces) {
      return absl::InvalidArgumentError(
          absl::StrCat(what, ": face ", f, " is out of range [0, ", num_faces, ")"));
    }
  }
  return absl::OkStatus();
}

absl::StatusOr<Eigen::VectorXd> ConstraintValueFromProto(const ServedBasis& basis, int32_t face,
                                                         absl::Span<const double> value,
                                                         int encoding, absl::string_view what) {
  const TriangleMesh& mesh = *basis.mesh;
  const FieldType& type = basis.basis->type;
  const int32_t faces[1] = {face};
  RETURN_IF_ERROR(CheckFaces(faces, mesh.num_faces(), what));
  ASSIGN_OR_RETURN(FieldEncoding enc, EncodingFromProto(encoding));
  const int32_t vpf = ValuesPerFace(type, enc);
  if (static_cast<int64_t>(value.size()) != vpf) {
    return absl::InvalidArgumentError(absl::StrCat(
        what, ": value has ", value.size(), " numbers; a ", type.ToString(), " constraint in ",
        enc == FieldEncoding::kAmbient ? "ambient" : "DOF", " encoding needs ", vpf));
  }
  // Finite but absurd values would overflow the solve (the design session would then hold a
  // field of infinities): refuse them here, where the message can name the request part.
  constexpr double kMaxValue = 1e100;
  for (double v : value) {
    if (std::abs(v) > kMaxValue) {
      return absl::InvalidArgumentError(
          absl::StrCat(what, ": value ", v, " is out of range (|value| <= 1e100)"));
    }
  }
  Eigen::VectorXd dofs(type.dofs_per_face());
  RETURN_IF_ERROR(
      ValuesToDofs(mesh, type, enc, faces, value, absl::MakeSpan(dofs.data(), dofs.size())));
  return dofs;
}

absl::StatusOr<FieldConstraint> ConstraintFromProto(const ServedBasis& basis,
                                                    const v1::Constraint& c,
                                                    absl::string_view what) {
  FieldConstraint out;
  out.face = c.face();
  ASSIGN_OR_RETURN(out.value,
                   ConstraintValueFromProto(basis, c.face(), c.value(), c.encoding(), what));
  if (c.has_weight()) {
    if (!std::isfinite(c.weight()) || c.weight() <= 0) {
      return absl::InvalidArgumentError(
          absl::StrCat(what, ": weight must be finite and > 0, got ", c.weight()));
    }
    out.weight = c.weight();
  }
  out.kind = c.hard() ? ConstraintKind::kHard : ConstraintKind::kSoft;
  return out;
}

absl::StatusOr<Eigen::VectorXd> CoefficientsFromProto(absl::Span<const double> c,
                                                      const ServedBasis& basis) {
  const int32_t d = basis.basis->dimension();
  if (static_cast<int64_t>(c.size()) != d) {
    return absl::InvalidArgumentError(
        absl::StrCat("expected ", d, " coefficients (the basis dimension), got ", c.size()));
  }
  for (size_t i = 0; i < c.size(); ++i) {
    if (!std::isfinite(c[i])) {
      return absl::InvalidArgumentError(absl::StrCat("coefficient ", i, " is not finite"));
    }
  }
  return Eigen::Map<const Eigen::VectorXd>(c.data(), d);
}

absl::StatusOr<Eigen::VectorXd> FieldFromProto(const v1::FieldValues& field,
                                               const ServedBasis& basis) {
  const TriangleMesh& mesh = *basis.mesh;
  const FieldType& type = basis.basis->type;
  if (!field.faces().empty()) {
    return absl::InvalidArgumentError(
        "Project takes a field on all faces: leave field.faces empty");
  }
  ASSIGN_OR_RETURN(FieldEncoding encoding, EncodingFromProto(field.encoding()));
  const int64_t vpf = ValuesPerFace(type, encoding);
  if (field.values().size() != vpf * mesh.num_faces()) {
    return absl::InvalidArgumentError(
        absl::StrCat("field has ", field.values().size(), " values; ", mesh.num_faces(),
                     " faces x ", vpf, " values per face = ", vpf * mesh.num_faces(), " expected"));
  }
  const std::vector<double> values(field.values().begin(), field.values().end());
  std::vector<int32_t> faces(mesh.num_faces());
  std::iota(faces.begin(), faces.end(), 0);
  Eigen::VectorXd X(int64_t{type.dofs_per_face()} * mesh.num_faces());
  RETURN_IF_ERROR(
      ValuesToDofs(mesh, type, encoding, faces, values, absl::MakeSpan(X.data(), X.size())));
  return X;
}

absl::Status CheckSolutionFinite(const Eigen::VectorXd& x) {
  if (!x.allFinite()) {
    return absl::InvalidArgumentError(
        "the solution is not finite: the input values are too large for double precision");
  }
  return absl::OkStatus();
}

absl::Status EncodeDofs(const ServedBasis& basis, absl::Span<const int32_t> faces,
                        absl::Span<const double> dofs, FieldEncoding encoding,
                        google::protobuf::RepeatedField<float>* out) {
  const int32_t vpf = ValuesPerFace(basis.basis->type, encoding);
  const int count = static_cast<int>(faces.size()) * vpf;
  out->Reserve(out->size() + count);
  // Uninitialized: every value is written below (no zero-fill pass over large lifts).
  const absl::Span<float> values = absl::MakeSpan(out->AddNAlreadyReserved(count), count);
  std::atomic<bool> finite{true};
  if (encoding == FieldEncoding::kDof) {
    // The DOF encoding is a narrowing copy: one parallel pass converts and checks each block while
    // it is in cache (an all-faces lift of 1.38M faces is 2.8M values).
    if (dofs.size() != values.size()) {
      return absl::InternalError("EncodeDofs: the DOFs do not match the faces");
    }
    tbb::parallel_for(tbb::blocked_range<size_t>(0, values.size(), 1 << 16),
                      [&](const tbb::blocked_range<size_t>& r) {
                        bool ok = true;
                        for (size_t i = r.begin(); i < r.end(); ++i) {
                          values[i] = static_cast<float>(dofs[i]);
                          ok &= std::isfinite(values[i]);
                        }
                        if (!ok) finite.store(false, std::memory_order_relaxed);
                      });
  } else {
    RETURN_IF_ERROR(DofsToValues(*basis.mesh, basis.basis->type, encoding, faces, dofs, values));
    finite = std::all_of(values.begin(), values.end(), [](float v) { return std::isfinite(v); });
  }
  if (!finite) {
    return absl::InvalidArgumentError(kFloatOverflowMessage);
  }
  return absl::OkStatus();
}

absl::Status LiftToValues(const ServedBasis& basis, const Eigen::VectorXd& x,
                          absl::Span<const int32_t> faces, FieldEncoding encoding,
                          google::protobuf::RepeatedField<float>* out) {
  std::vector<double> dofs(faces.size() * basis.basis->type.dofs_per_face());
  RETURN_IF_ERROR(LiftFacesInto(*basis.system, x, faces, absl::MakeSpan(dofs)));
  return EncodeDofs(basis, faces, dofs, encoding, out);
}

absl::Status LiftAllToValues(const ServedBasis& basis, const Eigen::VectorXd& x,
                             FieldEncoding encoding, google::protobuf::RepeatedField<float>* out,
                             Eigen::VectorXd* dofs_out) {
  ASSIGN_OR_RETURN(Eigen::VectorXd dofs, Lift(*basis.system, x));
  std::vector<int32_t> faces(basis.mesh->num_faces());
  std::iota(faces.begin(), faces.end(), 0);
  RETURN_IF_ERROR(
      EncodeDofs(basis, faces, absl::MakeConstSpan(dofs.data(), dofs.size()), encoding, out));
  if (dofs_out != nullptr) *dofs_out = std::move(dofs);
  return absl::OkStatus();
}

}  // namespace fieldspace::server
