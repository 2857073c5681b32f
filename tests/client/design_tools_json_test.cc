// The designer's tools in the CLI's JSON: the Acceptance forms of design scripts and of
// `solve --constraints` files, group moves, and exact errors.

#include "client/design_tools_json.h"

#include "client/field_files.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tests/testing/matchers.h"

namespace fieldspace::client {
namespace {

using ::fieldspace::testing::StatusIs;
namespace v1 = ::fieldspace::v1;
using ::testing::HasSubstr;

TEST(DesignToolsJsonTest, ScriptFormsAsWritten) {
  auto stroke = ParseEdit(
      R"({"stroke": {"id": 1, "points": [[0, 0, 1], [0.5, 0.1, 0.8]], "hard": false,
          "weight": 1.0}})",
      "l1");
  ASSERT_TRUE(stroke.ok()) << stroke.status();
  ASSERT_TRUE(stroke->has_add_stroke());
  EXPECT_EQ(stroke->add_stroke().id(), 1);
  ASSERT_EQ(stroke->add_stroke().points_size(), 2);
  EXPECT_EQ(stroke->add_stroke().points(1).position().x(), 0.5);
  EXPECT_EQ(stroke->add_stroke().points(1).position().z(), 0.8);
  EXPECT_FALSE(stroke->add_stroke().hard());
  EXPECT_EQ(stroke->add_stroke().weight(), 1.0);
  EXPECT_EQ(DesignEditKind(*stroke), "stroke");

  auto singularity =
      ParseEdit(R"({"singularity": {"id": 2, "vertex": 17, "index": 0.25, "hard": true}})", "l2");
  ASSERT_TRUE(singularity.ok()) << singularity.status();
  EXPECT_EQ(singularity->place_singularity().id(), 2);
  EXPECT_EQ(singularity->place_singularity().vertex(), 17);
  EXPECT_EQ(singularity->place_singularity().index(), 0.25);
  EXPECT_TRUE(singularity->place_singularity().hard());
  EXPECT_FALSE(singularity->place_singularity().has_weight());

  auto boundary =
      ParseEdit(R"({"align_boundary": {"id": 3, "mode": "tangent", "hard": true}})", "l3");
  ASSERT_TRUE(boundary.ok()) << boundary.status();
  EXPECT_EQ(boundary->align_boundary().mode(), v1::BOUNDARY_ALIGN_TANGENT);
  EXPECT_TRUE(boundary->align_boundary().hard());
  auto normal =
      ParseEdit(R"({"align_boundary": {"id": 3, "mode": "normal", "loops": [0, 2]}})", "l3");
  ASSERT_TRUE(normal.ok()) << normal.status();
  EXPECT_EQ(normal->align_boundary().mode(), v1::BOUNDARY_ALIGN_NORMAL);
  EXPECT_EQ(normal->align_boundary().loops_size(), 2);

  auto features = ParseEdit(R"({"align_features": {"id": 4, "angle_degrees": 60}})", "l4");
  ASSERT_TRUE(features.ok()) << features.status();
  EXPECT_EQ(features->align_features().id(), 4);
  EXPECT_EQ(features->align_features().angle_degrees(), 60);
  EXPECT_EQ(DesignEditKind(*features), "align_features");

  auto remove = ParseEdit(R"({"remove": {"id": 2}})", "l5");
  ASSERT_TRUE(remove.ok());
  EXPECT_EQ(remove->remove().id(), 2);

  // A face point, and a group's move to a new stroke.
  auto move = ParseEdit(
      R"({"move": {"id": 1, "stroke": {"points": [{"face": 3, "barycentric": [0.2, 0.3, 0.5]},
          [0, 1, 0]]}}})",
      "l6");
  ASSERT_TRUE(move.ok()) << move.status();
  EXPECT_EQ(move->move().id(), 1);
  ASSERT_TRUE(move->move().group().has_stroke());
  EXPECT_EQ(move->move().group().stroke().points(0).face_point().face(), 3);
  EXPECT_EQ(move->move().group().stroke().points(0).face_point().barycentric(2), 0.5);
  EXPECT_EQ(DesignEditKind(*move), "move");
}

TEST(DesignToolsJsonTest, SolveConstraintFilesTakeToolsAsGroups) {
  std::vector<v1::ConstraintGroup> groups;
  auto constraints = ParseConstraints(
      "{\"face\": 3, \"vector\": [1, 0, 0]}\n"
      "{\"stroke\": {\"id\": 1, \"points\": [[0, 0, 1], [1, 0, 0]], \"hard\": true}}\n"
      "{\"singularity\": {\"vertex\": 5, \"index\": -0.25}}\n",
      &groups);
  ASSERT_TRUE(constraints.ok()) << constraints.status();
  EXPECT_EQ(constraints->size(), 1u);
  ASSERT_EQ(groups.size(), 2u);
  EXPECT_TRUE(groups[0].stroke().hard());
  EXPECT_EQ(groups[1].singularity().index(), -0.25);
  groups.clear();
  auto array = ParseConstraints(R"([{"align_features": {"angle_degrees": 45}}])", &groups);
  ASSERT_TRUE(array.ok()) << array.status();
  EXPECT_TRUE(array->empty());
  ASSERT_EQ(groups.size(), 1u);
  EXPECT_EQ(groups[0].align_features().angle_degrees(), 45);
  // Without a place for groups, a tool is not a constraint.
  EXPECT_THAT(ParseConstraints(R"({"align_features": {}})"),
              StatusIs(absl::StatusCode::kInvalidArgument));
}

TEST(DesignToolsJsonTest, ErrorsNameTheLineAndTheProblem) {
  const auto expect_error = [](const char* line, const char* what) {
    auto edit = ParseEdit(line, "s:7");
    EXPECT_THAT(edit, StatusIs(absl::StatusCode::kInvalidArgument)) << line;
    if (!edit.ok()) {
      EXPECT_THAT(edit.status().message(), HasSubstr("s:7")) << line;
      EXPECT_THAT(edit.status().message(), HasSubstr(what)) << line;
    }
  };
  expect_error(R"({"stroke": {"points": [[0, 0, 1], [1, 0, 0]]}})", "needs an 'id'");
  expect_error(R"({"stroke": {"id": 1, "points": [[0, 0], [1, 0, 0]]}})", "point 0");
  expect_error(R"({"stroke": {"id": 1, "points": [[0, 0, 1]], "color": 3}})", "'color'");
  expect_error(R"({"stroke": {"id": 1, "points": [[0, 0, 1]], "hard": 1}})", "'hard'");
  expect_error(R"({"singularity": {"id": 2, "index": 1}})", "'vertex' or 'face'");
  expect_error(R"({"singularity": {"id": 2, "vertex": 1}})", "'index'");
  expect_error(R"({"align_boundary": {"id": 3, "mode": "sideways"}})", "'mode'");
  expect_error(R"({"align_boundary": {"id": 3, "loops": [0.5]}})", "'loops'");
  expect_error(R"({"move": {"id": 1, "stroke": {}, "singularity": {}}})", "one tool");
  expect_error(R"({"paint": {"id": 1}})", "unknown edit 'paint'");
}

}  // namespace
}  // namespace fieldspace::client
