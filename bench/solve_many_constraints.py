#!/usr/bin/env python3
"""A Solve with many soft constraints through the daemon (issue 15, B2 and B3): its server-side
time and the daemon's peak resident memory (VmHWM), then the same Solve with a deadline that
expires, and how soon the next call is answered (the compute thread must be freed).

  bench/solve_many_constraints.py --mesh M --dim D --constraints K [--deadline S]
      [--fieldspaced build/bin/fieldspaced]

Uses the Python package (PYTHONPATH=build/python, /usr/bin/python3 with grpcio). Prints one line
per step.
"""

import argparse
import os
import shutil
import sys
import tempfile
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "tests", "server"))
from fs_testlib import Daemon  # noqa: E402
import fieldspace as fs  # noqa: E402


def peak_kb(pid):
    with open("/proc/%d/status" % pid) as f:
        for line in f:
            if line.startswith("VmHWM"):
                return int(line.split()[1])
    return -1


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--mesh", required=True)
    parser.add_argument("--dim", type=int, default=1000)
    parser.add_argument("--constraints", type=int, default=1 << 20)
    parser.add_argument("--deadline", type=float, default=1.0)
    parser.add_argument("--fieldspaced",
                        default=os.path.join(HERE, "..", "build", "bin", "fieldspaced"))
    args = parser.parse_args()
    work = tempfile.mkdtemp(prefix="fs_solve_many_")
    daemon = Daemon(args.fieldspaced, os.path.join(work, "store")).start()
    try:
        client = fs.Client(daemon.address, timeout=3600)
        mesh = client.upload(args.mesh)
        basis = client.build(mesh.id, "vector", args.dim, progress=False)
        client.solve(basis, [0], [[1.0, 0.0]], encoding="dof")  # loads everything
        print("mesh %s: %d faces, d = %d; daemon peak RSS before: %.0f MB"
              % (os.path.basename(args.mesh), mesh.num_faces, args.dim,
                 peak_kb(daemon.proc.pid) / 1024), flush=True)
        rng = np.random.default_rng(3)
        faces = rng.integers(0, mesh.num_faces, args.constraints)
        values = rng.normal(size=(args.constraints, 2))
        for raw in (True, False):
            r = client.solve(basis, faces, values, encoding="dof", raw_weights=raw)
            print("%d soft constraints, %s weights: solve %.0f ms, total %.0f ms server-side; "
                  "daemon peak RSS %.0f MB"
                  % (args.constraints, "raw" if raw else "scale-free", r.timings["solve_ms"],
                     r.timings["total_ms"], peak_kb(daemon.proc.pid) / 1024), flush=True)
        try:
            client.solve(basis, faces, values, encoding="dof", timeout=args.deadline)
            print("the deadline of %.1f s did not expire" % args.deadline)
        except fs.DeadlineExceeded:
            start = time.perf_counter()
            client.solve(basis, [1], [[1.0, 0.0]], encoding="dof")
            print("deadline %.1f s expired; the next Solve answered in %.1f ms"
                  % (args.deadline, 1000 * (time.perf_counter() - start)))
    finally:
        assert daemon.stop() == 0
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
