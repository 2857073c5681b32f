#ifndef FIELDSPACE_SERVER_REACTORS_H_
#define FIELDSPACE_SERVER_REACTORS_H_

// The streaming RPCs' reactors with state of their own, one file each (upload_reactor.cc,
// build_watcher.cc, design_reactor.cc; the chunked answers are rpc_util.h's ChunkWriter). Each
// deletes itself when gRPC is done with it.

#include "fieldspace/v1/fieldspace.grpc.pb.h"
#include "grpcpp/grpcpp.h"

namespace fieldspace::server {

class FieldService;

// UploadMesh (raw: UploadMeshRequest in, MeshInfo out): accumulates in-order chunks, then parses
// and registers the mesh on the pool.
grpc::ServerReadReactor<grpc::ByteBuffer>* NewUploadReactor(FieldService* service,
                                                            grpc::CallbackServerContext* context,
                                                            grpc::ByteBuffer* response);

// BuildBasis: watches a (possibly shared) build job; the job outlives the stream.
grpc::ServerWriteReactor<fieldspace::v1::BuildBasisProgress>* NewBuildWatcher(
    FieldService* service, const fieldspace::v1::BuildBasisRequest& request);

// Design (raw: DesignRequest in, DesignUpdate out): one session per stream (the edit logic is
// DesignEditor, design_editor.h).
grpc::ServerBidiReactor<grpc::ByteBuffer, grpc::ByteBuffer>* NewDesignReactor(
    FieldService* service, grpc::CallbackServerContext* context);

}  // namespace fieldspace::server

#endif  // FIELDSPACE_SERVER_REACTORS_H_
