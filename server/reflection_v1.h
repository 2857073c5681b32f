#ifndef FIELDSPACE_SERVER_REFLECTION_V1_H_
#define FIELDSPACE_SERVER_REFLECTION_V1_H_

// grpc.reflection.v1.ServerReflection. gRPC 1.51 (Debian's) ships only v1alpha, while buf curl
// and newer grpcurl ask v1 first. v1 is v1alpha under another package name: same messages, same
// answers, here over the generated descriptor pool (as v1alpha's).

#include <memory>

#include "grpcpp/impl/server_builder_option.h"

namespace fieldspace::server {

// For ServerBuilder::SetOption: registers grpc.reflection.v1.ServerReflection, which lists the
// services the server is built with.
std::unique_ptr<grpc::ServerBuilderOption> ReflectionV1Option();

}  // namespace fieldspace::server

#endif  // FIELDSPACE_SERVER_REFLECTION_V1_H_
