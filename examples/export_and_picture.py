#!/usr/bin/env python3
"""Hatching along curvature (paper Fig. 17), exported for other tools and drawn as a picture.

Uploads a mesh, builds a 2-field (line field) basis, aligns a smooth line field to the maximum
principal curvature direction (`Align`), lifts it, and writes into --out-dir:

    field.vtu        the mesh with both directions of the line field per face (ParaView, meshio)
    field.rawfield   the same in Directional's format, field.sing its singularities
    hatching.vtk     the hatching strokes traced on the field, as VTK polylines
    hatching.png     the picture (VTK, off screen: no GPU or display needed): render's hatching
                     style with its defaults, singular vertices as spheres

The mesh is --mesh (an .obj/.off/.ply file; default the shared fertility_28k.obj next to the
checkout when it exists) or else a torus made here. The README's picture is this example's
output on fertility_28k.

    examples/export_and_picture.py --server 127.0.0.1:50051 --out-dir /tmp/hatching
"""

import argparse
import json
import os
import sys

import numpy as np

import fieldspace
from fieldspace import export, render, streamlines

from design_session import torus  # the same torus as the design session example

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DEFAULT_MESH = os.path.join(REPO, "..", "shared", "meshes", "fertility_28k.obj")


def main():
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--server", default=fieldspace.DEFAULT_ADDRESS)
    parser.add_argument("--mesh", default=None,
                        help="a mesh file, or 'torus' for one made here (default: see above)")
    parser.add_argument("--dim", type=int, default=400, help="basis dimension")
    parser.add_argument("--out-dir", default="fieldspace-hatching")
    parser.add_argument("--size", default="900x600", help="picture size WxH")
    args = parser.parse_args()
    width, height = (int(x) for x in args.size.split("x"))
    os.makedirs(args.out_dir, exist_ok=True)
    out = lambda name: os.path.join(args.out_dir, name)  # noqa: E731

    client = fieldspace.Client(args.server, timeout=600)
    path = args.mesh or (DEFAULT_MESH if os.path.exists(DEFAULT_MESH) else "torus")
    path = None if path == "torus" else path
    mesh = client.upload(path) if path else client.upload(*torus(120, 40, 1.0, 0.45), name="torus")
    V, F = client.mesh_geometry(mesh.id)
    print("mesh %s: %d faces, genus %d" % (mesh.id, len(F), mesh.genus))

    basis = client.build(mesh.id, "nfield", args.dim, n=2)
    aligned = client.align(basis, return_field=True)  # (F, 2, 3): both directions of each line
    lines_field = aligned.field
    sing = client.singularities(basis, coefficients=aligned.coefficients)
    print("aligned line field: %d singular vertices, index sum %g = Euler characteristic %d"
          % (len(sing.vertices), sing.index_sum, sing.euler_characteristic))

    export.write_vtu(out("field.vtu"), V, F, lines_field, kind="nfield", name="lines")
    export.write_rawfield(out("field.rawfield"), lines_field, n=2)
    export.write_sing(out("field.sing"), list(zip(sing.vertices, sing.index)), n=2)
    diag = float(np.linalg.norm(np.ptp(V, axis=0)))
    strokes = streamlines.hatching(V, F, lines_field, kind="nfield", count=4000,
                                   stroke_length=0.03 * diag)
    export.write_polylines_vtk(out("hatching.vtk"), strokes.lines)
    # The picture with render's defaults for hatching (automatic view, plain paper, strokes),
    # and the singular vertices as spheres (red: positive index, blue: negative).
    picture = render.render(V, F, lines_field, "nfield", out=out("hatching.png"),
                            style="hatching", size=(width, height), singularities=sing)
    covered = float(np.mean(np.any(picture["image"] < 250, axis=2)))
    print(json.dumps({"faces": len(F), "strokes": len(strokes.lines),
                      "picture_lines": picture["lines"],
                      "picture_singularities": picture["singularities"],
                      "covered_fraction": round(covered, 3),
                      "files": sorted(os.listdir(args.out_dir))}))
    print("wrote field.vtu, field.rawfield, field.sing, hatching.vtk and hatching.png to %s"
          % args.out_dir)
    client.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
