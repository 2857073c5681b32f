"""Per-face field arrays, face frames, and the CLI's text field files, in numpy.

The Python package's array conventions (one row per face, ``F`` faces):

- vector field: ``(F, 3)`` ambient 3D vectors, tangent to the faces;
- n-field (n-RoSy): ``(F, n, 3)``, all n directions of each face, direction ``k`` being direction 0
  turned by ``2 pi k / n`` counter-clockwise about the face normal;
- symmetric (1,1)-tensor: ``(F, 3, 3)`` ambient symmetric matrices with ``A n_f = 0``.

Meshes are ``V`` ``(nV, 3)`` float and ``F`` ``(nF, 3)`` int, zero-based, faces in file order.
The face frames and the DOF encodings are those of docs/conventions.md ("Frames", "DOF layout",
"Wire encodings"); this module reimplements them in numpy so that files written by the
``fieldspace`` CLI (``--encoding ambient`` or ``dof``) convert to the arrays above.
"""

import math
import re
from dataclasses import dataclass
from typing import Optional

import numpy as np

VECTOR = "vector"
NFIELD = "nfield"
TENSOR = "tensor"
KINDS = (VECTOR, NFIELD, TENSOR)


def as_mesh(V, F):
    """Checked float64 ``(nV, 3)`` and int64 ``(nF, 3)`` copies of a triangle mesh."""
    V = np.ascontiguousarray(V, dtype=np.float64)
    F = np.ascontiguousarray(F)
    if V.ndim != 2 or V.shape[1] != 3:
        raise ValueError("V must be (nV, 3), got shape %s" % (V.shape,))
    if F.ndim != 2 or F.shape[1] != 3:
        raise ValueError("F must be (nF, 3) triangles, got shape %s" % (F.shape,))
    if not np.issubdtype(F.dtype, np.integer):
        if not np.all(np.mod(F, 1) == 0):
            raise ValueError("F must hold integer vertex indices")
    F = F.astype(np.int64)
    if F.size and (F.min() < 0 or F.max() >= len(V)):
        raise ValueError("F holds vertex indices outside [0, %d)" % len(V))
    if not np.all(np.isfinite(V)):
        raise ValueError("V holds non-finite coordinates")
    return V, F


def face_frames(V, F):
    """The face frames of docs/conventions.md: ``x_f = normalize(p1 - p0)``,
    ``n_f = normalize((p1 - p0) x (p2 - p0))``, ``y_f = n_f x x_f``; each ``(F, 3)``.

    Degenerate faces (zero area) get zero normals; the C++ mesh rejects them anyway.
    """
    V, F = as_mesh(V, F)
    p0, p1, p2 = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    e1 = p1 - p0
    x = e1 / _safe_norm(e1)[:, None]
    n = np.cross(e1, p2 - p0)
    n = n / _safe_norm(n)[:, None]
    y = np.cross(n, x)
    return x, y, n


def face_normals(V, F):
    """Unit face normals ``(F, 3)`` following the corner order."""
    return face_frames(V, F)[2]


def face_areas(V, F):
    """Face areas ``(F,)``."""
    V, F = as_mesh(V, F)
    c = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    return 0.5 * np.linalg.norm(c, axis=1)


def _safe_norm(a):
    r = np.linalg.norm(a, axis=-1)
    return np.where(r > 0, r, 1.0)


def infer_kind(field, kind=None):
    """``(kind, n)`` of a field array: ``(F, 3)`` vector, ``(F, n, 3)`` n-field, ``(F, 3, 3)``
    tensor. A ``(F, 3, 3)`` array is ambiguous (a 3-field or a tensor): without ``kind`` it is a
    tensor when every matrix is symmetric, else a 3-field.
    """
    a = np.asarray(field)
    if kind is not None and kind not in KINDS:
        raise ValueError("kind must be one of %s, got %r" % (", ".join(KINDS), kind))
    if a.ndim == 2 and a.shape[1] == 3:
        if kind not in (None, VECTOR):
            raise ValueError("a (F, 3) array is a vector field, not a %s" % kind)
        return VECTOR, 1
    if a.ndim == 3 and a.shape[2] == 3 and a.shape[1] >= 1:
        if kind == VECTOR:
            raise ValueError("a vector field must be (F, 3), got shape %s" % (a.shape,))
        if kind == TENSOR or (kind is None and a.shape[1] == 3 and _all_symmetric(a)):
            if a.shape[1] != 3:
                raise ValueError("a tensor field must be (F, 3, 3), got shape %s" % (a.shape,))
            return TENSOR, 3
        return NFIELD, a.shape[1]
    raise ValueError("field arrays are (F, 3), (F, n, 3) or (F, 3, 3); got shape %s" % (a.shape,))


def _all_symmetric(a):
    scale = max(float(np.abs(a).max()) if a.size else 0.0, 1e-300)
    return bool(np.all(np.abs(a - np.swapaxes(a, 1, 2)) <= 1e-6 * scale))


def check_field(V, F, field, kind=None):
    """The field as float64 with its ``(kind, n)``; ValueError when it does not fit the mesh."""
    kind, n = infer_kind(field, kind)
    a = np.asarray(field, dtype=np.float64)
    if a.shape[0] != len(F):
        raise ValueError("the field has %d faces, the mesh %d" % (a.shape[0], len(F)))
    if not np.all(np.isfinite(a)):
        bad = int(np.nonzero(~np.isfinite(a.reshape(len(a), -1)).all(axis=1))[0][0])
        raise ValueError("the field is not finite at face %d" % bad)
    return a, kind, n


# ---------------------------------------------------------------------------------------------
# Encodings (docs/conventions.md, "DOF layout" and "Wire encodings").


def rotate_in_plane(v, normals, angle):
    """``v`` (tangent, ``(F, 3)``) turned by ``angle`` (scalar or ``(F,)``) counter-clockwise
    about ``normals``: ``cos(a) v + sin(a) n x v``."""
    angle = np.asarray(angle, dtype=np.float64)
    c, s = np.cos(angle), np.sin(angle)
    if angle.ndim:
        c, s = c[:, None], s[:, None]
    return c * v + s * np.cross(normals, v)


def tangential(V, F, vectors):
    """Vectors ``(F, 3)`` projected to their faces' planes."""
    n = face_normals(V, F)
    vectors = np.asarray(vectors, dtype=np.float64)
    return vectors - np.sum(vectors * n, axis=1)[:, None] * n


def vectors_from_dofs(V, F, dofs):
    """Vector field DOFs ``(F, 2)`` (frame coordinates) to ambient ``(F, 3)``."""
    x, y, _ = face_frames(V, F)
    d = np.asarray(dofs, dtype=np.float64).reshape(len(x), 2)
    return d[:, :1] * x + d[:, 1:] * y


def dofs_from_vectors(V, F, vectors):
    """Ambient vectors ``(F, 3)`` to frame coordinates ``(F, 2)`` (the normal part dropped)."""
    x, y, _ = face_frames(V, F)
    v = np.asarray(vectors, dtype=np.float64)
    return np.stack([np.sum(v * x, axis=1), np.sum(v * y, axis=1)], axis=1)


def nfield_from_representative(V, F, representative, n):
    """All n directions ``(F, n, 3)`` from one direction per face ``(F, 3)`` (projected to the
    face; its length kept): direction k is it turned by ``2 pi k / n``."""
    n = _check_n(n)
    r = tangential(V, F, representative)
    normals = face_normals(V, F)
    return np.stack([rotate_in_plane(r, normals, 2.0 * math.pi * k / n) for k in range(n)],
                    axis=1)


def nfield_from_dofs(V, F, dofs, n):
    """n-field representation vectors ``(F, 2)`` to all n directions ``(F, n, 3)``: the
    representative has angle ``atan2(u1, u0) / n`` in the face frame and length ``|u|``."""
    n = _check_n(n)
    x, y, normals = face_frames(V, F)
    u = np.asarray(dofs, dtype=np.float64).reshape(len(x), 2)
    phi = np.arctan2(u[:, 1], u[:, 0]) / n
    r = np.hypot(u[:, 0], u[:, 1])
    rep = (r * np.cos(phi))[:, None] * x + (r * np.sin(phi))[:, None] * y
    return np.stack([rotate_in_plane(rep, normals, 2.0 * math.pi * k / n) for k in range(n)],
                    axis=1)


def nfield_dofs(V, F, directions):
    """Representation vectors ``(F, 2)`` of an n-field ``(F, n, 3)`` (from its direction 0):
    ``r (cos n phi, sin n phi)``."""
    d = np.asarray(directions, dtype=np.float64)
    n = d.shape[1]
    a = dofs_from_vectors(V, F, d[:, 0, :])
    phi = np.arctan2(a[:, 1], a[:, 0])
    r = np.hypot(a[:, 0], a[:, 1])
    return np.stack([r * np.cos(n * phi), r * np.sin(n * phi)], axis=1)


def nfield_representative(V, F, directions):
    """The representative direction ``(F, 3)`` the C++ code writes for an n-field: angle in
    ``(-pi/n, pi/n]`` in the face frame (docs/conventions.md)."""
    d = np.asarray(directions, dtype=np.float64)
    return nfield_from_dofs(V, F, nfield_dofs(V, F, d), d.shape[1])[:, 0, :]


def tensors_from_six(values):
    """``xx yy zz xy yz zx`` rows ``(F, 6)`` to symmetric matrices ``(F, 3, 3)``."""
    s = np.asarray(values, dtype=np.float64).reshape(-1, 6)
    xx, yy, zz, xy, yz, zx = s.T
    return np.stack([np.stack([xx, xy, zx], 1), np.stack([xy, yy, yz], 1),
                     np.stack([zx, yz, zz], 1)], axis=1)


def six_from_tensors(tensors):
    """Symmetric matrices ``(F, 3, 3)`` to ``xx yy zz xy yz zx`` rows ``(F, 6)``."""
    t = np.asarray(tensors, dtype=np.float64)
    return np.stack([t[:, 0, 0], t[:, 1, 1], t[:, 2, 2], t[:, 0, 1], t[:, 1, 2], t[:, 2, 0]],
                    axis=1)


def tensors_from_dofs(V, F, dofs):
    """Mandel-Voigt DOFs ``(F, 3)`` = ``(B11, B22, sqrt(2) B12)`` in the face frame to ambient
    ``A = B11 x x^T + B22 y y^T + B12 (x y^T + y x^T)``, ``(F, 3, 3)``."""
    x, y, _ = face_frames(V, F)
    d = np.asarray(dofs, dtype=np.float64).reshape(len(x), 3)
    b11, b22, b12 = d[:, 0], d[:, 1], d[:, 2] / math.sqrt(2.0)
    xx = np.einsum("fi,fj->fij", x, x)
    yy = np.einsum("fi,fj->fij", y, y)
    xy = np.einsum("fi,fj->fij", x, y)
    return (b11[:, None, None] * xx + b22[:, None, None] * yy
            + b12[:, None, None] * (xy + np.swapaxes(xy, 1, 2)))


def tensor_dofs(V, F, tensors):
    """Ambient tensors ``(F, 3, 3)`` to Mandel-Voigt DOFs ``(F, 3)`` of ``B = [x y]^T A [x y]``."""
    x, y, _ = face_frames(V, F)
    a = np.asarray(tensors, dtype=np.float64)
    a = 0.5 * (a + np.swapaxes(a, 1, 2))
    b11 = np.einsum("fi,fij,fj->f", x, a, x)
    b22 = np.einsum("fi,fij,fj->f", y, a, y)
    b12 = np.einsum("fi,fij,fj->f", x, a, y)
    return np.stack([b11, b22, math.sqrt(2.0) * b12], axis=1)


def tangential_tensors(V, F, tensors):
    """Ambient tensors restricted to the faces' planes (what the server stores and returns)."""
    return tensors_from_dofs(V, F, tensor_dofs(V, F, tensors))


def principal(V, F, tensors):
    """Principal values and directions of each face's tangential tensor.

    Returns ``values`` ``(F, 2)`` with ``values[:, 0] >= values[:, 1]`` and ``directions``
    ``(F, 2, 3)``: unit tangent vectors, ``directions[:, 1] = n_f x directions[:, 0]`` (the
    convention of docs/conventions.md, "Curvature"). A direction's sign is arbitrary.
    """
    x, y, normals = face_frames(V, F)
    d = tensor_dofs(V, F, tensors)
    b11, b22, b12 = d[:, 0], d[:, 1], d[:, 2] / math.sqrt(2.0)
    mean = 0.5 * (b11 + b22)
    radius = np.hypot(0.5 * (b11 - b22), b12)
    theta = 0.5 * np.arctan2(2.0 * b12, b11 - b22)
    d1 = np.cos(theta)[:, None] * x + np.sin(theta)[:, None] * y
    d2 = np.cross(normals, d1)
    values = np.stack([mean + radius, mean - radius], axis=1)
    return values, np.stack([d1, d2], axis=1)


def magnitude(field, kind=None):
    """Per-face magnitude ``(F,)``: the vector length, the n-field's direction length, the
    tensor's Frobenius norm."""
    a = np.asarray(field, dtype=np.float64)
    kind, _ = infer_kind(a, kind)
    if kind == VECTOR:
        return np.linalg.norm(a, axis=1)
    if kind == NFIELD:
        return np.linalg.norm(a[:, 0, :], axis=1)
    return np.sqrt(np.sum(a * a, axis=(1, 2)))


def _check_n(n):
    if int(n) != n or not 1 <= int(n) <= 64:
        raise ValueError("n must be an integer in [1, 64], got %r" % (n,))
    return int(n)


# ---------------------------------------------------------------------------------------------
# The CLI's text field files (docs/cli.md, "File formats"; client/field_files.cc).


@dataclass
class FieldText:
    """A text field file as written by ``fieldspace ... --out FILE``.

    ``values`` ``(F, k)`` the numbers, ``encoding`` ``"ambient"`` or ``"dof"``, ``type`` the
    header's field type (``"vector"``, ``"nfield4"``, ``"tensor"``, ``"principal curvatures"``)
    or None when the file has no header, ``n`` the symmetry order for ``nfield<n>`` files.
    """

    values: np.ndarray
    encoding: str
    type: Optional[str]
    n: Optional[int]

    @property
    def kind(self):
        if self.type is None:
            return None
        if self.type.startswith(NFIELD):
            return NFIELD
        return self.type if self.type in (VECTOR, TENSOR) else None


_TYPE_RE = re.compile(r"#\s*fieldspace field:\s*type\s+(.+?),\s*(\d+)\s+faces\s*$")


def parse_field_text(text):
    """Parses the text of a field file (the grammar of client/field_files.cc: ``#`` comments,
    ``# encoding: ambient|dof``, one face per line, numbers separated by spaces, tabs or commas,
    the same count on every line)."""
    encoding = "ambient"
    field_type = None
    rows = []
    width = None
    for number, line in enumerate(text.split("\n"), start=1):
        line = line.strip()
        if not line:
            continue
        if line.startswith("#"):
            m = _TYPE_RE.match(line)
            if m:
                field_type = m.group(1)
            comment = line[1:].strip()
            if comment.startswith("encoding:"):
                encoding = comment[len("encoding:"):].strip()
                if encoding not in ("ambient", "dof"):
                    raise ValueError("line %d: encoding must be 'ambient' or 'dof', got '%s'"
                                     % (number, encoding))
            continue
        tokens = [t for t in re.split(r"[ \t,\r]+", line) if t]
        try:
            row = [float(t) for t in tokens]
        except ValueError:
            raise ValueError("line %d: not a list of numbers: %r" % (number, line)) from None
        if not all(math.isfinite(v) for v in row):
            raise ValueError("line %d: non-finite value" % number)
        if width is None:
            width = len(row)
        elif len(row) != width:
            raise ValueError("line %d: %d values; earlier lines have %d"
                             % (number, len(row), width))
        rows.append(row)
    if not rows:
        raise ValueError("the field file has no values")
    n = None
    if field_type and field_type.startswith(NFIELD) and field_type[len(NFIELD):].isdigit():
        n = int(field_type[len(NFIELD):])
    return FieldText(np.array(rows, dtype=np.float64), encoding, field_type, n)


def read_field_text(path):
    """Reads a CLI field file; see :func:`parse_field_text`."""
    with open(path, "r", encoding="utf-8") as f:
        return parse_field_text(f.read())


def text_kind(text_field, kind=None, n=None):
    """``(kind, n)`` of a :class:`FieldText`: the given ones, else the header's, else by the
    number of values per face (6, or 3 in DOF encoding: tensor; else vector)."""
    kind = kind or text_field.kind
    n = n or text_field.n
    if kind is None:
        k = text_field.values.shape[1]
        if k == 6 or (k == 3 and text_field.encoding == "dof"):
            kind = TENSOR
        elif n is not None:
            kind = NFIELD
        else:
            kind = VECTOR
    if kind not in KINDS:
        raise ValueError("kind must be one of %s, got %r" % (", ".join(KINDS), kind))
    if kind == NFIELD and n is None:
        raise ValueError("an n-field needs n (the file has no 'nfield<n>' header)")
    return kind, (n if kind == NFIELD else (3 if kind == TENSOR else 1))


def field_from_text(V, F, text_field, kind=None, n=None):
    """The field array of a :class:`FieldText` on mesh ``(V, F)``.

    ``kind`` and ``n`` default to the file's header. Ambient vectors are projected to the faces,
    an ambient n-field line (one direction) gives all n directions, ambient tensors (6 values)
    are restricted to the faces; DOF lines are read in the face frames.
    """
    V, F = as_mesh(V, F)
    kind, n = text_kind(text_field, kind, n)
    values = text_field.values
    k = values.shape[1]
    if len(values) != len(F):
        raise ValueError("the file has %d faces, the mesh %d" % (len(values), len(F)))
    expected = {("ambient", VECTOR): 3, ("ambient", NFIELD): 3, ("ambient", TENSOR): 6,
                ("dof", VECTOR): 2, ("dof", NFIELD): 2, ("dof", TENSOR): 3}
    want = expected[(text_field.encoding, kind)]
    if k != want:
        raise ValueError("a %s field in %s encoding has %d values per face, the file %d"
                         % (kind, text_field.encoding, want, k))
    if text_field.encoding == "ambient":
        if kind == VECTOR:
            return tangential(V, F, values)
        if kind == NFIELD:
            return nfield_from_representative(V, F, values, n)
        return tangential_tensors(V, F, tensors_from_six(values))
    if kind == VECTOR:
        return vectors_from_dofs(V, F, values)
    if kind == NFIELD:
        return nfield_from_dofs(V, F, values, n)
    return tensors_from_dofs(V, F, values)


def format_field_text(V, F, field, kind=None, encoding="ambient"):
    """The text of a CLI field file for ``field`` (``project`` input, or to compare): ambient
    vectors ``x y z``, n-fields one direction ``x y z`` (the representative), tensors
    ``xx yy zz xy yz zx``; or the DOFs with ``encoding="dof"``."""
    V, F = as_mesh(V, F)
    a, kind, n = check_field(V, F, field, kind)
    if encoding == "ambient":
        if kind == VECTOR:
            values = a
        elif kind == NFIELD:
            values = nfield_representative(V, F, a)
        else:
            values = six_from_tensors(a)
    elif encoding == "dof":
        if kind == VECTOR:
            values = dofs_from_vectors(V, F, a)
        elif kind == NFIELD:
            values = nfield_dofs(V, F, a)
        else:
            values = tensor_dofs(V, F, a)
    else:
        raise ValueError("encoding must be 'ambient' or 'dof', got %r" % (encoding,))
    type_name = "%s%d" % (NFIELD, n) if kind == NFIELD else kind
    lines = ["# fieldspace field: type %s, %d faces" % (type_name, len(values)),
             "# encoding: %s" % encoding]
    lines += [" ".join(repr(float(v)) for v in row) for row in values]
    return "\n".join(lines) + "\n"


def write_field_text(path, V, F, field, kind=None, encoding="ambient"):
    """Writes :func:`format_field_text` to ``path``."""
    text = format_field_text(V, F, field, kind, encoding)
    with open(path, "w", encoding="utf-8") as f:
        f.write(text)
