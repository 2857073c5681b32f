#!/usr/bin/env python3
"""Health/Watch streams, which need no token, are capped (issue 22): the real fieldspaced with
--auth-token-file and --max-open-watches 8.
- 8 Watch streams without a token are served (each gets SERVING); a 9th is RESOURCE_EXHAUSTED
  naming the flag; Health/Check still answers.
- Once 3 of them are cancelled, 3 new ones are served again (the count follows the streams' ends).

Exit 0 on success, 1 on failure, 77 (skip) if python3-grpcio / numpy are absent.
"""

import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from fs_testlib import Daemon, check, client_test_args, daemon_workdir, log  # noqa: E402

MAX_WATCHES = 8
WATCH = "/grpc.health.v1.Health/Watch"
CHECK = "/grpc.health.v1.Health/Check"
SERVING = b"\x08\x01"  # HealthCheckResponse{status: SERVING}


def main():
    args, fs = client_test_args(__doc__)
    if fs is None:
        return 77
    import grpc

    daemons = []
    with daemon_workdir("fs_open_watches_", daemons) as (work, store, daemon_log):
        token_file = os.path.join(work, "token")
        with open(token_file, "w") as f:
            f.write("open-watches-test-token\n")
        d = Daemon(args.daemon, store, log=daemon_log,
                   extra=["--auth-token-file", token_file, "--max-open-watches", str(MAX_WATCHES)])
        daemons.append(d.start())
        channel = grpc.insecure_channel(d.address)
        watch = channel.unary_stream(WATCH, request_serializer=None, response_deserializer=None)
        check_call = channel.unary_unary(CHECK, request_serializer=None,
                                         response_deserializer=None)

        def open_watch():
            stream = watch(b"", timeout=60)
            return stream, next(stream)

        streams = []
        for i in range(MAX_WATCHES):
            stream, first = open_watch()
            check(first == SERVING, "watch %d: first answer %r" % (i, first))
            streams.append(stream)
        log("ok: %d watches without a token served" % MAX_WATCHES)
        try:
            open_watch()
            raise AssertionError("watch %d was served" % (MAX_WATCHES + 1))
        except grpc.RpcError as e:
            check(e.code() == grpc.StatusCode.RESOURCE_EXHAUSTED, "watch %d: %s %s" %
                  (MAX_WATCHES + 1, e.code(), e.details()))
            check("--max-open-watches" in e.details(), e.details())
            log("ok: one more: %s" % e.details())
        check(check_call(b"", timeout=10) == SERVING, "Health/Check beside the watches")

        for stream in streams[:3]:
            stream.cancel()
        deadline = time.monotonic() + 10
        reopened = 0
        while reopened < 3 and time.monotonic() < deadline:
            try:
                stream, first = open_watch()
                streams.append(stream)
                reopened += 1
            except grpc.RpcError as e:
                check(e.code() == grpc.StatusCode.RESOURCE_EXHAUSTED, "reopen: %s" % e)
                time.sleep(0.1)  # the cancellations reach the server
        check(reopened == 3, "only %d watches reopened after 3 were cancelled" % reopened)
        log("ok: 3 watches cancelled, 3 reopened")
        try:
            open_watch()
            raise AssertionError("the cap no longer holds after reopening")
        except grpc.RpcError as e:
            check(e.code() == grpc.StatusCode.RESOURCE_EXHAUSTED, "after reopening: %s" % e)
        for stream in streams:
            stream.cancel()
        channel.close()
        check(d.stop() == 0, "daemon did not exit 0 on SIGTERM")
    log("open watches: all passed")
    return 0


if __name__ == "__main__":
    sys.exit(main())
