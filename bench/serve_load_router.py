#!/usr/bin/env python3
"""serve-load through a router: N fieldspaced replicas (--shared-store, one store) behind nginx
(the configuration of tests/server/scale_out_test.py: grpc_pass, `hash $http_x_fieldspace_key
consistent`), and `fieldspace-bench serve-load --server` run alternately against the router and
directly against the replica the router sends the basis to, so that the difference is the
router's overhead (all sessions of one basis share one routing key, hence one replica).
Optionally also against a plain single daemon (exclusive store) for the baseline.

  bench/serve_load_router.py --mesh M --dim D [--sessions S] [--edits E] [--rate HZ]
      [--replicas 3] [--threads T] [--rounds R] [--single]

Prints each run's JSON (one line, with "target" added) and a summary table (markdown).
"""

import argparse
import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "tests", "server"))
from fs_testlib import Daemon  # noqa: E402
from scale_out_test import start_nginx  # noqa: E402


def serve_load(bench, target, args):
    command = [bench, "serve-load", args.mesh, "--dim", str(args.dim), "--sessions",
               str(args.sessions), "--edits", str(args.edits), "--lifts", "0", "--server", target]
    if args.rate:
        command += ["--rate", str(args.rate)]
    p = subprocess.run(command, capture_output=True, text=True, timeout=3600)
    if p.returncode != 0:
        raise SystemExit("serve-load failed (%d): %s" % (p.returncode, p.stderr[-2000:]))
    return json.loads(p.stdout.strip().splitlines()[-1])


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--daemon", default=os.path.join(HERE, "..", "build", "bin",
                                                         "fieldspaced"))
    parser.add_argument("--bench", default=os.path.join(HERE, "..", "build", "bin",
                                                        "fieldspace-bench"))
    parser.add_argument("--nginx", default=shutil.which("nginx") or "/usr/sbin/nginx")
    parser.add_argument("--mesh", required=True)
    parser.add_argument("--dim", type=int, required=True)
    parser.add_argument("--sessions", type=int, default=16)
    parser.add_argument("--edits", type=int, default=200)
    parser.add_argument("--rate", type=float, default=0)
    parser.add_argument("--replicas", type=int, default=3)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--single", action="store_true",
                        help="also run against a plain single daemon (its own store)")
    args = parser.parse_args()

    work = tempfile.mkdtemp(prefix="fs_serve_load_router_")
    store = os.path.join(work, "store")
    replicas, nginx, single = [], None, None
    runs = []
    try:
        for i in range(args.replicas):
            replicas.append(Daemon(args.daemon, store, threads=args.threads,
                                   extra=["--shared-store", "--daemon-id", "r%d" % i],
                                   log=os.path.join(work, "r%d.log" % i)).start())
        nginx, router = start_nginx(args.nginx, work, [d.address for d in replicas])
        first = serve_load(args.bench, router, args)  # builds the basis (once)
        first["target"] = "router (first run: upload + build)"
        print(json.dumps(first), flush=True)
        # The replica that served the sessions: nginx's upstream for the basis's key.
        access = open(os.path.join(work, "access.log")).read().splitlines()
        designs = [line.split() for line in access if "/Design " in line]
        direct = designs[-1][2]
        targets = [("router", router), ("replica directly", direct)]
        if args.single:
            single = Daemon(args.daemon, os.path.join(work, "single"), threads=args.threads,
                            log=os.path.join(work, "single.log")).start()
            warm = serve_load(args.bench, single.address, args)  # builds the basis there
            warm["target"] = "single daemon (first run: upload + build)"
            print(json.dumps(warm), flush=True)
            targets.append(("single daemon", single.address))
        for _ in range(args.rounds):
            for name, address in targets:
                result = serve_load(args.bench, address, args)
                result["target"] = name
                print(json.dumps(result), flush=True)
                runs.append(result)
    finally:
        if nginx is not None:
            nginx.send_signal(signal.SIGQUIT)
            nginx.wait(10)
        for d in replicas + ([single] if single else []):
            if d.alive():
                d.stop()
        shutil.rmtree(work, ignore_errors=True)
    print("\n| target | edits | throughput | round trip p50 / p99 | server edit p50 / p99 |")
    print("|---|--:|--:|--:|--:|")
    for r in runs:
        rt, se = r["round_trip_ms"], r["server_edit_ms"]
        print("| %s | %d | %.0f/s | %.2f / %.2f ms | %.2f / %.2f ms |" % (
            r["target"], r["edits"], r["edits_per_second"], rt["p50"], rt["p99"], se["p50"],
            se["p99"]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
