#!/usr/bin/env python3
"""Runs README.md's install block and its Python example as written: `make install` into a
temporary prefix (against an already built tree), then the example with the installed package
against the installed `fieldspaced --demo` (as `make run` starts it, on a free port).

Exit 0 on success, 1 on failure.
"""

import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "server"))
from fs_testlib import Daemon, check, log  # noqa: E402

MARKER = "<!-- tested-by: tests/python/readme_python_test.py -->"


def blocks(readme):
    text = open(readme).read()
    out = []
    for part in text.split(MARKER)[1:]:
        m = re.match(r"\s*```(bash|python)\n(.*?)\n```", part, re.S)
        check(m is not None, "a ```bash or ```python block must follow the marker")
        out.append((m.group(1), m.group(2)))
    check([kind for kind, _ in out] == ["bash", "python"], "README: the install block, then the "
          "Python example")
    return out[0][1], out[1][1]


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--readme", required=True)
    parser.add_argument("--build-dir", required=True)
    parser.add_argument("--daemon", required=True, help="the build tree's fieldspaced")
    args = parser.parse_args()
    install_block, example = blocks(args.readme)
    repo = os.path.dirname(os.path.abspath(args.readme))
    work = tempfile.mkdtemp(prefix="fs_readme_python_")
    prefix = os.path.join(work, "prefix")
    daemons = []
    try:
        # The install block ends with a health check of a running daemon.
        d = Daemon(args.daemon, os.path.join(work, "store-build")).start()
        daemons.append(d)
        env = dict(os.environ, PREFIX=prefix, PORT=str(d.port),
                   BUILD_DIR=os.path.abspath(args.build_dir))
        script = install_block + '\necho "PYTHONPATH=$PYTHONPATH"\n'
        p = subprocess.run(["bash", "-euo", "pipefail", "-c", script], cwd=repo, env=env,
                           capture_output=True, text=True, timeout=900)
        check(p.returncode == 0, "install block failed (%d):\nstdout:\n%s\nstderr:\n%s" %
              (p.returncode, p.stdout[-3000:], p.stderr[-3000:]))
        check('"status":"SERVING"' in p.stdout, "the installed CLI's health check:\n" + p.stdout)
        pythonpath = p.stdout.strip().splitlines()[-1][len("PYTHONPATH="):]
        check(os.path.isfile(os.path.join(pythonpath, "fieldspace", "v1", "fieldspace_pb2.py")),
              "the generated stubs are installed below %s" % pythonpath)
        for program in ("fieldspaced", "fieldspace", "fieldspace-bench"):
            check(os.access(os.path.join(prefix, "bin", program), os.X_OK),
                  "%s is installed" % program)
        check(d.stop() == 0, "daemon exits 0 on SIGTERM")

        # The example, against the installed daemon with the demo.
        demo = Daemon(os.path.join(prefix, "bin", "fieldspaced"), os.path.join(work, "store"),
                      extra=["--demo"]).start()
        daemons.append(demo)
        path = os.path.join(work, "example.py")
        with open(path, "w") as f:
            f.write(example + "\n")
        env = dict(os.environ, FIELDSPACE_SERVER=demo.address, PYTHONPATH=pythonpath)
        p = subprocess.run(["/usr/bin/python3", path], cwd=work, env=env, capture_output=True,
                           text=True, timeout=600)
        log(p.stdout)
        check(p.returncode == 0, "the example failed (%d):\nstderr:\n%s" %
              (p.returncode, p.stderr[-3000:]))
        check("move answered in" in p.stdout, "the design session's move")
        check("refactorized: True" in p.stdout, "set_weights refactorizes")
        m = re.search(r"\(49152, 3\) index sum (\S+) = Euler characteristic (\S+)", p.stdout)
        check(m is not None, "the lifted field and its singularities")
        check(float(m.group(1)) == float(m.group(2)) == 0.0, "Poincare-Hopf on the torus knot")
        # The example asked for the demo's basis, not for a second one.
        p = subprocess.run([os.path.join(prefix, "bin", "fieldspace"), "--server", demo.address,
                            "bases"], stdout=subprocess.PIPE, text=True, timeout=60)
        bases = json.loads(p.stdout)["bases"]
        check(len(bases) == 1 and bases[0]["kernel_columns"] is False,
              "the example built a second basis beside the demo's: %s" % bases)
        check(demo.stop() == 0, "the installed daemon exits 0 on SIGTERM")
        log("PASS")
        return 0
    finally:
        for d in daemons:
            if d.alive():
                d.proc.kill()
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
