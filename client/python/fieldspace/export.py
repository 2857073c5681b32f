"""Viewer-ready exports of meshes with per-face fields, and of polylines (docs/exports.md).

- :func:`write_vtu`: VTK XML UnstructuredGrid (ParaView, VisIt, meshio), ASCII or inline base64.
- :func:`write_vtk`: legacy VTK UnstructuredGrid, ASCII.
- :func:`write_ply_ascii`: ASCII PLY with the field as face properties (MeshLab, meshio).
- :func:`write_rawfield`, :func:`write_sing`: Directional's ``.rawfield`` and ``.sing`` files.
- :func:`write_polylines_vtk`, :func:`write_polylines_obj`: streamlines / hatching strokes.

Field arrays follow fieldspace.fields: vectors ``(F, 3)``, n-fields ``(F, n, 3)``, tensors
``(F, 3, 3)``; :func:`field_arrays` says which per-face arrays each kind becomes.
"""

import argparse
import base64
import json
import os
import sys
from xml.sax.saxutils import quoteattr

import numpy as np

from . import fields as fl

_VTK_TRIANGLE = 5


def field_arrays(V, F, field, kind=None, name="field"):
    """The per-face arrays an export holds for ``field``, in order: a dict name -> ``(F,)`` or
    ``(F, k)`` float64 array.

    - vector: ``name`` ``(F, 3)`` and ``name_magnitude``;
    - n-field: ``name_dir0`` .. ``name_dir{n-1}`` ``(F, 3)`` (all n directions, direction k
      turned by ``2 pi k / n`` from direction 0) and ``name_magnitude``;
    - tensor: ``name`` ``(F, 9)`` (the 3x3 matrix row-major), ``name_principal_values`` ``(F, 2)``
      (max, min), ``name_principal_max`` and ``name_principal_min`` ``(F, 3)`` unit principal
      directions (``min = n_f x max``), ``name_norm`` (Frobenius).
    """
    _check_name(name)
    V, F = fl.as_mesh(V, F)
    a, kind, n = fl.check_field(V, F, field, kind)
    out = {}
    if kind == fl.VECTOR:
        out[name] = a
        out[name + "_magnitude"] = np.linalg.norm(a, axis=1)
    elif kind == fl.NFIELD:
        for k in range(n):
            out["%s_dir%d" % (name, k)] = a[:, k, :]
        out[name + "_magnitude"] = np.linalg.norm(a[:, 0, :], axis=1)
    else:
        values, directions = fl.principal(V, F, a)
        out[name] = a.reshape(len(a), 9)
        out[name + "_principal_values"] = values
        out[name + "_principal_max"] = directions[:, 0, :]
        out[name + "_principal_min"] = directions[:, 1, :]
        out[name + "_norm"] = np.sqrt(np.sum(a * a, axis=(1, 2)))
    return out


def _check_name(name):
    if not name or any(c.isspace() for c in name) or any(c in name for c in "<>&\"'"):
        raise ValueError("array names must be non-empty, without spaces or <>&\"', got %r"
                         % (name,))


def _cell_arrays(V, F, field, kind, name, cell_data):
    arrays = {} if field is None else field_arrays(V, F, field, kind, name)
    for key, value in (cell_data or {}).items():
        _check_name(key)
        if key in arrays:
            raise ValueError("cell_data name %r clashes with a field array" % key)
        value = np.asarray(value, dtype=np.float64)
        if value.shape[0] != len(F):
            raise ValueError("cell_data %r has %d rows, the mesh %d faces"
                             % (key, value.shape[0], len(F)))
        arrays[key] = value.reshape(len(F), -1) if value.ndim > 2 else value
    return arrays


def _components(a):
    return 1 if a.ndim == 1 else a.shape[1]


# ---------------------------------------------------------------------------------------------
# VTK XML UnstructuredGrid


def _xml_array(out, name, a, vtk_type, binary, indent):
    a = np.ascontiguousarray(a)
    attrs = 'type="%s" Name=%s' % (vtk_type, quoteattr(name))
    if a.ndim > 1:
        attrs += ' NumberOfComponents="%d"' % a.shape[1]
    encoding = "binary" if binary else "ascii"
    out.append('%s<DataArray %s format="%s">\n' % (indent, attrs, encoding))
    if binary:
        little = a.astype(a.dtype.newbyteorder("<"), copy=False)
        data = little.tobytes()
        # VTK's layout: the UInt64 byte count and the data, base64-encoded separately.
        out.append(base64.b64encode(np.array([len(data)], dtype="<u8").tobytes()).decode())
        out.append(base64.b64encode(data).decode())
        out.append("\n")
    else:
        flat = a.reshape(-1)
        if np.issubdtype(a.dtype, np.floating):
            text = " ".join(repr(float(v)) for v in flat)
        else:
            text = " ".join(str(int(v)) for v in flat)
        out.append(text + "\n")
    out.append("%s</DataArray>\n" % indent)


def write_vtu(path, V, F, field=None, kind=None, name="field", binary=True, cell_data=None):
    """Writes the mesh and its per-face field as a VTK XML UnstructuredGrid (``.vtu``).

    ``field``: see :func:`field_arrays` for the cell arrays it becomes; ``cell_data``: more
    per-face arrays (name -> ``(F,)`` or ``(F, k)``). ``binary``: inline base64 (uncompressed,
    UInt64 headers) instead of ASCII. Values are float64 in both cases.
    """
    V, F = fl.as_mesh(V, F)
    arrays = _cell_arrays(V, F, field, kind, name, cell_data)
    out = ['<?xml version="1.0"?>\n',
           '<VTKFile type="UnstructuredGrid" version="1.0" byte_order="LittleEndian" '
           'header_type="UInt64">\n',
           '  <UnstructuredGrid>\n',
           '    <Piece NumberOfPoints="%d" NumberOfCells="%d">\n' % (len(V), len(F)),
           '      <Points>\n']
    _xml_array(out, "Points", V, "Float64", binary, "        ")
    out.append('      </Points>\n      <Cells>\n')
    _xml_array(out, "connectivity", F.reshape(-1), "Int64", binary, "        ")
    _xml_array(out, "offsets", 3 * np.arange(1, len(F) + 1, dtype=np.int64), "Int64", binary,
               "        ")
    _xml_array(out, "types", np.full(len(F), _VTK_TRIANGLE, dtype=np.uint8), "UInt8", binary,
               "        ")
    out.append('      </Cells>\n')
    attrs = _active_attributes(arrays)
    active = "".join(" %s=%s" % (k, quoteattr(v)) for k, v in attrs.items())
    out.append("      <CellData%s>\n" % active)
    for key, a in arrays.items():
        _xml_array(out, key, a, "Float64", binary, "        ")
    out.append('      </CellData>\n    </Piece>\n  </UnstructuredGrid>\n</VTKFile>\n')
    with open(path, "w", encoding="ascii") as f:
        f.write("".join(out))


def _active_attributes(arrays):
    attrs = {}
    for key, a in arrays.items():
        c = _components(a)
        if c == 1 and "Scalars" not in attrs:
            attrs["Scalars"] = key
        elif c == 3 and "Vectors" not in attrs:
            attrs["Vectors"] = key
        elif c == 9 and "Tensors" not in attrs:
            attrs["Tensors"] = key
    return attrs


# ---------------------------------------------------------------------------------------------
# Legacy VTK


def _legacy_numbers(values, per_line):
    flat = np.asarray(values).reshape(-1)
    if np.issubdtype(flat.dtype, np.floating):
        tokens = [repr(float(v)) for v in flat]
    else:
        tokens = [str(int(v)) for v in flat]
    return "".join(" ".join(tokens[i:i + per_line]) + "\n"
                   for i in range(0, len(tokens), per_line))


def _legacy_field(name, arrays, count):
    if not arrays:
        return ""
    out = ["FIELD %s %d\n" % (name, len(arrays))]
    for key, a in arrays.items():
        c = _components(a)
        out.append("%s %d %d double\n" % (key, c, count))
        out.append(_legacy_numbers(a, max(c, 3)))
    return "".join(out)


def write_vtk(path, V, F, field=None, kind=None, name="field", cell_data=None):
    """Writes the mesh and its field as a legacy ASCII VTK UnstructuredGrid (``.vtk``, format
    4.2): the same cell arrays as :func:`write_vtu`, in a ``FIELD`` block of ``CELL_DATA``."""
    V, F = fl.as_mesh(V, F)
    arrays = _cell_arrays(V, F, field, kind, name, cell_data)
    out = ["# vtk DataFile Version 4.2\n", "fieldspace mesh with a per-face field\n", "ASCII\n",
           "DATASET UNSTRUCTURED_GRID\n", "POINTS %d double\n" % len(V), _legacy_numbers(V, 3),
           "CELLS %d %d\n" % (len(F), 4 * len(F)),
           _legacy_numbers(np.hstack([np.full((len(F), 1), 3), F]), 4),
           "CELL_TYPES %d\n" % len(F), _legacy_numbers(np.full(len(F), _VTK_TRIANGLE), 1)]
    if arrays:
        out.append("CELL_DATA %d\n" % len(F))
        out.append(_legacy_field("FieldData", arrays, len(F)))
    with open(path, "w", encoding="ascii") as f:
        f.write("".join(out))


# ---------------------------------------------------------------------------------------------
# ASCII PLY


def ply_face_properties(V, F, field, kind=None):
    """The face properties :func:`write_ply_ascii` writes: a dict name -> ``(F,)``.

    - vector: ``vx vy vz magnitude``;
    - n-field: ``d0x d0y d0z`` .. ``d{n-1}x d{n-1}y d{n-1}z`` and ``magnitude``;
    - tensor: ``txx tyy tzz txy tyz tzx``, the principal values ``kmax kmin`` and unit principal
      directions ``dmaxx dmaxy dmaxz dminx dminy dminz``.
    """
    V, F = fl.as_mesh(V, F)
    a, kind, n = fl.check_field(V, F, field, kind)
    props = {}
    if kind == fl.VECTOR:
        for c, axis in enumerate("xyz"):
            props["v" + axis] = a[:, c]
        props["magnitude"] = np.linalg.norm(a, axis=1)
    elif kind == fl.NFIELD:
        for k in range(n):
            for c, axis in enumerate("xyz"):
                props["d%d%s" % (k, axis)] = a[:, k, c]
        props["magnitude"] = np.linalg.norm(a[:, 0, :], axis=1)
    else:
        six = fl.six_from_tensors(a)
        for c, key in enumerate(("txx", "tyy", "tzz", "txy", "tyz", "tzx")):
            props[key] = six[:, c]
        values, directions = fl.principal(V, F, a)
        props["kmax"], props["kmin"] = values[:, 0], values[:, 1]
        for j, which in enumerate(("max", "min")):
            for c, axis in enumerate("xyz"):
                props["d%s%s" % (which, axis)] = directions[:, j, c]
    return props


def write_ply_ascii(path, V, F, field=None, kind=None, face_properties=None):
    """Writes an ASCII PLY: vertices (double x y z), faces (``vertex_indices``) and the field as
    double face properties (:func:`ply_face_properties`), plus ``face_properties`` (name ->
    ``(F,)``)."""
    V, F = fl.as_mesh(V, F)
    props = {} if field is None else ply_face_properties(V, F, field, kind)
    for key, value in (face_properties or {}).items():
        _check_name(key)
        value = np.asarray(value, dtype=np.float64).reshape(-1)
        if len(value) != len(F) or key in props or key == "vertex_indices":
            raise ValueError("face property %r: needs %d values and a new name" % (key, len(F)))
        props[key] = value
    header = ["ply", "format ascii 1.0", "comment written by fieldspace",
              "element vertex %d" % len(V), "property double x", "property double y",
              "property double z", "element face %d" % len(F),
              "property list uchar int vertex_indices"]
    header += ["property double %s" % key for key in props]
    header.append("end_header")
    out = ["\n".join(header) + "\n", _legacy_numbers(V, 3)]
    columns = [np.full(len(F), "3", dtype=object)]
    columns += [F[:, c].astype(str) for c in range(3)]
    columns += [np.array([repr(float(v)) for v in p], dtype=object) for p in props.values()]
    if len(F):
        table = np.stack(columns, axis=1)
        out.append("\n".join(" ".join(row) for row in table) + "\n")
    with open(path, "w", encoding="ascii") as f:
        f.write("".join(out))


# ---------------------------------------------------------------------------------------------
# Directional


def write_rawfield(path, field, n=None):
    """Writes Directional's raw field format (``read_raw_field`` / ``write_raw_field``): a first
    line ``N #F``, then per face the N directions as ``3 N`` numbers ``x0 y0 z0 x1 y1 z1 ...``,
    counter-clockwise in order.

    ``field``: ``(F, 3)`` (a vector field, N = 1) or ``(F, N, 3)`` (an n-field); ``n``, when
    given, must match. Tensors are not a Directional raw field (export their principal
    directions as a 4-field instead).
    """
    a = np.asarray(field, dtype=np.float64)
    if a.ndim == 2 and a.shape[1] == 3:
        a = a[:, None, :]
    if a.ndim != 3 or a.shape[2] != 3:
        raise ValueError("a raw field is (F, 3) or (F, N, 3), got shape %s" % (a.shape,))
    if n is not None and n != a.shape[1]:
        raise ValueError("n = %d but the field has %d directions per face" % (n, a.shape[1]))
    if not np.all(np.isfinite(a)):
        raise ValueError("the field holds non-finite values")
    rows = a.reshape(len(a), -1)
    with open(path, "w", encoding="ascii") as f:
        f.write("%d %d\n" % (a.shape[1], len(a)))
        f.write(_legacy_numbers(rows, rows.shape[1]) if len(a) else "")


def principal_cross_field(V, F, tensors):
    """The principal directions of a tensor field as a 4-field ``(F, 4, 3)`` (max, min, -max,
    -min; unit length), e.g. for :func:`write_rawfield`."""
    _, directions = fl.principal(V, F, tensors)
    return np.stack([directions[:, 0], directions[:, 1], -directions[:, 0], -directions[:, 1]],
                    axis=1)


def singularity_pairs(singularities):
    """``(k, 2)`` int array of (vertex, index in 1/n turns) from: such an array or list of pairs;
    a dict vertex -> index; objects or dicts with ``vertex`` and ``index`` (the Singularities
    RPC's messages). The CLI prints indices in whole turns: use :func:`singularities_from_cli`
    for its output."""
    if isinstance(singularities, dict):
        pairs = list(singularities.items())
    else:
        pairs = []
        for s in singularities:
            if isinstance(s, dict):
                pairs.append((s["vertex"], s["index"]))
            elif hasattr(s, "vertex") and hasattr(s, "index"):
                pairs.append((s.vertex, s.index))
            else:
                pairs.append(tuple(s))
    a = np.array(pairs, dtype=np.float64).reshape(-1, 2) if pairs else np.zeros((0, 2))
    if not np.all(np.mod(a, 1) == 0):
        raise ValueError("singular vertices and indices (in 1/n turns) must be integers; for "
                         "the CLI's output (whole turns) use singularities_from_cli")
    return a.astype(np.int64)


def singularities_from_cli(output):
    """``(n, pairs)`` from the JSON that ``fieldspace singularities`` prints (text or parsed):
    its ``index`` is in whole turns, so each becomes ``round(index * n)`` in 1/n turns."""
    if isinstance(output, (str, bytes)):
        output = json.loads(output)
    n = int(output["n"])
    pairs = []
    for s in output.get("singularities", []):
        units = float(s["index"]) * n
        if abs(units - round(units)) > 1e-6:
            raise ValueError("vertex %d: index %r is not a multiple of 1/%d turn"
                             % (s["vertex"], s["index"], n))
        pairs.append((int(s["vertex"]), int(round(units))))
    return n, np.array(pairs, dtype=np.int64).reshape(-1, 2)


def write_sing(path, singularities, n):
    """Writes Directional's singularity format (``read_singularities`` / ``write_singularities``):
    ``N count`` and one ``vertex index`` line each, the index in units of 1/N turns (so the
    index is ``index / N`` turns: the Singularities RPC's ``index``). Zero indices are dropped.
    """
    n = int(n)
    if n < 1:
        raise ValueError("n must be >= 1")
    pairs = singularity_pairs(singularities)
    pairs = pairs[pairs[:, 1] != 0]
    if len(pairs) and pairs[:, 0].min() < 0:
        raise ValueError("negative vertex index")
    with open(path, "w", encoding="ascii") as f:
        f.write("%d %d\n" % (n, len(pairs)))
        for vertex, index in pairs:
            f.write("%d %d\n" % (vertex, index))


# ---------------------------------------------------------------------------------------------
# Polylines


def _check_lines(lines):
    out = []
    for i, line in enumerate(lines):
        a = np.asarray(line, dtype=np.float64)
        if a.ndim != 2 or a.shape[1] != 3 or len(a) < 2:
            raise ValueError("polyline %d must be (k >= 2, 3), got shape %s" % (i, a.shape))
        if not np.all(np.isfinite(a)):
            raise ValueError("polyline %d holds non-finite points" % i)
        out.append(a)
    return out


def polyline_lengths(lines):
    """Length of each polyline ``(len(lines),)``."""
    out = []
    for a in lines:
        a = np.asarray(a, dtype=np.float64)
        out.append(float(np.sum(np.linalg.norm(np.diff(a, axis=0), axis=1))))
    return np.array(out)


def write_polylines_vtk(path, lines, line_data=None):
    """Writes polylines (a list of ``(k_i, 3)`` arrays) as legacy ASCII VTK PolyData ``LINES``,
    one cell per polyline, with the cell arrays ``line_id`` and ``length`` and ``line_data``
    (name -> one value per line)."""
    lines = _check_lines(lines)
    points = np.vstack(lines) if lines else np.zeros((0, 3))
    counts = [len(a) for a in lines]
    out = ["# vtk DataFile Version 4.2\n", "fieldspace polylines\n", "ASCII\n",
           "DATASET POLYDATA\n", "POINTS %d double\n" % len(points), _legacy_numbers(points, 3),
           "LINES %d %d\n" % (len(lines), len(lines) + len(points))]
    start = 0
    for c in counts:
        out.append("%d %s\n" % (c, " ".join(str(i) for i in range(start, start + c))))
        start += c
    arrays = {"line_id": np.arange(len(lines), dtype=np.float64),
              "length": polyline_lengths(lines)}
    for key, value in (line_data or {}).items():
        _check_name(key)
        value = np.asarray(value, dtype=np.float64)
        if value.shape[0] != len(lines) or key in arrays:
            raise ValueError("line_data %r: needs %d rows and a new name" % (key, len(lines)))
        arrays[key] = value
    if lines:
        out.append("CELL_DATA %d\n" % len(lines))
        out.append(_legacy_field("FieldData", arrays, len(lines)))
    with open(path, "w", encoding="ascii") as f:
        f.write("".join(out))


def write_polylines_obj(path, lines):
    """Writes polylines as Wavefront OBJ: all points as ``v x y z``, then one ``l i j k ...``
    element per polyline (1-based indices)."""
    lines = _check_lines(lines)
    out = ["# fieldspace polylines: %d lines\n" % len(lines)]
    for a in lines:
        out.append("".join("v %r %r %r\n" % (float(x), float(y), float(z)) for x, y, z in a))
    start = 1
    for a in lines:
        out.append("l %s\n" % " ".join(str(i) for i in range(start, start + len(a))))
        start += len(a)
    with open(path, "w", encoding="ascii") as f:
        f.write("".join(out))


def main(argv=None):
    """python3 -m fieldspace.export MESH [FIELD_FILE] --out OUT: writes the mesh and a field
    file of the fieldspace CLI as .vtu, .vtk, ASCII .ply or Directional's .rawfield (a tensor
    field as its principal 4-field), chosen by the output's extension."""
    from . import mesh_io
    from .errors import FieldspaceError

    parser = argparse.ArgumentParser(prog="python3 -m fieldspace.export",
                                     description=main.__doc__)
    mesh_io.add_field_arguments(parser)
    parser.add_argument("--out", required=True, help="output file: .vtu .vtk .ply .rawfield")
    parser.add_argument("--name", default="field", help="array name prefix (.vtu, .vtk)")
    parser.add_argument("--ascii", action="store_true", help=".vtu: ASCII instead of base64")
    args = parser.parse_args(argv)
    try:
        V, F, field, kind = mesh_io.load_mesh_and_field(
            args.mesh, args.field, args.kind, args.n, server=args.server,
            token=mesh_io.read_token(args.token), tls=mesh_io.tls_arguments(args))
        ext = os.path.splitext(args.out)[1].lower()
        if ext == ".vtu":
            write_vtu(args.out, V, F, field, kind, args.name, binary=not args.ascii)
        elif ext == ".vtk":
            write_vtk(args.out, V, F, field, kind, args.name)
        elif ext == ".ply":
            write_ply_ascii(args.out, V, F, field, kind)
        elif ext == ".rawfield":
            if field is None:
                raise ValueError("a .rawfield export needs a field")
            if kind == fl.TENSOR:
                field = principal_cross_field(V, F, field)
            write_rawfield(args.out, field)
        else:
            raise ValueError("unknown output extension %r (.vtu .vtk .ply .rawfield)" % ext)
    except (OSError, ValueError) as e:
        print("fieldspace: export failed: %s" % e, file=sys.stderr)
        return 1
    except FieldspaceError as e:  # a mesh id the server could not give
        print("fieldspace: %s" % e, file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
