#include "server/field_answers.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <numeric>
#include <utility>
#include <vector>

#include "absl/strings/str_cat.h"
#include "core/common/status_macros.h"
#include "core/operators/singularities.h"
#include "core/subspace/projection.h"
#include "oneapi/tbb/blocked_range.h"
#include "oneapi/tbb/parallel_for.h"
#include "server/clock.h"
#include "server/proto_convert.h"

namespace fieldspace::server {

absl::Status CheckHasSingularities(const ServedBasis& basis) {
  if (basis.basis->type.kind == FieldKind::kTensor) {
    return absl::InvalidArgumentError(
        "singularities are defined for vector and n-field bases, not tensor bases");
  }
  return absl::OkStatus();
}

absl::Status SingularitiesToProto(const ServedBasis& basis, const Eigen::VectorXd& dofs,
                                  double zero_tolerance, v1::SingularitiesResponse* out) {
  const TriangleMesh& mesh = *basis.mesh;
  const FieldType& type = basis.basis->type;
  RETURN_IF_ERROR(CheckHasSingularities(basis));
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

absl::Status CheckFieldFits(const ServedBasis& basis, FieldEncoding encoding,
                            int64_t message_room) {
  const int64_t bytes =
      int64_t{4} * ValuesPerFace(basis.basis->type, encoding) * basis.mesh->num_faces();
  if (bytes > message_room) {
    return absl::ResourceExhaustedError(absl::StrCat(
        "the field on all faces (", bytes, " bytes) exceeds the message size limit; use Lift"));
  }
  return absl::OkStatus();
}

absl::StatusOr<double> AnswerField(const ServedBasis& basis, const Eigen::VectorXd& x,
                                   FieldEncoding encoding, v1::FieldValues* field,
                                   v1::SingularitiesResponse* singularities) {
  double lift_ms = 0;
  Eigen::VectorXd dofs;  // the lifted field, once, for the values and the singularities
  if (field != nullptr) {
    const auto lift_start = Clock::now();
    field->set_encoding(EncodingToProto(encoding));
    RETURN_IF_ERROR(LiftAllToValues(basis, x, encoding, field->mutable_values(), &dofs));
    lift_ms = MsSince(lift_start);
  }
  if (singularities != nullptr) {
    if (dofs.size() == 0) {
      ASSIGN_OR_RETURN(dofs, Lift(*basis.system, x));
    }
    RETURN_IF_ERROR(SingularitiesToProto(basis, dofs, 0, singularities));
  }
  return lift_ms;
}

}  // namespace fieldspace::server
