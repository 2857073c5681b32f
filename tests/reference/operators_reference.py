#!/usr/bin/python3
"""Independent reference for the field operators of docs/conventions.md, Operators.

Builds S and M for the vector Hodge Laplacian (eq. 1, from literal gradient matrices G_V, G_E),
the n-field connection Laplacian and the (1,1)-tensor Laplacian (appendix eqs. 14-20, from the
literal per-edge energy), straight from the written conventions with numpy/scipy, and compares
them entry by entry with what `fieldspace-bench operator` writes. It shares no code with the C++
implementation: only the mesh file and the convention text.

usage: operators_reference.py BENCH_BINARY [MESH_DIR]
Without MESH_DIR (the default suite) the meshes are made here: a latitude-longitude sphere
(non-uniform, fans at the poles), a noisy torus with a hole (a boundary loop) and a torus of
obtuse slivers, written as OBJ (CRLF) and OFF files. With MESH_DIR (the large-mesh check) the real
meshes of ../shared/meshes are used. Exit 0 on agreement, 1 on a mismatch, 77 when a shared mesh
is absent (ctest SKIP_RETURN_CODE).
"""
import math
import os
import subprocess
import sys
import tempfile

import numpy as np
import scipy.io
import scipy.sparse as sp

import made_meshes


def read_mesh(path):
    """Minimal OBJ/OFF reader for the triangle meshes used here (no unreferenced vertices)."""
    verts, faces = [], []
    with open(path, "r", encoding="utf-8", errors="replace") as f:
        text = f.read().replace("\r", "")
    if path.endswith(".obj"):
        for line in text.split("\n"):
            t = line.split()
            if not t:
                continue
            if t[0] == "v":
                verts.append([float(x) for x in t[1:4]])
            elif t[0] == "f":
                idx = [int(x.split("/")[0]) for x in t[1:]]
                idx = [i - 1 if i > 0 else len(verts) + i for i in idx]
                for k in range(1, len(idx) - 1):
                    faces.append([idx[0], idx[k], idx[k + 1]])
    elif path.endswith(".off"):
        tokens = []
        for line in text.split("\n"):
            line = line.split("#")[0]
            tokens.extend(line.split())
        assert tokens[0] == "OFF"
        nv, nf = int(tokens[1]), int(tokens[2])
        pos = 4
        for _ in range(nv):
            verts.append([float(x) for x in tokens[pos:pos + 3]])
            pos += 3
        for _ in range(nf):
            n = int(tokens[pos])
            idx = [int(x) for x in tokens[pos + 1:pos + 1 + n]]
            pos += 1 + n
            for k in range(1, n - 1):
                faces.append([idx[0], idx[k], idx[k + 1]])
    else:
        raise ValueError("unsupported mesh format: " + path)
    return np.array(verts, dtype=float), np.array(faces, dtype=np.int64)


def frames(V, F):
    p0, p1, p2 = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    cross = np.cross(p1 - p0, p2 - p0)
    area = 0.5 * np.linalg.norm(cross, axis=1)
    n = cross / np.linalg.norm(cross, axis=1)[:, None]
    x = (p1 - p0) / np.linalg.norm(p1 - p0, axis=1)[:, None]
    y = np.cross(n, x)
    return x, y, n, area


def edges_of(F):
    """Edge list (a < b) and, for every edge, its incident faces."""
    edge_index = {}
    edges, edge_faces = [], []
    face_edges = np.zeros(F.shape, dtype=np.int64)  # edge opposite corner k
    for f, tri in enumerate(F):
        for k in range(3):
            a, b = int(tri[(k + 1) % 3]), int(tri[(k + 2) % 3])
            key = (min(a, b), max(a, b))
            if key not in edge_index:
                edge_index[key] = len(edges)
                edges.append(key)
                edge_faces.append([])
            e = edge_index[key]
            edge_faces[e].append(f)
            face_edges[f, k] = e
    return edges, edge_faces, face_edges


def vector_hodge(V, F):
    nf, nv = len(F), len(V)
    x, y, n, area = frames(V, F)
    edges, edge_faces, face_edges = edges_of(F)
    ne = len(edges)
    rows_v, cols_v, vals_v = [], [], []
    rows_e, cols_e, vals_e = [], [], []
    for f in range(nf):
        p = V[F[f]]
        for k in range(3):
            # grad phi_k = n x (p_{k+2} - p_{k+1}) / (2 area): perpendicular to the opposite edge.
            g = np.cross(n[f], p[(k + 2) % 3] - p[(k + 1) % 3]) / (2 * area[f])
            gx, gy = g @ x[f], g @ y[f]
            rows_v += [2 * f, 2 * f + 1]
            cols_v += [F[f, k], F[f, k]]
            vals_v += [gx, gy]
            # Crouzeix-Raviart function of the edge opposite corner k: grad psi = -2 grad phi_k.
            rows_e += [2 * f, 2 * f + 1]
            cols_e += [face_edges[f, k], face_edges[f, k]]
            vals_e += [-2 * gx, -2 * gy]
    GV = sp.csr_matrix((vals_v, (rows_v, cols_v)), shape=(2 * nf, nv))
    GE = sp.csr_matrix((vals_e, (rows_e, cols_e)), shape=(2 * nf, ne))
    mass = np.repeat(area, 2)
    M = sp.diags(mass)
    mv = np.zeros(nv)
    for f in range(nf):
        mv[F[f]] += area[f] / 3
    me = np.zeros(ne)
    for e, fs in enumerate(edge_faces):
        me[e] = sum(area[f] for f in fs) / 3
    J = sp.block_diag([np.array([[0.0, -1.0], [1.0, 0.0]])] * nf, format="csr")
    S = M @ GV @ sp.diags(1 / mv) @ GV.T @ M + M @ J @ GE @ sp.diags(1 / me) @ GE.T @ J.T @ M
    return S.tocsr(), mass


def rot(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s], [s, c]])


def mandel_transport(G):
    """Eq. 18: P with P a = Mandel-Voigt(G^T A G) for A with Mandel-Voigt a."""
    g1, g2, g3, g4 = G[0, 0], G[0, 1], G[1, 0], G[1, 1]
    r2 = math.sqrt(2)
    return np.array([[g1 * g1, g3 * g3, r2 * g1 * g3],
                     [g2 * g2, g4 * g4, r2 * g2 * g4],
                     [r2 * g1 * g2, r2 * g3 * g4, g1 * g4 + g2 * g3]])


def connection(V, F, kind, nsym):
    """n-field or tensor Laplacian from the per-edge energy sum_e w_e |u_i - T_{j->i} u_j|^2."""
    nf = len(F)
    x, y, n, area = frames(V, F)
    edges, edge_faces, _ = edges_of(F)
    dof = 3 if kind == "tensor" else 2
    rows, cols, vals = [], [], []

    def add_block(bi, bj, B):
        for r in range(dof):
            for c in range(dof):
                rows.append(dof * bi + r)
                cols.append(dof * bj + c)
                vals.append(B[r, c])

    for e, fs in enumerate(edges_of(F)[1]):
        if len(fs) != 2:
            continue
        i, j = fs
        a, b = edges[e]
        ev = V[b] - V[a]
        length = np.linalg.norm(ev)
        u = ev / length
        th_i = math.atan2(u @ y[i], u @ x[i])
        th_j = math.atan2(u @ y[j], u @ x[j])
        w = 3 * length * length / (area[i] + area[j])
        if kind == "tensor":
            # R_f rotates frame-f coordinates to edge-aligned ones; transport j -> i is G^T A G
            # with G = R_j^T R_i.
            Ri, Rj = rot(-th_i), rot(-th_j)
            T = mandel_transport(Rj.T @ Ri)
        else:
            T = rot(nsym * (th_i - th_j))
        I = np.eye(dof)
        add_block(i, i, w * I)
        add_block(j, j, w * T.T @ T)
        add_block(i, j, -w * T)
        add_block(j, i, -w * T.T)
    S = sp.csr_matrix((vals, (rows, cols)), shape=(dof * nf, dof * nf))
    return S, np.repeat(area, dof)


def compare(name, A, B, tol):
    A = sp.csr_matrix(A)
    B = sp.csr_matrix(B)
    if A.shape != B.shape:
        print(f"{name}: shape {A.shape} != reference {B.shape}")
        return False
    diff = abs(A - B).max()
    scale = abs(B).max()
    ok = diff <= tol * scale
    print(f"{name}: max |diff| = {diff:.3e}, max |ref| = {scale:.3e} -> {'ok' if ok else 'MISMATCH'}")
    return ok


def generated_meshes(folder):
    """Writes the generated meshes into `folder`; returns their file names."""
    V, F = made_meshes.lat_long_sphere()
    made_meshes.write_mesh(os.path.join(folder, "lat_long_sphere.obj"), V, F, crlf=True)
    made_meshes.write_mesh(os.path.join(folder, "lat_long_sphere.off"), V, F)
    V, F = made_meshes.torus()
    V = made_meshes.noisy(V, 0.02, seed=7)  # a tenth of an edge
    made_meshes.write_mesh(os.path.join(folder, "chipped_torus.obj"), V, F[2:])  # a quad chipped off
    V, F = made_meshes.torus(major=12, minor=48, stagger=True)
    made_meshes.write_mesh(os.path.join(folder, "obtuse_torus.off"), V, F, crlf=True)
    return ["lat_long_sphere.obj", "lat_long_sphere.off", "chipped_torus.obj", "obtuse_torus.off"]


def main():
    bench = sys.argv[1]
    shared_dir = None
    if len(sys.argv) > 2:
        shared_dir = os.environ.get("FIELDSPACE_MESH_DIR") or sys.argv[2]
    with tempfile.TemporaryDirectory() as made:
        if shared_dir is None:
            generated_meshes(made)
            mesh_dir = made
            cases = [("lat_long_sphere.obj", "vector", 1), ("chipped_torus.obj", "vector", 1),
                     ("obtuse_torus.off", "vector", 1), ("lat_long_sphere.off", "nfield", 4),
                     ("chipped_torus.obj", "nfield", 1), ("obtuse_torus.off", "nfield", 3),
                     ("chipped_torus.obj", "tensor", 1), ("lat_long_sphere.obj", "tensor", 1),
                     ("obtuse_torus.off", "tensor", 1)]
        else:
            mesh_dir = shared_dir
            cases = [("sphere_1k.obj", "vector", 1), ("chipped_torus_1k.obj", "vector", 1),
                     ("bimba_1k.off", "nfield", 4), ("chipped_torus_1k.obj", "nfield", 1),
                     ("rocker_arm_1k.off", "nfield", 3), ("chipped_torus_1k.obj", "tensor", 1),
                     ("sphere_1k.obj", "tensor", 1)]
        return compare_cases(bench, mesh_dir, cases)


def compare_cases(bench, mesh_dir, cases):
    ok = True
    for mesh_name, kind, nsym in cases:
        path = os.path.join(mesh_dir, mesh_name)
        if not os.path.exists(path):
            print(f"skipping: {path} not found (set FIELDSPACE_MESH_DIR)")
            return 77
        V, F = read_mesh(path)
        with tempfile.TemporaryDirectory() as out:
            cmd = [bench, "operator", path, "--field", kind, "--out", out]
            if kind == "nfield":
                cmd += ["--n", str(nsym)]
            res = subprocess.run(cmd, capture_output=True, text=True)
            if res.returncode != 0:
                print(f"{' '.join(cmd)} failed: {res.stderr}")
                return 1
            S = scipy.io.mmread(os.path.join(out, "S.mtx"))
            M = scipy.io.mmread(os.path.join(out, "M.mtx"))
        if kind == "vector":
            S_ref, mass = vector_hodge(V, F)
        else:
            S_ref, mass = connection(V, F, kind, nsym)
        label = f"{mesh_name} {kind}{nsym if kind == 'nfield' else ''}"
        ok &= compare(label + " S", S, S_ref, 1e-10)
        ok &= compare(label + " M", M, sp.diags(mass), 1e-12)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
