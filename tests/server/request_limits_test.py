#!/usr/bin/env python3
"""What one client can hold on to is bounded (issue 22, item 2): the real fieldspaced with
--memory-budget-mb 1024, --upload-idle-seconds 2 and --max-queued-builds 2.
- An UploadMesh whose header announces 512 MiB (the server reserves twice that: the whole budget)
  and then sends nothing: while it is open, a basis build is RESOURCE_EXHAUSTED; within the idle
  timeout (+ 1.5 s) the upload ends with DEADLINE_EXCEEDED, nothing is stored, and the Solve then
  works. An upload that keeps sending, slower than the timeout in total but never idle that long,
  is stored.
- Builds beyond --max-queued-builds (running or queued) are RESOURCE_EXHAUSTED at once; asking
  again for a build already queued joins it; after they finish new builds are accepted.

Exit 0 on success, 1 on failure, 77 (skip) if python3-grpcio / numpy are absent.
"""

import os
import sys
import threading
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from fs_testlib import (Daemon, check, client_test_args, daemon_workdir, icosphere_obj,  # noqa: E402
                        log, obj_arrays)

IDLE_SECONDS = 2


def main():
    args, fs = client_test_args(__doc__)
    if fs is None:
        return 77
    import grpc
    import numpy as np
    from fieldspace.v1 import fieldspace_pb2 as pb

    daemons = []
    with daemon_workdir("fs_request_limits_", daemons) as (work, store, daemon_log):
        d = Daemon(args.daemon, store, log=daemon_log, threads=2,
                   extra=["--memory-budget-mb", "1024", "--upload-idle-seconds", str(IDLE_SECONDS),
                          "--max-queued-builds", "2"])
        daemons.append(d.start())
        client = fs.Client(d.address)
        text, _ = icosphere_obj(4)
        V, F = obj_arrays(text)
        mesh = client.upload(V, F)
        basis = client.build(mesh.id, "vector", 1500, progress=False)
        rng = np.random.default_rng(3)
        faces = rng.choice(len(F), 300, replace=False)
        values = rng.normal(size=(len(faces), 3))

        def solve():
            return client.solve(basis, faces=faces, values=values, hard=True, timeout=30)

        solve()  # fits the budget alone
        listed = sorted(m.id for m in client.meshes())

        # An idle upload holding the whole budget.
        release = threading.Event()

        def idle_requests():
            yield pb.UploadMeshRequest(header=pb.UploadMeshHeader(
                name="idle.obj", format=pb.MESH_FORMAT_OBJ, total_bytes=512 << 20))
            release.wait(30)  # sends nothing more until the test ends

        started = time.monotonic()
        idle = client._stub.UploadMesh.future(idle_requests(), timeout=60)
        time.sleep(0.5)
        try:
            # Admitted before any work (a Solve loads its evicted basis first, which may outlast
            # the idle timeout on a busy machine).
            client.build(mesh.id, "vector", 1000, seed=9, progress=False, timeout=30)
            raise AssertionError("a build was admitted while an idle upload reserved the whole "
                                 "budget (upload done: %s)" % (idle.done() and idle.exception()))
        except fs.ResourceExhausted as e:
            check("--memory-budget-mb" in str(e), "build next to the idle upload: %s" % e)
            log("ok: a build next to the idle upload: %s" % e)
        try:
            idle.result(timeout=IDLE_SECONDS + 5)
            raise AssertionError("the idle upload succeeded")
        except grpc.RpcError as e:
            took = time.monotonic() - started
            check(e.code() == grpc.StatusCode.DEADLINE_EXCEEDED,
                  "idle upload: %s %s" % (e.code(), e.details()))
            check("--upload-idle-seconds" in e.details(), "idle upload: %s" % e.details())
            check(IDLE_SECONDS - 0.1 <= took <= IDLE_SECONDS + 1.5,
                  "the idle upload ended after %.2f s" % took)
            log("ok: idle upload ended after %.2f s: %s" % (took, e.details()))
        release.set()
        solve()
        log("ok: Solve works once the idle upload is gone")
        check(sorted(m.id for m in client.meshes()) == listed, "the idle upload stored a mesh")

        # Slow but never idle for the timeout: stored.
        body = text

        def slow_requests():
            offset = 0
            chunks = [body[i * len(body) // 4:(i + 1) * len(body) // 4].encode()
                      for i in range(4)]
            for i, chunk in enumerate(chunks):
                header = pb.UploadMeshHeader(name="slow.obj", format=pb.MESH_FORMAT_OBJ) \
                    if i == 0 else None
                yield pb.UploadMeshRequest(header=header, offset=offset, data=chunk,
                                           last=i == len(chunks) - 1)
                offset += len(chunk)
                time.sleep(IDLE_SECONDS * 0.6)

        start = time.monotonic()
        info = client._stub.UploadMesh(slow_requests(), timeout=60)
        check(time.monotonic() - start > IDLE_SECONDS, "the slow upload was not slow")
        check(info.id == mesh.id, "slow upload: %s, expected %s" % (info.id, mesh.id))
        log("ok: an upload slower than the idle timeout in total, never idle that long, stored")

        # Builds beyond --max-queued-builds.
        V2, F2 = obj_arrays(icosphere_obj(5)[0])
        big = client.upload(V2, F2)
        streams = []
        for seed in (1, 2):
            request = pb.BuildBasisRequest(mesh_id=big.id, field=pb.FieldType(
                kind=pb.FIELD_KIND_VECTOR), dimension=1500, seed=seed)
            stream = client._stub.BuildBasis(request, timeout=300)
            first = next(stream)
            streams.append((request, stream, first))
        try:
            client.build(big.id, "vector", 1500, seed=3, progress=False)
            raise AssertionError("a third build was accepted with --max-queued-builds 2")
        except fs.ResourceExhausted as e:
            check("--max-queued-builds" in str(e), "third build: %s" % e)
            log("ok: third build: %s" % e)
        # The same build again joins it.
        again = client._stub.BuildBasis(streams[1][0], timeout=300)
        joined = next(again)
        check(joined.basis_id == streams[1][2].basis_id, "asking again did not join the build")
        again.cancel()
        for _, stream, _ in streams:
            for _ in stream:
                pass
        built = client.build(big.id, "vector", 1500, seed=3, progress=False)
        check(built.startswith("b-"), "build after the queue drained: %r" % built)
        log("ok: builds accepted again once the queue drained")
        check(d.stop() == 0, "daemon did not exit 0 on SIGTERM")
    log("request limits: all passed")
    return 0


if __name__ == "__main__":
    sys.exit(main())
