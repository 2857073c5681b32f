#include "client/json.h"

#include <charconv>
#include <cmath>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "core/common/status_macros.h"
#include "google/protobuf/util/json_util.h"

namespace fieldspace::client {

void JsonWriter::Separate() {
  if (need_comma_) out_ += ',';
  need_comma_ = true;
}

JsonWriter& JsonWriter::BeginObject() {
  Separate();
  out_ += '{';
  need_comma_ = false;
  return *this;
}

JsonWriter& JsonWriter::EndObject() {
  out_ += '}';
  need_comma_ = true;
  return *this;
}

JsonWriter& JsonWriter::BeginArray() {
  Separate();
  out_ += '[';
  need_comma_ = false;
  return *this;
}

JsonWriter& JsonWriter::EndArray() {
  out_ += ']';
  need_comma_ = true;
  return *this;
}

JsonWriter& JsonWriter::Key(std::string_view key) {
  String(key);
  out_ += ':';
  need_comma_ = false;
  return *this;
}

JsonWriter& JsonWriter::String(std::string_view value) {
  Separate();
  out_ += '"';
  for (char c : value) {
    switch (c) {
      case '"':
        out_ += "\\\"";
        break;
      case '\\':
        out_ += "\\\\";
        break;
      case '\n':
        out_ += "\\n";
        break;
      case '\r':
        out_ += "\\r";
        break;
      case '\t':
        out_ += "\\t";
        break;
      default:
        if (static_cast<unsigned char>(c) < 0x20) {
          out_ += absl::StrFormat("\\u%04x", static_cast<int>(c));
        } else {
          out_ += c;
        }
    }
  }
  out_ += '"';
  return *this;
}

JsonWriter& JsonWriter::Number(double value) {
  if (!std::isfinite(value)) return Null();
  Separate();
  char buffer[32];
  auto [end, ec] = std::to_chars(buffer, buffer + sizeof(buffer), value);
  out_.append(buffer, ec == std::errc() ? end : buffer);
  return *this;
}

JsonWriter& JsonWriter::Int(int64_t value) {
  Separate();
  absl::StrAppend(&out_, value);
  return *this;
}

JsonWriter& JsonWriter::Bool(bool value) {
  Separate();
  out_ += value ? "true" : "false";
  return *this;
}

JsonWriter& JsonWriter::Null() {
  Separate();
  out_ += "null";
  return *this;
}

absl::StatusOr<google::protobuf::Value> ParseJson(absl::string_view text) {
  google::protobuf::Value value;
  auto status = google::protobuf::util::JsonStringToMessage(
      google::protobuf::StringPiece(text.data(), text.size()), &value);
  if (!status.ok()) {
    return absl::InvalidArgumentError(
        absl::StrCat("malformed JSON: ", status.message().ToString()));
  }
  return value;
}

absl::StatusOr<double> GetNumber(const google::protobuf::Struct& object, const std::string& key,
                                 absl::string_view where) {
  auto it = object.fields().find(key);
  if (it == object.fields().end() ||
      it->second.kind_case() != google::protobuf::Value::kNumberValue) {
    return absl::InvalidArgumentError(absl::StrCat(where, ": '", key, "' must be a number"));
  }
  return it->second.number_value();
}

absl::StatusOr<int64_t> GetInteger(const google::protobuf::Struct& object, const std::string& key,
                                   absl::string_view where) {
  auto it = object.fields().find(key);
  if (it == object.fields().end() ||
      it->second.kind_case() != google::protobuf::Value::kNumberValue ||
      std::floor(it->second.number_value()) != it->second.number_value() ||
      std::abs(it->second.number_value()) > 9.0e15) {
    return absl::InvalidArgumentError(absl::StrCat(where, ": '", key, "' must be an integer"));
  }
  return static_cast<int64_t>(it->second.number_value());
}

absl::StatusOr<std::vector<double>> NumberArray(const google::protobuf::Struct& object,
                                                const std::string& key, absl::string_view where) {
  auto it = object.fields().find(key);
  if (it == object.fields().end() ||
      it->second.kind_case() != google::protobuf::Value::kListValue) {
    return absl::InvalidArgumentError(absl::StrCat(where, ": '", key, "' must be an array"));
  }
  std::vector<double> out;
  for (const google::protobuf::Value& v : it->second.list_value().values()) {
    if (v.kind_case() != google::protobuf::Value::kNumberValue) {
      return absl::InvalidArgumentError(
          absl::StrCat(where, ": '", key, "' must hold numbers only"));
    }
    out.push_back(v.number_value());
  }
  return out;
}

absl::Status CheckKeys(const google::protobuf::Struct& object,
                       std::initializer_list<const char*> allowed, absl::string_view where) {
  for (const auto& [key, value] : object.fields()) {
    bool ok = false;
    for (const char* a : allowed) ok = ok || key == a;
    if (!ok) return absl::InvalidArgumentError(absl::StrCat(where, ": unknown key '", key, "'"));
  }
  return absl::OkStatus();
}

absl::StatusOr<int32_t> GetInt32(const google::protobuf::Struct& object, const std::string& key,
                                 absl::string_view where) {
  ASSIGN_OR_RETURN(int64_t v, GetInteger(object, key, where));
  if (v < INT32_MIN || v > INT32_MAX) {
    return absl::InvalidArgumentError(absl::StrCat(where, ": '", key, "' is out of range"));
  }
  return static_cast<int32_t>(v);
}

absl::StatusOr<const google::protobuf::Struct*> ObjectOf(const google::protobuf::Value& v,
                                                         absl::string_view where) {
  if (v.kind_case() != google::protobuf::Value::kStructValue) {
    return absl::InvalidArgumentError(absl::StrCat(where, ": expected a JSON object"));
  }
  return &v.struct_value();
}

}  // namespace fieldspace::client
