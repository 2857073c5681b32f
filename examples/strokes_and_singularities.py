#!/usr/bin/env python3
"""Strokes and placed singularities: the designer's tools in a design session.

On a sphere, a 4-field (cross field) is drawn with two strokes along great circles and given a
+1/4 and a -1/4 singularity at chosen vertices; the second stroke is then moved (one edit for
all its faces). The singularities of the result are listed (the placed ones among them, the index
sum the sphere's Euler characteristic) and the field is rendered to strokes.png.

    examples/strokes_and_singularities.py --server 127.0.0.1:50051 [--out-dir DIR]
"""

import argparse
import json
import os
import sys

import numpy as np

import fieldspace
from fieldspace import render


def icosphere(subdivisions):
    """(V, F) of the unit icosphere with 20 * 4^s faces."""
    t = (1 + 5 ** 0.5) / 2
    V = [(-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0), (0, -1, t), (0, 1, t), (0, -1, -t),
         (0, 1, -t), (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1)]
    V = [np.array(v, dtype=float) / np.linalg.norm(v) for v in V]
    F = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4),
         (11, 10, 2), (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8),
         (3, 8, 9), (4, 9, 5), (2, 4, 11), (6, 2, 10), (8, 6, 7), (9, 8, 1)]
    for _ in range(subdivisions):
        midpoint, out = {}, []

        def mid(a, b):
            key = (min(a, b), max(a, b))
            if key not in midpoint:
                m = V[a] + V[b]
                V.append(m / np.linalg.norm(m))
                midpoint[key] = len(V) - 1
            return midpoint[key]

        for a, b, c in F:
            ab, bc, ca = mid(a, b), mid(b, c), mid(c, a)
            out += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
        F = out
    return np.array(V), np.array(F, dtype=np.int32)


def great_circle(a, b, span, count):
    """`count` points from unit a towards b along their great circle, over `span` radians."""
    a = np.asarray(a, float) / np.linalg.norm(a)
    b = np.asarray(b, float) - np.dot(b, a) * a
    b /= np.linalg.norm(b)
    return [np.cos(t) * a + np.sin(t) * b for t in np.linspace(0.0, span, count)]


def nearest_vertex(V, p):
    return int(np.argmin(np.linalg.norm(V - np.asarray(p, float), axis=1)))


def main():
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--server", default=fieldspace.DEFAULT_ADDRESS)
    parser.add_argument("--dim", type=int, default=300, help="basis dimension")
    parser.add_argument("--out-dir", default="fieldspace-strokes")
    args = parser.parse_args()
    os.makedirs(args.out_dir, exist_ok=True)

    client = fieldspace.Client(args.server, timeout=600)
    V, F = icosphere(4)
    mesh = client.upload(V, F, name="icosphere-5k")
    basis = client.build(mesh.id, "nfield", args.dim, n=4)
    print("mesh %s: %d faces; basis %s (4-field, d = %d)" % (mesh.id, len(F), basis, args.dim))

    plus = nearest_vertex(V, (0.0, 0.0, 1.0))     # +1/4 at the north pole
    minus = nearest_vertex(V, (0.0, 0.0, -1.0))   # -1/4 at the south pole
    with client.design(basis, fieldspace.Weights(1.0, 0.0, 1.0)) as s:
        equator = s.stroke(great_circle((1, 0, 0), (0, 1, 0), 2.5, 6), weight=2.0)
        print("stroke along the equator: %d faces, %.2f ms"
              % (equator.num_constraints, equator.timings["edit_ms"]))
        meridian = s.stroke(great_circle((0, -1, 0.2), (0, 0.2, 1), 1.2, 4), weight=2.0)
        s.place_singularity(plus, 0.25, weight=10.0)
        s.place_singularity(minus, -0.25, weight=10.0)
        moved = s.stroke(great_circle((0, 1, 0.2), (0, -0.2, 1), 1.2, 4), weight=2.0,
                         id=meridian.constraint_id, move=True)
        print("moved the second stroke as one edit: %.2f ms, %d constraints"
              % (moved.timings["edit_ms"], moved.num_constraints))
        coefficients = s.coefficients

    sing = client.singularities(basis, coefficients=coefficients)
    placed = {int(v): float(t) for v, t in zip(sing.vertices, sing.turns)}
    print("singularities: %d, index sum %g = Euler characteristic %d"
          % (len(sing.vertices), sing.index_sum, sing.euler_characteristic))
    print("placed: vertex %d turns %s, vertex %d turns %s"
          % (plus, placed.get(plus), minus, placed.get(minus)))

    field = client.lift(basis, coefficients)  # (F, 4, 3): the cross at every face
    V, F = client.mesh_geometry(mesh.id)
    out_png = os.path.join(args.out_dir, "strokes.png")
    # render's defaults: the automatic view, the hatching style; the singularities as spheres.
    picture = render.render(V, F, field, "nfield", out=out_png, style="hatching",
                            singularities=sing)
    covered = float(np.mean(np.any(picture["image"] < 250, axis=2)))
    print(json.dumps({"faces": len(F), "picture_lines": picture["lines"],
                      "covered_fraction": round(covered, 3)}))
    print("wrote %s" % out_png)
    client.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
