"""numpy arrays <-> the wire's per-face values (FieldValues) and constraint values.

Shapes (F faces, or k constraints):

============  ==========================  ===============================================
field type    ambient (the default)       DOF (``encoding="dof"``)
============  ==========================  ===============================================
vector        (F, 3)                      (F, 2): frame coordinates
n-field       out: (F, n, 3), all n       (F, 2): the representation vector
              directions; in: (F, 3) one
              direction, or (F, n, 3)
tensor        (F, 3, 3) symmetric; in     (F, 3): Mandel-Voigt (a11, a22, sqrt(2) a12)
              also (F, 6) xx yy zz xy yz
              zx
============  ==========================  ===============================================

The face frames and layouts are docs/conventions.md's. Input arrays choose their encoding by
their shape; ``encoding=`` may say it explicitly (and must then agree with the shape).
"""

import math

import numpy as np

from . import fields
from ._stubs import pb
from .errors import InvalidArgument

AMBIENT = "ambient"
DOF = "dof"

_KIND_NAMES = {
    pb.FIELD_KIND_VECTOR: "vector",
    pb.FIELD_KIND_NFIELD: "nfield",
    pb.FIELD_KIND_TENSOR: "tensor",
}
_KINDS = {name: kind for kind, name in _KIND_NAMES.items()}
_ENCODINGS = {AMBIENT: pb.FIELD_ENCODING_AMBIENT, DOF: pb.FIELD_ENCODING_DOF}


class FieldType:
    """A basis's field type: kind ``"vector"``, ``"nfield"`` (with n) or ``"tensor"``."""

    __slots__ = ("kind", "n")

    def __init__(self, kind, n=0):
        self.kind = kind
        self.n = n if kind == "nfield" else 0

    @classmethod
    def from_proto(cls, field):
        return cls(_KIND_NAMES.get(field.kind, "unspecified"), field.n)

    def __eq__(self, other):
        return isinstance(other, FieldType) and (self.kind, self.n) == (other.kind, other.n)

    def __hash__(self):
        return hash((self.kind, self.n))

    def __str__(self):
        return "nfield%d" % self.n if self.kind == "nfield" else self.kind

    def __repr__(self):
        return "FieldType(%r, %d)" % (self.kind, self.n) if self.kind == "nfield" else \
            "FieldType(%r)" % self.kind


def field_type_proto(kind, n, what):
    """The wire FieldType of ``kind`` ("vector", "nfield", "tensor") and ``n``."""
    if kind not in _KINDS:
        raise InvalidArgument(what, "field must be 'vector', 'nfield' or 'tensor', not %r"
                              % (kind,))
    if kind == "nfield":
        if n is None:
            raise InvalidArgument(what, "field 'nfield' needs n (the symmetry order, 1..64)")
    elif n is not None:
        raise InvalidArgument(what, "n applies to field 'nfield' only, not %r" % kind)
    return pb.FieldType(kind=_KINDS[kind], n=int(n) if n is not None else 0)


def encoding_proto(encoding, what):
    """The wire FieldEncoding of ``"ambient"`` or ``"dof"``."""
    if encoding not in _ENCODINGS:
        raise InvalidArgument(what, "encoding must be 'ambient' or 'dof', not %r" % (encoding,))
    return _ENCODINGS[encoding]


def values_per_face(field_type, encoding):
    tensor = field_type.kind == "tensor"
    if encoding == AMBIENT:
        return 6 if tensor else 3
    return 3 if tensor else 2


def encode(values, field_type, what, encoding=None, count=None, single=False):
    """(wire encoding, float64 array of shape (k, values per face)) of per-face values.

    ``single``: ``values`` is one face's value (e.g. a design edit) instead of an array of them.
    ``count``: the number of rows required (e.g. all faces of the mesh).
    """
    try:
        a = np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError) as e:
        raise InvalidArgument(what, "values are not an array of numbers: %s" % e) from None
    if single:
        a = a[np.newaxis]
    if encoding is not None and encoding not in _ENCODINGS:
        raise InvalidArgument(what, "encoding must be 'ambient' or 'dof', not %r" % (encoding,))
    shape = a.shape[1:] if a.ndim >= 1 else ()
    kind = field_type.kind
    if kind == "tensor":
        if shape == (3, 3):
            sym = 0.5 * (a + np.swapaxes(a, 1, 2))
            scale = max(float(np.max(np.abs(a))) if a.size else 0.0, 1e-300)
            if a.size and float(np.max(np.abs(a - sym))) > 1e-6 * scale:
                raise InvalidArgument(what, "tensors must be symmetric (to a relative 1e-6)")
            flat = np.stack([sym[:, 0, 0], sym[:, 1, 1], sym[:, 2, 2], sym[:, 0, 1],
                             sym[:, 1, 2], sym[:, 2, 0]], axis=1)
            shape_encoding = AMBIENT
        elif shape == (6,):
            flat, shape_encoding = a, AMBIENT
        elif shape == (3,):
            flat, shape_encoding = a, DOF
        else:
            raise InvalidArgument(what, _shape_message(
                a, single, "a tensor basis takes (3, 3) or 6 ambient values (xx yy zz xy yz zx) "
                "or 3 DOFs (a11 a22 sqrt2_a12) per face"))
    else:
        if kind == "nfield" and len(shape) == 2 and shape[1] == 3 and shape[0] >= 1:
            # All n directions give the same representation vector: take the first.
            flat, shape_encoding = a[:, 0, :], AMBIENT
        elif shape == (3,):
            flat, shape_encoding = a, AMBIENT
        elif shape == (2,):
            flat, shape_encoding = a, DOF
        else:
            raise InvalidArgument(what, _shape_message(
                a, single, "a %s basis takes 3 ambient values (x y z) or 2 DOFs per face%s" %
                (field_type, ", or (n, 3) directions" if kind == "nfield" else "")))
    if encoding is not None and encoding != shape_encoding:
        raise InvalidArgument(what, "values of shape %s are %s values for a %s basis, but "
                              "encoding=%r was given" % (_shape(a, single), shape_encoding,
                                                         field_type, encoding))
    if count is not None and flat.shape[0] != count:
        raise InvalidArgument(what, "expected values for %d faces, got %d" % (count, flat.shape[0]))
    return _ENCODINGS[shape_encoding], np.ascontiguousarray(flat, dtype=np.float64)


def _shape(a, single):
    return tuple(a.shape[1:]) if single else tuple(a.shape)


def _shape_message(a, single, expectation):
    return "values of shape %s: %s" % (_shape(a, single), expectation)


def decode(values, field_type, encoding, normals=None):
    """Per-face values from the wire (a flat float array) as the arrays of the module docstring.

    ``normals``: the unit normals of the same faces, needed for ambient n-fields (the other n - 1
    directions are the wire's representative rotated by 2 pi j / n about the normal).
    """
    vpf = values_per_face(field_type, encoding)
    a = np.asarray(values, dtype=np.float64).reshape(-1, vpf)
    if encoding == DOF:
        return a
    kind = field_type.kind
    if kind == "tensor":
        return fields.tensors_from_six(a)
    if kind == "nfield":
        n = field_type.n
        a = a - np.sum(a * normals, axis=1, keepdims=True) * normals  # float32 rounding
        # Direction j is the wire's representative turned by 2 pi j / n about the normal.
        return np.stack([fields.rotate_in_plane(a, normals, 2.0 * math.pi * j / n)
                         for j in range(n)], axis=1)
    return a


def flat_floats(chunks_values, total):
    """A float64 array of ``total`` values from the repeated float fields of several chunks."""
    out = np.empty(total, dtype=np.float64)
    at = 0
    for values in chunks_values:
        k = len(values)
        if at + k > total:
            raise ValueError("more values than announced")
        out[at:at + k] = np.fromiter(values, dtype=np.float64, count=k)
        at += k
    if at != total:
        raise ValueError("expected %d values, got %d" % (total, at))
    return out
