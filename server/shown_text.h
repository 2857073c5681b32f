#ifndef FIELDSPACE_SERVER_SHOWN_TEXT_H_
#define FIELDSPACE_SERVER_SHOWN_TEXT_H_

// How client-given text appears in error messages: cut to a bound, so that a message never echoes
// a huge input (a 60 MB id made a 60 MB grpc-message header: a 20 s stall, then UNKNOWN on the
// client's side). No gRPC here: the handlers' library uses it.

#include <cstddef>
#include <string>
#include <string_view>

namespace fieldspace::server {

// `text` cut to at most `max` bytes (never inside a UTF-8 sequence), the cut marked with "…".
std::string CutText(std::string_view text, size_t max);

// A client-given id as error messages show it: quoted, and cut after 64 bytes
// ("'m-0123…' (70000 bytes)").
std::string ShownId(std::string_view id);

}  // namespace fieldspace::server

#endif  // FIELDSPACE_SERVER_SHOWN_TEXT_H_
