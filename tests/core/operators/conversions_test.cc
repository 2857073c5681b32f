#include "core/operators/conversions.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <optional>
#include <random>
#include <vector>

#include "Eigen/Geometry"
#include "core/mesh/shapes.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tests/testing/fixtures.h"
#include "tests/testing/matchers.h"
#include "tests/testing/test_meshes.h"

namespace fieldspace {
namespace {

using ::fieldspace::testing::MustCreate;
using ::fieldspace::testing::StatusIs;
using ::testing::HasSubstr;

class ConversionsTest : public ::testing::Test {
 protected:
  void SetUp() override { mesh_.emplace(MustCreate(MakeTorus(2.0, 0.7, 24, 12))); }
  const TriangleMesh& mesh() const { return *mesh_; }
  int nf() const { return mesh_->num_faces(); }

  AmbientVectors RandomVectors(uint32_t seed) const {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<double> u(-1.0, 1.0);
    AmbientVectors v(nf(), 3);
    for (int f = 0; f < nf(); ++f) v.row(f) << u(rng), u(rng), u(rng);
    return v;
  }
  Eigen::Vector3d Tangential(int f, const Eigen::Vector3d& v) const {
    const Eigen::Vector3d n = mesh_->face_normals().row(f);
    return v - v.dot(n) * n;
  }

  std::optional<TriangleMesh> mesh_;
};

TEST_F(ConversionsTest, VectorRoundTripProjectsToTangentPlane) {
  const AmbientVectors v = RandomVectors(1);
  auto dofs = VectorDofsFromAmbient(mesh(), v);
  ASSERT_TRUE(dofs.ok()) << dofs.status();
  ASSERT_EQ(dofs->size(), 2 * nf());
  auto back = AmbientFromVectorDofs(mesh(), *dofs);
  ASSERT_TRUE(back.ok()) << back.status();
  for (int f = 0; f < nf(); ++f) {
    EXPECT_LT((Eigen::Vector3d(back->row(f)) - Tangential(f, v.row(f))).norm(), 1e-14);
    // Frame coordinates: dof 2f is along x_f.
    EXPECT_NEAR((*dofs)[2 * f], v.row(f).dot(mesh().frame_x().row(f)), 1e-15);
  }
  auto again = VectorDofsFromAmbient(mesh(), *back);
  ASSERT_TRUE(again.ok());
  EXPECT_LT((*again - *dofs).cwiseAbs().maxCoeff(), 1e-14);
}

TEST_F(ConversionsTest, NFieldAllRotationsGiveTheSameDofs) {
  const AmbientVectors v = RandomVectors(2);
  for (int n : {1, 2, 3, 4, 6}) {
    auto dofs = NFieldDofsFromAmbient(mesh(), n, v);
    ASSERT_TRUE(dofs.ok()) << dofs.status();
    // Each of the n directions (v rotated by 2 pi k / n about the normal) maps to the same DOFs,
    // and the length of the tangential part is kept.
    for (int k = 1; k < n; ++k) {
      AmbientVectors rotated(nf(), 3);
      for (int f = 0; f < nf(); ++f) {
        const Eigen::Vector3d n_f = mesh().face_normals().row(f);
        const Eigen::Vector3d t = Tangential(f, v.row(f));
        const double a = 2 * std::numbers::pi * k / n;
        rotated.row(f) = std::cos(a) * t + std::sin(a) * n_f.cross(t);
      }
      auto other = NFieldDofsFromAmbient(mesh(), n, rotated);
      ASSERT_TRUE(other.ok());
      EXPECT_LT((*other - *dofs).cwiseAbs().maxCoeff(), 1e-12) << "n = " << n << " k = " << k;
    }
    for (int f = 0; f < nf(); ++f) {
      EXPECT_NEAR(dofs->segment<2>(2 * f).norm(), Tangential(f, v.row(f)).norm(), 1e-14);
    }
    // Back to the n directions: each maps to the same DOFs, they are 2 pi / n apart, and the
    // representative is the first.
    auto dirs = NFieldDirectionsFromDofs(mesh(), n, *dofs);
    ASSERT_TRUE(dirs.ok()) << dirs.status();
    ASSERT_EQ(static_cast<int>(dirs->size()), n);
    auto rep = NFieldRepresentativeFromDofs(mesh(), n, *dofs);
    ASSERT_TRUE(rep.ok());
    EXPECT_LT((*rep - (*dirs)[0]).cwiseAbs().maxCoeff(), 1e-15);
    for (int k = 0; k < n; ++k) {
      auto d = NFieldDofsFromAmbient(mesh(), n, (*dirs)[k]);
      ASSERT_TRUE(d.ok());
      EXPECT_LT((*d - *dofs).cwiseAbs().maxCoeff(), 1e-12) << "n = " << n << " k = " << k;
    }
    // The original direction is one of the n roots.
    for (int f = 0; f < nf(); f += 17) {
      const Eigen::Vector3d t = Tangential(f, v.row(f));
      double best = 1e300;
      for (int k = 0; k < n; ++k) {
        best = std::min(best, (Eigen::Vector3d((*dirs)[k].row(f)) - t).norm());
      }
      EXPECT_LT(best, 1e-12);
    }
  }
}

TEST_F(ConversionsTest, ZeroNFieldStaysZero) {
  AmbientVectors v = AmbientVectors::Zero(nf(), 3);
  auto dofs = NFieldDofsFromAmbient(mesh(), 4, v);
  ASSERT_TRUE(dofs.ok());
  EXPECT_EQ(dofs->cwiseAbs().maxCoeff(), 0.0);
  auto rep = NFieldRepresentativeFromDofs(mesh(), 4, *dofs);
  ASSERT_TRUE(rep.ok());
  EXPECT_EQ(rep->cwiseAbs().maxCoeff(), 0.0);
}

TEST_F(ConversionsTest, TensorRoundTrip) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  AmbientTensors t(nf(), 9);
  for (int f = 0; f < nf(); ++f) {
    Eigen::Matrix3d A;
    A << u(rng), u(rng), u(rng), u(rng), u(rng), u(rng), u(rng), u(rng), u(rng);
    A = (A + A.transpose()).eval();
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 3; ++c) t(f, 3 * r + c) = A(r, c);
    }
  }
  auto dofs = TensorDofsFromAmbient(mesh(), t);
  ASSERT_TRUE(dofs.ok()) << dofs.status();
  ASSERT_EQ(dofs->size(), 3 * nf());
  auto back = AmbientFromTensorDofs(mesh(), *dofs);
  ASSERT_TRUE(back.ok()) << back.status();
  for (int f = 0; f < nf(); ++f) {
    Eigen::Matrix3d A, B;
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 3; ++c) {
        A(r, c) = t(f, 3 * r + c);
        B(r, c) = (*back)(f, 3 * r + c);
      }
    }
    // B is the tangential part: P A P with P the projector onto the tangent plane.
    const Eigen::Vector3d n = mesh().face_normals().row(f);
    const Eigen::Matrix3d P = Eigen::Matrix3d::Identity() - n * n.transpose();
    EXPECT_LT((B - P * A * P).cwiseAbs().maxCoeff(), 1e-13);
    // Mandel-Voigt: (x^T A x, y^T A y, sqrt2 x^T A y), Frobenius norm kept.
    const Eigen::Vector3d x = mesh().frame_x().row(f), y = mesh().frame_y().row(f);
    EXPECT_NEAR((*dofs)[3 * f + 2], std::sqrt(2.0) * x.dot(A * y), 1e-14);
    EXPECT_NEAR(dofs->segment<3>(3 * f).norm(), B.norm(), 1e-13);
  }
  auto again = TensorDofsFromAmbient(mesh(), *back);
  ASSERT_TRUE(again.ok());
  EXPECT_LT((*again - *dofs).cwiseAbs().maxCoeff(), 1e-13);
}

TEST_F(ConversionsTest, GenericSubsetMatchesWholeMeshConversions) {
  const std::vector<int32_t> faces = {5, 0, 17, 5, nf() - 1};
  const AmbientVectors v = RandomVectors(4);
  for (FieldType type : {FieldType::Vector(), FieldType::NField(3)}) {
    Eigen::MatrixXd values(faces.size(), 3);
    for (size_t i = 0; i < faces.size(); ++i) values.row(i) = v.row(faces[i]);
    auto sub = DofsFromAmbient(mesh(), type, faces, values);
    ASSERT_TRUE(sub.ok()) << sub.status();
    auto all = type.kind == FieldKind::kVector ? VectorDofsFromAmbient(mesh(), v)
                                               : NFieldDofsFromAmbient(mesh(), type.n, v);
    ASSERT_TRUE(all.ok());
    for (size_t i = 0; i < faces.size(); ++i) {
      EXPECT_EQ(sub->segment<2>(2 * i), all->segment<2>(2 * faces[i]));
    }
    auto back = AmbientFromDofs(mesh(), type, faces, *sub);
    ASSERT_TRUE(back.ok()) << back.status();
    auto sub2 = DofsFromAmbient(mesh(), type, faces, *back);
    ASSERT_TRUE(sub2.ok());
    EXPECT_LT((*sub2 - *sub).cwiseAbs().maxCoeff(), 1e-12);
  }
  Eigen::MatrixXd tensors = Eigen::MatrixXd::Zero(faces.size(), 9);
  for (size_t i = 0; i < faces.size(); ++i) {
    tensors(i, 0) = 1.0 + i;
    tensors(i, 4) = -2.0;
    tensors(i, 1) = tensors(i, 3) = 0.5;
  }
  auto sub = DofsFromAmbient(mesh(), FieldType::Tensor(), faces, tensors);
  ASSERT_TRUE(sub.ok()) << sub.status();
  EXPECT_EQ(sub->size(), 3 * static_cast<int>(faces.size()));
  auto back = AmbientFromDofs(mesh(), FieldType::Tensor(), faces, *sub);
  ASSERT_TRUE(back.ok());
  EXPECT_EQ(back->cols(), 9);
}

TEST_F(ConversionsTest, ErrorsAreInvalidArgumentNamingTheFace) {
  AmbientVectors v = RandomVectors(5);
  AmbientVectors short_v = v.topRows(nf() - 1);
  EXPECT_THAT(VectorDofsFromAmbient(mesh(), short_v), StatusIs(absl::StatusCode::kInvalidArgument));
  v(7, 1) = std::numeric_limits<double>::quiet_NaN();
  auto bad = VectorDofsFromAmbient(mesh(), v);
  EXPECT_THAT(bad, StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(bad.status().message(), HasSubstr("face 7"));
  bad = NFieldDofsFromAmbient(mesh(), 4, v);
  EXPECT_THAT(bad, StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(bad.status().message(), HasSubstr("face 7"));
  EXPECT_THAT(NFieldDofsFromAmbient(mesh(), 0, RandomVectors(6)),
              StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(NFieldRepresentativeFromDofs(mesh(), 65, Eigen::VectorXd::Zero(2 * nf())),
              StatusIs(absl::StatusCode::kInvalidArgument));

  Eigen::VectorXd dofs = Eigen::VectorXd::Zero(2 * nf());
  EXPECT_THAT(AmbientFromVectorDofs(mesh(), dofs.head(2 * nf() - 1)),
              StatusIs(absl::StatusCode::kInvalidArgument));
  dofs[2 * 11 + 1] = std::numeric_limits<double>::infinity();
  auto bad_back = AmbientFromVectorDofs(mesh(), dofs);
  EXPECT_THAT(bad_back, StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(bad_back.status().message(), HasSubstr("face 11"));
  EXPECT_THAT(NFieldDirectionsFromDofs(mesh(), 3, dofs),
              StatusIs(absl::StatusCode::kInvalidArgument));

  AmbientTensors t = AmbientTensors::Zero(nf(), 9);
  t(9, 1) = 1.0;  // A01 != A10
  auto asym = TensorDofsFromAmbient(mesh(), t);
  EXPECT_THAT(asym, StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(asym.status().message(), HasSubstr("face 9"));
  EXPECT_THAT(AmbientFromTensorDofs(mesh(), Eigen::VectorXd::Zero(2 * nf())),
              StatusIs(absl::StatusCode::kInvalidArgument));

  const std::vector<int32_t> out_of_range = {0, nf()};
  EXPECT_THAT(
      DofsFromAmbient(mesh(), FieldType::Vector(), out_of_range, Eigen::MatrixXd::Zero(2, 3))
          .status(),
      StatusIs(absl::StatusCode::kInvalidArgument));
  const std::vector<int32_t> two = {0, 1};
  EXPECT_THAT(
      DofsFromAmbient(mesh(), FieldType::Tensor(), two, Eigen::MatrixXd::Zero(2, 3)).status(),
      StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(
      DofsFromAmbient(mesh(), FieldType::NField(0), two, Eigen::MatrixXd::Zero(2, 3)).status(),
      StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(AmbientFromDofs(mesh(), FieldType::Vector(), two, Eigen::VectorXd::Zero(3)),
              StatusIs(absl::StatusCode::kInvalidArgument));
}

}  // namespace
}  // namespace fieldspace
