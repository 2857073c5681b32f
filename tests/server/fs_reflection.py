"""A grpcio client that knows nothing of fieldspace: it learns the schema through reflection.

Shared by the end-to-end tests (needs python3-grpcio and python3-protobuf; importing this module
raises ImportError without them, which the tests turn into a skip).
"""

import os
import shutil
import sys

import grpc
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

from fs_testlib import check, run


def message_class(pool, name):
    descriptor = pool.FindMessageTypeByName(name)
    if hasattr(message_factory, "GetMessageClass"):
        return message_factory.GetMessageClass(descriptor)
    return message_factory.MessageFactory(pool).GetPrototype(descriptor)


class ReflectionClient:
    """A grpcio client that knows nothing of fieldspace: it fetches the schema through reflection."""

    def __init__(self, address, protoc, grpc_proto_dir, workdir, credentials=None):
        """``credentials``: grpc channel credentials for a TLS server (default: plaintext)."""
        # Only the reflection protocol itself is compiled here (protoc is a build dependency);
        # it is copied under another folder so that its module does not shadow the grpc package.
        src = os.path.join(workdir, "refl_src", "fsrefl")
        os.makedirs(src, exist_ok=True)
        shutil.copy(os.path.join(grpc_proto_dir, "grpc/reflection/v1alpha/reflection.proto"),
                    os.path.join(src, "reflection.proto"))
        out = os.path.join(workdir, "refl_py")
        os.makedirs(out, exist_ok=True)
        run([protoc, "-I", os.path.join(workdir, "refl_src"), "--python_out=" + out,
             "fsrefl/reflection.proto"], check=0)
        sys.path.insert(0, out)
        from fsrefl import reflection_pb2  # noqa: E402
        self.r = reflection_pb2
        self.channel = (grpc.secure_channel(address, credentials) if credentials is not None
                        else grpc.insecure_channel(address))
        self.pool = descriptor_pool.DescriptorPool()
        self.loaded = set()
        self.reflect = self.channel.stream_stream(
            "/grpc.reflection.v1alpha.ServerReflection/ServerReflectionInfo",
            request_serializer=reflection_pb2.ServerReflectionRequest.SerializeToString,
            response_deserializer=reflection_pb2.ServerReflectionResponse.FromString)

    def _ask(self, **kwargs):
        responses = list(self.reflect(iter([self.r.ServerReflectionRequest(**kwargs)]), timeout=30))
        check(len(responses) == 1, "one reflection answer expected")
        response = responses[0]
        check(not response.HasField("error_response"),
              "reflection error: %s" % response.error_response.error_message)
        return response

    def services(self):
        return [s.name for s in self._ask(list_services="").list_services_response.service]

    def load_symbol(self, symbol):
        response = self._ask(file_containing_symbol=symbol)
        files = [descriptor_pb2.FileDescriptorProto.FromString(b)
                 for b in response.file_descriptor_response.file_descriptor_proto]
        # Dependencies first (the answer may list them in any order).
        pending = [f for f in files if f.name not in self.loaded]
        while pending:
            progress = False
            for f in list(pending):
                if all(d in self.loaded for d in f.dependency):
                    self.pool.Add(f)
                    self.loaded.add(f.name)
                    pending.remove(f)
                    progress = True
            check(progress, "unresolvable descriptor dependencies: %s" %
                  [f.name for f in pending])

    def method(self, kind, service, name, request_type, response_type):
        req = message_class(self.pool, request_type)
        resp = message_class(self.pool, response_type)
        factory = getattr(self.channel, kind)
        call = factory("/%s/%s" % (service, name), request_serializer=req.SerializeToString,
                       response_deserializer=resp.FromString)
        return call, req
