"""The designer's tools as constraint groups: one stroke, placed singularity, boundary or feature
alignment each. ``DesignSession`` sends them as session edits and ``Client.solve(groups=...)``
as ``SolveRequest.constraint_groups``; docs/api.md says how each becomes constraints."""

import numpy as np

from ._stubs import pb

_BOUNDARY_MODES = {"tangent": pb.BOUNDARY_ALIGN_TANGENT, "normal": pb.BOUNDARY_ALIGN_NORMAL}


def stroke(points, *, hard=False, weight=None, anisotropy=None):
    """A stroke through ``points``: an (m, 3) array of 3D points (each snapped to the closest
    point of the surface) or a list of ``(face, (b0, b1, b2))`` surface points; consecutive
    points are joined by the shortest path on the mesh. It constrains every face it crosses to
    its direction there (n-fields: one of the n; tensors: the principal direction with
    eigenvalues 1 and 1 - ``anisotropy``), soft weights by its length in each face, ``weight``
    their mean."""
    message = pb.Stroke(hard=bool(hard))
    for p in points:
        if len(p) == 2 and np.ndim(p[1]) == 1:
            face, b = p
            message.points.add().face_point.CopyFrom(
                pb.SurfacePoint.FacePoint(face=int(face), barycentric=[float(x) for x in b]))
        else:
            x, y, z = (float(c) for c in p)
            message.points.add().position.CopyFrom(pb.Point3(x=x, y=y, z=z))
    if weight is not None:
        message.weight = float(weight)
    if anisotropy is not None:
        message.anisotropy = float(anisotropy)
    return pb.ConstraintGroup(stroke=message)


def singularity(vertex, index, *, hard=False, weight=None):
    """A singularity of ``index`` (whole turns, a multiple of 1/n: 1 for a vector source, 0.25 or
    -0.25 for a 4-field) at interior ``vertex``, by constraints on the faces around it that turn
    the field that much (soft, or ``hard``)."""
    message = pb.PlaceSingularity(vertex=int(vertex), index=float(index), hard=bool(hard))
    if weight is not None:
        message.weight = float(weight)
    return pb.ConstraintGroup(singularity=message)


def align_boundary(mode="tangent", *, loops=None, hard=False, weight=None):
    """The boundary faces (all loops, or the listed loop indices) aligned to their boundary edges
    (``mode="tangent"``) or to the edges' in-plane normals (``"normal"``)."""
    if mode not in _BOUNDARY_MODES:
        raise ValueError("align_boundary: mode must be 'tangent' or 'normal', got %r" % (mode,))
    message = pb.AlignBoundary(mode=_BOUNDARY_MODES[mode], hard=bool(hard))
    message.loops.extend(int(x) for x in (loops or ()))
    if weight is not None:
        message.weight = float(weight)
    return pb.ConstraintGroup(align_boundary=message)


def align_features(angle_degrees=60.0, *, hard=False, weight=None):
    """The faces along sharp edges (normals differing by more than ``angle_degrees``) aligned to
    those edges."""
    message = pb.AlignFeatures(angle_degrees=float(angle_degrees), hard=bool(hard))
    if weight is not None:
        message.weight = float(weight)
    return pb.ConstraintGroup(align_features=message)
