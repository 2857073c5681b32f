// The client's file formats: field text files, coefficients, constraints, edit scripts, JSON.

#include "client/field_files.h"

#include <cmath>
#include <filesystem>
#include <fstream>

#include "client/json.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tests/testing/matchers.h"

namespace fieldspace::client {
namespace {

using ::fieldspace::testing::StatusIs;

namespace v1 = ::fieldspace::v1;
using ::testing::ElementsAre;
using ::testing::HasSubstr;

TEST(FieldTextTest, ParsesCommentsEncodingAndRows) {
  auto f = ParseFieldText("# a comment\n# encoding: dof\n1 2\n\n3, 4\r\n-5e-1 6\n");
  ASSERT_TRUE(f.ok()) << f.status();
  EXPECT_EQ(f->encoding, v1::FIELD_ENCODING_DOF);
  EXPECT_EQ(f->values_per_face, 2);
  EXPECT_EQ(f->num_faces(), 3);
  EXPECT_THAT(f->values, ElementsAre(1, 2, 3, 4, -0.5, 6));
  auto g = ParseFieldText("1 0 0\n0 1 0\n");
  ASSERT_TRUE(g.ok());
  EXPECT_EQ(g->encoding, v1::FIELD_ENCODING_AMBIENT);  // the default
}

TEST(FieldTextTest, ErrorsNameTheLine) {
  auto ragged = ParseFieldText("1 2 3\n4 5\n");
  EXPECT_THAT(ragged, StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(ragged.status().message(), HasSubstr("line 2"));
  auto nan = ParseFieldText("1 2 3\n4 nan 6\n");
  EXPECT_THAT(nan, StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(nan.status().message(), HasSubstr("line 2"));
  EXPECT_THAT(ParseFieldText("1 x 3\n"), StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(ParseFieldText("# encoding: polar\n1 2 3\n"),
              StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(ParseFieldText("# only comments\n"), StatusIs(absl::StatusCode::kInvalidArgument));
}

TEST(FieldTextTest, WriteThenReadRoundTripsExactly) {
  FieldFile f;
  f.encoding = v1::FIELD_ENCODING_AMBIENT;
  f.values_per_face = 6;
  for (int i = 0; i < 60; ++i) f.values.push_back(std::sin(i) / 3.0);
  const std::string path =
      (std::filesystem::temp_directory_path() / "fs_field_roundtrip.txt").string();
  ASSERT_TRUE(WriteFieldText(path, f, "tensor").ok());
  auto back = ReadFieldFile(path);
  ASSERT_TRUE(back.ok()) << back.status();
  EXPECT_EQ(back->values_per_face, 6);
  EXPECT_EQ(back->values, f.values);  // shortest round-trip formatting
  std::filesystem::remove(path);
  EXPECT_THAT(ReadFieldFile("/nonexistent/field.txt"), StatusIs(absl::StatusCode::kNotFound));
}

TEST(CoefficientsTest, AcceptsJsonFromSolveArraysAndPlainNumbers) {
  EXPECT_THAT(*ParseCoefficients(R"({"basis_id": "b-1", "coefficients": [1, 2.5, -3]})"),
              ElementsAre(1, 2.5, -3));
  EXPECT_THAT(*ParseCoefficients("[4, 5]"), ElementsAre(4, 5));
  EXPECT_THAT(*ParseCoefficients("6 7,\n8\n"), ElementsAre(6, 7, 8));
  EXPECT_THAT(ParseCoefficients(R"({"x": [1]})"), StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(ParseCoefficients(R"({"coefficients": [1, "a"]})"),
              StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(ParseCoefficients("1 inf"), StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(ParseCoefficients("  "), StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(ParseCoefficients("{not json"), StatusIs(absl::StatusCode::kInvalidArgument));
}

TEST(CoefficientsTest, ModePicksOneEigenfieldOfEigenOutput) {
  const std::string eigen =
      R"({"basis_id": "b-1", "eigenvalues": [0.5, 2], "coefficients": [[1, 0, 2], [0, 3, 4]]})";
  EXPECT_THAT(*ParseCoefficients(eigen, 0), ElementsAre(1, 0, 2));
  EXPECT_THAT(*ParseCoefficients(eigen, 1), ElementsAre(0, 3, 4));
  EXPECT_THAT(ParseCoefficients(eigen), StatusIs(absl::StatusCode::kInvalidArgument,
                                                 HasSubstr("holds 2 eigenfields: pick one")));
  EXPECT_THAT(ParseCoefficients(eigen, 2),
              StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr("out of range")));
  EXPECT_THAT(ParseCoefficients("[4, 5]", 0),
              StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr("holds one field")));
  EXPECT_THAT(ParseCoefficients("4 5", 0),
              StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr("holds one field")));
}

TEST(ConstraintsTest, JsonLinesAndArrays) {
  auto lines = ParseConstraints(
      "# soft and hard\n"
      R"({"face": 10, "vector": [1, 0, 0], "weight": 2.5})"
      "\n"
      R"({"face": 11, "tensor": [1, 2, 3, 4, 5, 6], "hard": true})"
      "\n"
      R"({"face": 12, "dofs": [0.5, 0.25]})"
      "\n");
  ASSERT_TRUE(lines.ok()) << lines.status();
  ASSERT_EQ(lines->size(), 3u);
  const v1::Constraint& a = (*lines)[0];
  EXPECT_EQ(a.face(), 10);
  EXPECT_THAT(a.value(), ElementsAre(1, 0, 0));
  EXPECT_EQ(a.encoding(), v1::FIELD_ENCODING_AMBIENT);
  EXPECT_TRUE(a.has_weight());
  EXPECT_EQ(a.weight(), 2.5);
  EXPECT_FALSE(a.hard());
  EXPECT_THAT((*lines)[1].value(), ElementsAre(1, 2, 3, 4, 5, 6));
  EXPECT_TRUE((*lines)[1].hard());
  EXPECT_FALSE((*lines)[1].has_weight());
  EXPECT_EQ((*lines)[2].encoding(), v1::FIELD_ENCODING_DOF);
  auto array = ParseConstraints(R"([{"face": 1, "vector": [0, 1, 0]}])");
  ASSERT_TRUE(array.ok());
  EXPECT_EQ(array->size(), 1u);
}

TEST(ConstraintsTest, BadConstraintsNameTheLineAndProblem) {
  auto missing_face = ParseConstraints(
      "\n"
      R"({"vector": [1, 0, 0]})");
  EXPECT_THAT(missing_face, StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(missing_face.status().message(), HasSubstr("line 2"));
  EXPECT_THAT(missing_face.status().message(), HasSubstr("face"));
  EXPECT_THAT(ParseConstraints(R"({"face": 1})"), StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(ParseConstraints(R"({"face": 1, "vector": [1, 0]})"),
              StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(ParseConstraints(R"({"face": 1.5, "vector": [1, 0, 0]})"),
              StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(
      ParseConstraints(R"({"face": 1, "vector": [1, 0, 0], "tensor": [1,2,3,4,5,6]})").status(),
      StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(ParseConstraints(R"({"face": 1, "vector": [1, 0, 0], "hard": "yes"})"),
              StatusIs(absl::StatusCode::kInvalidArgument));
  auto unknown = ParseConstraints(R"({"face": 1, "vector": [1, 0, 0], "wieght": 2})");
  EXPECT_THAT(unknown.status().message(), HasSubstr("wieght"));
  EXPECT_THAT(ParseConstraints("{oops"), StatusIs(absl::StatusCode::kInvalidArgument));
}

TEST(EditScriptTest, ParsesEveryEditOfTheIssueFormat) {
  auto add = ParseEdit(
      R"({"add": {"id": 1, "face": 10, "vector": [1, 0, 0], "weight": 1.0, "hard": false}})", "l1");
  ASSERT_TRUE(add.ok()) << add.status();
  ASSERT_TRUE(add->has_add());
  EXPECT_EQ(add->add().id(), 1);
  EXPECT_EQ(add->add().constraint().face(), 10);
  EXPECT_THAT(add->add().constraint().value(), ElementsAre(1, 0, 0));
  auto move = ParseEdit(R"({"move": {"id": 1, "face": 12, "vector": [0, 1, 0]}})", "l2");
  ASSERT_TRUE(move.ok()) << move.status();
  EXPECT_EQ(move->move().face(), 12);
  EXPECT_THAT(move->move().value(), ElementsAre(0, 1, 0));
  auto remove = ParseEdit(R"({"remove": {"id": 1}})", "l3");
  ASSERT_TRUE(remove.ok());
  EXPECT_EQ(remove->remove().id(), 1);
  auto weights = ParseEdit(R"({"weights": {"mu_s": 1.0, "mu_b": 0.001, "mu_c": 1.0}})", "l4");
  ASSERT_TRUE(weights.ok());
  EXPECT_EQ(weights->set_weights().mu_b(), 0.001);
  auto watch = ParseEdit(R"({"watch": {"faces": [0, 1, 2]}})", "l5");
  ASSERT_TRUE(watch.ok());
  EXPECT_THAT(watch->watch().faces(), ElementsAre(0, 1, 2));
  EXPECT_EQ(watch->watch().encoding(), v1::FIELD_ENCODING_AMBIENT);
  auto tensor = ParseEdit(R"({"add": {"id": 2, "face": 3, "tensor": [1, 0, 0, 0, 0, 0]}})", "l6");
  ASSERT_TRUE(tensor.ok());
  EXPECT_EQ(tensor->add().constraint().value_size(), 6);
}

TEST(EditScriptTest, Errors) {
  EXPECT_THAT(ParseEdit(R"({"frobnicate": {}})", "x"),
              StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(ParseEdit(R"({"add": {}, "remove": {}})", "x"),
              StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(ParseEdit(R"({"remove": {}})", "x"), StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(ParseEdit(R"({"weights": {}})", "x"), StatusIs(absl::StatusCode::kInvalidArgument));
  // Weights left out are left out of the request (the session keeps their values).
  absl::StatusOr<v1::DesignRequest> only_s = ParseEdit(R"({"weights": {"mu_s": 1}})", "x");
  ASSERT_TRUE(only_s.ok()) << only_s.status();
  EXPECT_TRUE(only_s->set_weights().has_mu_s());
  EXPECT_FALSE(only_s->set_weights().has_mu_b());
  EXPECT_FALSE(only_s->set_weights().has_mu_c());
  EXPECT_THAT(ParseEdit(R"({"watch": {"faces": [0.5]}})", "x"),
              StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(ParseEdit("[1, 2]", "x"), StatusIs(absl::StatusCode::kInvalidArgument));
  auto bad = ParseEdit(R"({"move": {"id": 1, "vector": [0, 1, 0]}})", "edits.jsonl:7");
  EXPECT_THAT(bad.status().message(), HasSubstr("edits.jsonl:7"));
}

TEST(JsonWriterTest, EscapesAndRoundTripsNumbers) {
  JsonWriter j;
  j.BeginObject();
  j.Key("id").String("m-\"x\"\n");
  j.Key("v").BeginArray().Number(0.1).Number(1e300).Number(std::nan("")).Int(-7).EndArray();
  j.Key("ok").Bool(true);
  j.EndObject();
  EXPECT_EQ(j.str(), R"({"id":"m-\"x\"\n","v":[0.1,1e+300,null,-7],"ok":true})");
  auto parsed = ParseJson(j.str());
  ASSERT_TRUE(parsed.ok()) << parsed.status();
  EXPECT_EQ(parsed->struct_value().fields().at("v").list_value().values(0).number_value(), 0.1);
}

}  // namespace
}  // namespace fieldspace::client
