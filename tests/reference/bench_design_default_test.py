#!/usr/bin/env python3
"""`fieldspace-bench design` reports its biharmonic form: mixed by default, exact on request.

usage: bench_design_default_test.py BENCH_BINARY     (exit 0 ok, 1 failure)

Pins the default of the design bench (and so of DesignSessionOptions it passes through) on a
shape built by the bench itself: no mesh files needed.
"""
import json
import os
import subprocess
import sys
import tempfile


def main():
    bench = sys.argv[1]
    failures = []
    with tempfile.TemporaryDirectory() as tmp:
        mesh = os.path.join(tmp, "sphere.ply")
        subprocess.run([bench, "shape", "icosphere", "--level", "3", "--out", mesh], check=True,
                       capture_output=True, timeout=60)
        results = {}
        for form in (None, "mixed", "exact"):
            cmd = [bench, "design", mesh, "--field", "vector", "--dim", "60", "--edits", "40",
                   "--seed", "1", "--no-full"]
            if form is not None:
                cmd += ["--biharmonic", form]
            res = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
            if res.returncode != 0:
                failures.append("%s: exit %d: %s" % (cmd, res.returncode, res.stderr))
                continue
            out = json.loads(res.stdout)
            results[form] = out
            if out["backward_error"]["max"] > 1e-12:
                failures.append("%s: backward error %g" % (form, out["backward_error"]["max"]))
        if results.get(None, {}).get("biharmonic") != "mixed":
            failures.append("default form: %s" % results.get(None, {}).get("biharmonic"))
        if results.get("mixed", {}).get("biharmonic") != "mixed":
            failures.append("--biharmonic mixed: %s" % results.get("mixed", {}).get("biharmonic"))
        if results.get("exact", {}).get("biharmonic") != "exact":
            failures.append("--biharmonic exact: %s" % results.get("exact", {}).get("biharmonic"))
    for f in failures:
        print("FAIL:", f)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
