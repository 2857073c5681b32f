"""Makes the pictures under docs/images with the project's own tools.

    /usr/bin/python3 docs/images/make_pictures.py [--bin-dir build/bin] [--out-dir docs/images]

knot_hatching.png: the demo mesh (fieldspace-bench's torus knot, 49k faces), a 2-field basis
(d = 400), the curvature-aligned 2-field of `fieldspace align --curvature --n 2`, drawn as
hatching strokes (paper Fig. 17) by fieldspace.render. A private daemon on a temporary store
serves the steps; nothing else is touched.
"""

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(os.path.dirname(HERE))
sys.path[:0] = [os.path.join(REPO, "client", "python"), os.path.join(REPO, "tests", "server")]

import numpy as np  # noqa: E402

import fs_testlib  # noqa: E402
from fieldspace import mesh_io, render  # noqa: E402


def main():
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--bin-dir", default=os.path.join(REPO, "build", "bin"))
    parser.add_argument("--out-dir", default=HERE)
    args = parser.parse_args()
    work = tempfile.mkdtemp(prefix="fieldspace-pictures-")
    try:
        knot = os.path.join(work, "knot.ply")
        subprocess.run([os.path.join(args.bin_dir, "fieldspace-bench"), "shape", "torus-knot",
                        "--out", knot], check=True, stdout=subprocess.DEVNULL)
        daemon = fs_testlib.Daemon(os.path.join(args.bin_dir, "fieldspaced"),
                                   os.path.join(work, "store")).start()
        try:
            cli = fs_testlib.Cli(os.path.join(args.bin_dir, "fieldspace"), daemon.address)
            mesh_id = json.loads(cli("upload", knot)[1])["id"]
            basis = json.loads(cli("build", mesh_id, "--field", "nfield", "--n", "2", "--dim",
                                   "400", timeout=1800)[1])["id"]
            aligned = os.path.join(work, "aligned.txt")
            cli("align", basis, "--curvature", "--n", "2", "--out", aligned)
        finally:
            daemon.stop()
            daemon.proc.stdout.close()
        V, F, field, kind = mesh_io.load_mesh_and_field(knot, aligned)
        diag = float(np.linalg.norm(np.ptp(V, axis=0)))
        out = os.path.join(args.out_dir, "knot_hatching.png")
        result = render.render(V, F, field, kind, out_png=out, style="streamlines",
                               size=(900, 560), streamline_count=6000,
                               streamline_length=0.012 * diag, line_width=1.0, colorize=False,
                               surface_color=(0.97, 0.95, 0.9), line_color=(0.1, 0.1, 0.15))
        print(json.dumps({"out": out, "faces": len(F), "strokes": result["lines"]}))
    finally:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
