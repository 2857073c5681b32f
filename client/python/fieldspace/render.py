"""Pictures of a mesh and its field with VTK, on machines with no GPU and no display.

:func:`render` draws the surface (plain, or coloured by the field's magnitude or given values)
with glyphs of one length (vectors as arrows, n-fields as n-crosses, tensors as principal
crosses: the maximum direction red, the minimum blue; or ellipses), streamlines, hatching
strokes (fieldspace.streamlines) or a line integral convolution texture, and singular vertices
as spheres coloured by the sign of their index, from an automatic view (:func:`automatic_view`:
up axis and side from the shape's principal axes) or a given camera. :class:`RenderOptions`
holds every option and its default; the command line (``python3 -m fieldspace.render``, which
``fieldspace render`` runs) maps its flags onto it.

VTK is the field's standard library (ParaView, 3D Slicer, PyVista build on it) and Debian ships
it (python3-vtk9); it renders with Mesa's software OpenGL into an off-screen buffer, through a
private Xvfb when there is no DISPLAY (fieldspace.display).
"""

import argparse
import dataclasses
import importlib
import json
import math
import sys

import numpy as np

from . import fields as fl
from . import streamlines as sl
from .display import x_display

# Viridis (matplotlib's default colormap, CC0), 17 samples from 0 to 1; interpolated linearly.
_VIRIDIS = np.array([
    [0.267004, 0.004874, 0.329415], [0.282623, 0.140926, 0.457517],
    [0.253935, 0.265254, 0.529983], [0.206756, 0.371758, 0.553117],
    [0.163625, 0.471133, 0.558148], [0.127568, 0.566949, 0.550556],
    [0.134692, 0.658636, 0.517649], [0.266941, 0.748751, 0.440573],
    [0.477504, 0.821444, 0.318195], [0.741388, 0.873449, 0.149561],
    [0.993248, 0.906157, 0.143936]])
_GRAY = np.array([[0.15, 0.15, 0.15], [0.95, 0.95, 0.95]])

STYLES = ("glyphs", "streamlines", "hatching", "lic", "surface")


def colormap(name_or_table="viridis", samples=256):
    """``(samples, 3)`` RGB in [0, 1]: ``"viridis"``, ``"gray"`` or an ``(k, 3)`` table of
    colours from low to high, interpolated linearly."""
    if isinstance(name_or_table, str):
        tables = {"viridis": _VIRIDIS, "gray": _GRAY}
        if name_or_table not in tables:
            raise ValueError("colormap must be one of %s or a (k, 3) table"
                             % ", ".join(sorted(tables)))
        table = tables[name_or_table]
    else:
        table = np.asarray(name_or_table, dtype=np.float64)
        if table.ndim != 2 or table.shape[1] != 3 or len(table) < 2:
            raise ValueError("a colormap table is (k >= 2, 3)")
    x = np.linspace(0.0, 1.0, len(table))
    t = np.linspace(0.0, 1.0, samples)
    return np.stack([np.interp(t, x, table[:, c]) for c in range(3)], axis=1)


def map_colors(values, value_range, table="viridis", samples=256):
    """The colours (``(len(values), 3)`` in [0, 1]) :func:`render` gives ``values`` for a
    ``value_range``: the lookup table's entry of each clamped value."""
    lut = colormap(table, samples)
    lo, hi = value_range
    t = (np.asarray(values, dtype=np.float64) - lo) / (hi - lo if hi > lo else 1.0)
    index = np.clip(np.floor(t * samples), 0, samples - 1).astype(int)
    return lut[index]


def glyph_faces(V, F, count, rng=0, allowed=None):
    """About ``count`` faces spread evenly over the surface (one per cell of a 3D grid whose
    spacing is ``sqrt(area / count)``, picked at random in the cell), for glyphs."""
    V, F = fl.as_mesh(V, F)
    if allowed is None:
        allowed = np.ones(len(F), dtype=bool)
    candidates = np.nonzero(allowed)[0]
    if len(candidates) <= count:
        return candidates
    rng = np.random.default_rng(rng)
    area = float(fl.face_areas(V, F)[candidates].sum())
    centers = V[F[candidates]].mean(axis=1)
    spacing = math.sqrt(area / count)
    chosen = candidates
    for _ in range(8):
        cells = np.floor(centers / spacing).astype(np.int64)
        order = rng.permutation(len(candidates))
        _, first = np.unique(cells[order], axis=0, return_index=True)
        chosen = candidates[order[first]]
        if len(chosen) <= 1.25 * count:
            break
        spacing *= math.sqrt(len(chosen) / count)
    return np.sort(chosen)


def _segments_polydata(starts, ends, colors):
    from vtkmodules.util.numpy_support import numpy_to_vtk, numpy_to_vtkIdTypeArray
    from vtkmodules.vtkCommonCore import vtkPoints
    from vtkmodules.vtkCommonDataModel import vtkCellArray, vtkPolyData

    k = len(starts)
    pts = np.empty((2 * k, 3))
    pts[0::2], pts[1::2] = starts, ends
    points = vtkPoints()
    points.SetData(numpy_to_vtk(pts, deep=True))
    cells = vtkCellArray()
    conn = np.arange(2 * k, dtype=np.int64)
    offsets = np.arange(0, 2 * k + 1, 2, dtype=np.int64)
    cells.SetData(numpy_to_vtkIdTypeArray(offsets, deep=True),
                  numpy_to_vtkIdTypeArray(conn, deep=True))
    poly = vtkPolyData()
    poly.SetPoints(points)
    poly.SetLines(cells)
    rgb = numpy_to_vtk(np.ascontiguousarray((np.clip(colors, 0, 1) * 255).astype(np.uint8)),
                       deep=True)
    rgb.SetName("colors")
    poly.GetCellData().SetScalars(rgb)
    return poly


def _polylines_polydata(lines, offset_normals=None):
    from vtkmodules.util.numpy_support import numpy_to_vtk, numpy_to_vtkIdTypeArray
    from vtkmodules.vtkCommonCore import vtkPoints
    from vtkmodules.vtkCommonDataModel import vtkCellArray, vtkPolyData

    pts = np.vstack(lines) if lines else np.zeros((0, 3))
    counts = np.array([len(a) for a in lines], dtype=np.int64)
    points = vtkPoints()
    points.SetData(numpy_to_vtk(np.ascontiguousarray(pts), deep=True))
    cells = vtkCellArray()
    offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    cells.SetData(numpy_to_vtkIdTypeArray(offsets, deep=True),
                  numpy_to_vtkIdTypeArray(np.arange(len(pts), dtype=np.int64), deep=True))
    poly = vtkPolyData()
    poly.SetPoints(points)
    poly.SetLines(cells)
    return poly


def _glyph_segments(V, F, a, kind, faces, arm, by_magnitude, tensor_glyph="cross"):
    """Segments (starts, ends, colours) of the glyphs at ``faces``, face-major (the segments
    of each glyph together, in the order of ``faces``); ``arm`` the longest arm. Every glyph
    gets the full length unless ``by_magnitude`` (then its length is its magnitude over the
    largest one); a tensor's smaller arm is its principal values' ratio of the larger one."""
    normals = fl.face_normals(V, F)[faces]
    centers = V[F[faces]].mean(axis=1)
    black = np.array([0.05, 0.05, 0.05])
    starts, ends, colors = [], [], []

    def scales(length, full):
        # Factor per glyph turning a direction of ``length`` into one of length ``full``
        # (times its share of the largest length when drawn by magnitude).
        top = length.max() if len(length) and length.max() > 0 else 1.0
        share = length / top if by_magnitude else 1.0
        return np.where(length > 0, share * full / np.where(length > 0, length, 1.0), 0.0)

    if kind == fl.VECTOR:
        v = a[faces]
        d = v * scales(np.linalg.norm(v, axis=1), arm)[:, None]
        tail = centers - 0.5 * d
        tip = centers + 0.5 * d
        side = np.cross(normals, d)
        starts += [tail, tip, tip]
        ends += [tip, tip - 0.3 * d + 0.15 * side, tip - 0.3 * d - 0.15 * side]
        colors += [black] * 3
    elif kind == fl.NFIELD:
        dirs = a[faces]
        scale = scales(np.linalg.norm(dirs[:, 0], axis=1), 0.5 * arm)
        for k in range(dirs.shape[1]):
            starts.append(centers)
            ends.append(centers + dirs[:, k] * scale[:, None])
            colors.append(black)
    else:
        values, directions = fl.principal(V, F[faces], a[faces])
        palette = (np.array([0.8, 0.1, 0.1]), np.array([0.1, 0.2, 0.85]))
        largest = np.abs(values).max(axis=1)
        full = scales(largest, 0.5 * arm)
        halves = [np.abs(values[:, j]) * full for j in range(2)]
        if tensor_glyph == "ellipse":
            # Semi-axes |k1| d1 and |k2| d2 (scaled), 24 segments, coloured by the sign of k1.
            t = np.linspace(0.0, 2.0 * math.pi, 25)
            ring = (np.cos(t)[None, :, None] * (directions[:, 0] * halves[0][:, None])[:, None]
                    + np.sin(t)[None, :, None] * (directions[:, 1] * halves[1][:, None])[:, None]
                    + centers[:, None, :])
            starts.append(ring[:, :-1].reshape(-1, 3))
            ends.append(ring[:, 1:].reshape(-1, 3))
            sign = np.repeat(values[:, 0] >= 0, 24)
            colors.append(np.where(sign[:, None], palette[0], palette[1]))
        else:
            for j in range(2):
                d = directions[:, j] * halves[j][:, None]
                starts.append(centers - d)
                ends.append(centers + d)
                colors.append(palette[j])
    if kind == fl.TENSOR and tensor_glyph == "ellipse":
        return starts[0], ends[0], colors[0]
    # Blocks of one segment per glyph -> face-major order (all segments of glyph 0 first).
    count = len(faces)

    def face_major(blocks):
        stacked = np.stack([np.broadcast_to(b, (count, 3)) for b in blocks], axis=1)
        return stacked.reshape(-1, 3)

    return face_major(starts), face_major(ends), face_major(colors)


# The automatic view looks at the shape from the side of its thinnest principal axis, turned by
# these angles (degrees) about the up axis and above the horizon: a three-quarter view from a
# little above, never from above or below.
_VIEW_AZIMUTH = 30.0
_VIEW_ELEVATION = 15.0


def principal_axes(V, F):
    """Principal axes of the surface: ``(center, axes, extents)``, ``axes`` ``(3, 3)`` with one
    unit axis per row from the longest to the shortest, ``extents`` the standard deviations
    along them. Vertices are weighted by a third of the area of their faces, so the answer is
    the surface's, not its sampling's."""
    V, F = fl.as_mesh(V, F)
    return _principal_axes(V, F, _areas_and_normals(V, F)[0])


def _areas_and_normals(V, F):
    """Face areas ``(F,)`` and unit normals ``(F, 3)`` from one cross product (those of
    fieldspace.fields, which take one each: this is for large meshes)."""
    c = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    length = np.linalg.norm(c, axis=1)
    return 0.5 * length, c / np.where(length > 0, length, 1.0)[:, None]


def _principal_axes(V, F, areas):
    weights = np.bincount(F.reshape(-1), weights=np.repeat(areas / 3.0, 3), minlength=len(V))
    total = weights.sum()
    if total <= 0:
        weights, total = np.ones(len(V)), float(len(V))
    center = weights @ V / total
    rel = V - center
    values, vectors = np.linalg.eigh((rel * weights[:, None]).T @ rel / total)
    order = np.argsort(values)[::-1]
    return center, vectors[:, order].T, np.sqrt(np.maximum(values[order], 0.0))


def base_area(V, F, up):
    """The share of the surface's area that is a flat base below it along ``up``: faces whose
    normal is within 10 degrees of ``-up`` and whose corners all lie in the lowest 0.2% of the
    height (a vase's foot, a bust's cut). A smooth convex bottom scores at most about 0.4%
    (twice the height share), a cut base much more."""
    V, F = fl.as_mesh(V, F)
    return _base_area(V, F, *_areas_and_normals(V, F), up)


def _base_area(V, F, areas, normals, up):
    up = np.asarray(up, dtype=np.float64)
    height = V @ up
    low = height[F].max(axis=1) <= height.min() + 0.002 * (height.max() - height.min())
    down = normals @ up < -math.cos(math.radians(10.0))
    total = areas.sum()
    return float(areas[low & down].sum() / total) if total > 0 else 0.0


def automatic_view(V, F):
    """The automatic camera's ``(direction, view_up)``: the side the camera looks from and the
    picture's up, both unit 3-vectors.

    Scans are stored with y or z up. The up axis is the one of the two that a flat base faces
    away from (:func:`base_area`: at least 0.6% of the area, 3 times a flat top's, so that a
    plate's sides are no base, and 3 times the other axis's); without
    one, the one closer to the plane of the shape's two longest principal axes (more
    perpendicular to the thinnest one, by more than 0.25 in cosine), else y. The camera looks
    along the thinnest principal axis made horizontal (the largest silhouette; the longer
    remaining one when the thinnest is the up axis) from the front, the side of ``x cross up``
    (+z for y up, -y for z up), turned by 30 degrees about the up axis and raised by 15 degrees:
    never from above or below.
    """
    V, F = fl.as_mesh(V, F)
    areas, normals = _areas_and_normals(V, F)
    _, axes, _ = _principal_axes(V, F, areas)
    thinnest = axes[2]
    candidates = (np.array([0.0, 1.0, 0.0]), np.array([0.0, 0.0, 1.0]))
    bases = []
    for c in candidates:
        # A base counts when the shape has no such flat face on top (a plate has both).
        below, above = (_base_area(V, F, areas, normals, s * c) for s in (1.0, -1.0))
        bases.append(below if below >= 3.0 * above else 0.0)
    across = [abs(float(c @ thinnest)) for c in candidates]
    if max(bases) >= 0.006 and max(bases) >= 3.0 * min(bases):
        up = candidates[int(np.argmax(bases))]
    elif abs(across[0] - across[1]) > 0.25:
        up = candidates[int(np.argmin(across))]
    else:
        up = candidates[0]
    # The thinnest principal axis that is not (nearly) the up axis, made horizontal.
    for axis in (axes[2], axes[1]):
        side = axis - (axis @ up) * up
        if np.linalg.norm(side) > 0.5:
            break
    side /= np.linalg.norm(side)
    front = np.cross([1.0, 0.0, 0.0], up)
    if side @ front < -1e-9 or (abs(side @ front) <= 1e-9 and side[0] < 0):
        side = -side
    az, el = math.radians(_VIEW_AZIMUTH), math.radians(_VIEW_ELEVATION)
    turned = math.cos(az) * side + math.sin(az) * np.cross(up, side)
    direction = math.cos(el) * turned + math.sin(el) * up
    return direction / np.linalg.norm(direction), up


def _camera_frame(cam):
    position = np.array(cam.GetPosition())
    forward = np.array(cam.GetFocalPoint()) - position
    forward /= np.linalg.norm(forward)
    up = np.array(cam.GetViewUp())
    up -= np.dot(up, forward) * forward
    up /= np.linalg.norm(up)
    return position, forward, up, np.cross(forward, up)


def _fit_view(cam, points, aspect, fill):
    """Centres ``points`` in the view and narrows the view angle until they fill ``fill`` of
    its height or width, whichever limits (the automatic camera starts from VTK's
    bounding-sphere framing, which leaves wide margins and need not centre the silhouette)."""
    for _ in range(3):
        position, forward, up, right = _camera_frame(cam)
        rel = points - position
        depth = rel @ forward
        if np.any(depth <= 0):
            return
        x, y = (rel @ right) / depth, (rel @ up) / depth
        # Turn the camera (same position) towards the middle of the silhouette's tangents.
        mx, my = 0.5 * (x.max() + x.min()), 0.5 * (y.max() + y.min())
        distance = np.linalg.norm(np.array(cam.GetFocalPoint()) - position)
        target = forward + mx * right + my * up
        cam.SetFocalPoint(*(position + distance * target / np.linalg.norm(target)))
        cam.OrthogonalizeViewUp()
    position, forward, up, right = _camera_frame(cam)
    rel = points - position
    depth = rel @ forward
    x, y = (rel @ right) / depth, (rel @ up) / depth
    need = max(0.5 * (y.max() - y.min()), 0.5 * (x.max() - x.min()) / aspect)
    angle = 2.0 * math.degrees(math.atan(need / fill))
    cam.SetViewAngle(min(max(angle, 1.0), 120.0))


def _apply_camera(renderer, camera, bounds, fit_points, aspect, fill, automatic):
    """Sets the renderer's camera from ``camera`` (None: ``automatic``, a (direction, view_up)
    pair) and returns its state."""
    cam = renderer.GetActiveCamera()
    camera = dict(camera or {})
    unknown = set(camera) - set(CAMERA_KEYS)
    if unknown:
        raise ValueError("unknown camera keys: %s (known: %s)"
                         % (", ".join(sorted(unknown)), ", ".join(CAMERA_KEYS)))
    lo, hi = np.array(bounds[0::2]), np.array(bounds[1::2])
    center = 0.5 * (lo + hi)
    if "view_angle" in camera:
        cam.SetViewAngle(float(camera["view_angle"]))
    if "position" in camera:
        cam.SetFocalPoint(*map(float, camera.get("focal_point", center)))
        cam.SetPosition(*map(float, camera["position"]))
        cam.SetViewUp(*map(float, camera.get("view_up", automatic[1])))
        if "parallel_scale" in camera:
            cam.ParallelProjectionOn()
            cam.SetParallelScale(float(camera["parallel_scale"]))
        else:
            renderer.ResetCameraClippingRange()
    else:
        direction = np.asarray(camera.get("direction", automatic[0]), dtype=np.float64)
        if not np.linalg.norm(direction) > 0:
            raise ValueError("camera direction must be a nonzero 3-vector")
        direction = direction / np.linalg.norm(direction)
        up = np.asarray(camera.get("view_up", automatic[1]), dtype=np.float64)
        if abs(np.dot(up, direction)) > 0.99 * np.linalg.norm(up):
            up = np.array([0.0, 1.0, 0.0]) if abs(direction[1]) < 0.9 else np.array([0, 0, 1.0])
        focal = np.asarray(camera.get("focal_point", center), dtype=np.float64)
        cam.SetFocalPoint(*focal)
        cam.SetPosition(*(focal + direction))
        cam.SetViewUp(*up)
        if "parallel_scale" in camera:
            cam.ParallelProjectionOn()
        renderer.ResetCamera(bounds)
        if "parallel_scale" in camera:
            cam.SetParallelScale(float(camera["parallel_scale"]))
        elif "view_angle" not in camera and fit_points is not None and len(fit_points):
            _fit_view(cam, fit_points, aspect, fill)
    if "azimuth" in camera:
        cam.Azimuth(float(camera["azimuth"]))
    if "elevation" in camera:
        cam.Elevation(float(camera["elevation"]))
        cam.OrthogonalizeViewUp()
    if "zoom" in camera:
        cam.Zoom(float(camera["zoom"]))
    renderer.ResetCameraClippingRange(bounds)
    state = {"position": tuple(cam.GetPosition()), "focal_point": tuple(cam.GetFocalPoint()),
             "view_up": tuple(cam.GetViewUp()), "view_angle": cam.GetViewAngle()}
    if cam.GetParallelProjection():
        state["parallel_scale"] = cam.GetParallelScale()
    return state


def project(points, camera, size):
    """Pixel coordinates ``(k, 2)`` (column, row; row 0 at the top, pixel centres at .5) of
    ``points`` ``(k, 3)`` in a picture of ``size`` (width, height) taken with ``camera`` (the
    camera state :func:`render` returns)."""
    from vtkmodules.vtkRenderingCore import vtkCamera
    width, height = size
    cam = vtkCamera()
    cam.SetPosition(*camera["position"])
    cam.SetFocalPoint(*camera["focal_point"])
    cam.SetViewUp(*camera["view_up"])
    cam.SetViewAngle(camera["view_angle"])
    if "parallel_scale" in camera:
        cam.ParallelProjectionOn()
        cam.SetParallelScale(camera["parallel_scale"])
    return _project(cam, points, width, height)


def _project(cam, points, width, height):
    matrix = cam.GetCompositeProjectionTransformMatrix(width / height, -1.0, 1.0)
    P = np.array([[matrix.GetElement(i, j) for j in range(4)] for i in range(4)])
    h = np.hstack([np.asarray(points, dtype=np.float64).reshape(-1, 3),
                   np.ones((len(points), 1))]) @ P.T
    ndc = h[:, :2] / h[:, 3:4]
    return np.stack([(ndc[:, 0] + 1.0) * width / 2.0, (1.0 - ndc[:, 1]) * height / 2.0], axis=1)


def _grab(window, vtkWindowToImageFilter, vtk_to_numpy):
    """Renders ``window`` and returns its pixels ``(h, w, 3)`` uint8, top row first."""
    window.Render()
    grab = vtkWindowToImageFilter()
    grab.SetInput(window)
    grab.SetInputBufferTypeToRGB()
    grab.ReadFrontBufferOff()
    grab.Update()
    image = grab.GetOutput()
    w, h, _ = image.GetDimensions()
    pixels = vtk_to_numpy(image.GetPointData().GetScalars()).reshape(h, w, -1)[::-1]
    return np.ascontiguousarray(pixels[:, :, :3])


IMAGE_FORMATS = {".png": "PNG", ".jpg": "JPEG", ".jpeg": "JPEG"}


def image_format(path):
    """The picture format of ``path`` by its extension (``"PNG"`` or ``"JPEG"``); any other
    extension is refused (ValueError) before anything is drawn."""
    import os
    ext = os.path.splitext(str(path))[1].lower()
    if ext not in IMAGE_FORMATS:
        raise ValueError("cannot write a picture to %s: the extension must be one of %s"
                         % (path, ", ".join(IMAGE_FORMATS)))
    return IMAGE_FORMATS[ext]


def write_image(path, pixels):
    """Writes ``pixels`` (``(h, w, 3)`` uint8, top row first) as PNG or JPEG (quality 95), by
    the extension of ``path`` (:func:`image_format`)."""
    from vtkmodules.util.numpy_support import numpy_to_vtk
    from vtkmodules.vtkCommonDataModel import vtkImageData
    from vtkmodules.vtkIOImage import vtkJPEGWriter, vtkPNGWriter
    kind = image_format(path)
    h, w, _ = pixels.shape
    image = vtkImageData()
    image.SetDimensions(w, h, 1)
    data = numpy_to_vtk(np.ascontiguousarray(pixels[::-1].reshape(-1, 3)), deep=True)
    image.GetPointData().SetScalars(data)
    if kind == "JPEG":
        writer = vtkJPEGWriter()
        writer.SetQuality(95)
        writer.ProgressiveOff()
    else:
        writer = vtkPNGWriter()
    writer.SetFileName(str(path))
    writer.SetInputData(image)
    writer.Write()
    if writer.GetErrorCode():
        raise OSError("could not write %s" % path)


def family_directions(V, F, a, kind):
    """Unit line directions per face ``(F, m, 3)``: one per family of lines (vector: the
    vector; n-field: n / 2 directions for even n, n for odd n; tensor: max and min principal
    directions)."""
    if kind == fl.VECTOR:
        d = a[:, None, :]
    elif kind == fl.NFIELD:
        n = a.shape[1]
        d = a[:, :n // 2] if n % 2 == 0 else a
    else:
        d = fl.principal(V, F, a)[1]
    length = np.linalg.norm(d, axis=2)
    return d / np.where(length > 0, length, 1.0)[:, :, None]


def lic(directions, mask, length=20, rng=0, noise=None):
    """Line integral convolution in image space.

    ``directions``: ``(m, h, w, 2)`` unit screen directions of m line families (sign
    irrelevant), ``mask``: ``(h, w)`` pixels that carry a direction. Every pixel of the mask
    averages white noise along the lines through it, ``length`` pixels each way, for each family
    it starts on; a step continues along whichever family is closest to the direction it came
    with (so crossing families need no consistent labelling). Returns ``(h, w)`` in [0, 1].
    """
    m, h, w, _ = directions.shape
    rng = np.random.default_rng(rng)
    if noise is None:
        noise = rng.random((h, w))
    ys, xs = np.nonzero(mask)
    total = np.zeros(len(ys))
    count = np.zeros(len(ys))
    for family in range(m):
        for sign in (1.0, -1.0):
            px, py = xs + 0.5, ys + 0.5
            d = directions[family, ys, xs] * sign
            alive = np.ones(len(ys), dtype=bool)
            if sign > 0:
                total += noise[ys, xs]
                count += 1.0
            for _ in range(length):
                px = px + d[:, 0]
                py = py - d[:, 1]  # screen y goes up, rows go down
                ix, iy = np.floor(px).astype(np.int64), np.floor(py).astype(np.int64)
                inside = (ix >= 0) & (ix < w) & (iy >= 0) & (iy < h)
                alive &= inside
                ix, iy = np.clip(ix, 0, w - 1), np.clip(iy, 0, h - 1)
                alive &= mask[iy, ix]
                if not alive.any():
                    break
                cand = directions[:, iy, ix]  # (m, k, 2)
                dots = np.einsum("mkc,kc->mk", cand, d)
                best = np.argmax(np.abs(dots), axis=0)
                k = np.arange(len(best))
                new = cand[best, k] * np.sign(dots[best, k])[:, None]
                d = np.where(alive[:, None], new, d)
                total += np.where(alive, noise[iy, ix], 0.0)
                count += alive
    out = np.zeros((h, w))
    out[ys, xs] = total / np.maximum(count, 1.0)
    return out


def _screen_directions(renderer, V, F, dirs, width, height):
    """Per face and family, the unit screen direction (x right, y up) of the 3D direction at
    the face's centre, by the camera's projection."""
    cam = renderer.GetActiveCamera()
    centers = V[F].mean(axis=1)
    eps = 1e-3 * float(np.linalg.norm(np.ptp(V, axis=0)))
    base = _project(cam, centers, width, height)
    out = np.zeros(dirs.shape[:2] + (2,))
    for j in range(dirs.shape[1]):
        s = _project(cam, centers + eps * dirs[:, j], width, height) - base
        s[:, 1] = -s[:, 1]  # rows go down, screen y up
        norm = np.linalg.norm(s, axis=1)
        out[:, j] = s / np.where(norm > 0, norm, 1.0)[:, None]
    return out


def _lic_pass(window, renderer, legend, actor, mapper, occluder, V, F, a, kind, pixels, width,
              height, length, rng, numpy_to_vtk, vtkWindowToImageFilter, vtk_to_numpy):
    """Renders each line family's screen directions into the picture's pixels (doubled angle
    in red and green, blue marks the surface; ``occluder``, the singularity spheres or None,
    black in front of it) and modulates ``pixels`` by their LIC."""
    dirs = family_directions(V, F, a, kind)
    screen = _screen_directions(renderer, V, F, dirs, width, height)
    # The mapper draws a copy of the surface (with vertex normals) when lighting is on.
    cd = mapper.GetInput().GetCellData()
    saved_scalars = cd.GetScalars()
    saved = (mapper.GetScalarVisibility(), mapper.GetColorMode(), actor.GetVisibility())
    prop = actor.GetProperty()
    lighting = (prop.GetAmbient(), prop.GetDiffuse(), prop.GetSpecular())
    others = [x for x in _actors(renderer) if x is not actor and x is not occluder]
    visible = [x.GetVisibility() for x in others]
    for x in others:
        x.VisibilityOff()
    if occluder is not None:
        occluder.GetMapper().ScalarVisibilityOff()
        occluder.GetProperty().SetColor(0.0, 0.0, 0.0)
        occluder.GetProperty().LightingOff()
    if legend is not None:
        legend_background = legend.GetBackground()
        legend.SetBackground(0.0, 0.0, 0.0)
        legend_actors = legend.GetActors2D()
        legend_actors.InitTraversal()
        bars = [legend_actors.GetNextActor2D() for _ in range(legend_actors.GetNumberOfItems())]
        for bar in bars:
            bar.VisibilityOff()
    background = renderer.GetBackground()
    renderer.SetBackground(0.0, 0.0, 0.0)
    prop.SetAmbient(1.0)
    prop.SetDiffuse(0.0)
    prop.SetSpecular(0.0)
    mapper.ScalarVisibilityOn()
    mapper.SetColorModeToDirectScalars()
    mapper.SetScalarModeToUseCellData()
    images = []
    try:
        for j in range(dirs.shape[1]):
            angle = 2.0 * np.arctan2(screen[:, j, 1], screen[:, j, 0])
            rgb = np.stack([0.5 + 0.5 * np.cos(angle), 0.5 + 0.5 * np.sin(angle),
                            np.ones(len(angle))], axis=1)
            codes = numpy_to_vtk(np.round(rgb * 254 + 1).astype(np.uint8), deep=True)
            codes.SetName("lic_directions")
            cd.SetScalars(codes)
            mapper.GetInput().Modified()
            images.append(_grab(window, vtkWindowToImageFilter, vtk_to_numpy).astype(float))
    finally:
        renderer.SetBackground(*background)
        cd.SetScalars(saved_scalars)
        mapper.SetScalarVisibility(saved[0])
        mapper.SetColorMode(saved[1])
        prop.SetAmbient(lighting[0])
        prop.SetDiffuse(lighting[1])
        prop.SetSpecular(lighting[2])
        for x, v in zip(others, visible):
            x.SetVisibility(v)
        if occluder is not None:
            occluder.GetMapper().ScalarVisibilityOn()
            occluder.GetProperty().LightingOn()
        if legend is not None:
            legend.SetBackground(*legend_background)
            for bar in bars:
                bar.VisibilityOn()
    mask = np.all([im[:, :, 2] > 127 for im in images], axis=0)
    doubled = np.stack([np.arctan2((im[:, :, 1] - 1) / 254 - 0.5, (im[:, :, 0] - 1) / 254 - 0.5)
                        for im in images])
    half = 0.5 * doubled
    directions = np.stack([np.cos(half), np.sin(half)], axis=-1)
    texture = lic(directions, mask, length=length, rng=rng)
    shade = np.where(mask, 0.25 + 0.75 * stretch_contrast(texture, mask), 1.0)
    return np.clip(pixels * shade[:, :, None], 0, 255).astype(np.uint8)


def stretch_contrast(texture, mask, low=2.0, high=98.0):
    """``texture`` mapped linearly so that its ``low`` and ``high`` percentiles over ``mask``
    become 0 and 1 (clipped). Averaging noise over 2L + 1 pixels shrinks its spread by about
    sqrt(2L + 1), so LIC needs the stretch to be seen."""
    values = texture[mask]
    if not values.size:
        return texture
    lo, hi = np.percentile(values, [low, high])
    if hi <= lo:
        return np.full_like(texture, 0.5)
    return np.clip((texture - lo) / (hi - lo), 0.0, 1.0)


def _actors(renderer):
    actors = renderer.GetActors()
    actors.InitTraversal()
    out = []
    for _ in range(actors.GetNumberOfItems()):
        out.append(actors.GetNextActor())
    return out


CAMERA_KEYS = ("position", "focal_point", "view_up", "view_angle", "parallel_scale",
               "direction", "azimuth", "elevation", "zoom")
COLORS = ("none", "magnitude")
GLYPH_LENGTHS = ("even", "magnitude")
TENSOR_GLYPHS = ("cross", "ellipse")


def _option(default, flag=None, help=None, **argparse_keywords):
    """A RenderOptions field; ``flag``: its option of ``python3 -m fieldspace.render`` (and so
    of ``fieldspace render``), with ``argparse_keywords`` for argparse."""
    metadata = {"flag": flag, "help": help, "argparse": argparse_keywords} if flag else {}
    return dataclasses.field(default=default, metadata=metadata)


def _size(text):
    try:
        w, h = (int(x) for x in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError("size is WIDTHxHEIGHT, e.g. 800x600") from None
    return w, h


@dataclasses.dataclass(frozen=True)
class RenderOptions:
    """How :func:`render` draws: every option with its default, in one place. The command line
    (``python3 -m fieldspace.render``, ``fieldspace render``) has a flag for those that name one;
    ``render(..., name=value)`` overrides any of them for one call.

    - ``style``: ``"glyphs"``, ``"streamlines"``, ``"hatching"`` (many short strokes on a plain
      surface, the paper's Fig. 17), ``"lic"`` (line integral convolution) or ``"surface"``.
    - ``color``: ``"none"`` (a plain ``surface_color`` surface) or ``"magnitude"`` (the field's
      magnitude through ``colormap``); ``scalars`` given to :func:`render` always colour.
    - ``glyph_length``: ``"even"`` (every glyph as long as ``glyph_scale`` allows; a tensor's
      smaller arm in proportion) or ``"magnitude"`` (in proportion to the largest).
    - ``fill``: the share of the picture's limiting dimension the automatic camera gives the mesh.
    """

    style: str = _option("glyphs", "--style", "what to draw", choices=STYLES)
    size: tuple = _option((800, 600), "--size", "WIDTHxHEIGHT", type=_size)
    camera: dict = _option(None, "--camera", "JSON, e.g. '{\"direction\": [0, -1, 0.3]}' or "
                           "position, focal_point, view_up, view_angle, parallel_scale, zoom "
                           "(default: the automatic view)", type=json.loads)
    fill: float = _option(0.8, "--fill", "share of the picture the mesh fills (automatic "
                          "camera)", type=float)
    color: str = _option("none", "--color", "colour the surface by the field's magnitude, or "
                         "not", choices=COLORS)
    colormap: object = _option("viridis", "--colormap", "colormap of --color magnitude",
                               choices=("viridis", "gray"))
    scalar_range: tuple = None
    scalar_bar: bool = _option(False, "--scalar-bar", "add a colour legend",
                               action="store_true")
    title: str = None
    max_glyphs: int = _option(None, "--glyphs", "glyphs at most (about; default one per 600 "
                              "pixels)", type=int)
    glyph_scale: float = _option(1.0, "--glyph-scale", "glyph length factor", type=float)
    glyph_length: str = _option("even", "--glyph-length", "even lengths, or in proportion to "
                                "the magnitude", choices=GLYPH_LENGTHS)
    tensor_glyph: str = _option("cross", "--tensor-glyph", "tensors as principal crosses or "
                                "ellipses", choices=TENSOR_GLYPHS)
    streamline_count: int = _option(None, "--lines", "streamline / hatching seeds (default one "
                                    "per 2500 / 90 pixels)", type=int)
    streamline_length: float = _option(None, "--line-length", "half length of a streamline "
                                       "or hatching stroke (default 12% / 1.2% of the "
                                       "diagonal)", type=float)
    streamline_separation: float = _option(None, "--separation", "streamlines: keep lines of "
                                           "a family this far apart (default: not spaced)",
                                           type=float)
    lic_length: int = _option(None, "--lic-length", "LIC: pixels each way (default a "
                              "thirtieth of the picture)", type=int)
    singularity_radius: float = _option(0.012, "--singularity-radius", "radius of the "
                                        "singularity spheres, share of the diagonal",
                                        type=float)
    lighting: bool = True
    background: tuple = (1.0, 1.0, 1.0)
    surface_color: tuple = None
    line_width: float = None
    line_color: tuple = (0.08, 0.08, 0.08)
    rng: int = _option(0, "--seed", "random seed (glyph places, seeds, LIC noise)", type=int)
    use_display: bool = True

    def __post_init__(self):
        if self.style not in STYLES:
            raise ValueError("style must be one of %s, got %r" % (", ".join(STYLES), self.style))
        for name, allowed in (("color", COLORS), ("glyph_length", GLYPH_LENGTHS),
                              ("tensor_glyph", TENSOR_GLYPHS)):
            if getattr(self, name) not in allowed:
                raise ValueError("%s must be one of %s, got %r"
                                 % (name, ", ".join(allowed), getattr(self, name)))
        try:
            width, height = (int(x) for x in self.size)
        except (TypeError, ValueError):
            raise ValueError("size must be (width, height)") from None
        if not (1 <= width <= 8192 and 1 <= height <= 8192):
            raise ValueError("size must be (width, height) within 1..8192")
        if not 0.05 <= self.fill <= 1.0:
            raise ValueError("fill must be within 0.05..1, got %r" % (self.fill,))
        for name in ("max_glyphs", "streamline_count", "lic_length"):
            value = getattr(self, name)
            if value is not None and value < 1:
                raise ValueError("%s must be at least 1, got %r" % (name, value))
        if not self.singularity_radius > 0:
            raise ValueError("singularity_radius must be positive")

    @property
    def plain_color(self):
        """The surface's colour when it is not coloured by values: warm paper for hatching,
        light grey otherwise."""
        if self.surface_color is not None:
            return tuple(self.surface_color)
        return (0.97, 0.95, 0.9) if self.style == "hatching" else (0.85, 0.85, 0.85)

    @classmethod
    def add_arguments(cls, parser):
        """Adds the options that have a flag to an argparse ``parser`` (defaults: None, so
        :meth:`from_arguments` keeps the dataclass's)."""
        for f in dataclasses.fields(cls):
            if not f.metadata:
                continue
            keywords = dict(f.metadata["argparse"])
            default = f.default
            shown = "x".join(map(str, default)) if f.name == "size" else default
            text = f.metadata["help"]
            if keywords.get("action") != "store_true":
                if "default" not in text:
                    text += " (default: %s)" % ("automatic" if default is None else shown)
                keywords["default"] = None
                if "choices" not in keywords:
                    keywords["metavar"] = f.metadata["flag"][2:].upper().replace("-", "_")
            parser.add_argument(f.metadata["flag"], dest=f.name, help=text.replace("%", "%%"),
                                **keywords)

    @classmethod
    def from_arguments(cls, args):
        """The options of parsed arguments (:meth:`add_arguments`), the rest at defaults."""
        given = {}
        for f in dataclasses.fields(cls):
            value = getattr(args, f.name, None) if f.metadata else None
            if value is not None and value is not False:
                given[f.name] = value
        return cls(**given)


def _facing(V, F, camera):
    """Per face, |cos| of the angle between its normal and the line of sight to its centre
    (the camera state of :func:`_apply_camera`; parallel projections look along one axis)."""
    centers = V[F].mean(axis=1)
    if "parallel_scale" in camera:
        sight = np.array(camera["position"]) - np.array(camera["focal_point"])
        sight = np.broadcast_to(sight / np.linalg.norm(sight), centers.shape)
    else:
        sight = np.array(camera["position"]) - centers
        sight = sight / np.maximum(np.linalg.norm(sight, axis=1), 1e-300)[:, None]
    return np.abs(np.einsum("ij,ij->i", fl.face_normals(V, F), sight))


def _singularity_pairs(singularities):
    """``(vertices, index)`` int arrays from a Singularities answer, ``(vertex, index)`` pairs or
    a dict vertex -> index (fieldspace.export.singularity_pairs); only the signs and relative
    sizes of the indices matter here."""
    if hasattr(singularities, "vertices") and hasattr(singularities, "index"):
        return (np.asarray(singularities.vertices, dtype=np.int64).reshape(-1),
                np.asarray(singularities.index, dtype=np.int64).reshape(-1))
    from .export import singularity_pairs
    pairs = singularity_pairs(singularities)
    return pairs[:, 0], pairs[:, 1]


# Singularity colours by the sign of the index.
POSITIVE_COLOR = (0.9, 0.1, 0.1)
NEGATIVE_COLOR = (0.1, 0.3, 0.95)


def _spheres_polydata(centers, radii, colors):
    """One triangulated sphere per centre, coloured per cell."""
    from vtkmodules.util.numpy_support import numpy_to_vtk, numpy_to_vtkIdTypeArray, vtk_to_numpy
    from vtkmodules.vtkCommonCore import vtkPoints
    from vtkmodules.vtkCommonDataModel import vtkCellArray, vtkPolyData
    from vtkmodules.vtkFiltersSources import vtkSphereSource
    source = vtkSphereSource()
    source.SetThetaResolution(16)
    source.SetPhiResolution(12)
    source.SetRadius(1.0)
    source.Update()
    unit = source.GetOutput()
    P = vtk_to_numpy(unit.GetPoints().GetData()).astype(np.float64)
    T = vtk_to_numpy(unit.GetPolys().GetConnectivityArray()).reshape(-1, 3)
    k = len(centers)
    pts = (P[None] * np.asarray(radii)[:, None, None] + centers[:, None, :]).reshape(-1, 3)
    tris = (T[None] + (np.arange(k) * len(P))[:, None, None]).reshape(-1)
    points = vtkPoints()
    points.SetData(numpy_to_vtk(np.ascontiguousarray(pts), deep=True))
    cells = vtkCellArray()
    offsets = np.arange(0, len(tris) + 1, 3, dtype=np.int64)
    cells.SetData(numpy_to_vtkIdTypeArray(offsets, deep=True),
                  numpy_to_vtkIdTypeArray(tris.astype(np.int64), deep=True))
    poly = vtkPolyData()
    poly.SetPoints(points)
    poly.SetPolys(cells)
    rgb = np.repeat((np.clip(colors, 0, 1) * 255).astype(np.uint8), len(T), axis=0)
    data = numpy_to_vtk(np.ascontiguousarray(rgb), deep=True)
    data.SetName("colors")
    poly.GetCellData().SetScalars(data)
    return poly


def render(V, F, field=None, kind=None, out=None, options=None, scalars=None,
           singularities=None, **overrides):
    """Renders the mesh ``(V, F)`` with ``field`` and writes ``out`` (if given: ``.png``, or
    ``.jpg`` / ``.jpeg`` for JPEG; any other extension is refused before drawing).

    - ``field``/``kind``: as in fieldspace.fields (vectors ``(F, 3)``, n-fields ``(F, n, 3)``,
      tensors ``(F, 3, 3)``), or None for the bare surface.
    - ``options``: a :class:`RenderOptions` (default: its defaults); ``overrides``: any of its
      fields by name, e.g. ``render(V, F, field, style="lic", size=(400, 300))``.
    - ``scalars``: ``(F,)`` values that colour the surface (through ``colormap`` over
      ``scalar_range``, default their min and max; a constant gets the colormap's middle);
      with ``color="magnitude"`` the field's magnitude (fieldspace.fields.magnitude).
    - ``singularities``: spheres at singular vertices, red for a positive index, blue for a
      negative one, radius ``singularity_radius`` times the bounding box diagonal (times the
      square root of the index over the smallest one): a Singularities answer
      (``client.singularities``) or ``(vertex, index)`` pairs.
    - Styles: ``"glyphs"``: about ``max_glyphs`` glyphs spread evenly (arrows, n-crosses, tensor
      crosses with the maximum direction red and the minimum blue, or ellipses with semi-axes
      ``|k1| d1``, ``|k2| d2``, red where ``k1 >= 0``). ``"streamlines"``: ``streamline_count``
      seeds (default one per 2500 pixels), half length ``streamline_length`` (12% of the
      diagonal), every line family. ``"hatching"``: the same with one short stroke (half length
      1.2% of the diagonal) per 90 pixels on a plain surface. ``"lic"``: line integral
      convolution in image space (:func:`lic`, ``lic_length`` pixels each way), contrast
      stretched (:func:`stretch_contrast`). ``"surface"``.
    - ``camera``: None: the automatic view (:func:`automatic_view`: up and side from the
      principal axes), centred, the mesh filling ``fill`` of the picture; or a dict with
      ``position``, ``focal_point``, ``view_up``, ``view_angle`` (degrees) and
      ``parallel_scale`` (parallel projection: half the view's height), or ``direction``
      (automatic framing from that side; ``view_up`` defaults to the automatic one), plus
      ``azimuth``, ``elevation``, ``zoom``.
    - ``lighting=False`` shows the colormap's colours unshaded (flat ambient light).
    - ``use_display``: use ``DISPLAY`` when it is set; else (or when False) a private Xvfb.

    Returns a dict: ``image`` (``(h, w, 3)`` uint8, top row first), ``camera`` (the camera
    used, in the dict form above), ``scalar_range``, ``glyphs`` (count), ``lines`` (count),
    ``singularities`` (spheres drawn).
    """
    from vtkmodules.util.numpy_support import numpy_to_vtk, numpy_to_vtkIdTypeArray, vtk_to_numpy
    from vtkmodules.vtkCommonCore import vtkLookupTable, vtkPoints
    from vtkmodules.vtkCommonDataModel import vtkCellArray, vtkPolyData
    from vtkmodules.vtkRenderingCore import (vtkActor, vtkPolyDataMapper, vtkRenderer,
                                             vtkRenderWindow, vtkWindowToImageFilter)
    # Side-effect imports: the OpenGL implementations and the text renderer (scalar bar).
    importlib.import_module("vtkmodules.vtkRenderingOpenGL2")
    importlib.import_module("vtkmodules.vtkRenderingFreeType")

    o = options if options is not None else RenderOptions()
    if not isinstance(o, RenderOptions):
        raise TypeError("options must be a RenderOptions")
    if overrides:
        unknown = set(overrides) - {f.name for f in dataclasses.fields(RenderOptions)}
        if unknown:
            raise TypeError("render() got unknown options: %s" % ", ".join(sorted(unknown)))
        o = dataclasses.replace(o, **overrides)
    if out is not None:
        image_format(out)
    width, height = (int(o.size[0]), int(o.size[1]))
    V, F = fl.as_mesh(V, F)
    a = None
    if field is not None:
        a, kind, n = fl.check_field(V, F, field, kind)
    if scalars is None and a is not None and o.color == "magnitude":
        scalars = fl.magnitude(a, kind)
    scalar_range = o.scalar_range
    if scalars is not None:
        scalars = np.asarray(scalars, dtype=np.float64).reshape(-1)
        if len(scalars) != len(F):
            raise ValueError("scalars: %d values for %d faces" % (len(scalars), len(F)))
        if scalar_range is None:
            scalar_range = (float(scalars.min()), float(scalars.max())) if len(scalars) \
                else (0.0, 1.0)
        lo, hi = float(scalar_range[0]), float(scalar_range[1])
        if hi - lo <= 1e-9 * max(abs(lo), abs(hi)) or hi <= lo:
            # A constant (up to rounding) shows the colormap's middle, not amplified noise.
            middle = 0.5 * (lo + hi)
            half = max(0.5 * abs(middle), 0.5)
            lo, hi = middle - half, middle + half
        scalar_range = (lo, hi)
    sing_vertices = sing_index = None
    if singularities is not None:
        sing_vertices, sing_index = _singularity_pairs(singularities)
        keep = sing_index != 0
        sing_vertices, sing_index = sing_vertices[keep], sing_index[keep]
        if len(sing_vertices) and (sing_vertices.min() < 0 or sing_vertices.max() >= len(V)):
            raise ValueError("singularities: vertex out of range 0..%d" % (len(V) - 1))

    diag = float(np.linalg.norm(V.max(axis=0) - V.min(axis=0))) if len(V) else 1.0

    # The surface.
    points = vtkPoints()
    points.SetData(numpy_to_vtk(V, deep=True))
    tris = vtkCellArray()
    tris.SetData(numpy_to_vtkIdTypeArray(np.arange(0, 3 * len(F) + 1, 3, dtype=np.int64),
                                         deep=True),
                 numpy_to_vtkIdTypeArray(F.reshape(-1).astype(np.int64), deep=True))
    surface = vtkPolyData()
    surface.SetPoints(points)
    surface.SetPolys(tris)
    mapper = vtkPolyDataMapper()
    mapper.SetResolveCoincidentTopologyToPolygonOffset()
    mapper.SetRelativeCoincidentTopologyPolygonOffsetParameters(1.0, 2.0)
    actor = vtkActor()
    actor.SetMapper(mapper)
    lut = None
    if scalars is not None:
        values = numpy_to_vtk(np.ascontiguousarray(scalars), deep=True)
        values.SetName("magnitude")
        surface.GetCellData().SetScalars(values)
        lut = vtkLookupTable()
        table = colormap(o.colormap)
        lut.SetNumberOfTableValues(len(table))
        for i, c in enumerate(table):
            lut.SetTableValue(i, float(c[0]), float(c[1]), float(c[2]), 1.0)
        lut.SetRange(*scalar_range)
        lut.Build()
        mapper.SetLookupTable(lut)
        mapper.SetScalarModeToUseCellData()
        mapper.SetScalarRange(*scalar_range)
        mapper.ScalarVisibilityOn()
    else:
        mapper.ScalarVisibilityOff()
        actor.GetProperty().SetColor(*o.plain_color)
    if o.lighting:
        # Smooth shading from vertex normals; the colours stay per face.
        from vtkmodules.vtkFiltersCore import vtkPolyDataNormals
        normals = vtkPolyDataNormals()
        normals.SetInputData(surface)
        normals.SplittingOff()
        normals.ConsistencyOff()
        normals.AutoOrientNormalsOff()
        normals.ComputeCellNormalsOff()
        normals.Update()
        mapper.SetInputData(normals.GetOutput())
    else:
        mapper.SetInputData(surface)
    prop = actor.GetProperty()
    if o.lighting:
        prop.SetAmbient(0.25)
        prop.SetDiffuse(0.75)
        prop.SetSpecular(0.1)
        prop.SetInterpolationToGouraud()
    else:
        prop.SetAmbient(1.0)
        prop.SetDiffuse(0.0)
        prop.SetSpecular(0.0)
        prop.SetInterpolationToFlat()

    # The camera first: glyphs are placed where it sees the surface.
    renderer = vtkRenderer()
    legend_split = 0.86 if o.scalar_bar and lut is not None else None
    aspect = width / height * (legend_split or 1.0)
    automatic = automatic_view(V, F) if len(F) else ((1.0, -1.6, 0.9), (0.0, 0.0, 1.0))
    state = _apply_camera(renderer, o.camera, surface.GetBounds(), V, aspect, o.fill, automatic)

    overlays = []
    n_glyphs, n_lines = 0, 0
    line_width = o.line_width if o.line_width is not None else \
        (1.0 if o.style == "hatching" else 1.5)
    if a is not None and o.style == "glyphs":
        mag = fl.magnitude(a, kind)
        allowed = mag > 1e-12 * (mag.max() if len(mag) else 0.0)
        count = o.max_glyphs or max(50, width * height // 600)
        # Glyphs on faces seen at a grazing angle (within 24 degrees) fringe the outline:
        # they are left out, at the density the whole surface would have.
        areas = fl.face_areas(V, F)
        seen = _facing(V, F, state) > 0.4
        share = float(areas[allowed & seen].sum() / max(areas[allowed].sum(), 1e-300))
        faces = glyph_faces(V, F, max(1, round(count * share)), rng=o.rng,
                            allowed=allowed & seen)
        arm = 0.8 * o.glyph_scale * math.sqrt(float(areas[allowed & seen].sum())
                                              / max(len(faces), 1))
        if len(faces):
            starts, ends, colors = _glyph_segments(V, F, a, kind, faces, arm,
                                                   o.glyph_length == "magnitude", o.tensor_glyph)
            # Lift glyphs off the surface (along their face's normal) so that the depth test
            # keeps them where the surface curves away under their flat arms.
            lift = max(0.002 * diag, 0.1 * arm)
            per_glyph = len(starts) // len(faces)
            offset = lift * np.repeat(fl.face_normals(V, F)[faces], per_glyph, axis=0)
            overlays.append(_segments_polydata(starts + offset, ends + offset, colors))
            n_glyphs = len(faces)
    elif a is not None and o.style in ("streamlines", "hatching"):
        m = 1 if kind == fl.VECTOR else (4 if kind == fl.TENSOR else a.shape[1])
        families = len(sl.line_families(kind, m))
        if o.style == "hatching":
            count = o.streamline_count or max(20, width * height // (90 * families))
            length = o.streamline_length or 0.012 * diag
        else:
            count = o.streamline_count or max(20, width * height // (2500 * families))
            length = o.streamline_length or 0.12 * diag
        seeds = None
        if o.style == "hatching":
            # Strokes spread evenly (one seed face per grid cell, as glyphs): random seeds clump.
            mag = fl.magnitude(a, kind)
            faces = glyph_faces(V, F, count, rng=o.rng,
                                allowed=mag > 1e-6 * (mag.max() if len(mag) else 0.0))
            seeds = (faces, np.full((len(faces), 3), 1.0 / 3.0))
        lines = sl.trace_streamlines(V, F, a, kind=kind, count=count, seeds=seeds, rng=o.rng,
                                     max_length=length, max_faces=20000,
                                     separation=o.streamline_separation)
        if len(lines):
            poly = _polylines_polydata(list(lines))
            rgb = np.tile((np.clip(o.line_color, 0, 1) * 255).astype(np.uint8),
                          (len(lines), 1))
            colors = numpy_to_vtk(rgb, deep=True)
            colors.SetName("colors")
            poly.GetCellData().SetScalars(colors)
            overlays.append(poly)
            n_lines = len(lines)
    spheres = None
    if sing_vertices is not None and len(sing_vertices):
        size = np.abs(sing_index).astype(np.float64)
        radii = o.singularity_radius * diag * np.sqrt(size / size.min())
        colors = np.where((sing_index > 0)[:, None], POSITIVE_COLOR, NEGATIVE_COLOR)
        spheres = _spheres_polydata(V[sing_vertices], radii, colors)

    with x_display(width, height, use_existing=o.use_display):
        renderer.SetBackground(*o.background)
        renderer.AddActor(actor)
        for poly in overlays:
            m = vtkPolyDataMapper()
            m.SetInputData(poly)
            m.SetScalarModeToUseCellData()
            m.SetColorModeToDirectScalars()
            m.SetResolveCoincidentTopologyToPolygonOffset()
            line_actor = vtkActor()
            line_actor.SetMapper(m)
            line_actor.GetProperty().SetLineWidth(line_width)
            line_actor.GetProperty().LightingOff()
            renderer.AddActor(line_actor)
        sphere_actor = None
        if spheres is not None:
            m = vtkPolyDataMapper()
            m.SetInputData(spheres)
            m.SetScalarModeToUseCellData()
            m.SetColorModeToDirectScalars()
            sphere_actor = vtkActor()
            sphere_actor.SetMapper(m)
            sphere_actor.GetProperty().SetAmbient(0.45)
            sphere_actor.GetProperty().SetDiffuse(0.6)
            renderer.AddActor(sphere_actor)
        if legend_split is not None:
            from vtkmodules.vtkRenderingAnnotation import vtkScalarBarActor
            split = legend_split
            renderer.SetViewport(0.0, 0.0, split, 1.0)
            legend = vtkRenderer()
            legend.SetViewport(split, 0.0, 1.0, 1.0)
            legend.SetBackground(*o.background)
            bar = vtkScalarBarActor()
            bar.SetLookupTable(lut)
            bar.SetTitle(o.title or "magnitude")
            bar.SetNumberOfLabels(5)
            bar.SetPosition(0.3, 0.12)
            bar.SetWidth(0.4)
            bar.SetHeight(0.76)
            bar.UnconstrainedFontSizeOn()
            for text in (bar.GetTitleTextProperty(), bar.GetLabelTextProperty()):
                text.SetColor(0.1, 0.1, 0.1)
                text.SetFontSize(max(10, height // 40))
                text.ShadowOff()
                text.ItalicOff()
            legend.AddActor2D(bar)
        else:
            legend = None
        window = vtkRenderWindow()
        window.SetOffScreenRendering(1)
        window.SetMultiSamples(0)
        window.SetSize(width, height)
        window.AddRenderer(renderer)
        if legend is not None:
            window.AddRenderer(legend)
        try:
            pixels = _grab(window, vtkWindowToImageFilter, vtk_to_numpy)
            if o.style == "lic" and a is not None:
                length = o.lic_length or max(8, min(width, height) // 30)
                pixels = _lic_pass(window, renderer, legend, actor, mapper, sphere_actor, V, F,
                                   a, kind, pixels, width, height, length, o.rng, numpy_to_vtk,
                                   vtkWindowToImageFilter, vtk_to_numpy)
            if out is not None:
                write_image(out, pixels)
        finally:
            window.Finalize()
    return {"image": pixels, "camera": state, "scalar_range": scalar_range,
            "glyphs": n_glyphs, "lines": n_lines,
            "singularities": 0 if sing_vertices is None else len(sing_vertices)}


def _read_singularities(path):
    """Singular vertices and indices from a file: the JSON that ``fieldspace singularities``
    prints (or that of ``solve``/``smooth``/``align`` with ``--singularities``: its
    ``singularities`` object), or Directional's ``.sing`` (``N count``, then ``vertex index``
    lines)."""
    from .export import singularities_from_cli
    with open(path, encoding="utf-8") as f:
        text = f.read()
    if text.lstrip().startswith("{"):
        data = json.loads(text)
        if isinstance(data.get("singularities"), dict):
            data = data["singularities"]
        if "n" not in data or "singularities" not in data:
            raise ValueError("%s: no singularities in this JSON (the output of `fieldspace "
                             "singularities` has n and singularities)" % path)
        return singularities_from_cli(data)[1]
    numbers = text.split()
    try:
        count = int(numbers[1])
        pairs = np.array([int(x) for x in numbers[2:]], dtype=np.int64).reshape(-1, 2)
    except (IndexError, ValueError):
        raise ValueError("%s: neither the JSON of `fieldspace singularities` nor a .sing file "
                         "(N count, then vertex index lines)" % path) from None
    if len(pairs) != count:
        raise ValueError("%s: header says %d singularities, file has %d" % (path, count,
                                                                            len(pairs)))
    return pairs


def main(argv=None):
    """python3 -m fieldspace.render MESH [FIELD_FILE] --out FILE.png|.jpg: draws the mesh and a
    field file of the fieldspace CLI (glyphs, streamlines, hatching, LIC or the bare surface)
    into a picture, without a display."""
    from . import mesh_io
    from .errors import FieldspaceError

    parser = argparse.ArgumentParser(prog="python3 -m fieldspace.render",
                                     description=main.__doc__)
    mesh_io.add_field_arguments(parser)
    parser.add_argument("--out", required=True, help="the picture to write (.png, .jpg, .jpeg)")
    parser.add_argument("--singularities", default=None, metavar="FILE",
                        help="spheres at singular vertices (red +, blue -): the JSON "
                        "`fieldspace singularities` prints, or a .sing file")
    RenderOptions.add_arguments(parser)
    args = parser.parse_args(argv)
    try:
        options = RenderOptions.from_arguments(args)
        image_format(args.out)
        singularities = _read_singularities(args.singularities) if args.singularities else None
        V, F, field, kind = mesh_io.load_mesh_and_field(
            args.mesh, args.field, args.kind, args.n, server=args.server,
            token=mesh_io.read_token(args.token), tls=mesh_io.tls_arguments(args))
        result = render(V, F, field, kind, out=args.out, options=options,
                        singularities=singularities)
    except (OSError, ValueError, RuntimeError) as e:
        print("fieldspace: render failed: %s" % e, file=sys.stderr)
        return 1
    except FieldspaceError as e:  # a mesh id the server could not give
        print("fieldspace: %s" % e, file=sys.stderr)
        return 1
    print(json.dumps({"out": args.out, "glyphs": result["glyphs"], "lines": result["lines"],
                      "singularities": result["singularities"], "camera": result["camera"],
                      "scalar_range": result["scalar_range"]}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
