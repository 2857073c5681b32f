#include "client/cli_flags.h"

#include <cstdint>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "client/cli_context.h"
#include "client/field_files.h"

namespace fieldspace::client::cli {
namespace {

namespace v1 = ::fieldspace::v1;

// The value of a parsed flag, or a usage error with the parser's message.
template <typename T>
T OrUsageError(absl::StatusOr<T> value) {
  if (!value.ok()) throw UsageError(std::string(value.status().message()));
  return *std::move(value);
}

}  // namespace

std::string GetString(const CommandLine& args, const std::string& flag,
                      const std::string& fallback) {
  return args.Get(flag).value_or(fallback);
}

double ParseDouble(const CommandLine& args, const std::string& flag, double fallback) {
  return OrUsageError(args.GetDouble(flag, fallback));
}

int64_t ParseInt(const CommandLine& args, const std::string& flag, int64_t fallback) {
  return OrUsageError(args.GetInt(flag, fallback));
}

absl::StatusOr<std::vector<double>> ReadNumbersFile(const std::string& path, int mode) {
  absl::StatusOr<std::string> text = ReadFile(path);
  if (!text.ok()) return text.status();
  absl::StatusOr<std::vector<double>> numbers = ParseCoefficients(*text, mode);
  if (!numbers.ok()) {
    return absl::InvalidArgumentError(absl::StrCat(path, ": ", numbers.status().message()));
  }
  return numbers;
}

std::vector<int32_t> ParseFaceList(const std::string& text) {
  std::vector<int32_t> faces;
  for (absl::string_view token : absl::StrSplit(text, ',', absl::SkipEmpty())) {
    int32_t f;
    if (!absl::SimpleAtoi(token, &f)) {
      throw UsageError("bad face index '" + std::string(token) + "'");
    }
    faces.push_back(f);
  }
  return faces;
}

void SetWeights(const CommandLine& a, const char* mu_s_flag, v1::Weights* w) {
  if (a.Has(mu_s_flag)) w->set_mu_s(ParseDouble(a, mu_s_flag, 0));
  if (a.Has("mu-b")) w->set_mu_b(ParseDouble(a, "mu-b", 0));
  if (a.Has("mu-c")) w->set_mu_c(ParseDouble(a, "mu-c", 0));
  if (a.Has("mu-a")) w->set_mu_a(ParseDouble(a, "mu-a", 0));
}

v1::CurvatureEstimator ParseEstimator(const CommandLine& a) {
  const std::string estimator = GetString(a, "estimator", "jet");
  if (estimator == "jet") return v1::CURVATURE_ESTIMATOR_JET;
  if (estimator == "normal-differences") return v1::CURVATURE_ESTIMATOR_NORMAL_DIFFERENCES;
  throw UsageError("--estimator must be jet or normal-differences");
}

v1::FieldEncoding ParseEncoding(const CommandLine& a) {
  const std::string e = GetString(a, "encoding", "ambient");
  if (e == "ambient") return v1::FIELD_ENCODING_AMBIENT;
  if (e == "dof") return v1::FIELD_ENCODING_DOF;
  throw UsageError("--encoding must be ambient or dof");
}

v1::BiharmonicForm ParseBiharmonic(const CommandLine& a) {
  if (!a.Has("biharmonic")) return v1::BIHARMONIC_FORM_MIXED;  // the default
  const std::string form = GetString(a, "biharmonic");
  if (form == "exact") return v1::BIHARMONIC_FORM_EXACT;
  if (form == "mixed") return v1::BIHARMONIC_FORM_MIXED;
  throw UsageError(absl::StrCat("--biharmonic must be exact or mixed, got '", form, "'"));
}

int ParseMode(const CommandLine& a) {
  if (!a.Has("mode")) return -1;
  const int64_t mode = ParseInt(a, "mode", -1);
  if (mode < 0 || mode > INT32_MAX) throw UsageError("--mode must be a non-negative integer");
  return static_cast<int>(mode);
}

absl::Status ReadFaceWeights(const CommandLine& a, google::protobuf::RepeatedField<double>* out) {
  if (!a.Has("face-weights")) return absl::OkStatus();
  absl::StatusOr<std::vector<double>> weights = ReadNumbersFile(GetString(a, "face-weights"));
  if (!weights.ok()) return weights.status();
  out->Add(weights->begin(), weights->end());
  return absl::OkStatus();
}

}  // namespace fieldspace::client::cli
