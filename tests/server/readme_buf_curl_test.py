#!/usr/bin/env python3
"""Runs the shell blocks tagged with this test as written against a live fieldspaced, and checks
what they print: README.md's CLI block (a design script with a stroke and a placed singularity),
docs/cli.md's tour of every command and docs/api.md's buf curl block.

Exit 0 on success, 1 on failure, 77 (skip) when npx cannot provide buf (no node / no registry).
"""

import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from fs_testlib import Daemon, check, icosphere_obj, log  # noqa: E402

MARKER = "<!-- tested-by: tests/server/readme_buf_curl_test.py -->"


def blocks(readme):
    """The tagged blocks of README.md, docs/cli.md and docs/api.md, in that order."""
    docs = os.path.join(os.path.dirname(os.path.abspath(readme)), "docs")
    out = []
    for path in (readme, os.path.join(docs, "cli.md"), os.path.join(docs, "api.md")):
        for part in open(path).read().split(MARKER)[1:]:
            m = re.match(r"\s*```bash\n(.*?)\n```", part, re.S)
            check(m is not None, "%s: a ```bash block must follow the marker" % path)
            out.append(m.group(1))
    return out


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--daemon", required=True)
    parser.add_argument("--client", required=True)
    parser.add_argument("--readme", required=True)
    args = parser.parse_args()
    readme_block, cli_block, buf_block = blocks(args.readme)
    check("fieldspace --server" in readme_block and "fieldspace --server" in cli_block and
          "buf curl" in buf_block, "block order")

    npx = shutil.which("npx")
    if npx is None:
        print("SKIP: npx (nodejs) is not installed")
        return 77
    probe = subprocess.run([npx, "--yes", "@bufbuild/buf", "--version"], capture_output=True,
                           text=True, timeout=300)
    if probe.returncode != 0:
        print("SKIP: npx could not provide @bufbuild/buf: %s" % probe.stderr[-500:])
        return 77

    work = tempfile.mkdtemp(prefix="fs_readme_")
    # The blocks expect ../shared/meshes/sphere_1k.obj; without it, an identical icosphere.
    repo = os.path.dirname(os.path.abspath(args.readme))
    meshes = os.path.join(repo, "..", "shared", "meshes")
    if not os.path.exists(os.path.join(meshes, "sphere_1k.obj")):
        meshes = os.path.join(work, "meshes")
        os.makedirs(meshes)
        text, faces = icosphere_obj(3)
        assert faces == 1280
        with open(os.path.join(meshes, "sphere_1k.obj"), "w") as f:
            f.write(text)
    # As `make run` starts it: the demo mesh (its basis building in the background) and the data
    # root. The buf curl block runs first, so that it cannot lean on anything the CLI block made.
    d = Daemon(args.daemon, os.path.join(work, "store"), meshes, extra=["--demo"]).start()
    try:
        env = dict(os.environ)
        env["PORT"] = str(d.port)
        env["MESHES"] = os.path.abspath(meshes)
        env["PATH"] = os.path.dirname(os.path.abspath(args.client)) + os.pathsep + env["PATH"]
        outputs = []
        for block in (buf_block, readme_block, cli_block):
            p = subprocess.run(["bash", "-euo", "pipefail", "-c", block], cwd=repo, env=env,
                               capture_output=True, text=True, timeout=600)
            check(p.returncode == 0, "block failed (%d):\n%s\nstdout:\n%s\nstderr:\n%s" %
                  (p.returncode, block, p.stdout[-3000:], p.stderr[-3000:]))
            outputs.append(p.stdout)
        buf_out, readme_out, cli_out = outputs
        # README's block: open, the add, the stroke, the placed singularity and its removal.
        readme_lines = [l for l in readme_out.splitlines() if l.startswith('{"seq":')]
        check([json.loads(l)["edit"] for l in readme_lines] ==
              ["open", "add", "stroke", "singularity", "remove"],
              "README's design script: open + 4 updates:\n%s" % readme_out[-3000:])
        check(all(json.loads(l)["num_constraints"] > 0 for l in readme_lines[1:]),
              "README's design script keeps its constraints:\n%s" % readme_out[-3000:])
        for expected in ('{"status":"SERVING"}', '"relative_error":', '"eigenvalues":',
                         '"edit":"weights"', '"refactorized":true', '"field":"nfield4"'):
            check(expected in cli_out, "CLI block output lacks %s:\n%s" % (expected, cli_out[-3000:]))
        for expected in ('"euler_characteristic":2', '"index_sum":2', '"k_min":',
                         '"factorize_ms":'):
            check(expected in cli_out, "CLI block output lacks %s:\n%s" % (expected, cli_out[-3000:]))
        design_lines = [l for l in cli_out.splitlines() if l.startswith('{"seq":')]
        check(len(design_lines) == 10 + 3,
              "the tour's two design runs printed open + 9 and open + 2 updates, not %d" %
              len(design_lines))
        # The session aligned to curvature: its weights edit (mu_a) refactorizes.
        check('"edit":"weights"' in design_lines[-1] and '"refactorized":true' in design_lines[-1],
              "a new mu_a refactorizes: %s" % design_lines[-1])
        for expected in ("fieldspace.v1.FieldSpace", "grpc.health.v1.Health", '"SERVING"',
                         '"numFaces": 1280', "BUILD_PHASE_DONE", '"relativeError"',
                         '"seq": "3"'):
            check(expected in buf_out, "buf block output lacks %s:\n%s" % (expected, buf_out[-3000:]))
        check(d.stop() == 0, "daemon exits 0 on SIGTERM")
        log("PASS")
        return 0
    finally:
        if d.alive():
            d.proc.kill()
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
