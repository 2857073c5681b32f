#include "core/operators/curvature.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <optional>
#include <vector>

#include "Eigen/Cholesky"
#include "Eigen/Eigenvalues"
#include "Eigen/Geometry"
#include "Eigen/LU"
#include "absl/status/status.h"
#include "absl/strings/str_format.h"
#include "tbb/blocked_range.h"
#include "tbb/parallel_for.h"

namespace fieldspace {
namespace {

constexpr int64_t kGrain = 4096;

// Least squares eigenvalues below this fraction of the largest (edges scaled to unit length) are
// treated as zero: those components of B are not determined by the face's edges.
constexpr double kRelativeEigenvalueCutoff = 1e-12;

// Below this reciprocal condition number of the jet fit's normal matrix (coordinates scaled to the
// neighbourhood's radius) the quadric is not determined and the face falls back to normal
// differences.
constexpr double kJetMinReciprocalCondition = 1e-10;

Eigen::Vector3d Row(const VertexMatrix& m, int64_t i) { return m.row(i).transpose(); }

// The contribution of face f's corner k to the normal of its vertex.
Eigen::Vector3d CornerNormal(const TriangleMesh& mesh, int64_t f, int k,
                             VertexNormalWeighting weighting) {
  const VertexMatrix& V = mesh.vertices();
  const FaceMatrix& F = mesh.faces();
  const Eigen::Vector3d p = Row(V, F(f, k));
  const Eigen::Vector3d e1 = Row(V, F(f, (k + 1) % 3)) - p;
  const Eigen::Vector3d e2 = Row(V, F(f, (k + 2) % 3)) - p;
  switch (weighting) {
    case VertexNormalWeighting::kMax1999:
      return e1.cross(e2) / (e1.squaredNorm() * e2.squaredNorm());
    case VertexNormalWeighting::kAngle: {
      const Eigen::Vector3d n = Row(mesh.face_normals(), f);
      return std::atan2(e1.cross(e2).norm(), e1.dot(e2)) * n;
    }
    case VertexNormalWeighting::kArea:
      return 0.5 * e1.cross(e2);
  }
  return Eigen::Vector3d::Zero();
}

// Sums corner contributions into their vertices. Serial: a scatter over 3 #F corners is a small
// part of the cost and stays deterministic.
VertexMatrix AccumulateNormals(const TriangleMesh& mesh, VertexNormalWeighting weighting) {
  VertexMatrix N = VertexMatrix::Zero(mesh.num_vertices(), 3);
  const FaceMatrix& F = mesh.faces();
  for (int64_t f = 0; f < mesh.num_faces(); ++f) {
    for (int k = 0; k < 3; ++k) N.row(F(f, k)) += CornerNormal(mesh, f, k, weighting).transpose();
  }
  return N;
}

absl::Status CheckTensorDofs(const TriangleMesh& mesh, const Eigen::Ref<const Eigen::VectorXd>& a) {
  const int64_t expected = 3 * int64_t{mesh.num_faces()};
  if (a.size() != expected) {
    return absl::InvalidArgumentError(
        absl::StrFormat("tensor field has %d DOFs, expected 3 per face = %d", a.size(), expected));
  }
  for (int64_t i = 0; i < a.size(); ++i) {
    if (!std::isfinite(a[i])) {
      return absl::InvalidArgumentError(
          absl::StrFormat("tensor field has a non-finite value at face %d", i / 3));
    }
  }
  return absl::OkStatus();
}

// Frame-coordinate trace-free part q = (B11 - B22, 2 B12) of face f's Mandel-Voigt DOFs: its angle
// is twice the frame angle of the maximum principal direction, its length k1 - k2.
Eigen::Vector2d TraceFree(const Eigen::Ref<const Eigen::VectorXd>& a, int64_t f) {
  return {a[3 * f] - a[3 * f + 1], std::sqrt(2.0) * a[3 * f + 2]};
}

// Rusinkiewicz 2004, per face: the symmetric B (frame coordinates) that best maps the three edges
// to the differences of the vertex normals at their ends. Always finite.
Eigen::Matrix2d NormalDifferencesFace(const TriangleMesh& mesh, const VertexMatrix& normals,
                                      int64_t f) {
  const VertexMatrix& V = mesh.vertices();
  const FaceMatrix& F = mesh.faces();
  const Eigen::Vector3d x = Row(mesh.frame_x(), f), y = Row(mesh.frame_y(), f);
  // Edges are scaled by 1 / longest so the normal equations are O(1) whatever the mesh's units;
  // B = B_scaled / longest.
  double longest = 0;
  Eigen::Vector2d e[3], dn[3];
  for (int k = 0; k < 3; ++k) {
    const int32_t a = F(f, (k + 1) % 3), b = F(f, (k + 2) % 3);
    const Eigen::Vector3d edge = Row(V, b) - Row(V, a);
    const Eigen::Vector3d dnormal = Row(normals, b) - Row(normals, a);
    e[k] = {edge.dot(x), edge.dot(y)};
    dn[k] = {dnormal.dot(x), dnormal.dot(y)};
    longest = std::max(longest, e[k].norm());
  }
  // Unknowns (B11, B12, B22); each edge gives the rows [u v 0] and [0 u v] with (u, v) = e_k.
  Eigen::Matrix3d N = Eigen::Matrix3d::Zero();
  Eigen::Vector3d rhs = Eigen::Vector3d::Zero();
  for (int k = 0; k < 3; ++k) {
    const double u = e[k][0] / longest, v = e[k][1] / longest;
    const Eigen::Vector3d row0(u, v, 0), row1(0, u, v);
    N += row0 * row0.transpose() + row1 * row1.transpose();
    rhs += row0 * dn[k][0] + row1 * dn[k][1];
  }
  // Minimum-norm least squares through the eigen-decomposition of the 3 x 3 normal matrix, so a
  // thin face gives zero, not noise or NaN, in the components its edges do not see.
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(N);
  const Eigen::Vector3d lambda = eig.eigenvalues();
  const Eigen::Matrix3d& Q = eig.eigenvectors();
  const double cutoff = kRelativeEigenvalueCutoff * lambda[2];
  Eigen::Vector3d coeff = Q.transpose() * rhs;
  for (int i = 0; i < 3; ++i) coeff[i] = lambda[i] > cutoff ? coeff[i] / lambda[i] : 0.0;
  const Eigen::Vector3d b = (Q * coeff) / longest;  // (B11, B12, B22)
  Eigen::Matrix2d B;
  B << b[0], b[1], b[1], b[2];
  return B;
}

// Faces around each vertex (CSR).
struct VertexFaces {
  std::vector<int64_t> offsets;  // #V + 1
  std::vector<int32_t> faces;    // 3 #F
};

VertexFaces BuildVertexFaces(const TriangleMesh& mesh) {
  const FaceMatrix& F = mesh.faces();
  VertexFaces vf;
  vf.offsets.assign(mesh.num_vertices() + 1, 0);
  for (int64_t f = 0; f < F.rows(); ++f) {
    for (int k = 0; k < 3; ++k) ++vf.offsets[F(f, k) + 1];
  }
  for (int32_t v = 0; v < mesh.num_vertices(); ++v) vf.offsets[v + 1] += vf.offsets[v];
  vf.faces.resize(3 * F.rows());
  std::vector<int64_t> cursor(vf.offsets.begin(), vf.offsets.end() - 1);
  for (int64_t f = 0; f < F.rows(); ++f) {
    for (int k = 0; k < 3; ++k) vf.faces[cursor[F(f, k)]++] = static_cast<int32_t>(f);
  }
  return vf;
}

// Cazals and Pouget 2003, degree 2: the height over face f's plane, w = n_f . (p - c) at
// (u, v) = ((p - c) . x_f, (p - c) . y_f), c the barycenter, is fitted by least squares as
// w = a0 + a1 u + a2 v + a3 u^2 + a4 u v + a5 v^2 to the vertices of every face that shares a
// vertex with f. The shape operator of that graph at (0, 0), with the normal on the side of n_f,
// restricted to the face plane (the face frame's projection [x y]^T A [x y] of the ambient
// tangent tensor A) is B = -I^-1 H I^-1 / s with H = [[2 a3, a4], [a4, 2 a5]] the Hessian,
// I = Id + g g^T the first fundamental form, g = (a1, a2), s = sqrt(1 + |g|^2). Returns nothing
// when the neighbourhood does not determine the quadric (fewer than 6 vertices, or a normal
// matrix with reciprocal condition below 1e-10), so the caller falls back.
std::optional<Eigen::Matrix2d> JetFitFace(const TriangleMesh& mesh, const VertexFaces& vf,
                                          int64_t f, std::vector<int32_t>& ring) {
  const VertexMatrix& V = mesh.vertices();
  const FaceMatrix& F = mesh.faces();
  ring.clear();
  for (int k = 0; k < 3; ++k) {
    const int32_t v = F(f, k);
    for (int64_t i = vf.offsets[v]; i < vf.offsets[v + 1]; ++i) {
      for (int j = 0; j < 3; ++j) ring.push_back(F(vf.faces[i], j));
    }
  }
  std::sort(ring.begin(), ring.end());
  ring.erase(std::unique(ring.begin(), ring.end()), ring.end());
  if (ring.size() < 6) return std::nullopt;
  const Eigen::Vector3d c = Row(mesh.face_barycenters(), f);
  const Eigen::Vector3d x = Row(mesh.frame_x(), f), y = Row(mesh.frame_y(), f),
                        n = Row(mesh.face_normals(), f);
  // Coordinates scaled by the neighbourhood's radius so the normal matrix is O(1).
  double radius = 0;
  for (int32_t v : ring) radius = std::max(radius, (Row(V, v) - c).norm());
  const double inv = 1.0 / radius;
  Eigen::Matrix<double, 6, 6> N = Eigen::Matrix<double, 6, 6>::Zero();
  Eigen::Matrix<double, 6, 1> rhs = Eigen::Matrix<double, 6, 1>::Zero();
  for (int32_t v : ring) {
    const Eigen::Vector3d d = (Row(V, v) - c) * inv;
    const double u = d.dot(x), w = d.dot(y), h = d.dot(n);
    Eigen::Matrix<double, 6, 1> m;
    m << 1, u, w, u * u, u * w, w * w;
    N.selfadjointView<Eigen::Lower>().rankUpdate(m);
    rhs += h * m;
  }
  const Eigen::LDLT<Eigen::Matrix<double, 6, 6>> ldlt(N.selfadjointView<Eigen::Lower>());
  if (ldlt.info() != Eigen::Success || !(ldlt.rcond() > kJetMinReciprocalCondition)) {
    return std::nullopt;
  }
  const Eigen::Matrix<double, 6, 1> a = ldlt.solve(rhs);
  if (!a.allFinite()) return std::nullopt;
  const Eigen::Vector2d g(a[1], a[2]);
  Eigen::Matrix2d H;
  H << 2 * a[3], a[4], a[4], 2 * a[5];
  const Eigen::Matrix2d I_inv = (Eigen::Matrix2d::Identity() + g * g.transpose()).inverse();
  const double s = std::sqrt(1 + g.squaredNorm());
  // Scaled heights over scaled coordinates: second derivatives scale by 1 / radius.
  return Eigen::Matrix2d(-(I_inv * H * I_inv) / (s * radius));
}

}  // namespace

VertexMatrix ComputeVertexNormals(const TriangleMesh& mesh, VertexNormalWeighting weighting) {
  VertexMatrix N = AccumulateNormals(mesh, weighting);
  VertexMatrix area_weighted;    // only built if some vertex needs it
  std::vector<int64_t> face_at;  // one face per vertex, likewise
  const FaceMatrix& F = mesh.faces();
  for (int32_t v = 0; v < mesh.num_vertices(); ++v) {
    double norm = N.row(v).norm();
    if (norm > 0 && std::isfinite(norm)) {
      N.row(v) /= norm;
      continue;
    }
    if (area_weighted.size() == 0) {
      area_weighted = AccumulateNormals(mesh, VertexNormalWeighting::kArea);
    }
    N.row(v) = area_weighted.row(v);
    norm = N.row(v).norm();
    if (norm > 0 && std::isfinite(norm)) {
      N.row(v) /= norm;
      continue;
    }
    // Cancelling face normals: take any face at v (every kept vertex has one).
    if (face_at.empty()) {
      face_at.assign(mesh.num_vertices(), 0);
      for (int64_t f = 0; f < mesh.num_faces(); ++f) {
        for (int k = 0; k < 3; ++k) face_at[F(f, k)] = f;
      }
    }
    N.row(v) = mesh.face_normals().row(face_at[v]);
  }
  return N;
}

absl::StatusOr<Eigen::VectorXd> ComputeShapeOperator(const TriangleMesh& mesh,
                                                     const ShapeOperatorOptions& options) {
  switch (options.normal_weighting) {
    case VertexNormalWeighting::kMax1999:
    case VertexNormalWeighting::kAngle:
    case VertexNormalWeighting::kArea:
      break;
    default:
      return absl::InvalidArgumentError("unknown vertex normal weighting");
  }
  switch (options.estimator) {
    case CurvatureEstimator::kJetFit:
    case CurvatureEstimator::kNormalDifferences:
      break;
    default:
      return absl::InvalidArgumentError("unknown curvature estimator");
  }
  const int64_t nf = mesh.num_faces();
  Eigen::VectorXd dofs(3 * nf);
  auto store = [&](int64_t f, const Eigen::Matrix2d& B) {
    dofs[3 * f] = B(0, 0);
    dofs[3 * f + 1] = B(1, 1);
    dofs[3 * f + 2] = std::sqrt(2.0) * 0.5 * (B(0, 1) + B(1, 0));
  };
  // Faces that take normal differences: all of them, or the jet fit's fallbacks. Vertex normals
  // are only computed if there is one.
  std::vector<int64_t> fallback;
  if (options.estimator == CurvatureEstimator::kJetFit) {
    const VertexFaces vertex_faces = BuildVertexFaces(mesh);
    std::vector<uint8_t> failed(nf, 0);
    tbb::parallel_for(tbb::blocked_range<int64_t>(0, nf, kGrain), [&](const auto& range) {
      if (IsCancelled(options.cancel)) return;
      std::vector<int32_t> ring;
      for (int64_t f = range.begin(); f < range.end(); ++f) {
        const std::optional<Eigen::Matrix2d> B = JetFitFace(mesh, vertex_faces, f, ring);
        if (B.has_value()) {
          store(f, *B);
        } else {
          failed[f] = 1;
        }
      }
    });
    if (IsCancelled(options.cancel)) return absl::CancelledError("shape operator: cancelled");
    for (int64_t f = 0; f < nf; ++f) {
      if (failed[f]) fallback.push_back(f);
    }
  } else {
    fallback.resize(nf);
    for (int64_t f = 0; f < nf; ++f) fallback[f] = f;
  }
  if (fallback.empty()) return dofs;
  const VertexMatrix normals = ComputeVertexNormals(mesh, options.normal_weighting);
  const int64_t count = static_cast<int64_t>(fallback.size());
  tbb::parallel_for(tbb::blocked_range<int64_t>(0, count, kGrain), [&](const auto& range) {
    if (IsCancelled(options.cancel)) return;
    for (int64_t i = range.begin(); i < range.end(); ++i) {
      store(fallback[i], NormalDifferencesFace(mesh, normals, fallback[i]));
    }
  });
  if (IsCancelled(options.cancel)) return absl::CancelledError("shape operator: cancelled");
  return dofs;
}

absl::StatusOr<PrincipalCurvatures> ComputePrincipalCurvatures(
    const TriangleMesh& mesh, const Eigen::Ref<const Eigen::VectorXd>& tensor_dofs) {
  if (absl::Status s = CheckTensorDofs(mesh, tensor_dofs); !s.ok()) return s;
  const int64_t nf = mesh.num_faces();
  PrincipalCurvatures pc;
  pc.k1.resize(nf);
  pc.k2.resize(nf);
  pc.d1.resize(nf, 3);
  pc.d2.resize(nf, 3);
  tbb::parallel_for(tbb::blocked_range<int64_t>(0, nf, kGrain), [&](const auto& range) {
    for (int64_t f = range.begin(); f < range.end(); ++f) {
      const double mean = 0.5 * (tensor_dofs[3 * f] + tensor_dofs[3 * f + 1]);
      const Eigen::Vector2d q = TraceFree(tensor_dofs, f);
      const double half = 0.5 * std::hypot(q[0], q[1]);
      pc.k1[f] = mean + half;
      pc.k2[f] = mean - half;
      // atan2(0, 0) = 0: an umbilic face gets d1 = x_f.
      const double theta = 0.5 * std::atan2(q[1], q[0]);
      const Eigen::Vector3d x = Row(mesh.frame_x(), f), y = Row(mesh.frame_y(), f);
      const double c = std::cos(theta), s = std::sin(theta);
      pc.d1.row(f) = c * x + s * y;
      pc.d2.row(f) = c * y - s * x;  // n_f x d1, with n_f x x_f = y_f and n_f x y_f = -x_f
    }
  });
  return pc;
}

absl::StatusOr<CurvatureAlignedTargets> ComputeCurvatureAlignedTargets(
    const TriangleMesh& mesh, const Eigen::Ref<const Eigen::VectorXd>& tensor_dofs, int32_t n) {
  if (n != 2 && n != 4) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "curvature-aligned targets exist for n = 2 (maximum direction) and n = 4 (principal "
        "cross), got n = %d",
        n));
  }
  if (absl::Status s = CheckTensorDofs(mesh, tensor_dofs); !s.ok()) return s;
  const int64_t nf = mesh.num_faces();
  CurvatureAlignedTargets t;
  t.n = n;
  t.dofs.resize(2 * nf);
  t.weights.resize(nf);
  tbb::parallel_for(tbb::blocked_range<int64_t>(0, nf, kGrain), [&](const auto& range) {
    for (int64_t f = range.begin(); f < range.end(); ++f) {
      const Eigen::Vector2d q = TraceFree(tensor_dofs, f);
      const double len = std::hypot(q[0], q[1]);
      t.weights[f] = len;
      Eigen::Vector2d u = Eigen::Vector2d::Zero();
      if (len > 0) {
        u = q / len;  // angle 2 theta
        // Squaring the unit complex number doubles the angle: 4 theta.
        if (n == 4) u = Eigen::Vector2d(u[0] * u[0] - u[1] * u[1], 2 * u[0] * u[1]).normalized();
      }
      t.dofs.segment<2>(2 * f) = u;
    }
  });
  return t;
}

}  // namespace fieldspace
