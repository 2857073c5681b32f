#include "server/proto_convert.h"

#include <algorithm>
#include <cmath>
#include <numeric>

#include "absl/strings/str_cat.h"
#include "core/common/index_check.h"
#include "core/common/status_macros.h"

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

absl::StatusOr<Eigen::VectorXd> ConstraintValueFromProto(const ServedBasis& basis, int32_t face,
                                                         absl::Span<const double> value,
                                                         int encoding, absl::string_view what) {
  const TriangleMesh& mesh = *basis.mesh;
  const FieldType& type = basis.basis->type;
  const int32_t faces[1] = {face};
  RETURN_IF_ERROR(CheckFace(face, mesh.num_faces(), what));
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

}  // namespace fieldspace::server
