#include "core/operators/conversions.h"

#include <cmath>
#include <numbers>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "core/common/index_check.h"
#include "core/common/status_macros.h"
#include "core/operators/complex_power.h"
#include "tbb/blocked_range.h"
#include "tbb/parallel_for.h"

namespace fieldspace {
namespace {

constexpr double kTensorSymmetryTolerance = 1e-6;

Eigen::Vector3d FrameX(const TriangleMesh& mesh, int32_t f) {
  return mesh.frame_x().row(f).transpose();
}
Eigen::Vector3d FrameY(const TriangleMesh& mesh, int32_t f) {
  return mesh.frame_y().row(f).transpose();
}

// Tangential part of v in face f's frame coordinates.
Eigen::Vector2d ToFrame(const TriangleMesh& mesh, int32_t f, const Eigen::Vector3d& v) {
  return {v.dot(FrameX(mesh, f)), v.dot(FrameY(mesh, f))};
}
Eigen::Vector3d FromFrame(const TriangleMesh& mesh, int32_t f, const Eigen::Vector2d& d) {
  return d[0] * FrameX(mesh, f) + d[1] * FrameY(mesh, f);
}

// r (cos phi, sin phi) -> r (cos n phi, sin n phi), by complex powers of the unit direction.
Eigen::Vector2d PowerRepresentation(const Eigen::Vector2d& d, int32_t n) {
  const double r = d.norm();
  if (r == 0.0) return Eigen::Vector2d::Zero();
  return r * UnitComplexPower(d / r, n);
}

// The k-th n-th root direction of a representation vector, length kept.
Eigen::Vector2d RootDirection(const Eigen::Vector2d& rep, int32_t n, int32_t k) {
  const double r = rep.norm();
  if (r == 0.0) return Eigen::Vector2d::Zero();
  const double phi = std::atan2(rep[1], rep[0]) / n + 2.0 * std::numbers::pi * k / n;
  return {r * std::cos(phi), r * std::sin(phi)};
}

Eigen::Vector3d TensorToMandelVoigt(const TriangleMesh& mesh, int32_t f, const Eigen::Matrix3d& A) {
  const Eigen::Vector3d x = FrameX(mesh, f), y = FrameY(mesh, f);
  const Eigen::Matrix3d sym = 0.5 * (A + A.transpose());
  return {x.dot(sym * x), y.dot(sym * y), std::sqrt(2.0) * x.dot(sym * y)};
}

Eigen::Matrix3d MandelVoigtToTensor(const TriangleMesh& mesh, int32_t f, const Eigen::Vector3d& a) {
  const Eigen::Vector3d x = FrameX(mesh, f), y = FrameY(mesh, f);
  const double a12 = a[2] / std::sqrt(2.0);
  return a[0] * x * x.transpose() + a[1] * y * y.transpose() +
         a12 * (x * y.transpose() + y * x.transpose());
}

absl::Status CheckN(int32_t n) { return FieldType::NField(n).Validate(); }

// Rows of `values` (one per face f = face_of(i)) must be finite (and symmetric tensors).
template <typename Values, typename FaceOf>
absl::Status CheckRows(const Values& values, int64_t rows, FaceOf face_of, bool tensors) {
  for (int64_t i = 0; i < rows; ++i) {
    if (!values.row(i).allFinite()) {
      return absl::InvalidArgumentError(
          absl::StrFormat("face %d: value is not finite", face_of(i)));
    }
    if (tensors) {
      Eigen::Matrix3d A;
      for (int r = 0; r < 3; ++r) {
        for (int c = 0; c < 3; ++c) A(r, c) = values(i, 3 * r + c);
      }
      const double scale = A.cwiseAbs().maxCoeff();
      if ((A - A.transpose()).cwiseAbs().maxCoeff() > kTensorSymmetryTolerance * scale) {
        return absl::InvalidArgumentError(
            absl::StrFormat("face %d: tensor is not symmetric", face_of(i)));
      }
    }
  }
  return absl::OkStatus();
}

template <typename Dofs, typename FaceOf>
absl::Status CheckDofs(const Dofs& dofs, int64_t rows, int32_t p, FaceOf face_of) {
  if (dofs.size() != rows * p) {
    return absl::InvalidArgumentError(
        absl::StrFormat("expected %d DOFs (%d per face), got %d", rows * p, p, dofs.size()));
  }
  for (int64_t i = 0; i < rows; ++i) {
    if (!dofs.segment(i * p, p).allFinite()) {
      return absl::InvalidArgumentError(
          absl::StrFormat("face %d: DOFs are not finite", face_of(i)));
    }
  }
  return absl::OkStatus();
}

template <typename Body>
void ParallelRows(int64_t rows, Body body) {
  tbb::parallel_for(tbb::blocked_range<int64_t>(0, rows, 8192),
                    [&](const tbb::blocked_range<int64_t>& r) {
                      for (int64_t i = r.begin(); i != r.end(); ++i) body(i);
                    });
}

absl::Status CheckRowCount(const TriangleMesh& mesh, int64_t rows, int64_t values_per_row) {
  if (rows != mesh.num_faces()) {
    return absl::InvalidArgumentError(
        absl::StrFormat("expected %d rows (one per face) of %d values, got %d rows",
                        mesh.num_faces(), values_per_row, rows));
  }
  return absl::OkStatus();
}

auto Identity() {
  return [](int64_t i) { return static_cast<int32_t>(i); };
}

}  // namespace

absl::StatusOr<Eigen::VectorXd> VectorDofsFromAmbient(
    const TriangleMesh& mesh, const Eigen::Ref<const AmbientVectors>& vectors) {
  RETURN_IF_ERROR(CheckRowCount(mesh, vectors.rows(), 3));
  RETURN_IF_ERROR(CheckRows(vectors, vectors.rows(), Identity(), false));
  Eigen::VectorXd dofs(2 * vectors.rows());
  ParallelRows(vectors.rows(), [&](int64_t f) {
    dofs.segment<2>(2 * f) = ToFrame(mesh, f, vectors.row(f).transpose());
  });
  return dofs;
}

absl::StatusOr<AmbientVectors> AmbientFromVectorDofs(
    const TriangleMesh& mesh, const Eigen::Ref<const Eigen::VectorXd>& dofs) {
  RETURN_IF_ERROR(CheckDofs(dofs, mesh.num_faces(), 2, Identity()));
  AmbientVectors out(mesh.num_faces(), 3);
  ParallelRows(mesh.num_faces(), [&](int64_t f) {
    out.row(f) = FromFrame(mesh, f, dofs.segment<2>(2 * f)).transpose();
  });
  return out;
}

absl::StatusOr<Eigen::VectorXd> NFieldDofsFromAmbient(
    const TriangleMesh& mesh, int32_t n, const Eigen::Ref<const AmbientVectors>& vectors) {
  RETURN_IF_ERROR(CheckN(n));
  RETURN_IF_ERROR(CheckRowCount(mesh, vectors.rows(), 3));
  RETURN_IF_ERROR(CheckRows(vectors, vectors.rows(), Identity(), false));
  Eigen::VectorXd dofs(2 * vectors.rows());
  ParallelRows(vectors.rows(), [&](int64_t f) {
    dofs.segment<2>(2 * f) = PowerRepresentation(ToFrame(mesh, f, vectors.row(f).transpose()), n);
  });
  return dofs;
}

absl::StatusOr<AmbientVectors> NFieldRepresentativeFromDofs(
    const TriangleMesh& mesh, int32_t n, const Eigen::Ref<const Eigen::VectorXd>& dofs) {
  RETURN_IF_ERROR(CheckN(n));
  RETURN_IF_ERROR(CheckDofs(dofs, mesh.num_faces(), 2, Identity()));
  AmbientVectors out(mesh.num_faces(), 3);
  ParallelRows(mesh.num_faces(), [&](int64_t f) {
    out.row(f) = FromFrame(mesh, f, RootDirection(dofs.segment<2>(2 * f), n, 0)).transpose();
  });
  return out;
}

absl::StatusOr<std::vector<AmbientVectors>> NFieldDirectionsFromDofs(
    const TriangleMesh& mesh, int32_t n, const Eigen::Ref<const Eigen::VectorXd>& dofs) {
  RETURN_IF_ERROR(CheckN(n));
  RETURN_IF_ERROR(CheckDofs(dofs, mesh.num_faces(), 2, Identity()));
  std::vector<AmbientVectors> out(n, AmbientVectors(mesh.num_faces(), 3));
  ParallelRows(mesh.num_faces(), [&](int64_t f) {
    for (int32_t k = 0; k < n; ++k) {
      out[k].row(f) = FromFrame(mesh, f, RootDirection(dofs.segment<2>(2 * f), n, k)).transpose();
    }
  });
  return out;
}

absl::StatusOr<Eigen::VectorXd> TensorDofsFromAmbient(
    const TriangleMesh& mesh, const Eigen::Ref<const AmbientTensors>& tensors) {
  RETURN_IF_ERROR(CheckRowCount(mesh, tensors.rows(), 9));
  RETURN_IF_ERROR(CheckRows(tensors, tensors.rows(), Identity(), true));
  Eigen::VectorXd dofs(3 * tensors.rows());
  ParallelRows(tensors.rows(), [&](int64_t f) {
    Eigen::Matrix3d A;
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 3; ++c) A(r, c) = tensors(f, 3 * r + c);
    }
    dofs.segment<3>(3 * f) = TensorToMandelVoigt(mesh, f, A);
  });
  return dofs;
}

absl::StatusOr<AmbientTensors> AmbientFromTensorDofs(
    const TriangleMesh& mesh, const Eigen::Ref<const Eigen::VectorXd>& dofs) {
  RETURN_IF_ERROR(CheckDofs(dofs, mesh.num_faces(), 3, Identity()));
  AmbientTensors out(mesh.num_faces(), 9);
  ParallelRows(mesh.num_faces(), [&](int64_t f) {
    const Eigen::Matrix3d A = MandelVoigtToTensor(mesh, f, dofs.segment<3>(3 * f));
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 3; ++c) out(f, 3 * r + c) = A(r, c);
    }
  });
  return out;
}

absl::StatusOr<Eigen::VectorXd> DofsFromAmbient(const TriangleMesh& mesh, const FieldType& type,
                                                absl::Span<const int32_t> faces,
                                                const Eigen::Ref<const Eigen::MatrixXd>& values) {
  RETURN_IF_ERROR(type.Validate());
  const int64_t rows = static_cast<int64_t>(faces.size());
  const int64_t cols = type.kind == FieldKind::kTensor ? 9 : 3;
  if (values.rows() != rows || values.cols() != cols) {
    return absl::InvalidArgumentError(
        absl::StrFormat("expected %d x %d values (one row per listed face), got %d x %d", rows,
                        cols, values.rows(), values.cols()));
  }
  RETURN_IF_ERROR(CheckFaces(faces, mesh.num_faces(), ""));
  auto face_of = [&](int64_t i) { return faces[i]; };
  RETURN_IF_ERROR(CheckRows(values, rows, face_of, type.kind == FieldKind::kTensor));
  const int32_t p = type.dofs_per_face();
  Eigen::VectorXd dofs(rows * p);
  ParallelRows(rows, [&](int64_t i) {
    const int32_t f = faces[i];
    switch (type.kind) {
      case FieldKind::kVector:
        dofs.segment<2>(2 * i) = ToFrame(mesh, f, values.row(i).transpose());
        break;
      case FieldKind::kNField:
        dofs.segment<2>(2 * i) =
            PowerRepresentation(ToFrame(mesh, f, values.row(i).transpose()), type.n);
        break;
      case FieldKind::kTensor: {
        Eigen::Matrix3d A;
        for (int r = 0; r < 3; ++r) {
          for (int c = 0; c < 3; ++c) A(r, c) = values(i, 3 * r + c);
        }
        dofs.segment<3>(3 * i) = TensorToMandelVoigt(mesh, f, A);
        break;
      }
    }
  });
  return dofs;
}

absl::StatusOr<Eigen::MatrixXd> AmbientFromDofs(const TriangleMesh& mesh, const FieldType& type,
                                                absl::Span<const int32_t> faces,
                                                const Eigen::Ref<const Eigen::VectorXd>& dofs) {
  RETURN_IF_ERROR(type.Validate());
  const int64_t rows = static_cast<int64_t>(faces.size());
  RETURN_IF_ERROR(CheckFaces(faces, mesh.num_faces(), ""));
  const int32_t p = type.dofs_per_face();
  RETURN_IF_ERROR(CheckDofs(dofs, rows, p, [&](int64_t i) { return faces[i]; }));
  Eigen::MatrixXd out(rows, type.kind == FieldKind::kTensor ? 9 : 3);
  ParallelRows(rows, [&](int64_t i) {
    const int32_t f = faces[i];
    switch (type.kind) {
      case FieldKind::kVector:
        out.row(i) = FromFrame(mesh, f, dofs.segment<2>(2 * i)).transpose();
        break;
      case FieldKind::kNField:
        out.row(i) =
            FromFrame(mesh, f, RootDirection(dofs.segment<2>(2 * i), type.n, 0)).transpose();
        break;
      case FieldKind::kTensor: {
        const Eigen::Matrix3d A = MandelVoigtToTensor(mesh, f, dofs.segment<3>(3 * i));
        for (int r = 0; r < 3; ++r) {
          for (int c = 0; c < 3; ++c) out(i, 3 * r + c) = A(r, c);
        }
        break;
      }
    }
  });
  return out;
}

// --- Wire encodings -----------------------------------------------------------------------

namespace {

// Ambient (6-value) order of a symmetric tensor's 6 entries -> row-major 3 x 3 index.
constexpr int kTensorWire[6][2] = {{0, 0}, {1, 1}, {2, 2}, {0, 1}, {1, 2}, {2, 0}};

absl::Status CheckFacesAndSizes(const TriangleMesh& mesh, absl::Span<const int32_t> faces,
                                size_t values, size_t expected_values) {
  if (values != expected_values) {
    return absl::InvalidArgumentError(
        absl::StrCat("expected ", expected_values, " values, got ", values));
  }
  return CheckFaces(faces, mesh.num_faces(), "");
}

}  // namespace

int32_t ValuesPerFace(const FieldType& type, FieldEncoding encoding) {
  if (encoding == FieldEncoding::kDof) return type.dofs_per_face();
  return type.kind == FieldKind::kTensor ? 6 : 3;
}

absl::Status ValuesToDofs(const TriangleMesh& mesh, const FieldType& type, FieldEncoding encoding,
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
  if (encoding == FieldEncoding::kDof) {
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

absl::Status DofsToValues(const TriangleMesh& mesh, const FieldType& type, FieldEncoding encoding,
                          absl::Span<const int32_t> faces, absl::Span<const double> dofs,
                          absl::Span<float> out) {
  const int32_t vpf = ValuesPerFace(type, encoding);
  RETURN_IF_ERROR(
      CheckFacesAndSizes(mesh, faces, dofs.size(), faces.size() * type.dofs_per_face()));
  if (out.size() != faces.size() * vpf) {
    return absl::InternalError("DofsToValues: output size mismatch");
  }
  if (encoding == FieldEncoding::kDof) {
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

}  // namespace fieldspace
