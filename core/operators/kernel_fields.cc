#include "core/operators/kernel_fields.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <utility>
#include <vector>

#include "Eigen/Dense"
#include "Eigen/SparseCore"
#include "absl/strings/str_format.h"
#include "core/common/status_macros.h"
#include "core/linalg/sparse_cholesky.h"

namespace fieldspace {
namespace {

absl::Status Cancelled() { return absl::CancelledError("kernel field computation cancelled"); }

// Face f's edge vectors t_k (opposite corner k, counter-clockwise: corner k+1 to k+2) in frame
// coordinates.
Eigen::Matrix<double, 2, 3> FrameEdges(const TriangleMesh& mesh, int32_t f) {
  const FaceMatrix& F = mesh.faces();
  const Eigen::Vector3d x = mesh.frame_x().row(f).transpose();
  const Eigen::Vector3d y = mesh.frame_y().row(f).transpose();
  Eigen::Matrix<double, 2, 3> t;
  for (int k = 0; k < 3; ++k) {
    const Eigen::Vector3d e = mesh.vertices().row(F(f, (k + 2) % 3)).transpose() -
                              mesh.vertices().row(F(f, (k + 1) % 3)).transpose();
    t(0, k) = e.dot(x);
    t(1, k) = e.dot(y);
  }
  return t;
}

// Gradients of the hat functions of face f's corners in frame coordinates (columns):
// grad phi_k = J t_k / (2 area).
Eigen::Matrix<double, 2, 3> HatGradients(const TriangleMesh& mesh, int32_t f) {
  const Eigen::Matrix<double, 2, 3> t = FrameEdges(mesh, f);
  const double s = 0.5 / mesh.face_areas()[f];
  Eigen::Matrix<double, 2, 3> g;
  for (int k = 0; k < 3; ++k) {
    g(0, k) = -s * t(1, k);
    g(1, k) = s * t(0, k);
  }
  return g;
}

// +1 when face f traverses its edge opposite corner k (corner k+1 to k+2) from the edge's lower
// to its higher vertex index, else -1.
double EdgeSign(const TriangleMesh& mesh, int32_t f, int k) {
  const FaceMatrix& F = mesh.faces();
  return F(f, (k + 1) % 3) < F(f, (k + 2) % 3) ? 1.0 : -1.0;
}

// The candidate fields of the vector Hodge Laplacian's kernel (see the header): one harmonic
// field per tree-cotree generator. Columns of a k x (generators) matrix.
absl::StatusOr<Eigen::MatrixXd> HarmonicCandidates(const TriangleMesh& mesh,
                                                   const CancelFlag* cancel) {
  const int32_t nv = mesh.num_vertices();
  const int32_t ne = mesh.num_edges();
  const int32_t nf = mesh.num_faces();
  const PairMatrix& E = mesh.edges();
  const FaceMatrix& FE = mesh.face_edges();
  const FaceMatrix& FN = mesh.face_neighbors();

  // 1a. Primal spanning forest (BFS over the edges).
  std::vector<int64_t> offset(static_cast<size_t>(nv) + 1, 0);
  for (int32_t e = 0; e < ne; ++e) {
    ++offset[E(e, 0) + 1];
    ++offset[E(e, 1) + 1];
  }
  for (int32_t v = 0; v < nv; ++v) offset[v + 1] += offset[v];
  std::vector<int32_t> incident(static_cast<size_t>(2) * ne);
  {
    std::vector<int64_t> cursor(offset.begin(), offset.end() - 1);
    for (int32_t e = 0; e < ne; ++e) {
      incident[cursor[E(e, 0)]++] = e;
      incident[cursor[E(e, 1)]++] = e;
    }
  }
  std::vector<uint8_t> in_tree(ne, 0), seen_vertex(nv, 0);
  std::vector<int32_t> queue;
  queue.reserve(nv);
  for (int32_t root = 0; root < nv; ++root) {
    if (seen_vertex[root]) continue;
    seen_vertex[root] = 1;
    queue.clear();
    queue.push_back(root);
    for (size_t head = 0; head < queue.size(); ++head) {
      const int32_t v = queue[head];
      for (int64_t q = offset[v]; q < offset[v + 1]; ++q) {
        const int32_t e = incident[q];
        const int32_t w = E(e, 0) == v ? E(e, 1) : E(e, 0);
        if (seen_vertex[w]) continue;
        seen_vertex[w] = 1;
        in_tree[e] = 1;
        queue.push_back(w);
      }
    }
  }
  if (IsCancelled(cancel)) return Cancelled();

  // 1b. Dual spanning forest across the non-tree edges. A component with a boundary is rooted at
  // a virtual face beyond all its boundary loops (joined to the faces through boundary edges), a
  // closed one at its first face. parent_edge[f] = -1 for a root face.
  const int32_t nc = mesh.num_components();
  std::vector<uint8_t> has_boundary(nc, 0);
  for (int32_t c = 0; c < nc; ++c) has_boundary[c] = mesh.components()[c].num_boundary_loops > 0;
  std::vector<int32_t> parent_edge(nf, -1);
  std::vector<uint8_t> in_cotree(ne, 0), seen_face(nf, 0);
  std::vector<int32_t> order;  // faces in BFS order, every component
  order.reserve(nf);
  std::vector<uint8_t> component_done(nc, 0);
  for (int32_t f0 = 0; f0 < nf; ++f0) {
    const int32_t c = mesh.face_component()[f0];
    if (component_done[c]) continue;
    component_done[c] = 1;
    const size_t start = order.size();
    if (has_boundary[c]) {
      // The virtual root's children: faces with a boundary edge outside the primal tree.
      for (int32_t f = f0; f < nf; ++f) {
        if (mesh.face_component()[f] != c || seen_face[f]) continue;
        for (int k = 0; k < 3; ++k) {
          const int32_t e = FE(f, k);
          if (FN(f, k) == kNoFace && !in_tree[e]) {
            seen_face[f] = 1;
            parent_edge[f] = e;
            in_cotree[e] = 1;
            order.push_back(f);
            break;
          }
        }
      }
    } else {
      seen_face[f0] = 1;
      order.push_back(f0);
    }
    for (size_t head = start; head < order.size(); ++head) {
      const int32_t f = order[head];
      for (int k = 0; k < 3; ++k) {
        const int32_t e = FE(f, k);
        const int32_t g = FN(f, k);
        if (g == kNoFace || in_tree[e] || seen_face[g]) continue;
        seen_face[g] = 1;
        parent_edge[g] = e;
        in_cotree[e] = 1;
        order.push_back(g);
      }
    }
  }
  if (static_cast<int32_t>(order.size()) != nf) {
    return absl::InternalError(
        absl::StrFormat("tree-cotree: the dual tree reached %d of %d faces", order.size(), nf));
  }
  std::vector<int32_t> generators;
  for (int32_t e = 0; e < ne; ++e) {
    if (!in_tree[e] && !in_cotree[e]) generators.push_back(e);
  }
  // Per component: 1 - chi generators with a boundary, 2 - chi = 2 g without.
  int64_t expected = 0;
  for (int32_t c = 0; c < nc; ++c) {
    expected += (has_boundary[c] ? 1 : 2) - mesh.components()[c].euler_characteristic;
  }
  if (static_cast<int64_t>(generators.size()) != expected) {
    return absl::InternalError(
        absl::StrFormat("tree-cotree: %d generator edges where the topology implies %d",
                        generators.size(), expected));
  }
  const int32_t ng = static_cast<int32_t>(generators.size());
  Eigen::MatrixXd X = Eigen::MatrixXd::Zero(2 * static_cast<Eigen::Index>(nf), ng);
  if (ng == 0) return X;

  // 2. One cocycle per generator, solved face by face from the leaves of the dual tree up, read
  // as a piecewise constant field: with u = 0 at corner 0, u1 = omega(corner 0 -> 1) and
  // u2 = u1 + omega(corner 1 -> 2), X_f = u1 grad phi_1 + u2 grad phi_2.
  std::vector<Eigen::Matrix<double, 2, 3>> grads(nf);
  for (int32_t f = 0; f < nf; ++f) grads[f] = HatGradients(mesh, f);
  std::vector<double> omega(ne, 0.0);
  for (int32_t j = 0; j < ng; ++j) {
    std::fill(omega.begin(), omega.end(), 0.0);
    omega[generators[j]] = 1.0;
    for (int32_t i = nf - 1; i >= 0; --i) {
      const int32_t f = order[i];
      const int32_t p = parent_edge[f];
      if (p < 0) continue;  // a closed component's root: its equation holds by the others
      double sum = 0.0, sign_p = 0.0;
      for (int k = 0; k < 3; ++k) {
        const int32_t e = FE(f, k);
        if (e == p) {
          sign_p = EdgeSign(mesh, f, k);
        } else {
          sum += EdgeSign(mesh, f, k) * omega[e];
        }
      }
      omega[p] = -sum / sign_p;
    }
    for (int32_t f = 0; f < nf; ++f) {
      const double u1 = EdgeSign(mesh, f, 2) * omega[FE(f, 2)];
      const double u2 = u1 + EdgeSign(mesh, f, 0) * omega[FE(f, 0)];
      X.block<2, 1>(2 * f, j) = u1 * grads[f].col(1) + u2 * grads[f].col(2);
    }
    if (IsCancelled(cancel)) return Cancelled();
  }
  std::vector<double>().swap(omega);

  // 3. Remove the exact part: L u = G_V^T M X with L = G_V^T M G_V (cotan Laplacian, #V x #V,
  // symmetric PSD, constants per component in its kernel), one vertex per component pinned.
  const FaceMatrix& F = mesh.faces();
  std::vector<int32_t> pinned_of(nc, -1);
  for (int32_t f = 0; f < nf; ++f) {
    const int32_t c = mesh.face_component()[f];
    if (pinned_of[c] < 0) pinned_of[c] = F(f, 0);
  }
  std::vector<int32_t> index(nv, 0);
  for (int32_t c = 0; c < nc; ++c) index[pinned_of[c]] = -1;
  int32_t n = 0;
  for (int32_t v = 0; v < nv; ++v) index[v] = index[v] < 0 ? -1 : n++;
  Eigen::MatrixXd rhs = Eigen::MatrixXd::Zero(n, ng);
  std::vector<Eigen::Triplet<double>> triplets;
  triplets.reserve(static_cast<size_t>(9) * nf);
  for (int32_t f = 0; f < nf; ++f) {
    const double a = mesh.face_areas()[f];
    for (int r = 0; r < 3; ++r) {
      const int32_t i = index[F(f, r)];
      if (i < 0) continue;
      rhs.row(i) += a * grads[f].col(r).transpose() * X.middleRows<2>(2 * f);
      for (int c = 0; c < 3; ++c) {
        const int32_t j = index[F(f, c)];
        if (j >= 0) triplets.emplace_back(i, j, a * grads[f].col(r).dot(grads[f].col(c)));
      }
    }
  }
  if (n > 0) {
    Eigen::SparseMatrix<double> L(n, n);
    L.setFromTriplets(triplets.begin(), triplets.end());
    std::vector<Eigen::Triplet<double>>().swap(triplets);
    if (IsCancelled(cancel)) return Cancelled();
    CholeskyOptions cholesky;
    cholesky.check_input = false;  // symmetric by construction (summed in the same order)
    ASSIGN_OR_RETURN(SparseCholesky factor, SparseCholesky::Factorize(L, cholesky));
    if (IsCancelled(cancel)) return Cancelled();
    ASSIGN_OR_RETURN(Eigen::MatrixXd u, factor.SolveMatrix(rhs));
    for (int32_t f = 0; f < nf; ++f) {
      for (int r = 0; r < 3; ++r) {
        const int32_t i = index[F(f, r)];
        if (i >= 0) X.middleRows<2>(2 * f) -= grads[f].col(r) * u.row(i);
      }
    }
  }
  return X;
}

// The candidate fields of a connection Laplacian's kernel (n-fields, tensors): per component,
// p fields transported from its first face along a spanning tree of the dual graph. The
// transport P from face f to face g is read off S: S_gf = -w_e P with P orthogonal, so
// w_e = ||S_gf||_F / sqrt(p).
absl::StatusOr<Eigen::MatrixXd> ParallelCandidates(const TriangleMesh& mesh,
                                                   const FieldOperator& op,
                                                   const CancelFlag* cancel) {
  const int32_t p = op.type.dofs_per_face();
  const int32_t nf = mesh.num_faces();
  const FaceMatrix& FN = mesh.face_neighbors();
  const Eigen::SparseMatrix<double>& S = op.stiffness;
  // blocks[3 f + k] = S_gf for g = FN(f, k).
  std::vector<Eigen::Matrix3d> blocks(static_cast<size_t>(3) * nf, Eigen::Matrix3d::Zero());
  for (int32_t f = 0; f < nf; ++f) {
    for (int32_t cj = 0; cj < p; ++cj) {
      const int64_t col = static_cast<int64_t>(p) * f + cj;
      for (Eigen::SparseMatrix<double>::InnerIterator it(S, col); it; ++it) {
        const int32_t g = static_cast<int32_t>(it.row() / p);
        if (g == f) continue;
        for (int k = 0; k < 3; ++k) {
          if (FN(f, k) == g) blocks[3 * f + k](it.row() % p, cj) = it.value();
        }
      }
    }
  }
  const int32_t nc = mesh.num_components();
  Eigen::MatrixXd X =
      Eigen::MatrixXd::Zero(static_cast<Eigen::Index>(p) * nf, static_cast<Eigen::Index>(p) * nc);
  std::vector<uint8_t> seen(nf, 0), done(nc, 0);
  std::vector<int32_t> queue;
  queue.reserve(nf);
  for (int32_t f0 = 0; f0 < nf; ++f0) {
    const int32_t c = mesh.face_component()[f0];
    if (done[c]) continue;
    done[c] = 1;
    queue.clear();
    queue.push_back(f0);
    seen[f0] = 1;
    X.block(static_cast<Eigen::Index>(p) * f0, static_cast<Eigen::Index>(p) * c, p, p)
        .setIdentity();
    for (size_t head = 0; head < queue.size(); ++head) {
      const int32_t f = queue[head];
      for (int k = 0; k < 3; ++k) {
        const int32_t g = FN(f, k);
        if (g == kNoFace || seen[g]) continue;
        const Eigen::MatrixXd B = blocks[3 * f + k].topLeftCorner(p, p);
        const double w = B.norm() / std::sqrt(static_cast<double>(p));
        if (!(w > 0)) continue;  // no coupling across this edge
        seen[g] = 1;
        queue.push_back(g);
        X.block(static_cast<Eigen::Index>(p) * g, static_cast<Eigen::Index>(p) * c, p, p) =
            (-1.0 / w) * B *
            X.block(static_cast<Eigen::Index>(p) * f, static_cast<Eigen::Index>(p) * c, p, p);
      }
    }
    if (IsCancelled(cancel)) return Cancelled();
  }
  return X;
}

}  // namespace

absl::StatusOr<Eigen::MatrixXd> ComputeKernelFields(const TriangleMesh& mesh,
                                                    const FieldOperator& op,
                                                    const KernelFieldOptions& options,
                                                    KernelFieldStats* stats) {
  const auto t0 = std::chrono::steady_clock::now();
  const int64_t k = static_cast<int64_t>(op.type.dofs_per_face()) * mesh.num_faces();
  if (op.dofs() != k || op.stiffness.rows() != k || op.stiffness.cols() != k) {
    return absl::InvalidArgumentError(
        absl::StrFormat("operator size (S %d x %d, mass %d) does not match the mesh (%d DOFs)",
                        op.stiffness.rows(), op.stiffness.cols(), op.dofs(), k));
  }
  if (!(options.accept_tolerance > 0) || !std::isfinite(options.accept_tolerance)) {
    return absl::InvalidArgumentError("accept_tolerance must be finite and > 0");
  }
  KernelFieldStats local_stats;
  KernelFieldStats& st = stats != nullptr ? *stats : local_stats;
  st = KernelFieldStats();
  const bool vector = op.type.kind == FieldKind::kVector;
  Eigen::MatrixXd H;
  if (vector) {
    ASSIGN_OR_RETURN(H, HarmonicCandidates(mesh, options.cancel));
    for (const MeshComponent& c : mesh.components()) {
      if (c.num_boundary_loops == 0) st.expected_harmonic += 2 - c.euler_characteristic;
    }
  } else {
    ASSIGN_OR_RETURN(H, ParallelCandidates(mesh, op, options.cancel));
  }
  st.candidates = static_cast<int32_t>(H.cols());
  st.lambda_ref = op.stiffness.diagonal().sum() / op.mass.sum();
  if (H.cols() == 0) {
    st.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    return H;
  }
  // 4. Rank-revealing M-orthonormalization, then Rayleigh-Ritz with S.
  const Eigen::MatrixXd MH = op.mass.asDiagonal() * H;
  Eigen::MatrixXd gram = H.transpose() * MH;
  gram = 0.5 * (gram + gram.transpose()).eval();
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> ge(gram);
  const double dmax = ge.eigenvalues().maxCoeff();
  std::vector<int> keep;
  for (int i = 0; i < gram.rows(); ++i) {
    if (ge.eigenvalues()[i] > 1e-12 * dmax) keep.push_back(i);
  }
  Eigen::MatrixXd W(gram.rows(), static_cast<Eigen::Index>(keep.size()));
  for (size_t i = 0; i < keep.size(); ++i) {
    W.col(i) = ge.eigenvectors().col(keep[i]) / std::sqrt(ge.eigenvalues()[keep[i]]);
  }
  Eigen::MatrixXd Z = H * W;
  H.resize(0, 0);
  if (IsCancelled(options.cancel)) return Cancelled();
  const Eigen::MatrixXd SZ = op.stiffness * Z;
  Eigen::MatrixXd Q = Z.transpose() * SZ;
  Q = 0.5 * (Q + Q.transpose()).eval();
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> qe(Q);
  std::vector<int> accepted;
  for (int i = 0; i < Q.rows(); ++i) {
    const double r = std::max(0.0, qe.eigenvalues()[i]) / st.lambda_ref;
    if (r <= options.accept_tolerance) {
      accepted.push_back(i);
      st.max_rayleigh = std::max(st.max_rayleigh, r);
    } else if (st.min_rejected == 0 || r < st.min_rejected) {
      st.min_rejected = r;
    }
  }
  if (vector && static_cast<int32_t>(accepted.size()) < st.expected_harmonic) {
    return absl::InternalError(absl::StrFormat(
        "only %d of the %d harmonic fields of the closed components passed the kernel test "
        "(Rayleigh quotient <= %g lambda_ref); smallest rejected %g",
        accepted.size(), st.expected_harmonic, options.accept_tolerance, st.min_rejected));
  }
  Eigen::MatrixXd R(Q.rows(), static_cast<Eigen::Index>(accepted.size()));
  for (size_t i = 0; i < accepted.size(); ++i) R.col(i) = qe.eigenvectors().col(accepted[i]);
  Eigen::MatrixXd result = Z * R;
  // One more M-orthonormalization against the rounding of the two small eigensolves.
  if (result.cols() > 0) {
    Eigen::MatrixXd g2 = result.transpose() * (op.mass.asDiagonal() * result);
    g2 = 0.5 * (g2 + g2.transpose()).eval();
    Eigen::LLT<Eigen::MatrixXd> llt(g2);
    if (llt.info() == Eigen::Success) {
      result = llt.matrixL().solve(result.transpose()).transpose();
    }
  }
  st.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return result;
}

absl::StatusOr<Eigen::MatrixXd> ComputeKernelFields(const TriangleMesh& mesh, const FieldType& type,
                                                    const KernelFieldOptions& options) {
  ASSIGN_OR_RETURN(FieldOperator op, BuildFieldOperator(mesh, type));
  return ComputeKernelFields(mesh, op, options);
}

}  // namespace fieldspace
