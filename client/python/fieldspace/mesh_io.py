"""Mesh files as numpy arrays, with the server's face order (core/mesh/mesh_io.cc).

:func:`read_mesh` reads OBJ, OFF and PLY (ASCII, binary little or big endian) into ``V``
``(nV, 3)`` float64 and ``F`` ``(nF, 3)`` int64. Polygons are fan-triangulated the way the server
does it (corners ``(c0, ck, ck+1)``), so face ``f`` here is face ``f`` of a field the server
returns for the same file. Unlike the server, unreferenced vertices are kept: they change vertex
numbers, never faces. Only the geometry is read; the server's checks (manifold, orientation)
are not repeated.
"""

import os
import re

import numpy as np


def _fan(polygons):
    faces = []
    for poly in polygons:
        if len(poly) < 3:
            raise ValueError("a face has fewer than 3 corners")
        for k in range(1, len(poly) - 1):
            faces.append((poly[0], poly[k], poly[k + 1]))
    return np.array(faces, dtype=np.int64).reshape(-1, 3)


def _read_obj(text):
    verts, polygons = [], []
    for number, line in enumerate(text.splitlines(), start=1):
        tokens = line.split("#", 1)[0].split()
        if not tokens:
            continue
        if tokens[0] == "v":
            verts.append([float(t) for t in tokens[1:4]])
        elif tokens[0] == "f":
            poly = []
            for t in tokens[1:]:
                i = int(t.split("/", 1)[0])
                if i == 0:
                    raise ValueError("line %d: OBJ indices start at 1" % number)
                poly.append(i - 1 if i > 0 else len(verts) + i)
            polygons.append(poly)
    return np.array(verts, dtype=np.float64).reshape(-1, 3), _fan(polygons)


def _read_off(text):
    lines = [ln.split("#", 1)[0].split() for ln in text.splitlines()]
    lines = [ln for ln in lines if ln]
    if not lines or lines[0][0] != "OFF":
        raise ValueError("an OFF file starts with OFF")
    head = lines[0][1:] if len(lines[0]) > 1 else lines[1]
    rest = lines[1:] if len(lines[0]) > 1 else lines[2:]
    nv, nf = int(head[0]), int(head[1])
    if len(rest) < nv + nf:
        raise ValueError("the OFF file has fewer lines than its counts say")
    V = np.array([[float(t) for t in ln[:3]] for ln in rest[:nv]], dtype=np.float64)
    # One face per line: the corner count, the corners, maybe a colour (ignored).
    polygons = [[int(t) for t in ln[1:1 + int(ln[0])]] for ln in rest[nv:nv + nf]]
    return V.reshape(-1, 3), _fan(polygons)


_PLY_TYPES = {"char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2",
              "int16": "i2", "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4",
              "uint": "u4", "uint32": "u4", "float": "f4", "float32": "f4", "double": "f8",
              "float64": "f8"}


def _read_ply(data):
    end = data.find(b"end_header")
    if not data.startswith(b"ply") or end < 0:
        raise ValueError("not a PLY file")
    body_start = data.index(b"\n", end) + 1
    header = data[:end].decode("ascii", errors="replace").splitlines()
    fmt, elements = None, []
    for line in header[1:]:
        t = line.split()
        if not t or t[0] in ("comment", "obj_info"):
            continue
        if t[0] == "format":
            fmt = t[1]
        elif t[0] == "element":
            elements.append((t[1], int(t[2]), []))
        elif t[0] == "property":
            if t[1] == "list":
                elements[-1][2].append((t[4], _PLY_TYPES[t[2]], _PLY_TYPES[t[3]]))
            else:
                elements[-1][2].append((t[2], _PLY_TYPES[t[1]], None))
    if fmt not in ("ascii", "binary_little_endian", "binary_big_endian"):
        raise ValueError("unknown PLY format %r" % fmt)
    V, polygons = None, None
    if fmt == "ascii":
        tokens = data[body_start:].split()
        pos = 0
        for name, count, props in elements:
            rows = []
            for _ in range(count):
                row = {}
                for pname, ptype, itype in props:
                    if itype is None:
                        row[pname] = float(tokens[pos])
                        pos += 1
                    else:
                        k = int(tokens[pos])
                        row[pname] = [int(x) for x in tokens[pos + 1:pos + 1 + k]]
                        pos += 1 + k
                rows.append(row)
            if name == "vertex":
                V = np.array([[r["x"], r["y"], r["z"]] for r in rows], dtype=np.float64)
            elif name == "face":
                key = "vertex_indices" if props and any(
                    p[0] == "vertex_indices" for p in props) else "vertex_index"
                polygons = [r[key] for r in rows]
    else:
        order = "<" if fmt == "binary_little_endian" else ">"
        pos = body_start
        for name, count, props in elements:
            if all(p[2] is None for p in props):
                dtype = np.dtype([(p[0], order + p[1]) for p in props])
                table = np.frombuffer(data, dtype=dtype, count=count, offset=pos)
                pos += dtype.itemsize * count
                if name == "vertex":
                    V = np.stack([table["x"], table["y"], table["z"]], axis=1).astype(np.float64)
                continue
            rows = []
            for _ in range(count):
                row = {}
                for pname, ptype, itype in props:
                    if itype is None:
                        size = np.dtype(ptype).itemsize
                        row[pname] = np.frombuffer(data, order + ptype, 1, pos)[0]
                        pos += size
                    else:
                        k = int(np.frombuffer(data, order + ptype, 1, pos)[0])
                        pos += np.dtype(ptype).itemsize
                        row[pname] = np.frombuffer(data, order + itype, k, pos).tolist()
                        pos += k * np.dtype(itype).itemsize
                rows.append(row)
            if name == "face":
                key = "vertex_indices" if "vertex_indices" in rows[0] else "vertex_index"
                polygons = [r[key] for r in rows] if rows else []
    if V is None or polygons is None:
        raise ValueError("a PLY mesh needs vertex and face elements")
    return V, _fan(polygons)


def read_mesh(path):
    """``(V, F)`` of an ``.obj``, ``.off`` or ``.ply`` file (see the module comment)."""
    ext = os.path.splitext(path)[1].lower()
    with open(path, "rb") as f:
        data = f.read()
    if ext == ".obj":
        V, F = _read_obj(data.decode("utf-8", errors="replace"))
    elif ext == ".off":
        V, F = _read_off(data.decode("utf-8", errors="replace"))
    elif ext == ".ply":
        V, F = _read_ply(data)
    else:
        raise ValueError("%s: mesh files are .obj, .off or .ply" % path)
    if len(F) and (F.min() < 0 or F.max() >= len(V)):
        raise ValueError("%s: a face refers to a vertex that does not exist" % path)
    return V, F


def load_mesh_and_field(mesh_path, field_path=None, kind=None, n=None, server=None,
                        token=None, tls=None):
    """``(V, F, field, kind)`` from a mesh file and a CLI field file (fieldspace.fields
    :func:`read_field_text`); ``field`` and ``kind`` are None when ``field_path`` is None.
    ``mesh_path`` may also be a mesh id (``m-`` and 16 hex digits) of the daemon at ``server``
    (with the bearer ``token`` and the Client's ``tls_*`` arguments in ``tls``, see
    :func:`tls_arguments`), whose geometry is then fetched."""
    from . import fields as fl

    if re.fullmatch(r"m-[0-9a-f]{16}", mesh_path) and not os.path.exists(mesh_path):
        from .client import Client

        with Client(server, token=token, **(tls or {})) as client:
            V, F = client.mesh_geometry(mesh_path)
    else:
        V, F = read_mesh(mesh_path)
    if field_path is None:
        return V, F, None, None
    text = fl.read_field_text(field_path)
    kind, n = fl.text_kind(text, kind, n)
    return V, F, fl.field_from_text(V, F, text, kind=kind, n=n), kind


def tls_arguments(args):
    """The Client's ``tls_*`` arguments from parsed --tls-* options (add_field_arguments)."""
    return {name: getattr(args, name) for name in ("tls_ca", "tls_cert", "tls_key",
                                                   "tls_server_name")
            if getattr(args, name) is not None}


def read_token(path):
    """The token in the file ``path`` (trimmed), or None without a path."""
    if path is None:
        return None
    with open(path, "r", encoding="utf-8") as f:
        return f.read().strip()


def add_field_arguments(parser):
    """The arguments the ``python3 -m fieldspace.<tool>`` commands share."""
    parser.add_argument("mesh", help="the mesh file (.obj, .off, .ply) the field lives on, or "
                        "the id (m-...) of a mesh on the server")
    parser.add_argument("--server", default=None,
                        help="HOST:PORT of fieldspaced for a mesh id (default $FIELDSPACE_SERVER "
                        "or 127.0.0.1:50051)")
    parser.add_argument("--token", default=None, help="a file holding the server's token")
    for flag, what in (("--tls-ca", "FILE: the CA of the server's TLS certificate"),
                       ("--tls-cert", "FILE: this client's TLS certificate (mutual TLS)"),
                       ("--tls-key", "FILE: this client's TLS key (mutual TLS)"),
                       ("--tls-server-name", "NAME: the name in the server's certificate")):
        parser.add_argument(flag, default=None, help=what + " (as the fieldspace CLI)")
    parser.add_argument("field", nargs="?", default=None,
                        help="a field file as the fieldspace CLI writes it (--out FILE.txt)")
    parser.add_argument("--kind", choices=("vector", "nfield", "tensor"),
                        help="field kind (default: the file's header)")
    parser.add_argument("--n", type=int, help="symmetry order of an n-field (default: header)")
