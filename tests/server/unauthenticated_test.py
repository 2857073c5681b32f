#!/usr/bin/env python3
"""Calls without the token are turned away before their request is read (issue 15, B9): the real
fieldspaced with --auth-token-file.
- 16 concurrent 63 MB Project requests without a token: all UNAUTHENTICATED, and the daemon's
  peak memory grows by less than 4 of them (before, gRPC received and parsed each one in full
  before the handler checked the token: ~590 MB more).
- A request that is no protobuf at all, without a token: UNAUTHENTICATED (it is not parsed); with
  the token: INVALID_ARGUMENT.
- An upload stream without a token: UNAUTHENTICATED.
- Health checks and server reflection stay open; calls with the token work.

Exit 0 on success, 1 on failure, 77 (skip) if python3-grpcio / numpy are absent.
"""

import os
import sys
import threading

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from fs_testlib import Daemon, check, client_test_args, daemon_workdir, log  # noqa: E402

TOKEN = "unauthenticated-test-token"
SERVICE = "/fieldspace.v1.FieldSpace/"


def peak_rss_bytes(pid):
    with open("/proc/%d/status" % pid) as f:
        for line in f:
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) * 1024
    raise AssertionError("no VmHWM in /proc/%d/status" % pid)


def main():
    args, fs = client_test_args(__doc__)
    if fs is None:
        return 77
    import grpc
    from fieldspace.v1 import fieldspace_pb2 as pb

    daemons = []
    with daemon_workdir("fs_unauthenticated_", daemons) as (work, store, daemon_log):
        token_file = os.path.join(work, "token")
        with open(token_file, "w") as f:
            f.write(TOKEN + "\n")
        d = Daemon(args.daemon, store, log=daemon_log, extra=["--auth-token-file", token_file])
        daemons.append(d.start())
        channel = grpc.insecure_channel(d.address,
                                        options=[("grpc.max_send_message_length", 256 << 20)])

        def raw(method, body, metadata=None):
            """The status code and message of a unary call with raw request bytes."""
            call = channel.unary_unary(method, request_serializer=None,
                                       response_deserializer=None)
            try:
                return grpc.StatusCode.OK, call(body, timeout=120, metadata=metadata)
            except grpc.RpcError as e:
                return e.code(), e.details()

        # Open methods: health (an empty HealthCheckRequest; SERVING is field 1 = 1) and
        # reflection (list_services, field 7).
        code, answer = raw("/grpc.health.v1.Health/Check", b"")
        check(code == grpc.StatusCode.OK and answer == b"\x08\x01",
              "health without a token: %s %r" % (code, answer))
        for version in ("v1", "v1alpha"):
            stream = channel.stream_stream(
                "/grpc.reflection.%s.ServerReflection/ServerReflectionInfo" % version,
                request_serializer=None, response_deserializer=None)
            answers = list(stream(iter([b"\x3a\x00"]), timeout=30))
            check(len(answers) == 1 and b"fieldspace.v1.FieldSpace" in answers[0],
                  "reflection %s without a token lists the service" % version)

        # Garbage: not parsed without the token, refused as such with it.
        garbage = b"\xff\xff\xff\xff"
        code, message = raw(SERVICE + "Solve", garbage)
        check(code == grpc.StatusCode.UNAUTHENTICATED, "garbage, no token: %s %s" % (code, message))
        code, message = raw(SERVICE + "Solve", garbage, [("authorization", "Bearer " + TOKEN)])
        check(code == grpc.StatusCode.INVALID_ARGUMENT and "not a valid" in message,
              "garbage with the token: %s %s" % (code, message))

        # Large bodies without the token.
        request = pb.ProjectRequest(basis_id="b-0000000000000000")
        request.field.values.extend([0.5] * (60 * 1024 * 1024 // 4))
        body = request.SerializeToString()
        before = peak_rss_bytes(d.proc.pid)
        codes = []

        def send():
            codes.append(raw(SERVICE + "Project", body, [("authorization", "Bearer wrong")]))

        threads = [threading.Thread(target=send) for _ in range(16)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        growth = peak_rss_bytes(d.proc.pid) - before
        log("16 unauthenticated %.1f MB requests: daemon peak RSS +%.1f MB" %
            (len(body) / 1e6, growth / 1e6))
        check(all(c == grpc.StatusCode.UNAUTHENTICATED and m == "invalid token" for c, m in codes),
              "every large request is UNAUTHENTICATED: %s" % sorted(set(c for c, _ in codes)))
        check(growth < 4 * len(body), "peak RSS grew by %.1f MB" % (growth / 1e6))

        # Streams and the token path.
        upload = channel.stream_unary(SERVICE + "UploadMesh", request_serializer=None,
                                      response_deserializer=None)
        header = pb.UploadMeshRequest()
        header.header.name = "a.obj"
        header.header.total_bytes = 1 << 20
        try:
            upload(iter([header.SerializeToString()] + [b"\x12\x00"] * 64), timeout=30)
            check(False, "an upload without a token succeeded")
        except grpc.RpcError as e:
            check(e.code() == grpc.StatusCode.UNAUTHENTICATED, "upload: %s" % e.code())
        with fs.Client(d.address, token=TOKEN, timeout=30) as client:
            check(client.meshes() == [], "the token works")
        channel.close()
        check(d.stop() == 0, "SIGTERM exits 0")
        log("PASS")
        return 0


if __name__ == "__main__":
    sys.exit(main())
