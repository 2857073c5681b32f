#include "server/design_tools_convert.h"

#include <cmath>
#include <utility>

#include "absl/strings/str_cat.h"
#include "core/common/status_macros.h"
#include "core/subspace/design_tools.h"

namespace fieldspace::server {
namespace {

namespace v1 = ::fieldspace::v1;

// A core error with `what` in front of its message, its code kept.
absl::Status Named(const absl::Status& st, absl::string_view what) {
  return absl::Status(st.code(), absl::StrCat(what, ": ", st.message()));
}

ConstraintKind Kind(bool hard) { return hard ? ConstraintKind::kHard : ConstraintKind::kSoft; }

absl::StatusOr<SurfacePoint> FacePointFromProto(const TriangleMesh& mesh,
                                                const v1::SurfacePoint::FacePoint& p) {
  if (p.barycentric_size() != 3) {
    return absl::InvalidArgumentError(
        absl::StrCat("a face point needs 3 barycentric coordinates, got ", p.barycentric_size()));
  }
  SurfacePoint out{p.face(), Eigen::Vector3d(p.barycentric(0), p.barycentric(1), p.barycentric(2))};
  RETURN_IF_ERROR(ValidateSurfacePoint(mesh, out));
  return out;
}

absl::StatusOr<SurfacePoint> SurfacePointFromProto(const TriangleMesh& mesh,
                                                   const v1::SurfacePoint& p) {
  switch (p.at_case()) {
    case v1::SurfacePoint::kFacePoint:
      return FacePointFromProto(mesh, p.face_point());
    case v1::SurfacePoint::kPosition:
      return SnapToSurface(mesh,
                           Eigen::Vector3d(p.position().x(), p.position().y(), p.position().z()));
    case v1::SurfacePoint::AT_NOT_SET:
      break;
  }
  return absl::InvalidArgumentError("a surface point needs face_point or position");
}

absl::StatusOr<std::vector<FieldConstraint>> StrokeFromProto(const ServedBasis& basis,
                                                             const v1::Stroke& s) {
  const TriangleMesh& mesh = *basis.mesh;
  std::vector<SurfacePoint> points;
  points.reserve(s.points_size());
  for (int i = 0; i < s.points_size(); ++i) {
    absl::StatusOr<SurfacePoint> p = SurfacePointFromProto(mesh, s.points(i));
    if (!p.ok()) return Named(p.status(), absl::StrCat("point ", i));
    points.push_back(*p);
  }
  StrokeOptions options;
  options.kind = Kind(s.hard());
  if (s.has_weight()) options.weight = s.weight();
  if (s.has_anisotropy()) options.anisotropy = s.anisotropy();
  return StrokeConstraints(mesh, basis.basis->type, points, options);
}

absl::StatusOr<std::vector<FieldConstraint>> SingularityFromProto(const ServedBasis& basis,
                                                                  const v1::PlaceSingularity& s) {
  const TriangleMesh& mesh = *basis.mesh;
  int32_t vertex = 0;
  switch (s.at_case()) {
    case v1::PlaceSingularity::kVertex:
      vertex = s.vertex();
      break;
    case v1::PlaceSingularity::kFacePoint: {
      ASSIGN_OR_RETURN(SurfacePoint p, FacePointFromProto(mesh, s.face_point()));
      vertex = NearestCorner(mesh, p);
      break;
    }
    case v1::PlaceSingularity::AT_NOT_SET:
      return absl::InvalidArgumentError("a singularity needs a vertex or a face_point");
  }
  PlacedSingularityOptions options;
  options.kind = Kind(s.hard());
  if (s.has_weight()) options.weight = s.weight();
  return SingularityConstraints(mesh, basis.basis->type, vertex, s.index(), options);
}

absl::StatusOr<std::vector<FieldConstraint>> BoundaryFromProto(const ServedBasis& basis,
                                                               const v1::AlignBoundary& a) {
  BoundaryAlignmentOptions options;
  switch (a.mode()) {
    case v1::BOUNDARY_ALIGN_TANGENT:
      options.mode = BoundaryAlignment::kTangent;
      break;
    case v1::BOUNDARY_ALIGN_NORMAL:
      options.mode = BoundaryAlignment::kNormal;
      break;
    default:
      return absl::InvalidArgumentError(absl::StrCat("unknown boundary alignment mode ", a.mode()));
  }
  options.loops.assign(a.loops().begin(), a.loops().end());
  options.kind = Kind(a.hard());
  if (a.has_weight()) options.weight = a.weight();
  return BoundaryAlignmentConstraints(*basis.mesh, basis.basis->type, options);
}

absl::StatusOr<std::vector<FieldConstraint>> FeaturesFromProto(const ServedBasis& basis,
                                                               const v1::AlignFeatures& a) {
  FeatureAlignmentOptions options;
  if (a.has_angle_degrees()) options.angle_degrees = a.angle_degrees();
  options.kind = Kind(a.hard());
  if (a.has_weight()) options.weight = a.weight();
  return FeatureAlignmentConstraints(*basis.mesh, basis.basis->type, options);
}

}  // namespace

absl::StatusOr<std::vector<FieldConstraint>> ConstraintGroupFromProto(
    const ServedBasis& basis, const v1::ConstraintGroup& group, absl::string_view what) {
  absl::StatusOr<std::vector<FieldConstraint>> out =
      absl::InvalidArgumentError("a constraint group needs a tool");
  switch (group.tool_case()) {
    case v1::ConstraintGroup::kStroke:
      out = StrokeFromProto(basis, group.stroke());
      break;
    case v1::ConstraintGroup::kSingularity:
      out = SingularityFromProto(basis, group.singularity());
      break;
    case v1::ConstraintGroup::kAlignBoundary:
      out = BoundaryFromProto(basis, group.align_boundary());
      break;
    case v1::ConstraintGroup::kAlignFeatures:
      out = FeaturesFromProto(basis, group.align_features());
      break;
    case v1::ConstraintGroup::TOOL_NOT_SET:
      break;
  }
  if (!out.ok()) return Named(out.status(), what);
  return out;
}

absl::StatusOr<ToolEdit> ToolEditFromProto(const ServedBasis& basis,
                                           const v1::DesignRequest& request) {
  v1::ConstraintGroup group;
  switch (request.edit_case()) {
    case v1::DesignRequest::kAddStroke:
      *group.mutable_stroke() = request.add_stroke();
      break;
    case v1::DesignRequest::kPlaceSingularity:
      *group.mutable_singularity() = request.place_singularity();
      break;
    case v1::DesignRequest::kAlignBoundary:
      *group.mutable_align_boundary() = request.align_boundary();
      break;
    case v1::DesignRequest::kAlignFeatures:
      *group.mutable_align_features() = request.align_features();
      break;
    default:
      return absl::InvalidArgumentError("not a design tool edit");
  }
  const int64_t id = ToolEditId(request);
  ToolEdit edit;
  edit.id = id;
  ASSIGN_OR_RETURN(edit.constraints,
                   ConstraintGroupFromProto(basis, group, absl::StrCat("tool id ", id)));
  return edit;
}

int64_t ToolEditId(const v1::DesignRequest& request) {
  switch (request.edit_case()) {
    case v1::DesignRequest::kAddStroke:
      return request.add_stroke().id();
    case v1::DesignRequest::kPlaceSingularity:
      return request.place_singularity().id();
    case v1::DesignRequest::kAlignBoundary:
      return request.align_boundary().id();
    case v1::DesignRequest::kAlignFeatures:
      return request.align_features().id();
    default:
      return 0;
  }
}

absl::Status AppendConstraintGroups(
    const ServedBasis& basis, const google::protobuf::RepeatedPtrField<v1::ConstraintGroup>& groups,
    std::vector<FieldConstraint>* out) {
  for (int i = 0; i < groups.size(); ++i) {
    ASSIGN_OR_RETURN(
        std::vector<FieldConstraint> c,
        ConstraintGroupFromProto(basis, groups.Get(i), absl::StrCat("constraint_groups ", i)));
    out->insert(out->end(), std::make_move_iterator(c.begin()), std::make_move_iterator(c.end()));
  }
  return absl::OkStatus();
}

}  // namespace fieldspace::server
