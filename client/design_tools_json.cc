#include "client/design_tools_json.h"

#include <cmath>
#include <utility>
#include <vector>

#include "absl/strings/str_cat.h"
#include "client/json.h"
#include "core/common/status_macros.h"

namespace fieldspace::client {
namespace {

namespace v1 = ::fieldspace::v1;
using google::protobuf::Struct;
using google::protobuf::Value;

constexpr const char* kToolKeys[] = {"stroke", "singularity", "align_boundary", "align_features"};

// Optional boolean `key` (default false).
absl::StatusOr<bool> GetFlag(const Struct& object, const std::string& key,
                             absl::string_view where) {
  auto it = object.fields().find(key);
  if (it == object.fields().end()) return false;
  if (it->second.kind_case() != Value::kBoolValue) {
    return absl::InvalidArgumentError(absl::StrCat(where, ": '", key, "' must be true or false"));
  }
  return it->second.bool_value();
}

bool Has(const Struct& object, const char* key) { return object.fields().contains(key); }

absl::StatusOr<v1::SurfacePoint::FacePoint> FacePoint(const Struct& object,
                                                      absl::string_view where) {
  v1::SurfacePoint::FacePoint p;
  ASSIGN_OR_RETURN(int32_t face, GetInt32(object, "face", where));
  ASSIGN_OR_RETURN(std::vector<double> b, NumberArray(object, "barycentric", where));
  if (b.size() != 3) {
    return absl::InvalidArgumentError(
        absl::StrCat(where, ": 'barycentric' needs 3 numbers, got ", b.size()));
  }
  p.set_face(face);
  p.mutable_barycentric()->Assign(b.begin(), b.end());
  return p;
}

absl::Status ParsePoints(const Struct& object, absl::string_view where, v1::Stroke* stroke) {
  auto it = object.fields().find("points");
  if (it == object.fields().end() || it->second.kind_case() != Value::kListValue) {
    return absl::InvalidArgumentError(absl::StrCat(where, ": 'points' must be an array"));
  }
  int i = 0;
  for (const Value& item : it->second.list_value().values()) {
    const std::string at = absl::StrCat(where, " point ", i++);
    v1::SurfacePoint* point = stroke->add_points();
    if (item.kind_case() == Value::kStructValue) {
      RETURN_IF_ERROR(CheckKeys(item.struct_value(), {"face", "barycentric"}, at));
      ASSIGN_OR_RETURN(*point->mutable_face_point(), FacePoint(item.struct_value(), at));
      continue;
    }
    const auto& xyz = item.list_value().values();
    if (item.kind_case() != Value::kListValue || xyz.size() != 3 ||
        xyz[0].kind_case() != Value::kNumberValue || xyz[1].kind_case() != Value::kNumberValue ||
        xyz[2].kind_case() != Value::kNumberValue) {
      return absl::InvalidArgumentError(
          absl::StrCat(at, ": a point is [x, y, z] or {\"face\": f, \"barycentric\": [a, b, c]}"));
    }
    point->mutable_position()->set_x(xyz[0].number_value());
    point->mutable_position()->set_y(xyz[1].number_value());
    point->mutable_position()->set_z(xyz[2].number_value());
  }
  return absl::OkStatus();
}

// The common "hard" and "weight" of every tool.
template <typename Tool>
absl::Status ParseStrength(const Struct& object, absl::string_view where, Tool* tool) {
  ASSIGN_OR_RETURN(bool hard, GetFlag(object, "hard", where));
  tool->set_hard(hard);
  if (Has(object, "weight")) {
    ASSIGN_OR_RETURN(double weight, GetNumber(object, "weight", where));
    tool->set_weight(weight);
  }
  return absl::OkStatus();
}

// The optional "id" (an edit needs it: see ParseToolEdit).
template <typename Tool>
absl::Status ParseId(const Struct& object, absl::string_view where, Tool* tool) {
  if (!Has(object, "id")) return absl::OkStatus();
  ASSIGN_OR_RETURN(int32_t id, GetInt32(object, "id", where));
  tool->set_id(id);
  return absl::OkStatus();
}

}  // namespace

bool IsToolKey(absl::string_view key) {
  for (const char* k : kToolKeys) {
    if (key == k) return true;
  }
  return false;
}

absl::StatusOr<v1::ConstraintGroup> ParseToolGroup(absl::string_view key, const Struct& object,
                                                   absl::string_view where) {
  v1::ConstraintGroup group;
  if (key == "stroke") {
    RETURN_IF_ERROR(CheckKeys(object, {"id", "points", "hard", "weight", "anisotropy"}, where));
    v1::Stroke* s = group.mutable_stroke();
    RETURN_IF_ERROR(ParseId(object, where, s));
    RETURN_IF_ERROR(ParsePoints(object, where, s));
    RETURN_IF_ERROR(ParseStrength(object, where, s));
    if (Has(object, "anisotropy")) {
      ASSIGN_OR_RETURN(double a, GetNumber(object, "anisotropy", where));
      s->set_anisotropy(a);
    }
  } else if (key == "singularity") {
    RETURN_IF_ERROR(CheckKeys(
        object, {"id", "vertex", "face", "barycentric", "index", "hard", "weight"}, where));
    v1::PlaceSingularity* s = group.mutable_singularity();
    RETURN_IF_ERROR(ParseId(object, where, s));
    if (Has(object, "vertex") == Has(object, "face")) {
      return absl::InvalidArgumentError(
          absl::StrCat(where, ": give 'vertex' or 'face' with 'barycentric'"));
    }
    if (Has(object, "vertex")) {
      ASSIGN_OR_RETURN(int32_t vertex, GetInt32(object, "vertex", where));
      s->set_vertex(vertex);
    } else {
      ASSIGN_OR_RETURN(*s->mutable_face_point(), FacePoint(object, where));
    }
    ASSIGN_OR_RETURN(double index, GetNumber(object, "index", where));
    s->set_index(index);
    RETURN_IF_ERROR(ParseStrength(object, where, s));
  } else if (key == "align_boundary") {
    RETURN_IF_ERROR(CheckKeys(object, {"id", "mode", "loops", "hard", "weight"}, where));
    v1::AlignBoundary* a = group.mutable_align_boundary();
    RETURN_IF_ERROR(ParseId(object, where, a));
    if (auto it = object.fields().find("mode"); it != object.fields().end()) {
      if (it->second.string_value() == "normal") {
        a->set_mode(v1::BOUNDARY_ALIGN_NORMAL);
      } else if (it->second.string_value() != "tangent") {
        return absl::InvalidArgumentError(
            absl::StrCat(where, ": 'mode' must be \"tangent\" or \"normal\""));
      }
    }
    if (Has(object, "loops")) {
      ASSIGN_OR_RETURN(std::vector<double> loops, NumberArray(object, "loops", where));
      for (double l : loops) {
        if (std::floor(l) != l || l < 0 || l > INT32_MAX) {
          return absl::InvalidArgumentError(
              absl::StrCat(where, ": 'loops' must hold loop indices (integers >= 0)"));
        }
        a->add_loops(static_cast<int32_t>(l));
      }
    }
    RETURN_IF_ERROR(ParseStrength(object, where, a));
  } else if (key == "align_features") {
    RETURN_IF_ERROR(CheckKeys(object, {"id", "angle_degrees", "hard", "weight"}, where));
    v1::AlignFeatures* a = group.mutable_align_features();
    RETURN_IF_ERROR(ParseId(object, where, a));
    if (Has(object, "angle_degrees")) {
      ASSIGN_OR_RETURN(double angle, GetNumber(object, "angle_degrees", where));
      a->set_angle_degrees(angle);
    }
    RETURN_IF_ERROR(ParseStrength(object, where, a));
  } else {
    return absl::InvalidArgumentError(absl::StrCat(
        where, ": unknown tool '", key, "' (stroke, singularity, align_boundary, align_features)"));
  }
  return group;
}

absl::StatusOr<v1::DesignRequest> ParseToolEdit(absl::string_view key, const Struct& object,
                                                absl::string_view where) {
  if (!Has(object, "id")) return absl::InvalidArgumentError(absl::StrCat(where, ": needs an 'id'"));
  ASSIGN_OR_RETURN(v1::ConstraintGroup group, ParseToolGroup(key, object, where));
  v1::DesignRequest request;
  switch (group.tool_case()) {
    case v1::ConstraintGroup::kStroke:
      *request.mutable_add_stroke() = std::move(*group.mutable_stroke());
      break;
    case v1::ConstraintGroup::kSingularity:
      *request.mutable_place_singularity() = std::move(*group.mutable_singularity());
      break;
    case v1::ConstraintGroup::kAlignBoundary:
      *request.mutable_align_boundary() = std::move(*group.mutable_align_boundary());
      break;
    case v1::ConstraintGroup::kAlignFeatures:
      *request.mutable_align_features() = std::move(*group.mutable_align_features());
      break;
    case v1::ConstraintGroup::TOOL_NOT_SET:
      break;
  }
  return request;
}

bool IsToolMove(const Struct& object) {
  for (const char* k : kToolKeys) {
    if (Has(object, k)) return true;
  }
  return false;
}

absl::StatusOr<v1::DesignRequest> ParseToolMove(const Struct& object, absl::string_view where) {
  if (object.fields().size() != 2) {
    return absl::InvalidArgumentError(
        absl::StrCat(where, ": a tool's move is {\"id\": N, <tool>: {...}} with one tool"));
  }
  v1::DesignRequest request;
  ASSIGN_OR_RETURN(int32_t id, GetInt32(object, "id", where));
  request.mutable_move()->set_id(id);
  for (const auto& [key, value] : object.fields()) {
    if (key == "id") continue;
    const std::string at = absl::StrCat(where, " ", key);
    ASSIGN_OR_RETURN(const Struct* tool, ObjectOf(value, at));
    ASSIGN_OR_RETURN(*request.mutable_move()->mutable_group(), ParseToolGroup(key, *tool, at));
  }
  return request;
}

std::string DesignEditKind(const v1::DesignRequest& edit) {
  switch (edit.edit_case()) {
    case v1::DesignRequest::kOpen:
      return "open";
    case v1::DesignRequest::kAdd:
      return "add";
    case v1::DesignRequest::kMove:
      return "move";
    case v1::DesignRequest::kRemove:
      return "remove";
    case v1::DesignRequest::kSetWeights:
      return "weights";
    case v1::DesignRequest::kWatch:
      return "watch";
    case v1::DesignRequest::kAddStroke:
      return "stroke";
    case v1::DesignRequest::kPlaceSingularity:
      return "singularity";
    case v1::DesignRequest::kAlignBoundary:
      return "align_boundary";
    case v1::DesignRequest::kAlignFeatures:
      return "align_features";
    case v1::DesignRequest::EDIT_NOT_SET:
      break;
  }
  return "none";
}

}  // namespace fieldspace::client
