#include "tests/testing/matchers.h"

#include <string>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"

namespace fieldspace::testing {
namespace {

using ::testing::HasSubstr;
using ::testing::Not;

TEST(StatusIsTest, MatchesStatusByCodeAndMessage) {
  const absl::Status s = absl::InvalidArgumentError("face 7: bad index");
  EXPECT_THAT(s, StatusIs(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(s, StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr("face 7")));
  EXPECT_THAT(s, StatusIs(absl::StatusCode::kInvalidArgument, "face 7: bad index"));
  EXPECT_THAT(s, Not(StatusIs(absl::StatusCode::kNotFound)));
  EXPECT_THAT(s, Not(StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr("face 8"))));
  EXPECT_THAT(s, Not(IsOk()));
  EXPECT_THAT(absl::OkStatus(), IsOk());
  EXPECT_THAT(absl::OkStatus(), StatusIs(absl::StatusCode::kOk));
}

TEST(StatusIsTest, MatchesStatusOr) {
  const absl::StatusOr<int> value = 3;
  const absl::StatusOr<std::string> error = absl::NotFoundError("no such mesh");
  EXPECT_THAT(value, IsOk());
  EXPECT_THAT(error, Not(IsOk()));
  EXPECT_THAT(error, StatusIs(absl::StatusCode::kNotFound, HasSubstr("mesh")));
  EXPECT_THAT(error, Not(StatusIs(absl::StatusCode::kDataLoss)));
}

TEST(StatusIsTest, ExplainsAMismatchWithTheWholeStatus) {
  const absl::Status s = absl::DataLossError("truncated");
  const std::string explanation =
      ::testing::DescribeMatcher<absl::Status>(StatusIs(absl::StatusCode::kNotFound));
  EXPECT_THAT(explanation, HasSubstr("NOT_FOUND"));
  ::testing::StringMatchResultListener listener;
  EXPECT_FALSE(::testing::ExplainMatchResult(StatusIs(absl::StatusCode::kNotFound), s, &listener));
  EXPECT_THAT(listener.str(), HasSubstr("truncated"));
  EXPECT_THAT(listener.str(), HasSubstr("DATA_LOSS"));
}

}  // namespace
}  // namespace fieldspace::testing
