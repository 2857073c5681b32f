#include "core/basis/local_problem.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <utility>

#include "Eigen/SparseCore"
#include "absl/strings/str_cat.h"
#include "core/common/random.h"
#include "core/common/status_macros.h"
#include "core/operators/vector_laplacian.h"
#include "tbb/blocked_range.h"
#include "tbb/parallel_for.h"

namespace fieldspace::basis_internal {
namespace {

// The order's scratch, given back after a system as large as those whose factorization gives
// back its own (LocalCholesky::kReleaseScratchRows): not kept beside a coarse region's factor.
void ReleaseOrderScratch(int32_t rows, RegionWorkspace& ws) {
  if (rows <= LocalCholesky::kReleaseScratchRows) return;
  for (std::vector<int32_t>* v :
       {&ws.order, &ws.vertex_order, &ws.rank, &ws.edge_low, &ws.edge_high, &ws.bucket}) {
    std::vector<int32_t>().swap(*v);
  }
}

}  // namespace

// ---------------------------------------------------------------- RestrictedLocalOperator

RestrictedLocalOperator::RestrictedLocalOperator(const FieldOperator& op,
                                                 const Eigen::VectorXd& inv_sqrt_mass,
                                                 const std::vector<int32_t>& faces, double tau,
                                                 RegionWorkspace& ws, bool clamped)
    : tau_(tau), ws_(ws) {
  const int32_t dpf = op.type.dofs_per_face();
  const int32_t nfr = static_cast<int32_t>(faces.size());
  n_ = dpf * nfr;
  dofs_per_face_ = dpf;
  if (ws.dof_map.size() != static_cast<size_t>(op.dofs())) ws.dof_map.assign(op.dofs(), -1);
  for (int32_t i = 0; i < nfr; ++i) {
    for (int32_t c = 0; c < dpf; ++c)
      ws.dof_map[dpf * static_cast<int64_t>(faces[i]) + c] = dpf * i + c;
  }
  const Eigen::SparseMatrix<double>& S = op.stiffness;
  outer_.assign(static_cast<size_t>(n_) + 1, 0);
  inner_.clear();
  values_.clear();
  if (clamped) {
    // E = S~ V: column l holds S~'s column of the region DOF l at all its rows, numbered region
    // DOFs first (the dof_map) and then the outside rows in order of appearance; B_bar = E^T E.
    if (ws.outer_map.size() != static_cast<size_t>(op.dofs())) ws.outer_map.assign(op.dofs(), -1);
    std::vector<int32_t> outside;
    std::vector<Eigen::Triplet<double>> entries;
    for (int32_t l = 0; l < n_; ++l) {
      const int64_t g = dpf * static_cast<int64_t>(faces[l / dpf]) + l % dpf;
      const double sg = inv_sqrt_mass[g];
      for (Eigen::SparseMatrix<double>::InnerIterator it(S, g); it; ++it) {
        int32_t r = ws.dof_map[it.row()];
        if (r < 0) {
          int32_t& o = ws.outer_map[it.row()];
          if (o < 0) {
            o = static_cast<int32_t>(outside.size());
            outside.push_back(static_cast<int32_t>(it.row()));
          }
          r = n_ + o;
        }
        entries.emplace_back(r, l, it.value() * inv_sqrt_mass[it.row()] * sg);
      }
    }
    for (int32_t row : outside) ws.outer_map[row] = -1;
    Eigen::SparseMatrix<double> E(n_ + static_cast<int32_t>(outside.size()), n_);
    E.setFromTriplets(entries.begin(), entries.end());
    Eigen::SparseMatrix<double> B = E.transpose() * E;
    B.makeCompressed();
    for (int32_t l = 0; l < n_; ++l) {
      for (Eigen::SparseMatrix<double>::InnerIterator it(B, l); it; ++it) {
        inner_.push_back(static_cast<int32_t>(it.row()));
        values_.push_back(it.value());
      }
      outer_[l + 1] = static_cast<int32_t>(inner_.size());
    }
  } else {
    // S's columns of the region's faces are scattered over S: each face's column offsets are
    // prefetched 2 kPrefetchFaces faces ahead, the columns themselves kPrefetchFaces ahead.
    const auto* s_outer = S.outerIndexPtr();
    const auto* s_inner = S.innerIndexPtr();
    const double* s_values = S.valuePtr();
    for (int32_t l = 0; l < n_; ++l) {
      if (l % dpf == 0) {
        const int32_t i = l / dpf;
        if (i + 2 * kPrefetchFaces < nfr) {
          __builtin_prefetch(&s_outer[dpf * static_cast<int64_t>(faces[i + 2 * kPrefetchFaces])]);
        }
        if (i + kPrefetchFaces < nfr) {
          const int64_t g0 = dpf * static_cast<int64_t>(faces[i + kPrefetchFaces]);
          for (int32_t c = 0; c < dpf; ++c) {
            __builtin_prefetch(&s_inner[s_outer[g0 + c]]);
            __builtin_prefetch(&s_values[s_outer[g0 + c]]);
          }
          __builtin_prefetch(&inv_sqrt_mass[g0]);
        }
      }
      const int64_t g = dpf * static_cast<int64_t>(faces[l / dpf]) + l % dpf;
      const double sg = inv_sqrt_mass[g];
      for (Eigen::SparseMatrix<double>::InnerIterator it(S, g); it; ++it) {
        const int32_t r = ws.dof_map[it.row()];
        if (r < 0) continue;
        inner_.push_back(r);
        values_.push_back(it.value() * inv_sqrt_mass[it.row()] * sg);
      }
      outer_[l + 1] = static_cast<int32_t>(inner_.size());
    }
  }
  for (int32_t i = 0; i < nfr; ++i) {
    for (int32_t c = 0; c < dpf; ++c) ws.dof_map[dpf * static_cast<int64_t>(faces[i]) + c] = -1;
  }
}

void RestrictedLocalOperator::ApplyStiffness(const Eigen::MatrixXd& X, Eigen::MatrixXd* Y) {
  // One pass over S_bar for all p columns (row-major blocks keep each row's p values together).
  const int32_t p = static_cast<int32_t>(X.cols());
  RowBlock xr = X;
  RowBlock yr = RowBlock::Zero(n_, p);
  for (int32_t j = 0; j < n_; ++j) {
    const double* xj = xr.row(j).data();
    for (int32_t q = outer_[j]; q < outer_[j + 1]; ++q) {
      double* yi = yr.row(inner_[q]).data();
      const double v = values_[q];
      for (int32_t c = 0; c < p; ++c) yi[c] += v * xj[c];
    }
  }
  *Y = yr;
}

absl::Status RestrictedLocalOperator::PrepareShiftInverse(const CancelToken& cancel) {
  // S_bar + tau I's upper triangle is S_bar's columns (both triangles, rows sorted) cut at the
  // diagonal: each column's diagonal first (created when S_bar has none), then its rows above.
  UpperCsc A;
  A.n = n_;
  A.outer.resize(static_cast<size_t>(n_) + 1);
  A.outer[0] = 0;
  A.inner.reserve(inner_.size() / 2 + n_);
  A.values.reserve(inner_.size() / 2 + n_);
  for (int32_t j = 0; j < n_; ++j) {
    const size_t diagonal = A.inner.size();
    A.inner.push_back(j);
    A.values.push_back(tau_);
    for (int32_t q = outer_[j]; q < outer_[j + 1] && inner_[q] <= j; ++q) {
      if (inner_[q] == j) {
        A.values[diagonal] += values_[q];
      } else {
        A.inner.push_back(inner_[q]);
        A.values.push_back(values_[q]);
      }
    }
    A.outer[j + 1] = static_cast<int32_t>(A.inner.size());
  }
  // AMD on the faces (a face's DOFs couple to the same neighbours): the fill of AMD on the DOFs
  // for dofs_per_face^2 times fewer entries to read (bench/RESULTS.md, Session 31).
  RETURN_IF_ERROR(ws_.cholesky.BlockMinimumDegreeOrder(A, dofs_per_face_, &ws_.order));
  absl::Status factored = ws_.cholesky.Factorize(A, cancel, &ws_.order);
  ReleaseOrderScratch(n_, ws_);
  return factored;
}

void RestrictedLocalOperator::ApplyShiftInverse(const Eigen::MatrixXd& X, Eigen::MatrixXd* Y) {
  *Y = X;
  ws_.cholesky.SolveInPlace(Y->data(), static_cast<int32_t>(Y->cols()));
}

void RestrictedLocalOperator::ApplyShiftInverseAndStiffness(const Eigen::MatrixXd& X,
                                                            Eigen::MatrixXd* Y,
                                                            Eigen::MatrixXd* SY) {
  ApplyShiftInverse(X, Y);
  *SY = X - tau_ * *Y;
}

// ---------------------------------------------------------------- Hodge factor

HodgeFactorData BuildHodgeFactorData(const TriangleMesh& mesh) {
  HodgeInverseMasses inv = BuildHodgeInverseMasses(mesh);
  for (double& m : inv.vertex) m = std::sqrt(m);
  for (double& m : inv.edge) m = std::sqrt(m);
  return {std::move(inv.vertex), std::move(inv.edge)};
}

absl::Status MissingStiffnessError(const FieldType& type) {
  return absl::InvalidArgumentError(
      absl::StrCat("this build of ", type.ToString(),
                   " fields reads S (generic or clamped local problems), and the operator has "
                   "none (AssembleStiffness)"));
}

absl::StatusOr<bool> HodgeFactorMatches(const TriangleMesh& mesh, const FieldOperator& op,
                                        const HodgeFactorData& data, const CancelToken& cancel) {
  const int32_t nf = mesh.num_faces();
  const int64_t k = 2 * static_cast<int64_t>(nf);
  const Eigen::SparseMatrix<double>& S = op.stiffness;
  if (op.type.kind != FieldKind::kVector || S.rows() != k || S.cols() != k) return false;
  const FaceMatrix& F = mesh.faces();
  const FaceMatrix& FE = mesh.face_edges();
  SplitMix64 random(0x5eed5eedULL);
  // One random vector: a mismatch anywhere shows up in S x with probability 1.
  for (int trial = 0; trial < 1; ++trial) {
    Eigen::VectorXd x(k);
    for (int64_t i = 0; i < k; ++i) {
      x[i] = random.NextSigned();
    }
    // y1 = S x and the entrywise scale |S| |x| (S symmetric: row i = column i).
    Eigen::VectorXd y1(k), scale(k);
    std::atomic<bool> cancelled{false};
    tbb::parallel_for(tbb::blocked_range<int64_t>(0, k, 16384),
                      [&](const tbb::blocked_range<int64_t>& r) {
                        if (cancelled.load(std::memory_order_relaxed)) return;
                        if (cancel.Check()) cancelled.store(true);
                        for (int64_t j = r.begin(); j != r.end(); ++j) {
                          double s = 0.0, a = 0.0;
                          for (Eigen::SparseMatrix<double>::InnerIterator it(S, j); it; ++it) {
                            s += it.value() * x[it.row()];
                            a += std::abs(it.value() * x[it.row()]);
                          }
                          y1[j] = s;
                          scale[j] = a;
                        }
                      });
    if (cancelled.load() || cancel.Check()) {
      return absl::CancelledError("basis construction cancelled");
    }
    // z = B^T x (vertex part, edge part), then y2 = B z.
    std::vector<double> zv(mesh.num_vertices(), 0.0), ze(mesh.num_edges(), 0.0);
    for (int32_t f = 0; f < nf; ++f) {
      if ((f & 0xffff) == 0 && cancel.Check()) {
        return absl::CancelledError("basis construction cancelled");
      }
      for (int kk = 0; kk < 3; ++kk) {
        const Eigen::Vector2d t = mesh.EdgeVectorInFrame(f, kk);
        const double tx = t[0], ty = t[1];
        const int32_t v = F(f, kk);
        const int32_t e = FE(f, kk);
        zv[v] += (-0.5 * ty * x[2 * f] + 0.5 * tx * x[2 * f + 1]) * data.inv_sqrt_vertex_mass[v];
        ze[e] += (tx * x[2 * f] + ty * x[2 * f + 1]) * data.inv_sqrt_edge_mass[e];
      }
    }
    std::atomic<bool> mismatch{false};
    tbb::parallel_for(tbb::blocked_range<int32_t>(0, nf, 8192),
                      [&](const tbb::blocked_range<int32_t>& r) {
                        cancel.Check();  // progress only; cancellation checked below
                        for (int32_t f = r.begin(); f != r.end(); ++f) {
                          double y2[2] = {0.0, 0.0};
                          for (int kk = 0; kk < 3; ++kk) {
                            const Eigen::Vector2d t = mesh.EdgeVectorInFrame(f, kk);
                            const double tx = t[0], ty = t[1];
                            const double a = zv[F(f, kk)] * data.inv_sqrt_vertex_mass[F(f, kk)];
                            const double b = ze[FE(f, kk)] * data.inv_sqrt_edge_mass[FE(f, kk)];
                            y2[0] += -0.5 * ty * a + tx * b;
                            y2[1] += 0.5 * tx * a + ty * b;
                          }
                          for (int c = 0; c < 2; ++c) {
                            const int64_t i = 2 * static_cast<int64_t>(f) + c;
                            if (!(std::abs(y1[i] - y2[c]) <= 1e-10 * scale[i] + 1e-300)) {
                              mismatch.store(true, std::memory_order_relaxed);
                            }
                          }
                        }
                      });
    if (mismatch.load()) return false;
  }
  return true;
}

// ---------------------------------------------------------------- HodgeLocalOperator

HodgeLocalOperator::HodgeLocalOperator(const TriangleMesh& mesh, const HodgeFactorData& data,
                                       const std::vector<int32_t>& faces, double tau,
                                       RegionWorkspace& ws)
    : tau_(tau), ws_(ws) {
  const FaceMatrix& F = mesh.faces();
  const FaceMatrix& FE = mesh.face_edges();
  const Eigen::VectorXd& area = mesh.face_areas();
  const int32_t nfr = static_cast<int32_t>(faces.size());
  n_ = 2 * nfr;
  if (ws.vertex_map.size() != static_cast<size_t>(mesh.num_vertices())) {
    ws.vertex_map.assign(mesh.num_vertices(), -1);
  }
  if (ws.edge_map.size() != static_cast<size_t>(mesh.num_edges())) {
    ws.edge_map.assign(mesh.num_edges(), -1);
  }
  // Local numbering in order of first appearance; vertices first, edges after (offset below).
  std::vector<int32_t> local_vertices, local_edges;
  std::vector<uint8_t> edge_count;
  local_vertices.reserve(nfr / 2 + 16);
  local_edges.reserve(3 * nfr / 2 + 16);
  b_cols_.resize(6 * static_cast<size_t>(nfr));
  // The faces' rows (F, FE, then the vertex and edge maps they index) are prefetched ahead: the
  // region's faces, vertices and edges are scattered over the mesh's arrays.
  for (int32_t i = 0; i < nfr; ++i) {
    if (i + 2 * kPrefetchFaces < nfr) {
      const int32_t g = faces[i + 2 * kPrefetchFaces];
      __builtin_prefetch(&F(g, 0));
      __builtin_prefetch(&FE(g, 0));
    }
    if (i + kPrefetchFaces < nfr) {
      const int32_t g = faces[i + kPrefetchFaces];
      for (int k = 0; k < 3; ++k) {
        __builtin_prefetch(&ws.vertex_map[F(g, k)], 1);
        __builtin_prefetch(&ws.edge_map[FE(g, k)], 1);
      }
    }
    const int32_t f = faces[i];
    for (int k = 0; k < 3; ++k) {
      int32_t& lv = ws.vertex_map[F(f, k)];
      if (lv < 0) {
        lv = static_cast<int32_t>(local_vertices.size());
        local_vertices.push_back(F(f, k));
      }
      int32_t& le = ws.edge_map[FE(f, k)];
      if (le < 0) {
        le = static_cast<int32_t>(local_edges.size());
        local_edges.push_back(FE(f, k));
        edge_count.push_back(0);
      }
      ++edge_count[le];
      b_cols_[6 * i + k] = lv;
      b_cols_[6 * i + 3 + k] = le;
    }
  }
  num_vertices_ = static_cast<int32_t>(local_vertices.size());
  num_nodes_ = num_vertices_ + static_cast<int32_t>(local_edges.size());
  boundary_edge_.resize(local_edges.size());
  for (size_t e = 0; e < local_edges.size(); ++e) boundary_edge_[e] = edge_count[e] == 1;
  b_vals_.resize(12 * static_cast<size_t>(nfr));
  const VertexMatrix& X = mesh.vertices();
  for (int32_t i = 0; i < nfr; ++i) {
    if (i + kPrefetchFaces < nfr) {
      const int32_t g = faces[i + kPrefetchFaces];
      __builtin_prefetch(&area[g]);
      __builtin_prefetch(&mesh.frame_x()(g, 0));
      __builtin_prefetch(&mesh.frame_y()(g, 0));
      for (int k = 0; k < 3; ++k) {
        __builtin_prefetch(&X(F(g, k), 0));
        __builtin_prefetch(&data.inv_sqrt_vertex_mass[F(g, k)]);
        __builtin_prefetch(&data.inv_sqrt_edge_mass[FE(g, k)]);
      }
    }
    const int32_t f = faces[i];
    const double s = 1.0 / std::sqrt(area[f]);  // V = M^-1/2
    double* row0 = &b_vals_[12 * i];
    double* row1 = row0 + 6;
    for (int k = 0; k < 3; ++k) {
      const Eigen::Vector2d t = mesh.EdgeVectorInFrame(f, k);
      const double tx = t[0], ty = t[1];
      const double wv = s * data.inv_sqrt_vertex_mass[F(f, k)];
      const double we = s * data.inv_sqrt_edge_mass[FE(f, k)];
      row0[k] = -0.5 * ty * wv;
      row1[k] = 0.5 * tx * wv;
      row0[3 + k] = tx * we;
      row1[3 + k] = ty * we;
      b_cols_[6 * i + 3 + k] += num_vertices_;
    }
  }
  for (int32_t v : local_vertices) ws.vertex_map[v] = -1;
  for (int32_t e : local_edges) ws.edge_map[e] = -1;
}

void HodgeLocalOperator::ApplyBt(const Eigen::MatrixXd& X) {
  // One pass over B_D for all p columns, into the row-major zr_.
  const int32_t p = static_cast<int32_t>(X.cols());
  zr_.setZero(num_nodes_, p);
  const int32_t nfr = n_ / 2;
  const double* x = X.data();
  const int64_t ld = X.rows();
  for (int32_t i = 0; i < nfr; ++i) {
    const int32_t* cols = &b_cols_[6 * i];
    const double* v = &b_vals_[12 * i];
    const double* x0 = x + 2 * static_cast<int64_t>(i);
    for (int k = 0; k < 6; ++k) {
      double* z = zr_.row(cols[k]).data();
      const double a = v[k], b = v[6 + k];
      for (int32_t c = 0; c < p; ++c) z[c] += a * x0[c * ld] + b * x0[c * ld + 1];
    }
  }
}

void HodgeLocalOperator::ApplyB(Eigen::MatrixXd* Y, bool subtract) {
  const int32_t p = static_cast<int32_t>(zr_.cols());
  if (!subtract) Y->setZero(n_, p);
  const double sign = subtract ? -1.0 : 1.0;
  const int32_t nfr = n_ / 2;
  double* y = Y->data();
  const int64_t ld = Y->rows();
  for (int32_t i = 0; i < nfr; ++i) {
    const int32_t* cols = &b_cols_[6 * i];
    const double* v = &b_vals_[12 * i];
    double* y0 = y + 2 * static_cast<int64_t>(i);
    for (int k = 0; k < 6; ++k) {
      const double* z = zr_.row(cols[k]).data();
      const double a = sign * v[k], b = sign * v[6 + k];
      for (int32_t c = 0; c < p; ++c) {
        y0[c * ld] += a * z[c];
        y0[c * ld + 1] += b * z[c];
      }
    }
  }
}

void HodgeLocalOperator::ApplyStiffness(const Eigen::MatrixXd& X, Eigen::MatrixXd* Y) {
  ApplyBt(X);
  ApplyB(Y, /*subtract=*/false);
}

UpperCsc HodgeLocalOperator::AssembleK() {
  // From each face's 2 x 6 block, entry by entry, without sorting or summing duplicates:
  // vertex-vertex products along the region's edges (one entry per edge, from its one or two
  // faces), edge-edge products within a face (one entry per face and pair: two edges share at most
  // one face), vertex-edge products only for the region-boundary edges and their endpoints
  // (elsewhere the edge's two faces cancel exactly: the discrete gradients and co-gradients are
  // orthogonal), never a vertex with its opposite edge (J t . t = 0).
  const int32_t nfr = n_ / 2;
  const int32_t nv = num_vertices_;
  const int32_t ne = num_nodes_ - nv;
  std::vector<double> diagonal(num_nodes_, tau_);
  std::vector<double> along_edge(ne, 0.0);  // K(a, b) for the edge's endpoints a, b
  std::vector<int32_t> low(ne), high(ne);   // its endpoints
  UpperCsc K;
  K.n = num_nodes_;
  K.outer.assign(static_cast<size_t>(num_nodes_) + 1, 0);
  int32_t* count = K.outer.data() + 1;  // entries per column, then their offsets
  for (int32_t i = 0; i < nfr; ++i) {
    const int32_t* c = &b_cols_[6 * i];
    const double* r0 = &b_vals_[12 * i];
    const double* r1 = r0 + 6;
    for (int j = 0; j < 6; ++j) diagonal[c[j]] += r0[j] * r0[j] + r1[j] * r1[j];
    for (int k = 0; k < 3; ++k) {
      const int32_t e = c[3 + k] - nv;
      const int a = (k + 1) % 3, b = (k + 2) % 3;  // the edge opposite vertex k joins a and b
      along_edge[e] += r0[a] * r0[b] + r1[a] * r1[b];
      low[e] = std::min(c[a], c[b]);
      high[e] = std::max(c[a], c[b]);
      ++count[std::max(c[3 + a], c[3 + b])];  // the pair of edges opposite a and b
      if (boundary_edge_[e]) count[c[3 + k]] += 2;
    }
  }
  for (int32_t e = 0; e < ne; ++e) ++count[high[e]];
  for (int32_t j = 0; j < num_nodes_; ++j) ++count[j];  // the diagonal
  for (int32_t j = 0; j < num_nodes_; ++j) K.outer[j + 1] += K.outer[j];
  K.inner.resize(K.outer[num_nodes_]);
  K.values.resize(K.outer[num_nodes_]);
  std::vector<int32_t>& cursor = ws_.cursor;
  cursor.assign(K.outer.begin(), K.outer.end() - 1);
  auto put = [&](int32_t row, int32_t col, double v) {
    const int32_t q = cursor[col]++;
    K.inner[q] = row;
    K.values[q] = v;
  };
  for (int32_t j = 0; j < num_nodes_; ++j) put(j, j, diagonal[j]);
  for (int32_t e = 0; e < ne; ++e) put(low[e], high[e], along_edge[e]);
  for (int32_t i = 0; i < nfr; ++i) {
    const int32_t* c = &b_cols_[6 * i];
    const double* r0 = &b_vals_[12 * i];
    const double* r1 = r0 + 6;
    for (int k = 0; k < 3; ++k) {
      const int a = 3 + (k + 1) % 3, b = 3 + (k + 2) % 3;
      put(std::min(c[a], c[b]), std::max(c[a], c[b]), r0[a] * r0[b] + r1[a] * r1[b]);
      if (!boundary_edge_[c[3 + k] - nv]) continue;
      for (int j = 0; j < 3; ++j) {
        if (j != k) put(c[j], c[3 + k], r0[j] * r0[3 + k] + r1[j] * r1[3 + k]);
      }
    }
  }
  return K;
}

absl::Status HodgeLocalOperator::PrepareShiftInverse(const CancelToken& cancel) {
  const UpperCsc K = AssembleK();
  RETURN_IF_ERROR(InducedNodeOrder(K, num_vertices_, b_cols_, ws_));
  absl::Status factored = ws_.cholesky.Factorize(K, cancel, &ws_.order);
  ReleaseOrderScratch(num_nodes_, ws_);
  if (!factored.ok()) return factored;
  // Number the nodes as the factor does: B_D^T x is then solved where it is accumulated.
  const std::vector<int32_t>& order = ws_.cholesky.inverse_permutation();
  for (int32_t& c : b_cols_) c = order[c];
  return absl::OkStatus();
}

void HodgeLocalOperator::ApplyShiftInverseAndStiffness(const Eigen::MatrixXd& X, Eigen::MatrixXd* Y,
                                                       Eigen::MatrixXd* SY) {
  ApplyBt(X);
  ws_.cholesky.SolvePermutedInPlace(zr_.data(), static_cast<int32_t>(zr_.cols()));
  ApplyB(SY, /*subtract=*/false);
  *Y = (X - *SY) / tau_;
}

void HodgeLocalOperator::ApplyShiftInverse(const Eigen::MatrixXd& X, Eigen::MatrixXd* Y) {
  ApplyBt(X);
  ws_.cholesky.SolvePermutedInPlace(zr_.data(), static_cast<int32_t>(zr_.cols()));
  *Y = X;
  ApplyB(Y, /*subtract=*/true);
  *Y /= tau_;
}

absl::Status InducedNodeOrder(const UpperCsc& K, int32_t num_vertices,
                              const std::vector<int32_t>& face_nodes, RegionWorkspace& ws) {
  const int32_t nv = num_vertices;
  const int32_t ne = K.n - nv;
  const int32_t nfr = static_cast<int32_t>(face_nodes.size() / 6);
  if (nv < 0 || ne < 0 || face_nodes.size() % 6 != 0) {
    return absl::InvalidArgumentError("induced order: inconsistent node counts");
  }
  // K's vertex block is its leading one.
  std::vector<int32_t>& vertex_order = ws.vertex_order;
  RETURN_IF_ERROR(ws.cholesky.MinimumDegreeOrder(K, nv, &vertex_order));
  std::vector<int32_t>& rank = ws.rank;
  rank.resize(nv);
  for (int32_t k = 0; k < nv; ++k) rank[vertex_order[k]] = k;
  // Each edge's endpoints by rank (edge 3 + k of a face is opposite its vertex k).
  std::vector<int32_t>& low = ws.edge_low;
  std::vector<int32_t>& high = ws.edge_high;
  low.assign(ne, -1);
  high.resize(ne);
  for (int32_t i = 0; i < nfr; ++i) {
    const int32_t* c = &face_nodes[6 * i];
    for (int k = 0; k < 3; ++k) {
      if (c[k] < 0 || c[k] >= nv || c[3 + k] < nv || c[3 + k] >= K.n) {
        return absl::InvalidArgumentError("induced order: a face's node out of range");
      }
    }
    for (int k = 0; k < 3; ++k) {
      const int32_t a = rank[c[(k + 1) % 3]];
      const int32_t b = rank[c[(k + 2) % 3]];
      low[c[3 + k] - nv] = std::min(a, b);
      high[c[3 + k] - nv] = std::max(a, b);
    }
  }
  if (std::find(low.begin(), low.end(), -1) != low.end()) {
    return absl::InvalidArgumentError("induced order: an edge in no face");
  }
  // The edges bucketed by their earlier endpoint (counting sort), each bucket (about three
  // edges) sorted by the later one; then the order: each vertex's bucket, then the vertex.
  std::vector<int32_t>& start = ws.bucket;
  start.assign(static_cast<size_t>(nv) + 1, 0);
  for (int32_t e = 0; e < ne; ++e) ++start[low[e] + 1];
  for (int32_t r = 0; r < nv; ++r) start[r + 1] += start[r];
  std::vector<int32_t>& order = ws.order;
  order.resize(K.n);
  {
    // Edges go to order[start[r] + r ...]: bucket r is preceded by r vertices.
    std::vector<int32_t>& cursor = rank;  // the ranks are in low / high now
    for (int32_t r = 0; r < nv; ++r) cursor[r] = start[r] + r;
    for (int32_t e = 0; e < ne; ++e) order[cursor[low[e]]++] = nv + e;
  }
  for (int32_t r = 0; r < nv; ++r) {
    int32_t* bucket = order.data() + start[r] + r;
    const int32_t size = start[r + 1] - start[r];
    for (int32_t a = 1; a < size; ++a) {
      const int32_t node = bucket[a];
      int32_t b = a;
      for (; b > 0 && high[bucket[b - 1] - nv] > high[node - nv]; --b) bucket[b] = bucket[b - 1];
      bucket[b] = node;
    }
    bucket[size] = vertex_order[r];
  }
  return absl::OkStatus();
}

}  // namespace fieldspace::basis_internal
