// The request handlers (server/handlers.h) of every RPC that carries numbers for core, on a small
// basis of the fixture. Input: byte 0 picks the request type, byte 1 the basis (vector, 2-field,
// tensor), the rest is the serialized request. Each case calls the handler FieldService calls for
// that RPC, minus the transport; basis_id and mesh_id lead to the fixture's basis and its mesh
// (HandlerContext's lookups), LoadMesh adds to a registry on a temporary store.

#include <sys/stat.h>
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <string>
#include <vector>

#include "absl/strings/str_cat.h"
#include "core/common/status_macros.h"
#include "fuzz/tiny_bases.h"
#include "server/compute_pool.h"
#include "server/handlers.h"
#include "server/record_convert.h"
#include "server/registry.h"
#include "server/store.h"

namespace fieldspace::fuzz {
namespace {

namespace v1 = ::fieldspace::v1;
using server::ServedBasis;

// LoadMesh's data root: a folder holding the fixture's mesh in each format and a subfolder.
const std::string& DataRoot() {
  static const std::string* root = [] {
    const char* tmp = std::getenv("TMPDIR");
    std::string dir = std::string(tmp ? tmp : "/tmp") + "/fieldspace-root-fuzz-XXXXXX";
    if (mkdtemp(dir.data()) == nullptr) std::abort();
    const std::string sub = dir + "/sub";
    if (mkdir(sub.c_str(), 0755) != 0) std::abort();
    for (const char* format : {"obj", "off", "ply"}) {
      std::FILE* f = std::fopen(absl::StrCat(sub, "/torus.", format).c_str(), "wb");
      if (f == nullptr) std::abort();
      const std::string text = TinyMeshFile(format);
      std::fwrite(text.data(), 1, text.size(), f);
      std::fclose(f);
    }
    static const std::string remove = dir;
    std::atexit([] { std::system(("rm -rf '" + remove + "'").c_str()); });
    return new std::string(dir);
  }();
  return *root;
}

template <typename Message>
bool Parse(Message* m, const uint8_t* data, size_t size) {
  return m->ParseFromArray(data, static_cast<int>(size));
}

// The registry of LoadMesh (on a temporary store) and of the memory budget the handlers admit
// their work against; built once per process.
server::Registry& FuzzRegistry() {
  static server::Registry* registry = [] {
    absl::StatusOr<std::unique_ptr<server::Store>> opened =
        server::Store::Open(DataRoot() + "/store");
    if (!opened.ok()) std::abort();
    static std::unique_ptr<server::Store> store = *std::move(opened);
    static server::ComputePool pool(server::ComputePool::Options{});
    absl::StatusOr<std::unique_ptr<server::Registry>> made =
        server::Registry::Create(store.get(), &pool, server::RegistryOptions{});
    if (!made.ok()) std::abort();
    return made->release();
  }();
  return *registry;
}

// The handlers' context: basis_id and mesh_id lead to the fixture's basis and its mesh.
server::HandlerContext Context(const std::shared_ptr<const ServedBasis>& basis) {
  static const server::ServiceOptions options = [] {
    server::ServiceOptions o;
    o.data_root = DataRoot();
    return o;
  }();
  server::HandlerContext ctx;
  ctx.registry = &FuzzRegistry();
  ctx.options = &options;
  ctx.basis_lookup = [basis](const std::string&) { return basis; };
  ctx.mesh_lookup = [basis](const std::string&) { return basis->mesh; };
  return ctx;
}

// Opens a server-streaming answer and reads it to the end.
template <typename Message, typename Request>
absl::Status Drain(absl::StatusOr<std::unique_ptr<server::ChunkStream<Message>>> (*open)(
                       const server::HandlerContext&, const Request&),
                   const server::HandlerContext& ctx, const Request& request) {
  ASSIGN_OR_RETURN(std::unique_ptr<server::ChunkStream<Message>> stream, open(ctx, request));
  for (;;) {
    Message chunk;
    ASSIGN_OR_RETURN(bool more, stream->Next(&chunk));
    if (!more) return absl::OkStatus();
  }
}

// Parses the request and calls its handler.
template <typename Request, typename Response>
absl::Status Call(absl::Status (*handler)(const server::HandlerContext&, const Request&, Response*),
                  const server::HandlerContext& ctx, const uint8_t* data, size_t size) {
  Request request;
  if (!Parse(&request, data, size)) return absl::OkStatus();
  Response response;
  return handler(ctx, request, &response);
}

absl::Status Run(uint8_t type, const std::shared_ptr<const ServedBasis>& basis, const uint8_t* data,
                 size_t size) {
  const server::HandlerContext ctx = Context(basis);
  switch (type % 10) {
    case 0:
      return Call(&server::LoadMesh, ctx, data, size);
    case 1: {
      // Only the conversion: a registry build would run in the background, beyond this input.
      v1::BuildBasisRequest r;
      if (!Parse(&r, data, size)) return absl::OkStatus();
      return server::BuildRequestFromProto(r).status();
    }
    case 2:
      return Call(&server::Project, ctx, data, size);
    case 3:
      return Call(&server::Solve, ctx, data, size);
    case 4: {
      v1::LiftRequest r;
      if (!Parse(&r, data, size)) return absl::OkStatus();
      return Drain(&server::OpenLift, ctx, r);
    }
    case 5:
      return Call(&server::Eigenfields, ctx, data, size);
    case 6: {
      v1::CurvatureRequest r;
      if (!Parse(&r, data, size)) return absl::OkStatus();
      return Drain(&server::OpenCurvature, ctx, r);
    }
    case 7:
      return Call(&server::Singularities, ctx, data, size);
    case 8:
      return Call(&server::Smooth, ctx, data, size);
    default:
      return Call(&server::Align, ctx, data, size);
  }
}

}  // namespace
}  // namespace fieldspace::fuzz

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 2) return 0;
  (void)fieldspace::fuzz::Run(data[0], fieldspace::fuzz::TinyBasis(data[1]), data + 2, size - 2);
  return 0;
}
