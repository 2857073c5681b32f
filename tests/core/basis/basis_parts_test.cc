// Tests of the pieces of the basis construction: dual graph, sample allocation, farthest point
// sampling, region growth and the local eigensolver.
#include <algorithm>
#include <atomic>
#include <cmath>
#include <limits>
#include <memory>
#include <numeric>
#include <set>
#include <utility>
#include <vector>

#include "Eigen/Cholesky"
#include "Eigen/Eigenvalues"
#include "Eigen/SparseCore"
#include "core/basis/crc32c.h"
#include "core/basis/dual_graph.h"
#include "core/basis/local_eigensolver.h"
#include "core/basis/local_problem.h"
#include "core/basis/regions.h"
#include "core/basis/sampling.h"
#include "core/common/cancel.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tests/testing/fixtures.h"
#include "tests/testing/matchers.h"
#include "tests/testing/reference.h"
#include "tests/testing/test_meshes.h"

namespace fieldspace {
namespace {

using basis_internal::BuildHodgeFactorData;
using basis_internal::HodgeFactorData;
using basis_internal::HodgeLocalOperator;
using basis_internal::InducedNodeOrder;
using basis_internal::LocalEigenOptions;
using basis_internal::LocalOperator;
using basis_internal::RegionWorkspace;
using basis_internal::RestrictedLocalOperator;
using ::fieldspace::testing::StatusIs;
using testing::DualDistances;
using testing::Icosphere;
using testing::MustBuildOperator;
using testing::TwoSpheres;

// A flag that is already set: the cancellation paths return at their first check.
const CancelFlag kCancelled{true};

TEST(DualGraphTest, ArcsAndLengths) {
  const TriangleMesh mesh = Icosphere(2);
  auto g = BuildDualGraph(mesh, {});
  ASSERT_TRUE(g.ok()) << g.status();
  ASSERT_EQ(g->num_nodes, mesh.num_faces());
  // node_face and face_node are inverse permutations.
  std::vector<int32_t> sorted = g->node_face;
  std::sort(sorted.begin(), sorted.end());
  for (int32_t f = 0; f < mesh.num_faces(); ++f) {
    ASSERT_EQ(sorted[f], f);
    ASSERT_EQ(g->node_face[g->face_node[f]], f);
  }
  // Arcs: exactly the face neighbors, with barycenter distances.
  for (int32_t f = 0; f < mesh.num_faces(); ++f) {
    const int32_t v = g->face_node[f];
    for (int k = 0; k < 3; ++k) {
      const DualArc& arc = g->arcs[3 * v + k];
      ASSERT_GE(arc.target, 0);  // closed mesh
      const int32_t h = g->node_face[arc.target];
      EXPECT_EQ(h, mesh.face_neighbors()(f, k));
      EXPECT_NEAR(arc.length,
                  (mesh.face_barycenters().row(f) - mesh.face_barycenters().row(h)).norm(), 1e-15);
    }
  }
  Eigen::VectorXd w = Eigen::VectorXd::Constant(mesh.num_faces(), 2.0);
  w[0] = 4.0;
  auto gw = BuildDualGraph(mesh, w);
  ASSERT_TRUE(gw.ok());
  for (int k = 0; k < 3; ++k) {
    EXPECT_NEAR(gw->arcs[3 * gw->face_node[0] + k].length,
                3.0 * g->arcs[3 * g->face_node[0] + k].length, 1e-15);  // mean of 4 and 2
    EXPECT_NEAR(
        gw->arcs[3 * gw->face_node[5] + k].length,
        (mesh.face_neighbors()(5, k) == 0 ? 3.0 : 2.0) * g->arcs[3 * g->face_node[5] + k].length,
        1e-15);
  }
}

TEST(DualGraphTest, BoundaryFacesHaveFewerArcs) {
  const TriangleMesh mesh = testing::CatalogueMesh("PlateWithFiveHoles");
  auto g = BuildDualGraph(mesh, {});
  ASSERT_TRUE(g.ok());
  int64_t interior_edges = 0, arcs = 0;
  for (int32_t e = 0; e < mesh.num_edges(); ++e)
    interior_edges += mesh.edge_faces()(e, 1) != kNoFace;
  for (const DualArc& a : g->arcs) arcs += a.target >= 0;
  EXPECT_EQ(arcs, 2 * interior_edges);
}

TEST(DualGraphTest, RejectsBadWeights) {
  const TriangleMesh mesh = Icosphere(1);
  EXPECT_THAT(BuildDualGraph(mesh, Eigen::VectorXd::Ones(3)),
              StatusIs(absl::StatusCode::kInvalidArgument));
  Eigen::VectorXd w = Eigen::VectorXd::Ones(mesh.num_faces());
  w[3] = -1;
  EXPECT_THAT(BuildDualGraph(mesh, w), StatusIs(absl::StatusCode::kInvalidArgument));
  w[3] = std::numeric_limits<double>::infinity();
  EXPECT_THAT(BuildDualGraph(mesh, w), StatusIs(absl::StatusCode::kInvalidArgument));
}

TEST(SamplingTest, AllocationProportionalToArea) {
  const TriangleMesh mesh = TwoSpheres(2, 3.0);  // areas 1 : 9
  auto a = AllocateSamplesPerComponent(mesh, 100);
  ASSERT_TRUE(a.ok());
  EXPECT_EQ(*a, (std::vector<int32_t>{10, 90}));
  a = AllocateSamplesPerComponent(mesh, 7);  // quotas 0.7, 6.3: at least one each
  ASSERT_TRUE(a.ok());
  EXPECT_EQ(*a, (std::vector<int32_t>{1, 6}));
  a = AllocateSamplesPerComponent(mesh, 2);
  ASSERT_TRUE(a.ok());
  EXPECT_EQ(*a, (std::vector<int32_t>{1, 1}));
  EXPECT_THAT(AllocateSamplesPerComponent(mesh, 1), StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(AllocateSamplesPerComponent(mesh, mesh.num_faces() + 1),
              StatusIs(absl::StatusCode::kInvalidArgument));
  // All faces: each component is capped at its face count.
  a = AllocateSamplesPerComponent(mesh, mesh.num_faces());
  ASSERT_TRUE(a.ok());
  EXPECT_EQ((*a)[0], mesh.num_faces() / 2);
}

// Farthest point sampling, checked against brute force: every new sample is at the maximal
// distance from the previous ones, and the coverage radius is the final maximal distance.
TEST(SamplingTest, EachSampleIsTheFarthestFace) {
  const TriangleMesh mesh = Icosphere(3);
  auto g = BuildDualGraph(mesh, {});
  ASSERT_TRUE(g.ok());
  auto s = FarthestPointSampling(mesh, *g, {25}, /*seed=*/3, nullptr);
  ASSERT_TRUE(s.ok()) << s.status();
  ASSERT_EQ(s->samples.size(), 25u);
  std::vector<double> nearest(mesh.num_faces(), std::numeric_limits<double>::infinity());
  for (size_t i = 0; i < s->samples.size(); ++i) {
    if (i > 0) {
      const double best = *std::max_element(nearest.begin(), nearest.end());
      EXPECT_EQ(nearest[s->samples[i]], best) << "sample " << i;
    }
    const std::vector<double> d = DualDistances(mesh, s->samples[i]);
    for (int32_t f = 0; f < mesh.num_faces(); ++f) nearest[f] = std::min(nearest[f], d[f]);
  }
  EXPECT_EQ(s->coverage_radius, *std::max_element(nearest.begin(), nearest.end()));
  auto s2 = FarthestPointSampling(mesh, *g, {25}, /*seed=*/3, nullptr);
  EXPECT_EQ(s->samples, s2->samples);
}

TEST(SamplingTest, CancelledThroughPoll) {
  const TriangleMesh mesh = Icosphere(4);
  auto g = BuildDualGraph(mesh, {});
  auto s = FarthestPointSampling(mesh, *g, {50}, 0, &kCancelled);
  EXPECT_THAT(s, StatusIs(absl::StatusCode::kCancelled));
}

TEST(RegionsTest, RegionsAreDualDisks) {
  // 1,280 faces (the faces' indices sorted in one radix pass) and 20,480 (two passes).
  for (int level : {3, 5}) {
    const TriangleMesh mesh = Icosphere(level);
    auto g = BuildDualGraph(mesh, {});
    const std::vector<int32_t> samples = {0, 100, 700, mesh.num_faces() - 1};
    RegionOptions options;
    options.radius = 0.5;
    auto regions = GrowRegions(*g, samples, options, nullptr);
    ASSERT_TRUE(regions.ok());
    for (size_t i = 0; i < samples.size(); ++i) {
      const std::vector<double> d = DualDistances(mesh, samples[i]);
      std::vector<int32_t> expected;
      for (int32_t f = 0; f < mesh.num_faces(); ++f) {
        if (d[f] <= 0.5) expected.push_back(f);
      }
      EXPECT_EQ((*regions)[i], expected) << "level " << level << ", sample " << samples[i];
    }
  }
  const TriangleMesh mesh = Icosphere(3);
  auto g = BuildDualGraph(mesh, {});
  const std::vector<int32_t> samples = {0, 100, 700};
  RegionOptions options;
  // Tiny radius: only the sample, unless a minimum size is asked for.
  options.radius = 1e-9;
  options.min_faces = 4;
  auto regions = GrowRegions(*g, samples, options, nullptr);
  ASSERT_TRUE(regions.ok());
  EXPECT_EQ((*regions)[0].size(), 4u);
  EXPECT_THAT(GrowRegions(*g, samples, options, &kCancelled),
              StatusIs(absl::StatusCode::kCancelled));
}

// The local problems' shift-inverses solve (S_bar + tau I) Y = X, with S_bar taken from their own
// ApplyStiffness: the Hodge factor's K = tau I + B_D^T B_D assembled entry by entry from the faces
// (whose rim couples the boundary edges with their endpoints), and S_bar + tau I cut from S (also
// clamped), on a cap of the sphere and on the whole closed sphere.
TEST(LocalOperatorTest, ShiftInverseSolvesTheShiftedSystem) {
  const TriangleMesh mesh = Icosphere(4);
  const FieldOperator op = MustBuildOperator(mesh, FieldType::Vector());
  const Eigen::VectorXd inv_sqrt_mass = op.mass.cwiseSqrt().cwiseInverse();
  const HodgeFactorData hodge = BuildHodgeFactorData(mesh);
  auto g = BuildDualGraph(mesh, {});
  ASSERT_TRUE(g.ok());
  RegionOptions options;
  options.radius = 0.8;
  auto cap = GrowRegions(*g, {0}, options, nullptr);
  ASSERT_TRUE(cap.ok());
  std::vector<int32_t> sphere(mesh.num_faces());
  std::iota(sphere.begin(), sphere.end(), 0);
  ASSERT_GT((*cap)[0].size(), 300u);
  ASSERT_LT((*cap)[0].size(), sphere.size() / 2);
  for (const std::vector<int32_t>* faces : {&(*cap)[0], &sphere}) {
    for (int kind = 0; kind < 3; ++kind) {
      SCOPED_TRACE(::testing::Message() << faces->size() << " faces, operator " << kind);
      RegionWorkspace ws;
      const double tau = 0.5;
      std::unique_ptr<LocalOperator> local;
      if (kind == 0) {
        local = std::make_unique<HodgeLocalOperator>(mesh, hodge, *faces, tau, ws);
      } else {
        local = std::make_unique<RestrictedLocalOperator>(op, inv_sqrt_mass, *faces, tau, ws,
                                                          /*clamped=*/kind == 2);
      }
      ASSERT_EQ(local->size(), 2 * static_cast<int32_t>(faces->size()));
      ASSERT_TRUE(local->PrepareShiftInverse(nullptr).ok());
      const Eigen::MatrixXd X = Eigen::MatrixXd::Random(local->size(), 3);
      Eigen::MatrixXd Y, SY, Y2, SY2;
      local->ApplyShiftInverse(X, &Y);
      local->ApplyStiffness(Y, &SY);
      const double scale = X.cwiseAbs().maxCoeff() + SY.cwiseAbs().maxCoeff();
      EXPECT_LE((SY + tau * Y - X).cwiseAbs().maxCoeff(), 1e-9 * scale);
      local->ApplyShiftInverseAndStiffness(X, &Y2, &SY2);
      EXPECT_LE((Y2 - Y).cwiseAbs().maxCoeff(), 1e-9 * Y.cwiseAbs().maxCoeff());
      EXPECT_LE((SY2 - SY).cwiseAbs().maxCoeff(), 1e-9 * scale);
    }
  }
}

// S = 1D Dirichlet Laplacian (tridiagonal 2, -1): eigenvalues 2 - 2 cos(k pi / (n + 1)).
class PathOperator : public LocalOperator {
 public:
  explicit PathOperator(int n, double tau) : n_(n), tau_(tau) {
    Eigen::MatrixXd dense;
    dense_ = Eigen::MatrixXd::Zero(n, n);
    for (int i = 0; i < n; ++i) {
      dense_(i, i) = 2.0;
      if (i + 1 < n) dense_(i, i + 1) = dense_(i + 1, i) = -1.0;
    }
  }
  int32_t size() const override { return n_; }
  void ApplyStiffness(const Eigen::MatrixXd& X, Eigen::MatrixXd* Y) override { *Y = dense_ * X; }
  absl::Status PrepareShiftInverse(const CancelToken&) override {
    llt_.compute(dense_ + tau_ * Eigen::MatrixXd::Identity(n_, n_));
    prepared_ = true;
    return absl::OkStatus();
  }
  void ApplyShiftInverse(const Eigen::MatrixXd& X, Eigen::MatrixXd* Y) override {
    *Y = llt_.solve(X);
  }
  double shift() const override { return tau_; }
  bool prepared() const { return prepared_; }

 private:
  int n_;
  double tau_;
  Eigen::MatrixXd dense_;
  Eigen::LLT<Eigen::MatrixXd> llt_;
  bool prepared_ = false;
};

TEST(LocalEigensolverTest, LowestEigenpairsOfPathLaplacian) {
  // count 3 (block of 4 with the guard vector: LOBPCG's fixed-size update) and 6 (block of 7: its
  // general one).
  for (const auto& [n, count] : {std::pair{50, 3}, std::pair{400, 3}, std::pair{400, 6}}) {
    PathOperator op(n, 1e-4);
    LocalEigenOptions options;
    options.count = count;
    options.tolerance = 1e-8;
    auto r = basis_internal::SolveLocalEigenproblem(op, options, nullptr);
    ASSERT_TRUE(r.ok()) << r.status();
    EXPECT_EQ(r->dense, n <= options.dense_max_size);
    EXPECT_EQ(op.prepared(), !r->dense);
    EXPECT_FALSE(r->lanczos_fallback);
    for (int k = 0; k < count; ++k) {
      const double exact = 2.0 - 2.0 * std::cos((k + 1) * M_PI / (n + 1));
      EXPECT_NEAR(r->values[k], exact, 1e-10 * exact + 1e-14) << "n " << n << " k " << k;
      // Eigenvector: sin(j (k + 1) pi / (n + 1)), up to sign.
      Eigen::VectorXd v(n);
      for (int j = 0; j < n; ++j) v[j] = std::sin((j + 1) * (k + 1) * M_PI / (n + 1));
      v.normalize();
      EXPECT_NEAR(std::abs(v.dot(r->vectors.col(k))), 1.0, 1e-8);
    }
  }
  PathOperator op(10, 1.0);
  LocalEigenOptions options;
  options.count = 11;
  EXPECT_THAT(basis_internal::SolveLocalEigenproblem(op, options, nullptr),
              StatusIs(absl::StatusCode::kInvalidArgument));
  PathOperator big(500, 1e-3);
  options.count = 2;
  EXPECT_THAT(basis_internal::SolveLocalEigenproblem(big, options, &kCancelled),
              StatusIs(absl::StatusCode::kCancelled));
}

TEST(LocalEigensolverTest, FallsBackToLanczosWhenLobpcgDoesNotConverge) {
  PathOperator op(400, 1e-4);
  LocalEigenOptions options;
  options.count = 2;
  options.max_iterations = 1;  // cannot converge in one iteration
  options.tolerance = 1e-9;
  auto r = basis_internal::SolveLocalEigenproblem(op, options, nullptr);
  ASSERT_TRUE(r.ok()) << r.status();
  EXPECT_TRUE(r->lanczos_fallback);
  for (int k = 0; k < 2; ++k) {
    const double exact = 2.0 - 2.0 * std::cos((k + 1) * M_PI / 401);
    EXPECT_NEAR(r->values[k], exact, 1e-9 * exact);
  }
}

// The path Laplacian seen through an inverse that is off by a different random 1% at every
// application, as a factorization of a nearly singular region can be: Spectra's Lanczos then
// reports convergence on wrong pairs (lowest eigenvalue 1.09e-4 instead of 6.1e-5).
class NoisyInverseOperator : public PathOperator {
 public:
  using PathOperator::PathOperator;
  void ApplyShiftInverse(const Eigen::MatrixXd& X, Eigen::MatrixXd* Y) override {
    PathOperator::ApplyShiftInverse(X, Y);
    *Y += 0.01 * Y->norm() / std::sqrt(static_cast<double>(Y->size())) *
          Eigen::MatrixXd::Random(Y->rows(), Y->cols());
  }
};

// B9 of issue 15: a local eigenproblem on which neither LOBPCG nor the Lanczos fallback converges
// was INTERNAL (or, as here, wrong pairs were accepted); it is FAILED_PRECONDITION with advice,
// the Lanczos pairs checked against S_bar itself.
TEST(LocalEigensolverTest, NoConvergenceIsAFailedPreconditionWithAdvice) {
  NoisyInverseOperator op(400, 1e-4);
  LocalEigenOptions options;
  options.count = 2;
  options.max_iterations = 1;  // LOBPCG (robust to a poor preconditioner) stops early
  options.tolerance = 1e-9;
  EXPECT_THAT(basis_internal::SolveLocalEigenproblem(op, options, nullptr),
              StatusIs(absl::StatusCode::kFailedPrecondition,
                       ::testing::HasSubstr("a larger dimension d (smaller regions)")));
}

// The order the Hodge factor's K is factored in (InducedNodeOrder), on the pattern of K for a cap
// of a sphere (about a quarter of it, with a boundary), built here from the faces alone: vertex
// couplings along edges, edge couplings within faces, boundary edges coupled to their endpoints.
// Each edge sits between the vertex ranked before its earlier endpoint and that endpoint, and the
// fill stays that of AMD on the whole of K (the order an endpoint's later rank would induce has
// about three times as much).
TEST(InducedNodeOrderTest, EdgesWithTheirEarlierEndpointKeepAmdsFill) {
  const TriangleMesh mesh = Icosphere(5);
  std::vector<int32_t> vertex(mesh.num_vertices(), -1), edge(mesh.num_edges(), -1);
  std::vector<int32_t> vertices, edges, face_nodes, edge_faces;
  for (int32_t f = 0; f < mesh.num_faces(); ++f) {
    if (mesh.face_barycenters()(f, 2) < 0.5) continue;
    for (int k = 0; k < 3; ++k) {
      int32_t& v = vertex[mesh.faces()(f, k)];
      if (v < 0) {
        v = static_cast<int32_t>(vertices.size());
        vertices.push_back(mesh.faces()(f, k));
      }
      face_nodes.push_back(v);
    }
    for (int k = 0; k < 3; ++k) {
      int32_t& e = edge[mesh.face_edges()(f, k)];
      if (e < 0) {
        e = static_cast<int32_t>(edges.size());
        edges.push_back(mesh.face_edges()(f, k));
        edge_faces.push_back(0);
      }
      ++edge_faces[e];
      face_nodes.push_back(e);
    }
  }
  const int32_t nv = static_cast<int32_t>(vertices.size());
  const int32_t n = nv + static_cast<int32_t>(edges.size());
  for (size_t i = 0; i < face_nodes.size(); ++i) {
    if (i % 6 >= 3) face_nodes[i] += nv;
  }
  ASSERT_GT(face_nodes.size() / 6, 4000u);
  // K: -1 per coupling, diagonally dominant.
  std::vector<std::set<int32_t>> upper(n);
  for (size_t f = 0; f < face_nodes.size() / 6; ++f) {
    const int32_t* c = &face_nodes[6 * f];
    for (int j = 0; j < 3; ++j) {
      for (int k = j + 1; k < 3; ++k) {
        upper[std::max(c[j], c[k])].insert(std::min(c[j], c[k]));
        upper[std::max(c[3 + j], c[3 + k])].insert(std::min(c[3 + j], c[3 + k]));
      }
      if (edge_faces[c[3 + j] - nv] == 1) {
        for (int k = 0; k < 3; ++k) {
          if (k != j) upper[c[3 + j]].insert(c[k]);
        }
      }
    }
  }
  UpperCsc K;
  K.n = n;
  K.outer.push_back(0);
  std::vector<double> diagonal(n, 0.5);
  for (int32_t j = 0; j < n; ++j) {
    for (int32_t i : upper[j]) {
      diagonal[i] += 1.0;
      diagonal[j] += 1.0;
    }
  }
  for (int32_t j = 0; j < n; ++j) {
    K.inner.push_back(j);
    K.values.push_back(diagonal[j]);
    for (int32_t i : upper[j]) {
      K.inner.push_back(i);
      K.values.push_back(-1.0);
    }
    K.outer.push_back(static_cast<int32_t>(K.inner.size()));
  }

  RegionWorkspace ws;
  ASSERT_TRUE(InducedNodeOrder(K, nv, face_nodes, ws).ok());
  const std::vector<int32_t> order = ws.order;
  ASSERT_EQ(order.size(), static_cast<size_t>(n));
  std::vector<int32_t> position(n, -1);
  for (int32_t k = 0; k < n; ++k) position[order[k]] = k;
  for (int32_t p : position) ASSERT_GE(p, 0);
  for (size_t f = 0; f < face_nodes.size() / 6; ++f) {
    const int32_t* c = &face_nodes[6 * f];
    for (int k = 0; k < 3; ++k) {
      const int32_t a = c[(k + 1) % 3], b = c[(k + 2) % 3];
      const int32_t first = position[a] < position[b] ? a : b;
      EXPECT_LT(position[c[3 + k]], position[first]);
      // No vertex between the edge and its earlier endpoint.
      for (int32_t q = position[c[3 + k]] + 1; q < position[first]; ++q) ASSERT_GE(order[q], nv);
    }
  }

  LocalCholesky amd, induced, later;
  ASSERT_TRUE(amd.Factorize(K, nullptr).ok());
  ASSERT_TRUE(induced.Factorize(K, nullptr, &order).ok());
  EXPECT_LE(induced.factor_nonzeros(), amd.factor_nonzeros() * 21 / 20);
  EXPECT_LE(induced.flops(), 1.1 * amd.flops());
  // The same vertex order with each edge right after its later endpoint instead.
  std::vector<std::pair<int64_t, int32_t>> keys;
  for (int32_t v = 0; v < nv; ++v) keys.emplace_back(2 * int64_t{position[v]}, v);
  for (size_t f = 0; f < face_nodes.size() / 6; ++f) {
    const int32_t* c = &face_nodes[6 * f];
    for (int k = 0; k < 3; ++k) {
      const int32_t last = std::max(position[c[(k + 1) % 3]], position[c[(k + 2) % 3]]);
      keys.emplace_back(2 * int64_t{last} + 1, c[3 + k]);
    }
  }
  std::sort(keys.begin(), keys.end());
  keys.erase(std::unique(keys.begin(), keys.end()), keys.end());
  std::vector<int32_t> after_later;
  for (const auto& [key, node] : keys) after_later.push_back(node);
  ASSERT_TRUE(later.Factorize(K, nullptr, &after_later).ok());
  EXPECT_GT(later.factor_nonzeros(), 2 * induced.factor_nonzeros());
  // Exact solves in the induced order.
  Eigen::VectorXd x = Eigen::VectorXd::Ones(n);
  induced.SolveInPlace(x.data(), 1);
  Eigen::VectorXd r = -Eigen::VectorXd::Ones(n);
  for (int32_t j = 0; j < n; ++j) {
    for (int32_t p = K.outer[j]; p < K.outer[j + 1]; ++p) {
      const int32_t i = K.inner[p];
      r[i] += K.values[p] * x[j];
      if (i != j) r[j] += K.values[p] * x[i];
    }
  }
  EXPECT_LT(r.norm(), 1e-10 * std::sqrt(n));
  // Malformed input is refused, not read out of bounds.
  std::vector<int32_t> bad = face_nodes;
  bad[3] = nv - 1;  // a vertex where an edge belongs
  EXPECT_THAT(InducedNodeOrder(K, nv, bad, ws), StatusIs(absl::StatusCode::kInvalidArgument));
  // Without a face that holds a boundary edge, that edge is in no face.
  size_t with_boundary = 0;
  while (with_boundary < face_nodes.size() / 6 &&
         edge_faces[face_nodes[6 * with_boundary + 3] - nv] != 1 &&
         edge_faces[face_nodes[6 * with_boundary + 4] - nv] != 1 &&
         edge_faces[face_nodes[6 * with_boundary + 5] - nv] != 1) {
    ++with_boundary;
  }
  ASSERT_LT(with_boundary, face_nodes.size() / 6);
  bad = face_nodes;
  bad.erase(bad.begin() + 6 * with_boundary, bad.begin() + 6 * (with_boundary + 1));
  EXPECT_THAT(InducedNodeOrder(K, nv, bad, ws), StatusIs(absl::StatusCode::kInvalidArgument));
}

TEST(Crc32cTest, KnownValuesAndIncremental) {
  const char* s = "123456789";
  EXPECT_EQ(Crc32c(s, 9), 0xE3069283u);  // the standard check value
  EXPECT_EQ(Crc32c("", 0), 0u);
  std::vector<uint8_t> zeros(32, 0);
  EXPECT_EQ(Crc32c(zeros.data(), 32), 0x8A9136AAu);  // RFC 3720 B.4
  std::vector<uint8_t> data(1000);
  for (size_t i = 0; i < data.size(); ++i) data[i] = static_cast<uint8_t>(i * 31 + 7);
  const uint32_t whole = Crc32c(data.data(), data.size());
  EXPECT_EQ(Crc32cExtend(Crc32c(data.data(), 333), data.data() + 333, 667), whole);
  EXPECT_EQ(crc32c_internal::Crc32cExtendPortable(0, data.data(), data.size()), whole);
  for (size_t i = 0; i < data.size(); i += 97) {
    data[i] ^= 0x10;
    EXPECT_NE(Crc32c(data.data(), data.size()), whole);
    data[i] ^= 0x10;
  }
}

}  // namespace
}  // namespace fieldspace
