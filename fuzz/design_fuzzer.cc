// Design edit sequences (server/design_editor.h) on the fixture's bases. Input: byte 0 picks the
// basis (vector, 2-field, tensor) and, with bit 0x80, opens the session with a valid OpenDesign
// first; then up to 64 DesignRequests, each as "u16 little-endian length, serialized message".
// Checked after every request: an OK answer has d finite coefficients; a failed request leaves
// the session as it was (DesignEditor's contract).

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <string>

#include "fuzz/tiny_bases.h"
#include "server/design_editor.h"

namespace {

namespace v1 = ::fieldspace::v1;
using fieldspace::server::ServedBasis;

struct Snapshot {
  bool open = false;
  Eigen::VectorXd x;
  int32_t constraints = 0;
  int32_t hard = 0;
};

Snapshot Take(const fieldspace::server::DesignEditor& editor) {
  Snapshot s;
  s.open = editor.is_open();
  if (s.open) {
    s.x = editor.session()->coefficients();
    s.constraints = editor.session()->num_constraints();
    s.hard = editor.session()->num_hard_constraints();
  }
  return s;
}

bool Same(const Snapshot& a, const Snapshot& b) {
  if (a.open != b.open || a.constraints != b.constraints || a.hard != b.hard) return false;
  if (a.x.size() != b.x.size()) return false;
  // Bitwise, so that NaN == NaN: "as it was" means the same bits.
  return a.x.size() == 0 || std::memcmp(a.x.data(), b.x.data(), sizeof(double) * a.x.size()) == 0;
}

void Check(bool ok, const char* what) {
  if (ok) return;
  std::fprintf(stderr, "design fuzzer: invariant violated: %s\n", what);
  std::abort();
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 1) return 0;
  const std::shared_ptr<const ServedBasis>& basis = fieldspace::fuzz::TinyBasis(data[0] & 3);
  fieldspace::server::DesignEditorOptions options;
  options.max_constraints = 256;
  fieldspace::server::DesignEditor editor(
      [&basis](const std::string&) -> absl::StatusOr<std::shared_ptr<const ServedBasis>> {
        return basis;
      },
      options);
  if (data[0] & 0x80) {
    v1::DesignRequest open;
    open.mutable_open()->set_basis_id(basis->record.id);
    open.mutable_open()->add_watch_faces(0);
    v1::DesignUpdate update;
    Check(editor.Apply(open, &update).ok(), "the fixture's OpenDesign failed");
  }
  size_t at = 1;
  for (int i = 0; i < 64 && size - at >= 2; ++i) {
    const size_t n = std::min<size_t>(data[at] | (size_t{data[at + 1]} << 8), size - at - 2);
    v1::DesignRequest request;
    const bool parsed = request.ParseFromArray(data + at + 2, static_cast<int>(n));
    at += 2 + n;
    if (!parsed) continue;
    const Snapshot before = Take(editor);
    v1::DesignUpdate update;
    const absl::Status status = editor.Apply(request, &update);
    if (status.ok()) {
      Check(editor.is_open(), "OK without a session");
      Check(update.coefficients_size() == basis->basis->dimension(), "coefficient count");
      for (double c : update.coefficients()) Check(std::isfinite(c), "non-finite coefficient");
    } else {
      Check(Same(before, Take(editor)), "a failed request changed the session");
    }
  }
  return 0;
}
