// Field value conversions between the wire encodings and DOFs (core/operators/conversions.h).

#include <cmath>

#include "absl/strings/str_cat.h"
#include "core/common/status_macros.h"
#include "core/operators/conversions.h"
#include "server/engine.h"

namespace fieldspace::server {
namespace {

// Wire order of a symmetric tensor's 6 entries -> row-major 3 x 3 index.
constexpr int kTensorWire[6][2] = {{0, 0}, {1, 1}, {2, 2}, {0, 1}, {1, 2}, {2, 0}};

absl::Status CheckFacesAndSizes(const TriangleMesh& mesh, absl::Span<const int32_t> faces,
                                size_t values, size_t expected_values) {
  if (values != expected_values) {
    return absl::InvalidArgumentError(
        absl::StrCat("expected ", expected_values, " values, got ", values));
  }
  for (int32_t f : faces) {
    if (f < 0 || f >= mesh.num_faces()) {
      return absl::InvalidArgumentError(
          absl::StrCat("face ", f, " is out of range [0, ", mesh.num_faces(), ")"));
    }
  }
  return absl::OkStatus();
}

}  // namespace

absl::Status ValuesToDofs(const TriangleMesh& mesh, const FieldType& type, ValueEncoding encoding,
                          absl::Span<const int32_t> faces, absl::Span<const double> values,
                          absl::Span<double> dofs) {
  const int32_t vpf = ValuesPerFace(type, encoding);
  const int32_t dpf = type.dofs_per_face();
  RETURN_IF_ERROR(CheckFacesAndSizes(mesh, faces, values.size(), faces.size() * vpf));
  if (dofs.size() != faces.size() * dpf) {
    return absl::InternalError("ValuesToDofs: output size mismatch");
  }
  for (size_t i = 0; i < values.size(); ++i) {
    if (!std::isfinite(values[i])) {
      return absl::InvalidArgumentError(
          absl::StrCat("value ", i % vpf, " of face ", faces[i / vpf], " is not finite"));
    }
  }
  if (encoding == ValueEncoding::kDof) {
    std::copy(values.begin(), values.end(), dofs.begin());
    return absl::OkStatus();
  }
  const bool tensor = type.kind == FieldKind::kTensor;
  Eigen::MatrixXd ambient(faces.size(), tensor ? 9 : 3);
  for (size_t i = 0; i < faces.size(); ++i) {
    const double* v = values.data() + i * vpf;
    if (tensor) {
      for (int k = 0; k < 6; ++k) {
        const int r = kTensorWire[k][0], c = kTensorWire[k][1];
        ambient(i, 3 * r + c) = v[k];
        ambient(i, 3 * c + r) = v[k];
      }
    } else {
      ambient.row(i) << v[0], v[1], v[2];
    }
  }
  ASSIGN_OR_RETURN(Eigen::VectorXd out, DofsFromAmbient(mesh, type, faces, ambient));
  std::copy(out.data(), out.data() + out.size(), dofs.begin());
  return absl::OkStatus();
}

absl::Status DofsToValues(const TriangleMesh& mesh, const FieldType& type, ValueEncoding encoding,
                          absl::Span<const int32_t> faces, absl::Span<const double> dofs,
                          absl::Span<float> out) {
  const int32_t vpf = ValuesPerFace(type, encoding);
  RETURN_IF_ERROR(
      CheckFacesAndSizes(mesh, faces, dofs.size(), faces.size() * type.dofs_per_face()));
  if (out.size() != faces.size() * vpf) {
    return absl::InternalError("DofsToValues: output size mismatch");
  }
  if (encoding == ValueEncoding::kDof) {
    std::copy(dofs.begin(), dofs.end(), out.begin());
    return absl::OkStatus();
  }
  ASSIGN_OR_RETURN(Eigen::MatrixXd ambient,
                   AmbientFromDofs(mesh, type, faces,
                                   Eigen::Map<const Eigen::VectorXd>(dofs.data(), dofs.size())));
  const bool tensor = type.kind == FieldKind::kTensor;
  for (size_t i = 0; i < faces.size(); ++i) {
    float* o = out.data() + i * vpf;
    if (tensor) {
      for (int k = 0; k < 6; ++k) {
        o[k] = static_cast<float>(ambient(i, 3 * kTensorWire[k][0] + kTensorWire[k][1]));
      }
    } else {
      for (int k = 0; k < 3; ++k) o[k] = static_cast<float>(ambient(i, k));
    }
  }
  return absl::OkStatus();
}

}  // namespace fieldspace::server
