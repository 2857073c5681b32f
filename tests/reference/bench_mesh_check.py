#!/usr/bin/python3
"""Acceptance check of `fieldspace-bench mesh` (issue: foundation).

Without MESH_DIR (the default suite): feeds corrupt inputs (truncations, garbage, absurd header
counts, NaN, out-of-range indices, non-manifold meshes), each of which must give exit status 2
with a one-line message on stderr, never a signal or a hang, and checks the genus of the
procedural shapes and of meshes written here (OBJ with CRLF, OFF).

With MESH_DIR (a large-mesh check): runs the real binary on every mesh of the shared catalogue
and compares vertices, faces and genus with the catalogue's own README table, and checks that
teapot_6k.obj is rejected as non-manifold.

usage: bench_mesh_check.py BENCH_BINARY [MESH_DIR]  (exit 0 ok, 1 failure, 77 meshes absent)
"""
import json
import os
import random
import re
import subprocess
import sys
import tempfile

import made_meshes

EXPECTED_KEYS = ["vertices", "faces", "edges", "boundary_loops", "components",
                 "euler_characteristic", "genus", "area", "manifold",
                 "dropped_unreferenced_vertices"]


def run(bench, path, timeout=60):
    return subprocess.run([bench, "mesh", path], capture_output=True, text=True, timeout=timeout)


def catalogue(mesh_dir):
    """Rows of the README table: name -> (V, F, genus or None, closed)."""
    rows = {}
    with open(os.path.join(mesh_dir, "README.md"), encoding="utf-8") as f:
        for line in f:
            cells = [c.strip() for c in line.strip().strip("|").split("|")]
            if len(cells) < 4 or not re.match(r"^[\w.]+\.(obj|off|ply)$", cells[0]):
                continue
            v = int(cells[1].replace(",", ""))
            fcount = int(cells[2].replace(",", ""))
            m = re.search(r"genus (\d+)", cells[3])
            rows[cells[0]] = (v, fcount, int(m.group(1)) if m else None, cells[3])
    return rows


def check_catalogue(bench, mesh_dir, failures):
    """Every mesh of the shared catalogue against its README row."""
    rows = catalogue(mesh_dir)
    if len(rows) < 20:
        failures.append(f"catalogue table parsed only {len(rows)} rows")
    for name, (v, fcount, genus, topology) in sorted(rows.items()):
        path = os.path.join(mesh_dir, name)
        res = run(bench, path)
        if name == "teapot_6k.obj":
            if res.returncode != 2 or "non-manifold" not in res.stderr:
                failures.append(f"{name}: expected exit 2 naming non-manifold, got "
                                f"{res.returncode}: {res.stderr.strip()}")
            continue
        if res.returncode != 0:
            failures.append(f"{name}: exit {res.returncode}: {res.stderr.strip()}")
            continue
        out = json.loads(res.stdout)
        if list(out.keys()) != EXPECTED_KEYS:
            failures.append(f"{name}: keys {list(out.keys())}")
        if out["vertices"] != v or out["faces"] != fcount:
            failures.append(f"{name}: V/F {out['vertices']}/{out['faces']} != {v}/{fcount}")
        if genus is not None and out["genus"] != genus:
            failures.append(f"{name}: genus {out['genus']} != {genus}")
        if "closed" in topology and out["boundary_loops"] != 0:
            failures.append(f"{name}: closed mesh reports {out['boundary_loops']} boundary loops")
        chi = out["vertices"] - out["edges"] + out["faces"]
        if chi != out["euler_characteristic"] or out["manifold"] is not True:
            failures.append(f"{name}: inconsistent chi or manifold flag: {out}")
        print(f"ok {name}: {res.stdout.strip()}")


def check_inputs(bench, failures):
    """Corrupt and non-manifold inputs (each a clean exit 2), procedural shapes and written
    meshes (their genus), all made here."""
    rng = random.Random(7)
    with tempfile.TemporaryDirectory() as tmp:
        # Written meshes have their topology: OBJ with CRLF, OFF, a hole, obtuse triangles.
        sphere_v, sphere_f = made_meshes.lat_long_sphere()
        torus_v, torus_f = made_meshes.torus()
        torus_v = made_meshes.noisy(torus_v, 0.02, seed=3)
        obtuse_v, obtuse_f = made_meshes.torus(major=12, minor=48, stagger=True)
        written = [("sphere.obj", sphere_v, sphere_f, True, 0, 0),
                   ("chipped_torus.off", torus_v, torus_f[2:], False, 1, 1),
                   ("obtuse_torus.obj", obtuse_v, obtuse_f, True, 1, 0)]
        for name, verts, faces, crlf, genus, loops in written:
            path = os.path.join(tmp, name)
            made_meshes.write_mesh(path, verts, faces, crlf)
            res = run(bench, path)
            out = json.loads(res.stdout) if res.returncode == 0 else {}
            if (out.get("genus"), out.get("boundary_loops"), out.get("faces")) != (genus, loops,
                                                                                  len(faces)):
                failures.append(f"written {name}: {res.stdout}{res.stderr}")
            else:
                print(f"ok written {name}: {res.stdout.strip()}")

        # Procedural shapes (the demo mesh among them) have the genus they are built with.
        for shape, genus in [("torus-knot", 1), ("icosphere", 0), ("torus", 1), ("genus2", 2)]:
            out = os.path.join(tmp, shape + ".ply")
            made = subprocess.run([bench, "shape", shape, "--out", out], capture_output=True,
                                  text=True, timeout=60)
            res = run(bench, out)
            if made.returncode != 0 or res.returncode != 0 or json.loads(res.stdout)["genus"] != genus:
                failures.append(f"shape {shape}: {made.stderr}{res.stdout}{res.stderr}")
            else:
                print(f"ok shape {shape}: {res.stdout.strip()}")

        # Corrupt inputs: each must be a clean exit 2.
        cases = {}
        obj = made_meshes.mesh_text("s.obj", sphere_v, sphere_f, crlf=True).encode()
        off = made_meshes.mesh_text("t.off", torus_v, torus_f).encode()
        with open(os.path.join(tmp, "torus-knot.ply"), "rb") as f:
            ply_head = f.read(1 << 16)  # of about 1 MB of binary data
        cases["truncated.ply"] = ply_head
        cases["absurd_count.ply"] = (b"ply\nformat binary_little_endian 1.0\n"
                                     b"element vertex 999999999999\nproperty float x\n"
                                     b"property float y\nproperty float z\n"
                                     b"element face 3\nproperty list uchar int vertex_indices\n"
                                     b"end_header\n" + bytes(200))
        cases["garbage.ply"] = b"ply\n" + bytes(rng.getrandbits(8) for _ in range(4096))
        cases["garbage.obj"] = bytes(rng.getrandbits(8) for _ in range(4096))
        cases["truncated.off"] = off[: len(off) // 2]
        cases["absurd_count.off"] = b"OFF\n2000000000 2000000000 0\n0 0 0\n"
        cases["nan.obj"] = b"v 0 0 0\nv 1 0 0\nv nan 1 0\nf 1 2 3\n"
        cases["out_of_range.obj"] = b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n"
        cases["zero_area.obj"] = b"v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n"
        cases["empty.obj"] = b""
        cases["two_corner_face.obj"] = b"v 0 0 0\nv 1 0 0\nf 1 2\n"
        # Two spheres touching at the north pole (vertex 0): the second is the first reflected
        # through z = 1, with its pole replaced by the first's. A non-manifold vertex.
        n = len(sphere_v)
        mirrored = [[x, y, 2.0 - z] for x, y, z in sphere_v]
        glued = [[0 if i == 0 else i + n for i in (a, c, b)] for a, b, c in sphere_f]
        cases["non_manifold_vertex.obj"] = made_meshes.mesh_text(
            "x.obj", sphere_v + mirrored, sphere_f + glued).encode()
        # A fin: a third face on the edge of face 40's first two corners.
        a, b = torus_f[40][0], torus_f[40][1]
        fin_v = torus_v + [[0.0, 0.0, 3.0]]
        cases["non_manifold_edge.off"] = made_meshes.mesh_text(
            "x.off", fin_v, torus_f + [[a, b, len(torus_v)]]).encode()
        for i in range(8):
            cut = rng.randrange(1, len(obj))
            cases[f"cut{i}.obj"] = obj[:cut] + bytes(rng.getrandbits(8) for _ in range(16))
        cases["unknown.xyz"] = obj
        for name, data in cases.items():
            path = os.path.join(tmp, name)
            with open(path, "wb") as f:
                f.write(data)
            try:
                res = run(bench, path, timeout=30)
            except subprocess.TimeoutExpired:
                failures.append(f"corrupt {name}: hang")
                continue
            lines = res.stderr.strip().split("\n")
            if name.startswith("cut") and res.returncode == 0:
                print(f"ok corrupt {name}: still a valid mesh after truncation")
                continue
            if res.returncode != 2 or len(lines) != 1 or not lines[0]:
                failures.append(f"corrupt {name}: exit {res.returncode}, stderr {res.stderr!r}")
            elif name.startswith("non_manifold") and "non-manifold" not in lines[0]:
                failures.append(f"corrupt {name}: the message does not say non-manifold: {lines[0]}")
            else:
                print(f"ok corrupt {name}: {lines[0]}")
        res = run(bench, os.path.join(tmp, "does_not_exist.obj"))
        if res.returncode != 2:
            failures.append(f"missing file: exit {res.returncode}")


def main():
    bench = sys.argv[1]
    failures = []
    if len(sys.argv) > 2:
        mesh_dir = os.environ.get("FIELDSPACE_MESH_DIR") or sys.argv[2]
        if not os.path.exists(os.path.join(mesh_dir, "README.md")):
            print(f"skipping: no mesh catalogue in {mesh_dir} (set FIELDSPACE_MESH_DIR)")
            return 77
        check_catalogue(bench, mesh_dir, failures)
    else:
        check_inputs(bench, failures)
    for f in failures:
        print("FAIL", f)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
