#ifndef FIELDSPACE_SERVER_SERVICE_OPTIONS_H_
#define FIELDSPACE_SERVER_SERVICE_OPTIONS_H_

// The limits of the FieldSpace service that requests are checked against (fieldspaced's flags).

#include <algorithm>
#include <chrono>
#include <cstdint>
#include <string>

namespace fieldspace::server {

struct ServiceOptions {
  std::string data_root;  // LoadMesh reads only below it; empty disables LoadMesh
  int64_t max_upload_bytes = int64_t{2} << 30;
  int64_t max_message_bytes = int64_t{64} << 20;  // responses larger than this are refused
  // Design sessions check every k-th edit's solution against the true system (and the risky
  // ones always): DesignSessionOptions::verify_interval.
  int32_t design_verify_interval = 16;
  int32_t max_design_sessions = 256;
  // An upload with no message for this long is ended (DEADLINE_EXCEEDED) and its memory
  // reservation released; zero: never.
  std::chrono::steady_clock::duration upload_idle_timeout = std::chrono::seconds(60);

  // Bytes of payload (numbers) one response message may carry: the message limit less room for
  // the rest of the message (ids, timings, framing): 1/8 of the limit, at most 1 MiB.
  int64_t message_room() const {
    return max_message_bytes - std::min<int64_t>(int64_t{1} << 20, max_message_bytes / 8);
  }
  // Faces per streamed chunk for `bytes_per_face` of payload each: `requested` (0: 65,536),
  // at most 2^19 and at most what fits in message_room().
  int32_t ChunkFaces(int32_t requested, int64_t bytes_per_face) const {
    constexpr int32_t kDefaultChunkFaces = 65536;
    constexpr int32_t kMaxChunkFaces = 1 << 19;
    const int32_t wanted =
        requested == 0 ? kDefaultChunkFaces : std::min(requested, kMaxChunkFaces);
    const int64_t fits =
        std::max<int64_t>(1, message_room() / std::max<int64_t>(1, bytes_per_face));
    return static_cast<int32_t>(std::min<int64_t>(wanted, fits));
  }
};

}  // namespace fieldspace::server

#endif  // FIELDSPACE_SERVER_SERVICE_OPTIONS_H_
