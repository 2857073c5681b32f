#ifndef FIELDSPACE_CLIENT_JSON_H_
#define FIELDSPACE_CLIENT_JSON_H_

#include <cstdint>
#include <initializer_list>
#include <string>
#include <string_view>
#include <vector>

#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"
#include "google/protobuf/struct.pb.h"

namespace fieldspace::client {

// Compact JSON output, written in order: Key() then a value, or Begin/End of containers.
// Doubles use the shortest representation that reads back exactly; non-finite ones become null.
class JsonWriter {
 public:
  JsonWriter& BeginObject();
  JsonWriter& EndObject();
  JsonWriter& BeginArray();
  JsonWriter& EndArray();
  JsonWriter& Key(std::string_view key);
  JsonWriter& String(std::string_view value);
  JsonWriter& Number(double value);
  JsonWriter& Int(int64_t value);
  JsonWriter& Bool(bool value);
  JsonWriter& Null();

  const std::string& str() const { return out_; }

 private:
  void Separate();

  std::string out_;
  bool need_comma_ = false;
};

// Parses any JSON text into a google.protobuf.Value (protobuf's own JSON parser).
// InvalidArgument with the parser's message for malformed input.
absl::StatusOr<google::protobuf::Value> ParseJson(absl::string_view text);

// Typed access with clear errors ("<where>: 'face' must be an integer").
absl::StatusOr<double> GetNumber(const google::protobuf::Struct& object, const std::string& key,
                                 absl::string_view where);
absl::StatusOr<int64_t> GetInteger(const google::protobuf::Struct& object, const std::string& key,
                                   absl::string_view where);

// An array of numbers ("<where>: 'key' must be an array").
absl::StatusOr<std::vector<double>> NumberArray(const google::protobuf::Struct& object,
                                                const std::string& key, absl::string_view where);
// InvalidArgument naming the first key of `object` not in `allowed`.
absl::Status CheckKeys(const google::protobuf::Struct& object,
                       std::initializer_list<const char*> allowed, absl::string_view where);
// GetInteger within int32.
absl::StatusOr<int32_t> GetInt32(const google::protobuf::Struct& object, const std::string& key,
                                 absl::string_view where);
// `v` as an object ("<where>: expected a JSON object").
absl::StatusOr<const google::protobuf::Struct*> ObjectOf(const google::protobuf::Value& v,
                                                         absl::string_view where);

}  // namespace fieldspace::client

#endif  // FIELDSPACE_CLIENT_JSON_H_
