"""Meshes made in code for the reference scripts (pure Python, no numpy): the default suite needs
no mesh files. Vertices are [x, y, z] lists, faces zero-based [a, b, c] lists, outward oriented."""
import math
import random


def lat_long_sphere(rows=16, columns=32):
    """Unit sphere of `rows` latitude bands: quads split in two, fans at the poles (non-uniform)."""
    verts = [[0.0, 0.0, 1.0]]
    for i in range(1, rows):
        theta = math.pi * i / rows
        for j in range(columns):
            phi = 2 * math.pi * j / columns
            verts.append([math.sin(theta) * math.cos(phi), math.sin(theta) * math.sin(phi),
                          math.cos(theta)])
    verts.append([0.0, 0.0, -1.0])
    south = len(verts) - 1

    def ring(i, j):
        return 1 + (i - 1) * columns + j % columns

    faces = [[0, ring(1, j), ring(1, j + 1)] for j in range(columns)]
    for i in range(1, rows - 1):
        for j in range(columns):
            a, b, c, d = ring(i, j), ring(i + 1, j), ring(i + 1, j + 1), ring(i, j + 1)
            faces += [[a, b, c], [a, c, d]]
    faces += [[south, ring(rows - 1, j + 1), ring(rows - 1, j)] for j in range(columns)]
    return verts, faces


def torus(major=24, minor=12, stagger=False, R=1.0, r=0.4):
    """Torus of revolution; `stagger` turns odd rings by half a step, which makes the triangles
    obtuse once minor > 2 major r / (R - r)."""
    verts, faces = [], []
    for i in range(major):
        for j in range(minor):
            u = 2 * math.pi * (i + (0.5 * (j % 2) if stagger else 0.0)) / major
            v = 2 * math.pi * j / minor
            rho = R + r * math.cos(v)
            verts.append([rho * math.cos(u), rho * math.sin(u), r * math.sin(v)])

    def vid(i, j):
        return (i % major) * minor + j % minor

    for i in range(major):
        for j in range(minor):
            a, b, c, d = vid(i, j), vid(i + 1, j), vid(i + 1, j + 1), vid(i, j + 1)
            faces += [[a, b, d], [b, c, d]] if stagger and j % 2 == 0 else [[a, b, c], [a, c, d]]
    return verts, faces


def noisy(verts, amplitude, seed):
    """`verts` with each coordinate moved by a uniform offset in [-amplitude, amplitude]."""
    rng = random.Random(seed)
    return [[x + rng.uniform(-amplitude, amplitude) for x in v] for v in verts]


def mesh_text(path, verts, faces, crlf=False):
    """OBJ or OFF text (by the extension of `path`), coordinates exact (repr)."""
    eol = "\r\n" if crlf else "\n"
    if path.endswith(".off"):
        lines = ["OFF", f"{len(verts)} {len(faces)} 0"]
        lines += [f"{x!r} {y!r} {z!r}" for x, y, z in verts]
        lines += [f"3 {a} {b} {c}" for a, b, c in faces]
    else:
        lines = [f"v {x!r} {y!r} {z!r}" for x, y, z in verts]
        lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in faces]
    return eol.join(lines) + eol


def write_mesh(path, verts, faces, crlf=False):
    with open(path, "w", newline="") as f:
        f.write(mesh_text(path, verts, faces, crlf))
