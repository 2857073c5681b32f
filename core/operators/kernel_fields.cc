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
#include "core/linalg/multigrid.h"
#include "core/linalg/sparse_cholesky.h"
#include "core/operators/vector_laplacian.h"
#include "tbb/blocked_range.h"
#include "tbb/parallel_for.h"
#include "tbb/parallel_reduce.h"

namespace fieldspace {
namespace {

using RowMatrix = MultigridRowMatrix;

// Relative residual of the multigrid Poisson solve. A residual r leaves the harmonic candidate
// an exact part whose Rayleigh quotient is about ||r||^2 / ||b||^2 times the candidate's exact
// part's, far below accept_tolerance (measured in docs/conventions.md, Kernel fields).
constexpr double kPoissonTolerance = 1e-12;

absl::Status Cancelled() { return absl::CancelledError("kernel field computation cancelled"); }

// The kernel candidates of one component (at most its kernel fields): for vector fields the
// tree-cotree generators, 1 - chi with a boundary and 2 - chi = 2 g without; p parallel fields
// otherwise.
int64_t ComponentCandidates(const MeshComponent& c, const FieldType& type) {
  if (type.kind != FieldKind::kVector) return type.dofs_per_face();
  return (c.num_boundary_loops > 0 ? 1 : 2) - c.euler_characteristic;
}

// Face f's edge vectors (TriangleMesh::EdgeVectorInFrame) as columns.
Eigen::Matrix<double, 2, 3> FrameEdges(const TriangleMesh& mesh, int32_t f) {
  Eigen::Matrix<double, 2, 3> t;
  for (int k = 0; k < 3; ++k) t.col(k) = mesh.EdgeVectorInFrame(f, k);
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
absl::StatusOr<RowMatrix> HarmonicCandidates(const TriangleMesh& mesh,
                                             const KernelFieldOptions& options,
                                             KernelFieldStats* stats) {
  const CancelFlag* cancel = options.cancel;
  const auto t0 = std::chrono::steady_clock::now();
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
  std::vector<int32_t> queue;  // ends up holding every vertex in BFS order
  queue.reserve(nv);
  for (int32_t root = 0; root < nv; ++root) {
    if (seen_vertex[root]) continue;
    seen_vertex[root] = 1;
    const size_t start = queue.size();
    queue.push_back(root);
    for (size_t head = start; head < queue.size(); ++head) {
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
  int64_t expected = 0;
  for (const MeshComponent& c : mesh.components()) {
    expected += ComponentCandidates(c, FieldType::Vector());
  }
  if (static_cast<int64_t>(generators.size()) != expected) {
    return absl::InternalError(
        absl::StrFormat("tree-cotree: %d generator edges where the topology implies %d",
                        generators.size(), expected));
  }
  const int32_t ng = static_cast<int32_t>(generators.size());
  RowMatrix X = RowMatrix::Zero(2 * static_cast<Eigen::Index>(nf), ng);
  if (ng == 0) return X;

  // 2. One cocycle per generator (all at once, edge-major), solved face by face from the leaves
  // of the dual tree up, read as a piecewise constant field: with u = 0 at corner 0,
  // u1 = omega(corner 0 -> 1) and u2 = u1 + omega(corner 1 -> 2),
  // X_f = u1 grad phi_1 + u2 grad phi_2.
  std::vector<Eigen::Matrix<double, 2, 3>> grads(nf);
  for (int32_t f = 0; f < nf; ++f) grads[f] = HatGradients(mesh, f);
  {
    RowMatrix omega = RowMatrix::Zero(ne, ng);
    for (int32_t j = 0; j < ng; ++j) omega(generators[j], j) = 1.0;
    for (int32_t i = nf - 1; i >= 0; --i) {
      const int32_t f = order[i];
      const int32_t p = parent_edge[f];
      if (p < 0) continue;  // a closed component's root: its equation holds by the others
      double sign_p = 0.0;
      auto row_p = omega.row(p);
      row_p.setZero();
      for (int k = 0; k < 3; ++k) {
        const int32_t e = FE(f, k);
        if (e == p) {
          sign_p = EdgeSign(mesh, f, k);
        } else {
          row_p += EdgeSign(mesh, f, k) * omega.row(e);
        }
      }
      row_p *= -1.0 / sign_p;
    }
    if (IsCancelled(cancel)) return Cancelled();
    for (int32_t f = 0; f < nf; ++f) {
      // Plain loops here and below: Eigen's dynamic-size row products allocate temporaries.
      const double s2 = EdgeSign(mesh, f, 2), s0 = EdgeSign(mesh, f, 0);
      const double* o2 = omega.data() + static_cast<Eigen::Index>(FE(f, 2)) * ng;
      const double* o0 = omega.data() + static_cast<Eigen::Index>(FE(f, 0)) * ng;
      double* x0 = X.data() + 2 * static_cast<Eigen::Index>(f) * ng;
      double* x1 = x0 + ng;
      const Eigen::Matrix<double, 2, 3>& g = grads[f];
      for (int32_t j = 0; j < ng; ++j) {
        const double u1 = s2 * o2[j];
        const double u2 = u1 + s0 * o0[j];
        x0[j] = g(0, 1) * u1 + g(0, 2) * u2;
        x1[j] = g(1, 1) * u1 + g(1, 2) * u2;
      }
    }
  }
  if (IsCancelled(cancel)) return Cancelled();
  const auto t1 = std::chrono::steady_clock::now();
  stats->candidate_seconds = std::chrono::duration<double>(t1 - t0).count();

  // 3. Remove the exact part: L u = G_V^T M X with L = G_V^T M G_V (cotan Laplacian, #V x #V,
  // symmetric PSD, constants per component in its kernel), one vertex per component pinned.
  // Assembled per edge (off-diagonal) and vertex (diagonal), both triangles.
  const FaceMatrix& F = mesh.faces();
  std::vector<int32_t> pinned_of(nc, -1);
  for (int32_t f = 0; f < nf; ++f) {
    const int32_t c = mesh.face_component()[f];
    if (pinned_of[c] < 0) pinned_of[c] = F(f, 0);
  }
  // Unknowns numbered in BFS order, so that neighbours sit close in memory (the multigrid's
  // sweeps gather neighbour rows; meshes refined by subdivision number new vertices far from
  // their neighbours).
  std::vector<int32_t> index(nv, 0);
  for (int32_t c = 0; c < nc; ++c) index[pinned_of[c]] = -1;
  int32_t n = 0;
  for (int32_t v : queue) index[v] = index[v] < 0 ? -1 : n++;
  std::vector<double> edge_value(ne, 0.0), vertex_value(nv, 0.0);
  RowMatrix rhs = RowMatrix::Zero(n, ng);
  for (int32_t f = 0; f < nf; ++f) {
    const double a = mesh.face_areas()[f];
    const Eigen::Matrix<double, 2, 3>& g = grads[f];
    for (int k = 0; k < 3; ++k) {
      vertex_value[F(f, k)] += a * g.col(k).squaredNorm();
      edge_value[FE(f, k)] += a * g.col((k + 1) % 3).dot(g.col((k + 2) % 3));
      const int32_t i = index[F(f, k)];
      if (i < 0) continue;
      const double* x0 = X.data() + 2 * static_cast<Eigen::Index>(f) * ng;
      const double* x1 = x0 + ng;
      double* b = rhs.data() + static_cast<Eigen::Index>(i) * ng;
      const double c0 = a * g(0, k), c1 = a * g(1, k);
      for (int32_t j = 0; j < ng; ++j) b[j] += c0 * x0[j] + c1 * x1[j];
    }
  }
  if (n > 0) {
    // Both triangles: the multigrid reads rows, CHOLMOD accepts either.
    Eigen::SparseMatrix<double> L(n, n);
    {
      // Column index[v]: rows index[w] for the neighbours w (ascending), and v.
      int64_t nnz = 0;
      for (int32_t v : queue) {
        if (index[v] < 0) continue;
        ++nnz;
        for (int64_t q = offset[v]; q < offset[v + 1]; ++q) {
          const int32_t e = incident[q];
          const int32_t w = E(e, 0) == v ? E(e, 1) : E(e, 0);
          nnz += index[w] >= 0 ? 1 : 0;
        }
      }
      L.resizeNonZeros(static_cast<Eigen::Index>(nnz));
      int32_t* outer = L.outerIndexPtr();
      int32_t* inner = L.innerIndexPtr();
      double* value = L.valuePtr();
      int64_t pos = 0;
      std::vector<std::pair<int32_t, double>> column;
      for (int32_t v : queue) {  // columns in the order of their index
        const int32_t iv = index[v];
        if (iv < 0) continue;
        outer[iv] = static_cast<int32_t>(pos);
        column.clear();
        for (int64_t q = offset[v]; q < offset[v + 1]; ++q) {
          const int32_t e = incident[q];
          const int32_t w = E(e, 0) == v ? E(e, 1) : E(e, 0);
          if (index[w] >= 0) column.emplace_back(index[w], edge_value[e]);
        }
        column.emplace_back(iv, vertex_value[v]);
        std::sort(column.begin(), column.end());
        for (const auto& [row, x] : column) {
          inner[pos] = row;
          value[pos++] = x;
        }
      }
      outer[n] = static_cast<int32_t>(pos);
    }
    if (IsCancelled(cancel)) return Cancelled();
    RowMatrix u;
    bool solved = false;
    if (options.poisson_solver == PoissonSolver::kMultigrid) {
      MultigridOptions mg;
      mg.tolerance = kPoissonTolerance;
      mg.max_iterations = options.poisson_max_iterations;
      mg.cancel = cancel;
      MultigridStats ms;
      absl::StatusOr<RowMatrix> mu = SolveMultigridCg(L, rhs, mg, &ms);
      stats->poisson_iterations = ms.iterations;
      if (mu.ok()) {
        u = *std::move(mu);
        solved = true;
      } else if (absl::IsFailedPrecondition(mu.status())) {
        stats->poisson_fallback = true;  // a mesh the hierarchy does not suit: factorize
      } else {
        return mu.status();
      }
    }
    if (!solved) {
      CholeskyOptions cholesky;
      cholesky.check_input = false;  // symmetric by construction
      ASSIGN_OR_RETURN(SparseCholesky factor, SparseCholesky::Factorize(L, cholesky));
      if (IsCancelled(cancel)) return Cancelled();
      ASSIGN_OR_RETURN(Eigen::MatrixXd u_cols, factor.SolveMatrix(Eigen::MatrixXd(rhs)));
      u = u_cols;
    }
    for (int32_t f = 0; f < nf; ++f) {
      for (int r = 0; r < 3; ++r) {
        const int32_t i = index[F(f, r)];
        if (i < 0) continue;
        const double* ui = u.data() + static_cast<Eigen::Index>(i) * ng;
        double* x0 = X.data() + 2 * static_cast<Eigen::Index>(f) * ng;
        double* x1 = x0 + ng;
        const double g0 = grads[f](0, r), g1 = grads[f](1, r);
        for (int32_t j = 0; j < ng; ++j) {
          x0[j] -= g0 * ui[j];
          x1[j] -= g1 * ui[j];
        }
      }
    }
  }
  stats->poisson_seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t1).count();
  return X;
}

// The candidate fields of a connection Laplacian's kernel (n-fields, tensors): per component,
// p fields transported from its first face along a spanning tree of the dual graph. The
// transport P from face f to face g is read off S: S_gf = -w_e P with P orthogonal, so
// w_e = ||S_gf||_F / sqrt(p).
absl::StatusOr<RowMatrix> ParallelCandidates(const TriangleMesh& mesh, const FieldOperator& op,
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
  RowMatrix X =
      RowMatrix::Zero(static_cast<Eigen::Index>(p) * nf, static_cast<Eigen::Index>(p) * nc);
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

// X^T M X (q x q, symmetric) for a k x q row-major X and the diagonal mass (k), in parallel.
Eigen::MatrixXd MassGram(const Eigen::VectorXd& mass, const RowMatrix& X) {
  const Eigen::Index q = X.cols();
  Eigen::MatrixXd gram = tbb::parallel_deterministic_reduce(
      tbb::blocked_range<Eigen::Index>(0, X.rows(), 1 << 14), Eigen::MatrixXd::Zero(q, q).eval(),
      [&](const tbb::blocked_range<Eigen::Index>& r, Eigen::MatrixXd acc) {
        // Plain loops: Eigen's dynamic-size outer product would allocate a temporary per row.
        for (Eigen::Index i = r.begin(); i != r.end(); ++i) {
          const double* x = X.data() + i * q;
          for (Eigen::Index b = 0; b < q; ++b) {
            const double mx = mass[i] * x[b];
            for (Eigen::Index a = 0; a < q; ++a) acc(a, b) += mx * x[a];
          }
        }
        return acc;
      },
      [](const Eigen::MatrixXd& a, const Eigen::MatrixXd& b) -> Eigen::MatrixXd { return a + b; });
  return 0.5 * (gram + gram.transpose());
}

// X A (k x q') for a row-major k x q X and a small q x q' A, in parallel over rows; `Out` row-
// or column-major (the latter for a result handed out as Eigen::MatrixXd without another copy).
template <typename Out = RowMatrix>
Out RowTimes(const RowMatrix& X, const Eigen::MatrixXd& A) {
  const Eigen::Index q = X.cols(), q2 = A.cols();
  Out out(X.rows(), q2);
  tbb::parallel_for(tbb::blocked_range<Eigen::Index>(0, X.rows(), 1 << 14),
                    [&](const tbb::blocked_range<Eigen::Index>& r) {
                      for (Eigen::Index i = r.begin(); i != r.end(); ++i) {
                        const double* x = X.data() + i * q;
                        for (Eigen::Index b = 0; b < q2; ++b) {
                          double v = 0;
                          for (Eigen::Index a = 0; a < q; ++a) v += x[a] * A(a, b);
                          out(i, b) = v;
                        }
                      }
                    });
  return out;
}

// Z^T S Z (q x q, symmetric) for S symmetric (both triangles stored, column-major) and a k x q
// row-major Z, in parallel: column i of S is row i, so (S Z)_i = sum_j S_ji Z_j.
Eigen::MatrixXd StiffnessGram(const Eigen::SparseMatrix<double>& S, const RowMatrix& Z) {
  const Eigen::Index q = Z.cols();
  Eigen::MatrixXd gram = tbb::parallel_deterministic_reduce(
      tbb::blocked_range<Eigen::Index>(0, S.outerSize(), 1 << 12),
      Eigen::MatrixXd::Zero(q, q).eval(),
      [&](const tbb::blocked_range<Eigen::Index>& r, Eigen::MatrixXd acc) {
        std::vector<double> sz(q);
        for (Eigen::Index i = r.begin(); i != r.end(); ++i) {
          std::fill(sz.begin(), sz.end(), 0.0);
          for (Eigen::SparseMatrix<double>::InnerIterator it(S, i); it; ++it) {
            const double* zj = Z.data() + it.row() * q;
            for (Eigen::Index a = 0; a < q; ++a) sz[a] += it.value() * zj[a];
          }
          const double* zi = Z.data() + i * q;
          for (Eigen::Index b = 0; b < q; ++b) {
            for (Eigen::Index a = 0; a < q; ++a) acc(a, b) += zi[a] * sz[b];
          }
        }
        return acc;
      },
      [](const Eigen::MatrixXd& a, const Eigen::MatrixXd& b) -> Eigen::MatrixXd { return a + b; });
  return 0.5 * (gram + gram.transpose());
}

}  // namespace

// Through S's factored form (docs/conventions.md, Vector Hodge Laplacian):
//   x^T S x = sum_v (1 / Mv_v) (sum_{f at v} area_f grad phi_v . x_f)^2
//           + sum_e (1 / Me_e) (sum_{f at e} t_{f,e} . x_f)^2,
// O(#F q^2) instead of a pass over S's nonzeros with random reads of Z. The divergence part
// scatters into a #V x q array; the curl part is summed edge by edge from the edge's one or two
// faces, without a #E x q array.
Eigen::MatrixXd HodgeGram(const TriangleMesh& mesh, const RowMatrix& Z) {
  const Eigen::Index q = Z.cols();
  const int32_t nf = mesh.num_faces();
  const FaceMatrix& F = mesh.faces();
  const FaceMatrix& FE = mesh.face_edges();
  RowMatrix div = RowMatrix::Zero(mesh.num_vertices(), q);
  Eigen::VectorXd vertex_mass = Eigen::VectorXd::Zero(mesh.num_vertices());
  for (int32_t f = 0; f < nf; ++f) {
    const Eigen::Matrix<double, 2, 3> t = FrameEdges(mesh, f);
    const double third = mesh.face_areas()[f] / 3.0;
    const double* z0 = Z.data() + 2 * static_cast<Eigen::Index>(f) * q;
    const double* z1 = z0 + q;
    for (int k = 0; k < 3; ++k) {
      // area_f grad phi_k = J t_k / 2.
      const double ag0 = -0.5 * t(1, k), ag1 = 0.5 * t(0, k);
      double* dv = div.data() + static_cast<Eigen::Index>(F(f, k)) * q;
      for (Eigen::Index j = 0; j < q; ++j) dv[j] += ag0 * z0[j] + ag1 * z1[j];
      vertex_mass[F(f, k)] += third;
    }
  }
  const PairMatrix& EF = mesh.edge_faces();
  Eigen::MatrixXd curl = tbb::parallel_deterministic_reduce(
      tbb::blocked_range<int32_t>(0, mesh.num_edges(), 1 << 14), Eigen::MatrixXd::Zero(q, q).eval(),
      [&](const tbb::blocked_range<int32_t>& r, Eigen::MatrixXd acc) {
        std::vector<double> c(q);
        for (int32_t e = r.begin(); e != r.end(); ++e) {
          std::fill(c.begin(), c.end(), 0.0);
          double mass = 0;
          for (int side = 0; side < 2; ++side) {
            const int32_t f = EF(e, side);
            if (f < 0) continue;
            const int k = FE(f, 0) == e ? 0 : (FE(f, 1) == e ? 1 : 2);
            const Eigen::Vector2d t = mesh.EdgeVectorInFrame(f, k);
            const double t0 = t[0], t1 = t[1];
            const double* z0 = Z.data() + 2 * static_cast<Eigen::Index>(f) * q;
            const double* z1 = z0 + q;
            for (Eigen::Index j = 0; j < q; ++j) c[j] += t0 * z0[j] + t1 * z1[j];
            mass += mesh.face_areas()[f] / 3.0;
          }
          const double w = 1.0 / mass;
          for (Eigen::Index b = 0; b < q; ++b) {
            const double wc = w * c[b];
            for (Eigen::Index a = 0; a < q; ++a) acc(a, b) += wc * c[a];
          }
        }
        return acc;
      },
      [](const Eigen::MatrixXd& a, const Eigen::MatrixXd& b) -> Eigen::MatrixXd { return a + b; });
  return MassGram(vertex_mass.cwiseInverse(), div) + 0.5 * (curl + curl.transpose());
}

absl::StatusOr<Eigen::MatrixXd> ComputeKernelFields(const TriangleMesh& mesh,
                                                    const FieldOperator& op,
                                                    const KernelFieldOptions& options,
                                                    KernelFieldStats* stats) {
  const auto t0 = std::chrono::steady_clock::now();
  const int64_t k = static_cast<int64_t>(op.type.dofs_per_face()) * mesh.num_faces();
  const bool vector = op.type.kind == FieldKind::kVector;
  // A vector field's kernel is computed from the mesh: S may be unassembled then.
  if (!vector && !op.has_stiffness()) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "the kernel of %s fields reads S, which is not assembled", op.type.ToString()));
  }
  if (op.dofs() != k ||
      (op.has_stiffness() && (op.stiffness.rows() != k || op.stiffness.cols() != k))) {
    return absl::InvalidArgumentError(
        absl::StrFormat("operator size (S %d x %d, mass %d) does not match the mesh (%d DOFs)",
                        op.stiffness.rows(), op.stiffness.cols(), op.dofs(), k));
  }
  if (!(options.accept_tolerance > 0) || !std::isfinite(options.accept_tolerance)) {
    return absl::InvalidArgumentError("accept_tolerance must be finite and > 0");
  }
  if (options.poisson_max_iterations < 1) {
    return absl::InvalidArgumentError("poisson_max_iterations must be >= 1");
  }
  KernelFieldStats local_stats;
  KernelFieldStats& st = stats != nullptr ? *stats : local_stats;
  st = KernelFieldStats();
  // The scale of the acceptance test. Without S, from S's rows computed from the mesh, and first:
  // their tables are freed before the candidates and the Poisson solve take their memory. Not
  // needed (and left 0) when no component can have a kernel field.
  if (op.has_stiffness()) {
    st.lambda_ref = op.stiffness.diagonal().sum() / op.mass.sum();
  } else if (KernelEntriesBound(mesh, op.type) > 0) {
    ASSIGN_OR_RETURN(const VectorHodgeRows rows, VectorHodgeRows::Create(mesh));
    st.lambda_ref = rows.Trace() / op.mass.sum();
  }
  RowMatrix H;
  if (vector) {
    ASSIGN_OR_RETURN(H, HarmonicCandidates(mesh, options, &st));
    for (const MeshComponent& c : mesh.components()) {
      if (c.num_boundary_loops == 0) st.expected_harmonic += 2 - c.euler_characteristic;
    }
  } else {
    ASSIGN_OR_RETURN(H, ParallelCandidates(mesh, op, options.cancel));
    st.candidate_seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  }
  const auto t_ritz = std::chrono::steady_clock::now();
  st.candidates = static_cast<int32_t>(H.cols());
  if (H.cols() == 0) {
    st.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    return Eigen::MatrixXd(H.rows(), 0);
  }
  // 4. Rank-revealing M-orthonormalization, then Rayleigh-Ritz with S.
  Eigen::MatrixXd gram = MassGram(op.mass, H);
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
  RowMatrix Z = RowTimes(H, W);
  H.resize(0, 0);
  if (IsCancelled(options.cancel)) return Cancelled();
  Eigen::MatrixXd Q = vector ? HodgeGram(mesh, Z) : StiffnessGram(op.stiffness, Z);
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
  // One more M-orthonormalization against the rounding of the two small eigensolves:
  // result = Z R L^-T with L L^T = (Z R)^T M (Z R).
  Eigen::MatrixXd result;
  if (!accepted.empty()) {
    RowMatrix ZR = RowTimes(Z, R);
    Z.resize(0, 0);
    Eigen::LLT<Eigen::MatrixXd> llt(MassGram(op.mass, ZR));
    if (llt.info() == Eigen::Success) {
      const Eigen::MatrixXd Linv_t =
          llt.matrixL().solve(Eigen::MatrixXd::Identity(R.cols(), R.cols())).transpose();
      result = RowTimes<Eigen::MatrixXd>(ZR, Linv_t);
    } else {
      result = ZR;
    }
  } else {
    result.resize(Z.rows(), 0);
  }
  const auto t_end = std::chrono::steady_clock::now();
  st.ritz_seconds = std::chrono::duration<double>(t_end - t_ritz).count();
  st.seconds = std::chrono::duration<double>(t_end - t0).count();
  return result;
}

absl::StatusOr<Eigen::MatrixXd> ComputeKernelFields(const TriangleMesh& mesh, const FieldType& type,
                                                    const KernelFieldOptions& options) {
  // A vector field's kernel does not read S.
  ASSIGN_OR_RETURN(FieldOperator op, type.kind == FieldKind::kVector
                                         ? BuildFieldOperatorWithoutStiffness(mesh, type)
                                         : BuildFieldOperator(mesh, type));
  return ComputeKernelFields(mesh, op, options);
}

int64_t KernelEntriesBound(const TriangleMesh& mesh, const FieldType& type) {
  const int64_t p = type.dofs_per_face();
  int64_t entries = 0;
  for (const MeshComponent& c : mesh.components()) {
    entries += p * c.num_faces * std::max<int64_t>(ComponentCandidates(c, type), 0);
  }
  return entries;
}

}  // namespace fieldspace
