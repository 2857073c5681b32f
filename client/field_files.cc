#include "client/field_files.h"

#include <cerrno>
#include <charconv>
#include <cmath>
#include <fstream>
#include <sstream>
#include <utility>

#include "absl/strings/ascii.h"
#include "absl/strings/match.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "client/design_tools_json.h"
#include "client/json.h"
#include "core/common/status_macros.h"
#include "core/mesh/mesh_io.h"

namespace fieldspace::client {
namespace {

namespace v1 = ::fieldspace::v1;
using google::protobuf::Struct;
using google::protobuf::Value;

// The value of a constraint or move: exactly one of "vector", "tensor", "dofs".
absl::Status ParseValue(const Struct& object, absl::string_view where,
                        google::protobuf::RepeatedField<double>* value, int* encoding) {
  int found = 0;
  for (const char* key : {"vector", "tensor", "dofs"}) {
    if (object.fields().count(key) == 0) continue;
    ++found;
    ASSIGN_OR_RETURN(std::vector<double> numbers, NumberArray(object, key, where));
    const size_t expected = std::string_view(key) == "vector"   ? 3
                            : std::string_view(key) == "tensor" ? 6
                                                                : 0;
    if (expected != 0 && numbers.size() != expected) {
      return absl::InvalidArgumentError(
          absl::StrCat(where, ": '", key, "' needs ", expected, " numbers, got ", numbers.size()));
    }
    value->Assign(numbers.begin(), numbers.end());
    *encoding =
        std::string_view(key) == "dofs" ? v1::FIELD_ENCODING_DOF : v1::FIELD_ENCODING_AMBIENT;
  }
  if (found != 1) {
    return absl::InvalidArgumentError(
        absl::StrCat(where, ": give exactly one of 'vector', 'tensor' or 'dofs'"));
  }
  return absl::OkStatus();
}

}  // namespace

absl::StatusOr<std::string> ReadFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return absl::ErrnoToStatus(errno, absl::StrCat("cannot open ", path));
  std::stringstream ss;
  ss << in.rdbuf();
  if (in.bad()) return absl::DataLossError(absl::StrCat("error reading ", path));
  return ss.str();
}

absl::StatusOr<FieldFile> ParseFieldText(absl::string_view text) {
  FieldFile field;
  int64_t line_number = 0;
  for (absl::string_view line : absl::StrSplit(text, '\n')) {
    ++line_number;
    line = absl::StripAsciiWhitespace(line);
    if (line.empty()) continue;
    if (line[0] == '#') {
      absl::string_view comment = absl::StripAsciiWhitespace(line.substr(1));
      if (absl::ConsumePrefix(&comment, "encoding:")) {
        comment = absl::StripAsciiWhitespace(comment);
        if (comment == "dof") {
          field.encoding = v1::FIELD_ENCODING_DOF;
        } else if (comment == "ambient") {
          field.encoding = v1::FIELD_ENCODING_AMBIENT;
        } else {
          return absl::InvalidArgumentError(absl::StrCat(
              "line ", line_number, ": encoding must be 'ambient' or 'dof', got '", comment, "'"));
        }
      }
      continue;
    }
    int32_t count = 0;
    for (absl::string_view token :
         absl::StrSplit(line, absl::ByAnyChar(" \t,\r"), absl::SkipEmpty())) {
      double v;
      if (!absl::SimpleAtod(token, &v) || !std::isfinite(v)) {
        return absl::InvalidArgumentError(
            absl::StrCat("line ", line_number, ": '", token, "' is not a finite number"));
      }
      field.values.push_back(v);
      ++count;
    }
    if (field.values_per_face == 0) {
      field.values_per_face = count;
    } else if (count != field.values_per_face) {
      return absl::InvalidArgumentError(absl::StrCat("line ", line_number, ": ", count,
                                                     " values; earlier lines have ",
                                                     field.values_per_face));
    }
  }
  if (field.values.empty()) return absl::InvalidArgumentError("the field file has no values");
  return field;
}

absl::StatusOr<FieldFile> ReadFieldFile(const std::string& path) {
  ASSIGN_OR_RETURN(std::string text, ReadFile(path));
  absl::StatusOr<FieldFile> field = ParseFieldText(text);
  if (!field.ok()) {
    return absl::Status(field.status().code(), absl::StrCat(path, ": ", field.status().message()));
  }
  return field;
}

absl::Status WriteFieldText(const std::string& path, const FieldFile& field,
                            const std::string& field_type) {
  std::ofstream out(path);
  if (!out) return absl::ErrnoToStatus(errno, absl::StrCat("cannot write ", path));
  out << "# fieldspace field: type " << field_type << ", " << field.num_faces() << " faces\n";
  out << "# encoding: " << (field.encoding == v1::FIELD_ENCODING_DOF ? "dof" : "ambient") << "\n";
  std::string line;
  for (int64_t f = 0; f < field.num_faces(); ++f) {
    line.clear();
    for (int32_t c = 0; c < field.values_per_face; ++c) {
      if (c > 0) line += ' ';
      // Shortest representation that reads back to the same double.
      char buffer[32];
      auto [end, ec] = std::to_chars(buffer, buffer + sizeof(buffer),
                                     field.values[f * field.values_per_face + c]);
      line.append(buffer, ec == std::errc() ? end : buffer);
    }
    line += '\n';
    out << line;
  }
  out.close();
  if (!out) return absl::DataLossError(absl::StrCat("error writing ", path));
  return absl::OkStatus();
}

absl::Status WriteFieldPly(const std::string& path, const std::vector<double>& vertices,
                           const std::vector<int32_t>& faces, const FieldFile& field) {
  const int64_t nv = static_cast<int64_t>(vertices.size() / 3);
  const int64_t nf = static_cast<int64_t>(faces.size() / 3);
  if (field.num_faces() != nf) {
    return absl::InvalidArgumentError(
        absl::StrCat("field has ", field.num_faces(), " faces, mesh has ", nf));
  }
  VertexMatrix V = Eigen::Map<const VertexMatrix>(vertices.data(), nv, 3);
  FaceMatrix F = Eigen::Map<const FaceMatrix>(faces.data(), nf, 3);
  std::vector<std::string> names;
  const int32_t vpf = field.values_per_face;
  if (field.encoding == v1::FIELD_ENCODING_AMBIENT && vpf == 3) {
    names = {"vx", "vy", "vz"};
  } else if (field.encoding == v1::FIELD_ENCODING_AMBIENT && vpf == 6) {
    names = {"txx", "tyy", "tzz", "txy", "tyz", "tzx"};
  } else {
    for (int32_t c = 0; c < vpf; ++c) names.push_back(absl::StrCat("d", c));
  }
  std::vector<FaceProperty> properties(names.size());
  for (size_t c = 0; c < names.size(); ++c) {
    properties[c].name = names[c];
    properties[c].values.resize(nf);
    for (int64_t f = 0; f < nf; ++f) {
      properties[c].values[f] = static_cast<float>(field.values[f * vpf + c]);
    }
  }
  if (field.encoding == v1::FIELD_ENCODING_AMBIENT && vpf == 3) {
    FaceProperty magnitude{"magnitude", std::vector<float>(nf)};
    for (int64_t f = 0; f < nf; ++f) {
      const double* v = field.values.data() + 3 * f;
      magnitude.values[f] = static_cast<float>(std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]));
    }
    properties.push_back(std::move(magnitude));
  }
  return WritePly(path, V, F, properties);
}

absl::StatusOr<std::vector<double>> ParseCoefficients(absl::string_view text, int mode) {
  absl::string_view stripped = absl::StripAsciiWhitespace(text);
  if (!stripped.empty() && (stripped[0] == '{' || stripped[0] == '[')) {
    ASSIGN_OR_RETURN(Value value, ParseJson(stripped));
    const Value* list = &value;
    if (value.kind_case() == Value::kStructValue) {
      auto it = value.struct_value().fields().find("coefficients");
      if (it == value.struct_value().fields().end()) {
        return absl::InvalidArgumentError("JSON coefficients file has no 'coefficients' key");
      }
      list = &it->second;
    }
    if (list->kind_case() != Value::kListValue) {
      return absl::InvalidArgumentError("'coefficients' must be an array of numbers");
    }
    // `eigen --coefficients`: one array per eigenfield; `mode` picks one.
    const auto& rows = list->list_value().values();
    const bool nested = !rows.empty() && rows[0].kind_case() == Value::kListValue;
    if (nested) {
      if (mode < 0) {
        return absl::InvalidArgumentError(absl::StrCat("'coefficients' holds ", rows.size(),
                                                       " eigenfields: pick one with --mode K"));
      }
      if (mode >= rows.size()) {
        return absl::InvalidArgumentError(
            absl::StrCat("--mode ", mode, " is out of range: ", rows.size(), " eigenfields (0 to ",
                         rows.size() - 1, ")"));
      }
      list = &rows[mode];
    } else if (mode >= 0) {
      return absl::InvalidArgumentError(
          "--mode applies to the eigenfields of `eigen --coefficients`; this file holds one field");
    }
    std::vector<double> out;
    for (const Value& v : list->list_value().values()) {
      if (v.kind_case() != Value::kNumberValue) {
        return absl::InvalidArgumentError("'coefficients' must be an array of numbers");
      }
      out.push_back(v.number_value());
    }
    return out;
  }
  if (mode >= 0) {
    return absl::InvalidArgumentError(
        "--mode applies to the eigenfields of `eigen --coefficients`; this file holds one field");
  }
  std::vector<double> out;
  for (absl::string_view token :
       absl::StrSplit(stripped, absl::ByAnyChar(" \t\r\n,"), absl::SkipEmpty())) {
    double v;
    if (!absl::SimpleAtod(token, &v) || !std::isfinite(v)) {
      return absl::InvalidArgumentError(absl::StrCat("'", token, "' is not a finite number"));
    }
    out.push_back(v);
  }
  if (out.empty()) return absl::InvalidArgumentError("no coefficients found");
  return out;
}

absl::StatusOr<v1::Constraint> ParseConstraint(const Struct& object, absl::string_view where) {
  RETURN_IF_ERROR(
      CheckKeys(object, {"id", "face", "vector", "tensor", "dofs", "weight", "hard"}, where));
  v1::Constraint c;
  ASSIGN_OR_RETURN(int32_t face, GetInt32(object, "face", where));
  c.set_face(face);
  int encoding = 0;
  RETURN_IF_ERROR(ParseValue(object, where, c.mutable_value(), &encoding));
  c.set_encoding(static_cast<v1::FieldEncoding>(encoding));
  if (object.fields().count("weight") > 0) {
    ASSIGN_OR_RETURN(double weight, GetNumber(object, "weight", where));
    c.set_weight(weight);
  }
  if (auto it = object.fields().find("hard"); it != object.fields().end()) {
    if (it->second.kind_case() != Value::kBoolValue) {
      return absl::InvalidArgumentError(absl::StrCat(where, ": 'hard' must be true or false"));
    }
    c.set_hard(it->second.bool_value());
  }
  return c;
}

absl::StatusOr<std::vector<v1::Constraint>> ParseConstraints(
    absl::string_view text, std::vector<v1::ConstraintGroup>* groups) {
  std::vector<v1::Constraint> out;
  // One item: a constraint, or a tool ({"stroke": {...}}) when `groups` takes them.
  const auto parse = [&](const Struct& object, const std::string& where) -> absl::Status {
    if (groups != nullptr && object.fields().size() == 1 &&
        IsToolKey(object.fields().begin()->first)) {
      const auto& [key, body] = *object.fields().begin();
      ASSIGN_OR_RETURN(const Struct* tool, ObjectOf(body, where));
      ASSIGN_OR_RETURN(v1::ConstraintGroup group,
                       ParseToolGroup(key, *tool, absl::StrCat(where, " (", key, ")")));
      groups->push_back(std::move(group));
      return absl::OkStatus();
    }
    ASSIGN_OR_RETURN(v1::Constraint c, ParseConstraint(object, where));
    out.push_back(std::move(c));
    return absl::OkStatus();
  };
  absl::string_view stripped = absl::StripAsciiWhitespace(text);
  if (!stripped.empty() && stripped[0] == '[') {
    ASSIGN_OR_RETURN(Value value, ParseJson(stripped));
    int i = 0;
    for (const Value& item : value.list_value().values()) {
      const std::string where = absl::StrCat("constraint ", i++);
      ASSIGN_OR_RETURN(const Struct* object, ObjectOf(item, where));
      RETURN_IF_ERROR(parse(*object, where));
    }
    return out;
  }
  int64_t line_number = 0;
  for (absl::string_view line : absl::StrSplit(text, '\n')) {
    ++line_number;
    line = absl::StripAsciiWhitespace(line);
    if (line.empty() || line[0] == '#') continue;
    const std::string where = absl::StrCat("line ", line_number);
    absl::StatusOr<Value> value = ParseJson(line);
    if (!value.ok())
      return absl::InvalidArgumentError(absl::StrCat(where, ": ", value.status().message()));
    ASSIGN_OR_RETURN(const Struct* object, ObjectOf(*value, where));
    RETURN_IF_ERROR(parse(*object, where));
  }
  return out;
}

absl::StatusOr<v1::DesignRequest> ParseEdit(absl::string_view line, absl::string_view where) {
  absl::StatusOr<Value> value = ParseJson(line);
  if (!value.ok())
    return absl::InvalidArgumentError(absl::StrCat(where, ": ", value.status().message()));
  ASSIGN_OR_RETURN(const Struct* outer, ObjectOf(*value, where));
  if (outer->fields().size() != 1) {
    return absl::InvalidArgumentError(absl::StrCat(
        where,
        ": an edit is an object with exactly one key: add, move, remove, weights, watch or a "
        "tool"));
  }
  const auto& [kind, body] = *outer->fields().begin();
  const std::string inner_where = absl::StrCat(where, " (", kind, ")");
  ASSIGN_OR_RETURN(const Struct* object, ObjectOf(body, inner_where));
  v1::DesignRequest request;
  if (kind == "add") {
    ASSIGN_OR_RETURN(int32_t id, GetInt32(*object, "id", inner_where));
    ASSIGN_OR_RETURN(v1::Constraint c, ParseConstraint(*object, inner_where));
    request.mutable_add()->set_id(id);
    *request.mutable_add()->mutable_constraint() = std::move(c);
  } else if (kind == "move" && IsToolMove(*object)) {
    return ParseToolMove(*object, inner_where);
  } else if (kind == "move") {
    RETURN_IF_ERROR(CheckKeys(*object, {"id", "face", "vector", "tensor", "dofs"}, inner_where));
    v1::MoveConstraint* move = request.mutable_move();
    ASSIGN_OR_RETURN(int32_t id, GetInt32(*object, "id", inner_where));
    ASSIGN_OR_RETURN(int32_t face, GetInt32(*object, "face", inner_where));
    move->set_id(id);
    move->set_face(face);
    int encoding = 0;
    RETURN_IF_ERROR(ParseValue(*object, inner_where, move->mutable_value(), &encoding));
    move->set_encoding(static_cast<v1::FieldEncoding>(encoding));
  } else if (kind == "remove") {
    RETURN_IF_ERROR(CheckKeys(*object, {"id"}, inner_where));
    ASSIGN_OR_RETURN(int32_t id, GetInt32(*object, "id", inner_where));
    request.mutable_remove()->set_id(id);
  } else if (kind == "weights") {
    RETURN_IF_ERROR(CheckKeys(*object, {"mu_s", "mu_b", "mu_c", "mu_a"}, inner_where));
    // The weights given change; the others keep the session's values.
    if (object->fields().empty()) {
      return absl::InvalidArgumentError(
          absl::StrCat(inner_where, ": weights needs at least one of mu_s, mu_b, mu_c, mu_a"));
    }
    v1::Weights* w = request.mutable_set_weights();
    using Setter = void (v1::Weights::*)(double);
    for (const auto& [key, set] : {std::pair<const char*, Setter>{"mu_s", &v1::Weights::set_mu_s},
                                   {"mu_b", &v1::Weights::set_mu_b},
                                   {"mu_c", &v1::Weights::set_mu_c},
                                   {"mu_a", &v1::Weights::set_mu_a}}) {
      if (!object->fields().contains(key)) continue;
      ASSIGN_OR_RETURN(double value, GetNumber(*object, key, inner_where));
      (w->*set)(value);
    }
  } else if (kind == "watch") {
    RETURN_IF_ERROR(CheckKeys(*object, {"faces", "encoding"}, inner_where));
    ASSIGN_OR_RETURN(std::vector<double> faces, NumberArray(*object, "faces", inner_where));
    for (double f : faces) {
      if (std::floor(f) != f || f < INT32_MIN || f > INT32_MAX) {
        return absl::InvalidArgumentError(
            absl::StrCat(inner_where, ": 'faces' must hold integers"));
      }
      request.mutable_watch()->add_faces(static_cast<int32_t>(f));
    }
    request.mutable_watch()->set_encoding(v1::FIELD_ENCODING_AMBIENT);
    if (auto it = object->fields().find("encoding"); it != object->fields().end()) {
      if (it->second.string_value() == "dof") {
        request.mutable_watch()->set_encoding(v1::FIELD_ENCODING_DOF);
      } else if (it->second.string_value() != "ambient") {
        return absl::InvalidArgumentError(
            absl::StrCat(inner_where, ": 'encoding' must be \"ambient\" or \"dof\""));
      }
    }
  } else if (IsToolKey(kind)) {
    return ParseToolEdit(kind, *object, inner_where);
  } else {
    return absl::InvalidArgumentError(
        absl::StrCat(where, ": unknown edit '", kind,
                     "' (add, move, remove, weights, watch, stroke, singularity, align_boundary "
                     "or align_features)"));
  }
  return request;
}

}  // namespace fieldspace::client
