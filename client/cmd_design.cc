// The CLI's `design`: a JSONL script of edits streamed through one session that survives the loss
// of its replica.

#include <chrono>

#include "absl/strings/ascii.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "client/cli_commands.h"
#include "client/cli_flags.h"
#include "client/cli_json.h"
#include "client/design_tools_json.h"

namespace fieldspace::client::cli {

namespace v1 = ::fieldspace::v1;
using Clock = std::chrono::steady_clock;

int Design(Cli& cli, const CommandLine& a) {
  const std::string script = GetString(a, "script");
  absl::StatusOr<std::string> text = ReadFile(script);
  if (!text.ok()) return cli.FailLocal(text.status());
  // Parse the whole script first: a typo on line 40 should not leave a half-run session.
  std::vector<v1::DesignRequest> edits;
  std::vector<std::string> kinds;
  int64_t line_number = 0;
  for (absl::string_view line : absl::StrSplit(*text, '\n')) {
    ++line_number;
    line = absl::StripAsciiWhitespace(line);
    if (line.empty() || line[0] == '#') continue;
    absl::StatusOr<v1::DesignRequest> edit =
        ParseEdit(line, absl::StrCat(script, ":", line_number));
    if (!edit.ok()) return cli.FailLocal(edit.status());
    edit->set_seq(static_cast<uint64_t>(line_number));
    kinds.push_back(DesignEditKind(*edit));
    edits.push_back(*std::move(edit));
  }
  v1::DesignRequest open;
  open.set_seq(0);
  v1::OpenDesign* o = open.mutable_open();
  o->set_basis_id(a.positional()[0]);
  SetWeights(a, "mu-s", o->mutable_weights());
  o->set_raw_weights(a.Has("raw-weights"));
  o->set_biharmonic(ParseBiharmonic(a));
  if (a.Has("align-curvature") && a.Has("data")) {
    throw UsageError("design takes one data term: --align-curvature or --data FIELD_FILE");
  }
  if (a.Has("face-weights") && !a.Has("data")) {
    throw UsageError("design --face-weights weighs the --data field");
  }
  if (a.Has("mu-a") && !a.Has("align-curvature") && !a.Has("data")) {
    throw UsageError("design --mu-a weighs a data term: give --align-curvature or --data");
  }
  if (a.Has("align-curvature")) {
    v1::CurvatureEstimator estimator = ParseEstimator(a);
    o->mutable_data()->mutable_curvature()->set_estimator(estimator);
  } else if (a.Has("data")) {
    absl::StatusOr<FieldFile> field = ReadFieldFile(GetString(a, "data"));
    if (!field.ok()) return cli.FailLocal(field.status());
    v1::FieldValues* values = o->mutable_data()->mutable_field();
    values->set_encoding(field->encoding);
    values->mutable_values()->Add(field->values.begin(), field->values.end());
    if (absl::Status st = ReadFaceWeights(a, o->mutable_data()->mutable_face_weights()); !st.ok()) {
      return cli.FailLocal(st);
    }
  }
  o->set_watch_encoding(v1::FIELD_ENCODING_AMBIENT);
  o->set_singularities(a.Has("singularities"));
  for (int32_t f : ParseFaceList(GetString(a, "watch"))) o->add_watch_faces(f);
  kinds.insert(kinds.begin(), "open");

  const bool coefficients = !a.Has("no-coefficients");
  // Survives the loss of its replica (a daemon behind a router that dies or drains): the session
  // is reopened and replayed, and the answer of that edit says "resumed": true.
  ResumableDesign session(&cli.client(), open.open());
  absl::Status failed;
  int refused = 0;  // edits the server refused while the session went on
  for (size_t i = 0; i < edits.size() + 1; ++i) {
    const auto sent = Clock::now();
    absl::StatusOr<ResumableDesign::Update> resumable =
        i == 0 ? session.Open(0) : session.Edit(edits[i - 1]);
    if (!resumable.ok() && i > 0 && session.is_open()) {
      // A refused edit costs only that edit (the session is as it was): its line says why, on
      // stdout with the updates and on stderr as an error, and the script goes on.
      ++refused;
      JsonWriter j;
      j.BeginObject();
      j.Key("seq").Int(static_cast<int64_t>(edits[i - 1].seq()));
      j.Key("edit").String(kinds[i]);
      j.Key("error").BeginObject();
      j.Key("code").String(absl::StatusCodeToString(resumable.status().code()));
      j.Key("message").String(std::string(resumable.status().message()));
      j.EndObject();
      j.EndObject();
      cli.Emit(j);
      cli.Fail(resumable.status(), absl::StrCat("Design edit (line ", edits[i - 1].seq(), ")"));
      continue;
    }
    if (!resumable.ok()) {
      failed = resumable.status();
      break;
    }
    const v1::DesignUpdate* update = &resumable->update;
    const double round_trip_ms =
        std::chrono::duration<double, std::milli>(Clock::now() - sent).count();
    JsonWriter j;
    j.BeginObject();
    j.Key("seq").Int(static_cast<int64_t>(update->seq()));
    j.Key("edit").String(kinds[i]);
    j.Key("num_constraints").Int(update->num_constraints());
    j.Key("num_hard_constraints").Int(update->num_hard_constraints());
    j.Key("refactorized").Bool(update->timings().refactorized());
    j.Key("backward_error").Number(update->backward_error());  // null when unchecked (NaN)
    j.Key("iterations").Int(update->iterations());
    if (resumable->resumed) j.Key("resumed").Bool(true);
    j.Key("timings").BeginObject();
    j.Key("edit_ms").Number(update->timings().edit_ms());
    j.Key("lift_ms").Number(update->timings().lift_ms());
    j.Key("total_ms").Number(update->timings().total_ms());
    j.Key("round_trip_ms").Number(round_trip_ms);
    j.EndObject();
    j.Key("watched").BeginArray();
    WriteFaceValues(j, update->watched());
    j.EndArray();
    if (update->has_singularities()) {
      const v1::SingularityChanges& c = update->singularities();
      j.Key("singularities").BeginObject();
      j.Key("n").Int(c.n());
      j.Key("count").Int(c.count());
      j.Key("index_sum").Number(c.index_sum());
      j.Key("appeared").BeginArray();
      for (const v1::Singularity& s : c.appeared()) WriteSingularity(j, s);
      j.EndArray();
      j.Key("vanished");
      WriteNumbers(j, c.vanished());
      j.EndObject();
    }
    if (coefficients) {
      j.Key("coefficients");
      WriteNumbers(j, update->coefficients());
    }
    j.EndObject();
    cli.Emit(j);
  }
  if (!failed.ok()) return cli.Fail(failed, "Design");
  if (absl::Status status = session.Close(); !status.ok()) return cli.Fail(status, "Design");
  return refused == 0 ? 0 : 1;
}

}  // namespace fieldspace::client::cli
