"""Meshes made in code for the Python tests (numpy arrays V (nV, 3), F (nF, 3))."""

import math

import numpy as np


def icosphere(subdivisions, radius=1.0):
    """Icosphere with 20 * 4**s outward-oriented faces on a sphere of ``radius``."""
    t = (1.0 + math.sqrt(5.0)) / 2.0
    V = np.array([(-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0), (0, -1, t), (0, 1, t),
                  (0, -1, -t), (0, 1, -t), (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1)],
                 dtype=np.float64)
    F = np.array([(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9),
                  (5, 11, 4), (11, 10, 2), (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2),
                  (3, 2, 6), (3, 6, 8), (3, 8, 9), (4, 9, 5), (2, 4, 11), (6, 2, 10),
                  (8, 6, 7), (9, 8, 1)], dtype=np.int64)
    V /= np.linalg.norm(V, axis=1)[:, None]
    for _ in range(subdivisions):
        edges = np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
        unique, inverse = np.unique(edges, axis=0, return_inverse=True)
        inverse = inverse.reshape(-1)
        mid = V[unique[:, 0]] + V[unique[:, 1]]
        mid /= np.linalg.norm(mid, axis=1)[:, None]
        m = len(F)
        ab = len(V) + inverse[:m]
        bc = len(V) + inverse[m:2 * m]
        ca = len(V) + inverse[2 * m:]
        a, b, c = F[:, 0], F[:, 1], F[:, 2]
        F = np.concatenate([np.stack([a, ab, ca], 1), np.stack([b, bc, ab], 1),
                            np.stack([c, ca, bc], 1), np.stack([ab, bc, ca], 1)])
        V = np.vstack([V, mid])
    return V * radius, F


def torus(major=48, minor=24, R=1.0, r=0.4):
    """Closed torus around the z axis, 2 * major * minor faces, outward normals."""
    u = 2 * np.pi * np.arange(major) / major
    v = 2 * np.pi * np.arange(minor) / minor
    uu, vv = np.meshgrid(u, v, indexing="ij")
    V = np.stack([(R + r * np.cos(vv)) * np.cos(uu), (R + r * np.cos(vv)) * np.sin(uu),
                  r * np.sin(vv)], axis=-1).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(major), np.arange(minor), indexing="ij")

    def idx(a, b):
        return (a % major) * minor + (b % minor)

    a, b, c, d = idx(i, j), idx(i + 1, j), idx(i + 1, j + 1), idx(i, j + 1)
    F = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3),
                        np.stack([a, c, d], -1).reshape(-1, 3)])
    return V, F


def cylinder(around=32, along=16, radius=1.0, height=2.0):
    """Open cylinder (two boundary loops) around the z axis from z = 0 to ``height``, outward
    normals, 2 * around * along faces."""
    u = 2 * np.pi * np.arange(around) / around
    z = height * np.arange(along + 1) / along
    uu, zz = np.meshgrid(u, z, indexing="ij")
    V = np.stack([radius * np.cos(uu), radius * np.sin(uu), zz], axis=-1).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(around), np.arange(along), indexing="ij")

    def idx(a, b):
        return (a % around) * (along + 1) + b

    a, b, c, d = idx(i, j), idx(i + 1, j), idx(i + 1, j + 1), idx(i, j + 1)
    F = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3),
                        np.stack([a, c, d], -1).reshape(-1, 3)])
    return V, F


def centroids(V, F):
    return V[F].mean(axis=1)


def obj_text(V, F):
    lines = ["v %r %r %r" % tuple(map(float, p)) for p in V]
    lines += ["f %d %d %d" % tuple(int(i) + 1 for i in f) for f in F]
    return "\n".join(lines) + "\n"


def ellipsoid(semi_axes, subdivisions=4, up="z"):
    """An icosphere scaled to ``semi_axes`` (along x, y, z of a z-up scan). ``up="y"`` stores
    the same shape as a y-up scan would (x stays, the z-up scan's z becomes y and its y
    becomes -z: the rotation between the two conventions)."""
    V, F = icosphere(subdivisions)
    V = V * np.asarray(semi_axes, dtype=np.float64)
    if up == "y":
        V = np.stack([V[:, 0], V[:, 2], -V[:, 1]], axis=1)
    elif up != "z":
        raise ValueError("up is 'y' or 'z'")
    return V, F
