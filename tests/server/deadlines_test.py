#!/usr/bin/env python3
"""Long calls stop at their deadline (issue 22, item 4): the real fieldspaced with --threads 1, so
that a call still running after its deadline holds the only compute thread and delays the next.

For each of Solve with many hard constraints, Solve with many soft constraints, Curvature with
principal directions and Eigenfields, on problems that take seconds: the call with a 0.4 s deadline
is DEADLINE_EXCEEDED, and a small Solve sent at that deadline is answered within 1 s of it plus its
own time (measured alone first). The measured overrun of each is printed (the issue asks for
0.1 s; a loaded 2-core machine cannot assert that tightly). The same with the client cancelling
instead (CANCELLED).

Exit 0 on success, 1 on failure, 77 (skip) if python3-grpcio / numpy are absent.
"""

import os
import sys
import threading
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from fs_testlib import (Daemon, check, client_test_args, daemon_workdir, icosphere_obj,  # noqa: E402
                        log, obj_arrays)

DEADLINE = 0.4
MAX_OVERRUN = 1.0


def main():
    args, fs = client_test_args(__doc__)
    if fs is None:
        return 77
    import grpc
    import numpy as np

    daemons = []
    with daemon_workdir("fs_deadlines_", daemons) as (work, store, daemon_log):
        d = Daemon(args.daemon, store, log=daemon_log, threads=1)
        daemons.append(d.start())
        client = fs.Client(d.address)
        V, F = obj_arrays(icosphere_obj(6)[0])  # 81,920 faces
        mesh = client.upload(V, F)
        start = time.monotonic()
        basis = client.build(mesh.id, "vector", 3000, progress=False)
        log("basis d = 3000 on %d faces built in %.1f s" % (len(F), time.monotonic() - start))
        # Large enough that one Curvature call takes well over DEADLINE on an idle machine too
        # (327,680 faces finished within 0.4 s there, so the cancel came after the answer).
        V8, F8 = obj_arrays(icosphere_obj(8)[0])  # 1,310,720 faces
        big_mesh = client.upload(V8, F8)

        rng = np.random.default_rng(7)
        hard_faces = rng.choice(len(F), 1400, replace=False)
        hard_values = rng.normal(size=(len(hard_faces), 3))
        soft_faces = rng.choice(len(F), 60000, replace=False)
        soft_values = rng.normal(size=(len(soft_faces), 3))

        def small(timeout=30):
            return client.solve(basis, faces=[0], values=[[1.0, 0.0, 0.0]], timeout=timeout)

        small()
        start = time.monotonic()
        small()
        small_alone = time.monotonic() - start
        log("a small Solve alone: %.3f s" % small_alone)

        calls = {
            "Solve, 1400 hard constraints": lambda timeout: client.solve(
                basis, faces=hard_faces, values=hard_values, hard=True, timeout=timeout),
            "Solve, 60000 soft constraints": lambda timeout: client.solve(
                basis, faces=soft_faces, values=soft_values, timeout=timeout),
            "Curvature with principal directions, 1,310,720 faces": lambda timeout: client.curvature(
                big_mesh.id, principal=True, timeout=timeout),
            "Eigenfields, 1000 of d = 3000": lambda timeout: client.eigen(basis, 1000,
                                                                          timeout=timeout),
        }
        overruns = []
        for name, call in calls.items():
            for how in ("deadline", "cancel"):
                outcome = {}

                def heavy():
                    try:
                        if how == "deadline":
                            call(DEADLINE)
                        else:
                            call(60)
                        outcome["code"] = "OK"
                    except fs.FieldspaceError as e:
                        outcome["code"] = e.code.name

                if how == "cancel":
                    method, request, streaming = captured_call(client, call)
                    future = (StreamFuture(method(request, timeout=60)) if streaming else
                              method.future(request, timeout=60))
                    started = time.monotonic()
                    time.sleep(DEADLINE)
                    future.cancel()
                    stopped_at = time.monotonic()
                    try:
                        future.result()
                        outcome["code"] = "OK"
                    except grpc.FutureCancelledError:
                        outcome["code"] = "CANCELLED"
                    except grpc.RpcError as e:
                        outcome["code"] = e.code().name
                else:
                    thread = threading.Thread(target=heavy)
                    started = time.monotonic()
                    thread.start()
                    time.sleep(DEADLINE)
                    stopped_at = started + DEADLINE
                small()
                answered = time.monotonic()
                if how == "deadline":
                    thread.join(30)
                overrun = max(0.0, answered - stopped_at - small_alone)
                overruns.append((name, how, overrun))
                log("%s, %s: %s; the next small Solve %.3f s after the %s (overrun %.3f s)" %
                    (name, how, outcome.get("code"), answered - stopped_at, how, overrun))
                expected = "DEADLINE_EXCEEDED" if how == "deadline" else "CANCELLED"
                check(outcome.get("code") == expected,
                      "%s, %s: %s, expected %s" % (name, how, outcome.get("code"), expected))
                check(overrun <= MAX_OVERRUN, "%s, %s: ran %.2f s past its end" %
                      (name, how, overrun))
        check(d.stop() == 0, "daemon did not exit 0 on SIGTERM")
    log("deadlines: all passed; largest overrun %.3f s" % max(o for _, _, o in overruns))
    return 0


class _Captured(Exception):
    pass


def captured_call(client, call):
    """(stub method, request, whether it streams) of the package's call `call`, not sent: the
    package's calls block, the test needs a handle it can cancel."""
    def capture(streaming):
        def sender(what, method, request, timeout):
            raise _Captured(method, request, streaming)
        return sender

    saved = client._unary, client._collect
    client._unary, client._collect = capture(False), capture(True)
    try:
        call(60)
    except _Captured as c:
        return c.args
    finally:
        client._unary, client._collect = saved
    raise AssertionError("the call sent nothing")


class StreamFuture:
    """A server stream consumed on a thread, with a future's cancel() and result()."""

    def __init__(self, stream):
        self.stream = stream
        self.error = None
        self.thread = threading.Thread(target=self._drain)
        self.thread.start()

    def _drain(self):
        try:
            for _ in self.stream:
                pass
        except Exception as e:  # grpc.RpcError: CANCELLED after cancel()
            self.error = e

    def cancel(self):
        self.stream.cancel()

    def result(self):
        self.thread.join(60)
        if self.error is not None:
            raise self.error


if __name__ == "__main__":
    sys.exit(main())
