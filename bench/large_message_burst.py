#!/usr/bin/env python3
"""Peak RSS of fieldspaced while N concurrent large Solve requests (for an unknown basis) arrive
(issue 22, item 2: the transport's buffers, before any handler runs). Each request carries an
unknown length-delimited field of --mb MB, which gRPC receives and parses in full.

  bench/large_message_burst.py --daemon build/bin/fieldspaced --python-dir build/python \
      --requests 16 --mb 60 --budget-mb 1024
"""

import argparse
import collections
import os
import shutil
import sys
import tempfile
import threading
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "tests", "server"))
from fs_testlib import Daemon, with_unknown_field  # noqa: E402


def main():
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--daemon", required=True)
    parser.add_argument("--python-dir", required=True)
    parser.add_argument("--requests", type=int, default=16)
    parser.add_argument("--mb", type=int, default=60)
    parser.add_argument("--budget-mb", type=int, default=1024)
    args = parser.parse_args()
    sys.path.insert(0, args.python_dir)
    import grpc
    from fieldspace.v1 import fieldspace_pb2 as pb

    work = tempfile.mkdtemp(prefix="fs_burst_")
    try:
        d = Daemon(args.daemon, os.path.join(work, "store"), threads=2,
                   extra=["--memory-budget-mb", str(args.budget_mb)]).start()
        size = args.mb << 20
        payload = with_unknown_field(
            pb.SolveRequest(basis_id="b-0000000000000000").SerializeToString(), size)
        time.sleep(0.5)

        def hwm():
            with open("/proc/%d/status" % d.proc.pid) as f:
                return next(int(l.split()[1]) for l in f if l.startswith("VmHWM")) / 1024

        idle = hwm()
        codes = collections.Counter()
        lock = threading.Lock()

        def send():
            channel = grpc.insecure_channel(d.address,
                                            options=[("grpc.max_send_message_length", -1)])
            call = channel.unary_unary("/fieldspace.v1.FieldSpace/Solve")
            try:
                call(payload, timeout=300)
                code = "OK"
            except grpc.RpcError as e:
                code = e.code().name
            with lock:
                codes[code] += 1
            channel.close()

        start = time.monotonic()
        threads = [threading.Thread(target=send) for _ in range(args.requests)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        took = time.monotonic() - start
        alive = d.alive()
        peak = hwm()
        d.stop()
        print("load average %s" % " ".join(open("/proc/loadavg").read().split()[:3]))
        print("%d x %d MB Solves: idle %.0f MiB, peak %.0f MiB, %.1f s, answers %s%s" %
              (args.requests, args.mb, idle, peak, took, dict(codes),
               "" if alive else " (daemon died)"))
    finally:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
