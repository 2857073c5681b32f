#ifndef FIELDSPACE_CLIENT_CLI_FLAGS_H_
#define FIELDSPACE_CLIENT_CLI_FLAGS_H_

// Flags into request fields, shared by the CLI's commands. A bad value throws UsageError with a
// message naming the flag; a file that cannot be read is a Status naming the file.

#include <cstdint>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "core/common/command_line.h"
#include "fieldspace/v1/fieldspace.pb.h"

namespace fieldspace::client::cli {

std::string GetString(const CommandLine& args, const std::string& flag,
                      const std::string& fallback = "");
double ParseDouble(const CommandLine& args, const std::string& flag, double fallback);
int64_t ParseInt(const CommandLine& args, const std::string& flag, int64_t fallback);

// A file of numbers (coefficients, per-face weights): the JSON printed by solve / project /
// smoothest, a JSON array, or plain numbers; `mode` >= 0 picks one field of `eigen
// --coefficients` output. Errors name the file.
absl::StatusOr<std::vector<double>> ReadNumbersFile(const std::string& path, int mode = -1);

// "F1,F2,..." as face indices.
std::vector<int32_t> ParseFaceList(const std::string& text);

// The weights given on the command line (mu_s under `mu_s_flag`, --mu-b, --mu-c, --mu-a); the
// ones left out are left out of the request too, so that the server's defaults apply.
void SetWeights(const CommandLine& a, const char* mu_s_flag, fieldspace::v1::Weights* w);

// --estimator jet|normal-differences (default jet).
fieldspace::v1::CurvatureEstimator ParseEstimator(const CommandLine& a);
// --encoding ambient|dof (default ambient).
fieldspace::v1::FieldEncoding ParseEncoding(const CommandLine& a);
// --biharmonic exact|mixed (default exact).
fieldspace::v1::BiharmonicForm ParseBiharmonic(const CommandLine& a);
// --mode K (an eigenfield of `eigen --coefficients`), or -1.
int ParseMode(const CommandLine& a);

// --face-weights FILE (one number per face) into `out`; nothing without the flag.
absl::Status ReadFaceWeights(const CommandLine& a, google::protobuf::RepeatedField<double>* out);

}  // namespace fieldspace::client::cli

#endif  // FIELDSPACE_CLIENT_CLI_FLAGS_H_
