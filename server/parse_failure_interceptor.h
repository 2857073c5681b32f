#ifndef FIELDSPACE_SERVER_PARSE_FAILURE_INTERCEPTOR_H_
#define FIELDSPACE_SERVER_PARSE_FAILURE_INTERCEPTOR_H_

// gRPC's callback API (1.51) answers a unary or server-streaming request that does not parse as
// the method's request type with UNIMPLEMENTED and no message (the handler installs an
// UnimplementedUnaryReactor when deserialization fails), which reads as "no such method". This
// interceptor makes that answer INVALID_ARGUMENT "request is not a valid <type>". It rewrites only
// calls whose request failed to parse (the handler hands interceptors no message); unknown methods
// keep their UNIMPLEMENTED. The streaming RPCs that read several messages are raw and parse their
// messages themselves (ParseStreamMessage, rpc_util.h).

#include <memory>

#include "grpcpp/support/server_interceptor.h"

namespace fieldspace::server {

// For ServerBuilder::experimental().SetInterceptorCreators. Applies to the unary and
// server-streaming methods of every service whose descriptors are in the generated pool.
std::unique_ptr<grpc::experimental::ServerInterceptorFactoryInterface>
NewParseFailureInterceptorFactory();

}  // namespace fieldspace::server

#endif  // FIELDSPACE_SERVER_PARSE_FAILURE_INTERCEPTOR_H_
