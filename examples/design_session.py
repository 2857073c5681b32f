#!/usr/bin/env python3
"""An interactive design session with the fieldspace Python package.

Adds, moves and removes constraints on a vector field; every edit is answered by the server in
milliseconds with the new solution. Then checks the session's answer against a one-shot Solve
of the same constraints, lifts the field and counts its singularities.

Uses the demo mesh and its vector basis (d = 1000) when the server has them (`make run` starts
`fieldspaced --demo`), otherwise uploads a torus made here and builds a basis for it.

    examples/design_session.py --server 127.0.0.1:50051
"""

import argparse
import math
import sys

import numpy as np

import fieldspace


def torus(major=96, minor=32, R=1.0, r=0.4):
    """(V, F) of a closed torus with 2 * major * minor faces."""
    u = 2 * np.pi * np.arange(major) / major
    v = 2 * np.pi * np.arange(minor) / minor
    U, W = np.meshgrid(u, v, indexing="ij")
    V = np.stack([(R + r * np.cos(W)) * np.cos(U), (R + r * np.cos(W)) * np.sin(U),
                  r * np.sin(W)], axis=-1).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(major), np.arange(minor), indexing="ij")
    a, b = i * minor + j, ((i + 1) % major) * minor + j
    c, d = ((i + 1) % major) * minor + (j + 1) % minor, i * minor + (j + 1) % minor
    F = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3),
                        np.stack([a, c, d], -1).reshape(-1, 3)])
    return V, F.astype(np.int32)


def edge_direction(V, F, face):
    """A unit tangent vector of a face (its first edge)."""
    e = V[F[face, 1]] - V[F[face, 0]]
    return e / np.linalg.norm(e)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--server", default="127.0.0.1:50051", help="HOST:PORT of fieldspaced")
    parser.add_argument("--token", help="a file with the server's token, if it needs one")
    parser.add_argument("--dim", type=int, default=300, help="basis dimension for the torus")
    args = parser.parse_args()
    token = open(args.token).read() if args.token else None
    client = fieldspace.Client(args.server, token=token, timeout=60)

    demo = [m for m in client.meshes() if m.name == "demo-torus-knot"]
    if demo:
        # The demo's basis, asked for with the settings of --demo (d = 1000, no kernel columns):
        # built already, or joined while it builds; other settings would build a second basis.
        mesh, dim, kernel_columns = demo[0], 1000, False
    else:
        mesh, dim, kernel_columns = client.upload(*torus(), name="torus"), args.dim, True
    print("mesh %s: %d faces, genus %d" % (mesh.id, mesh.num_faces, mesh.genus))
    basis = client.build(mesh.id, "vector", dim, kernel_columns=kernel_columns)
    print("basis %s (vector, d = %d)" % (basis, dim))

    V, F = client.mesh_geometry(mesh.id)
    a, b, c = 0, len(F) // 3, (2 * len(F)) // 3
    with client.design(basis, fieldspace.Weights(mu_s=1.0, mu_b=0.0, mu_c=1.0),
                       watch=[a, b, c]) as session:
        def show(update):
            t = update.timings
            print("  %-7s constraints %d  edit %6.2f ms  round trip %6.2f ms%s" % (
                update.edit, update.num_constraints, t["edit_ms"], t["round_trip_ms"],
                "  (refactorized)" if update.refactorized else ""))
        show(session.last)  # the open
        first = session.add(a, edge_direction(V, F, a), weight=2.0)
        show(first)
        show(session.add(b, edge_direction(V, F, b), hard=True))
        show(session.move(first.constraint_id, c, -edge_direction(V, F, c)))
        extra = session.add(a, edge_direction(V, F, a))
        show(extra)
        show(session.remove(extra.constraint_id))
        show(session.set_weights(mu_b=0.001))
        coefficients = session.coefficients
        watched = session.last.watched

    # The same constraints in one Solve call give the same field.
    solved = client.solve(basis, [c, b], [-edge_direction(V, F, c), edge_direction(V, F, b)],
                          weights=(1.0, 0.001, 1.0), constraint_weights=[2.0, 1.0],
                          hard=[False, True])
    difference = np.linalg.norm(coefficients - solved.coefficients) / np.linalg.norm(
        solved.coefficients)
    print("session vs Solve: relative difference %.1e" % difference)

    field = client.lift(basis, coefficients)  # (F, 3) ambient vectors
    cos_b = np.dot(field[b], edge_direction(V, F, b)) / np.linalg.norm(field[b])
    print("lifted field %s; the hard constraint's face points along its target (cos %.6f)" %
          (field.shape, cos_b))
    print("watched faces %s: |X| = %s" % (
        [a, b, c], ", ".join("%.3g" % x for x in np.linalg.norm(watched, axis=1))))
    sing = client.singularities(basis, coefficients=coefficients)
    print("singularities: %d, index sum %g = Euler characteristic %d" % (
        len(sing.vertices), sing.index_sum, sing.euler_characteristic))
    ok = (difference < 1e-6 and cos_b > 0.999 and
          math.isclose(sing.index_sum, sing.euler_characteristic))
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
