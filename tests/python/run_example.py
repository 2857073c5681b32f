#!/usr/bin/env python3
"""Runs one script of examples/ against a fresh fieldspaced and checks that it succeeds and
prints what it should. Exit 0 on success, 1 on failure."""

import argparse
import os
import shutil
import subprocess
import sys
import tempfile

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "server"))
from fs_testlib import Daemon, check, log  # noqa: E402


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--daemon", required=True)
    parser.add_argument("--example", required=True)
    parser.add_argument("--expect", action="append", default=[],
                        help="a string the example's output must contain")
    args = parser.parse_args()
    work = tempfile.mkdtemp(prefix="fs_example_")
    d = Daemon(args.daemon, os.path.join(work, "store")).start()
    try:
        # In the work folder: what an example writes stays out of the tree.
        p = subprocess.run([sys.executable, args.example, "--server", d.address], cwd=work,
                           capture_output=True, text=True, timeout=300)
        log(p.stdout)
        check(p.returncode == 0, "%s exited %d\nstderr:\n%s" % (args.example, p.returncode,
                                                              p.stderr[-3000:]))
        for expected in args.expect:
            check(expected in p.stdout, "the output lacks %r" % expected)
        check(d.stop() == 0, "daemon exits 0 on SIGTERM")
        log("PASS")
        return 0
    finally:
        if d.alive():
            d.proc.kill()
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
