"""Pictures of a mesh and its field with VTK, on machines with no GPU and no display.

:func:`render` draws the surface coloured by the field's magnitude (viridis, optional scalar
bar) with glyphs (vectors as arrows, n-fields as n-crosses, tensors as principal crosses: the
maximum direction red, the minimum blue, arm lengths proportional to the principal values; or
ellipses), streamlines / hatching strokes (fieldspace.streamlines) or a line integral
convolution texture, from an automatic camera that frames the mesh or a given one.

VTK is the field's standard library (ParaView, 3D Slicer, PyVista build on it) and Debian ships
it (python3-vtk9); it renders with Mesa's software OpenGL into an off-screen buffer, through a
private Xvfb when there is no DISPLAY (fieldspace.display).
"""

import argparse
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

STYLES = ("glyphs", "streamlines", "lic", "surface")


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


def _glyph_segments(V, F, a, kind, faces, arm, normalize, tensor_glyph="cross"):
    """Segments (starts, ends, colours) of the glyphs at ``faces``, face-major (the segments
    of each glyph together, in the order of ``faces``); ``arm`` the longest arm."""
    normals = fl.face_normals(V, F)[faces]
    centers = V[F[faces]].mean(axis=1)
    black = np.array([0.05, 0.05, 0.05])
    starts, ends, colors = [], [], []
    if kind == fl.VECTOR:
        v = a[faces]
        length = np.linalg.norm(v, axis=1)
        top = length.max() if len(length) and length.max() > 0 else 1.0
        scale = np.where(length > 0, (length / top if normalize else 1.0) * arm
                         / np.where(length > 0, length, 1.0), 0.0)
        d = v * scale[:, None]
        tail = centers - 0.5 * d
        tip = centers + 0.5 * d
        side = np.cross(normals, d)
        starts += [tail, tip, tip]
        ends += [tip, tip - 0.3 * d + 0.15 * side, tip - 0.3 * d - 0.15 * side]
        colors += [black] * 3
    elif kind == fl.NFIELD:
        dirs = a[faces]
        length = np.linalg.norm(dirs[:, 0], axis=1)
        top = length.max() if len(length) and length.max() > 0 else 1.0
        scale = np.where(length > 0, (length / top if normalize else 1.0) * 0.5 * arm
                         / np.where(length > 0, length, 1.0), 0.0)
        for k in range(dirs.shape[1]):
            starts.append(centers)
            ends.append(centers + dirs[:, k] * scale[:, None])
            colors.append(black)
    else:
        values, directions = fl.principal(V, F[faces], a[faces])
        top = np.abs(values).max() if values.size and np.abs(values).max() > 0 else 1.0
        palette = (np.array([0.8, 0.1, 0.1]), np.array([0.1, 0.2, 0.85]))
        halves = [(np.abs(values[:, j]) / top if normalize else 1.0) * 0.5 * arm
                  for j in range(2)]
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


def _fit_view(cam, points, aspect, fill=0.9):
    """Narrows the view angle until ``points`` fill ``fill`` of the view (the automatic camera
    starts from VTK's bounding-sphere framing, which leaves wide margins)."""
    position = np.array(cam.GetPosition())
    forward = np.array(cam.GetFocalPoint()) - position
    forward /= np.linalg.norm(forward)
    up = np.array(cam.GetViewUp())
    up -= np.dot(up, forward) * forward
    up /= np.linalg.norm(up)
    right = np.cross(forward, up)
    rel = points - position
    depth = rel @ forward
    if np.any(depth <= 0):
        return
    need = max(np.max(np.abs(rel @ up) / depth), np.max(np.abs(rel @ right) / depth) / aspect)
    angle = 2.0 * math.degrees(math.atan(need / fill))
    cam.SetViewAngle(min(max(angle, 1.0), 120.0))


def _apply_camera(renderer, camera, bounds, fit_points=None, aspect=1.0):
    """Sets the renderer's camera from ``camera`` (None: automatic) and returns its state."""
    cam = renderer.GetActiveCamera()
    camera = dict(camera or {})
    unknown = set(camera) - {"position", "focal_point", "view_up", "view_angle",
                             "parallel_scale", "direction", "azimuth", "elevation", "zoom"}
    if unknown:
        raise ValueError("unknown camera keys: %s" % ", ".join(sorted(unknown)))
    lo, hi = np.array(bounds[0::2]), np.array(bounds[1::2])
    center = 0.5 * (lo + hi)
    if "view_angle" in camera:
        cam.SetViewAngle(float(camera["view_angle"]))
    if "position" in camera:
        cam.SetFocalPoint(*map(float, camera.get("focal_point", center)))
        cam.SetPosition(*map(float, camera["position"]))
        cam.SetViewUp(*map(float, camera.get("view_up", (0.0, 0.0, 1.0))))
        if "parallel_scale" in camera:
            cam.ParallelProjectionOn()
            cam.SetParallelScale(float(camera["parallel_scale"]))
        else:
            renderer.ResetCameraClippingRange()
    else:
        direction = np.asarray(camera.get("direction", (1.0, -1.6, 0.9)), dtype=np.float64)
        direction = direction / np.linalg.norm(direction)
        up = np.asarray(camera.get("view_up", (0.0, 0.0, 1.0)), dtype=np.float64)
        if abs(np.dot(up, direction)) > 0.99 * np.linalg.norm(up):
            up = np.array([0.0, 1.0, 0.0])
        focal = np.asarray(camera.get("focal_point", center), dtype=np.float64)
        cam.SetFocalPoint(*focal)
        cam.SetPosition(*(focal + direction))
        cam.SetViewUp(*up)
        if "parallel_scale" in camera:
            cam.ParallelProjectionOn()
        renderer.ResetCamera(bounds)
        if "parallel_scale" in camera:
            cam.SetParallelScale(float(camera["parallel_scale"]))
        elif fit_points is not None and len(fit_points):
            _fit_view(cam, fit_points, aspect)
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


def _write_png(path, pixels, numpy_to_vtk):
    from vtkmodules.vtkCommonDataModel import vtkImageData
    from vtkmodules.vtkIOImage import vtkPNGWriter
    h, w, _ = pixels.shape
    image = vtkImageData()
    image.SetDimensions(w, h, 1)
    data = numpy_to_vtk(np.ascontiguousarray(pixels[::-1].reshape(-1, 3)), deep=True)
    image.GetPointData().SetScalars(data)
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
    matrix = cam.GetCompositeProjectionTransformMatrix(width / height, -1.0, 1.0)
    P = np.array([[matrix.GetElement(i, j) for j in range(4)] for i in range(4)])
    centers = V[F].mean(axis=1)
    eps = 1e-3 * float(np.linalg.norm(np.ptp(V, axis=0)))

    def project(points):
        h = np.hstack([points, np.ones((len(points), 1))]) @ P.T
        return h[:, :2] / h[:, 3:4] * np.array([width / 2.0, height / 2.0])

    base = project(centers)
    out = np.zeros(dirs.shape[:2] + (2,))
    for j in range(dirs.shape[1]):
        s = project(centers + eps * dirs[:, j]) - base
        norm = np.linalg.norm(s, axis=1)
        out[:, j] = s / np.where(norm > 0, norm, 1.0)[:, None]
    return out


def _lic_pass(window, renderer, legend, actor, mapper, V, F, a, kind, pixels, width, height,
              length, rng, numpy_to_vtk, vtkWindowToImageFilter, vtk_to_numpy):
    """Renders each line family's screen directions into the picture's pixels (doubled angle
    in red and green, blue marks the surface) and modulates ``pixels`` by their LIC."""
    dirs = family_directions(V, F, a, kind)
    screen = _screen_directions(renderer, V, F, dirs, width, height)
    # The mapper draws a copy of the surface (with vertex normals) when lighting is on.
    cd = mapper.GetInput().GetCellData()
    saved_scalars = cd.GetScalars()
    saved = (mapper.GetScalarVisibility(), mapper.GetColorMode(), actor.GetVisibility())
    prop = actor.GetProperty()
    lighting = (prop.GetAmbient(), prop.GetDiffuse(), prop.GetSpecular())
    others = [x for x in _actors(renderer) if x is not actor]
    visible = [x.GetVisibility() for x in others]
    for x in others:
        x.VisibilityOff()
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
    values = texture[mask]
    if values.size:
        spread = values.std() if values.std() > 0 else 1.0
        texture = np.clip(0.5 + 0.18 * (texture - values.mean()) / spread, 0.0, 1.0)
    shade = np.where(mask, 0.35 + 0.65 * texture, 1.0)
    return np.clip(pixels * shade[:, :, None], 0, 255).astype(np.uint8)


def _actors(renderer):
    actors = renderer.GetActors()
    actors.InitTraversal()
    out = []
    for _ in range(actors.GetNumberOfItems()):
        out.append(actors.GetNextActor())
    return out


def render(V, F, field=None, kind=None, out_png=None, style="glyphs", size=(800, 600),
           camera=None, colormap_name="viridis", scalars=None, scalar_range=None,
           scalar_bar=False, title=None, max_glyphs=3000, glyph_scale=1.0, normalize=True,
           streamline_count=None, streamline_length=None, streamline_separation=None,
           lic_length=None, lighting=True,
           background=(1.0, 1.0, 1.0), surface_color=(0.85, 0.85, 0.85), line_width=1.5,
           line_color=(0.08, 0.08, 0.08), colorize=True, tensor_glyph="cross", rng=0,
           use_display=True):
    """Renders the mesh ``(V, F)`` with ``field`` and writes a PNG to ``out_png`` (if given).

    - ``field``/``kind``: as in fieldspace.fields (vectors ``(F, 3)``, n-fields ``(F, n, 3)``,
      tensors ``(F, 3, 3)``), or None for the bare surface.
    - ``style``: ``"glyphs"`` (about ``max_glyphs`` glyphs spread evenly; arms scaled by
      magnitude unless ``normalize=False``; ``glyph_scale`` scales them; tensors as principal
      crosses or, with ``tensor_glyph="ellipse"``, ellipses with semi-axes ``|k1| d1``,
      ``|k2| d2``, red where ``k1 >= 0``, blue elsewhere), ``"streamlines"``
      (``streamline_count`` seeds, half length ``streamline_length``; n-fields and tensors draw
      every line family; default about one seed per 2500 pixels, drawn in ``line_color``;
      ``streamline_separation``: evenly spaced lines, see streamlines.space_lines), ``"lic"``
      (line integral convolution in image space, :func:`lic`, ``lic_length`` pixels each way)
      or ``"surface"`` (colour only).
    - the surface is coloured by ``scalars`` (``(F,)``, default the field's magnitude:
      fieldspace.fields.magnitude) through the colormap over ``scalar_range`` (default the
      values' min and max); ``scalar_bar`` adds a legend titled ``title``. ``colorize=False``
      (and no ``scalars``): a plain ``surface_color`` surface, e.g. for hatching.
    - ``camera``: None (look from ``(1, -1.6, 0.9)`` with z up, framing the mesh) or a dict with
      ``position``, ``focal_point``, ``view_up``, ``view_angle`` (degrees) and
      ``parallel_scale`` (parallel projection: half the view's height), or ``direction``
      (automatic framing from that side), plus ``azimuth``, ``elevation``, ``zoom``.
    - ``lighting=False`` shows the colormap's colours unshaded (flat ambient light).
    - ``use_display``: use ``DISPLAY`` when it is set; else (or when False) a private Xvfb.

    Returns a dict: ``image`` (``(h, w, 3)`` uint8, top row first), ``camera`` (the camera
    used, in the dict form above), ``scalar_range``, ``glyphs`` (count), ``lines`` (count).
    """
    from vtkmodules.util.numpy_support import numpy_to_vtk, numpy_to_vtkIdTypeArray, vtk_to_numpy
    from vtkmodules.vtkCommonCore import vtkLookupTable, vtkPoints
    from vtkmodules.vtkCommonDataModel import vtkCellArray, vtkPolyData
    from vtkmodules.vtkRenderingCore import (vtkActor, vtkPolyDataMapper, vtkRenderer,
                                             vtkRenderWindow, vtkWindowToImageFilter)
    # Side-effect imports: the OpenGL implementations and the text renderer (scalar bar).
    importlib.import_module("vtkmodules.vtkRenderingOpenGL2")
    importlib.import_module("vtkmodules.vtkRenderingFreeType")

    if tensor_glyph not in ("cross", "ellipse"):
        raise ValueError("tensor_glyph must be 'cross' or 'ellipse', got %r" % (tensor_glyph,))
    if style not in STYLES:
        raise ValueError("style must be one of %s, got %r" % (", ".join(STYLES), style))
    width, height = (int(size[0]), int(size[1]))
    if not (1 <= width <= 8192 and 1 <= height <= 8192):
        raise ValueError("size must be (width, height) within 1..8192")
    V, F = fl.as_mesh(V, F)
    a = None
    if field is not None:
        a, kind, n = fl.check_field(V, F, field, kind)
    if scalars is None and a is not None and colorize:
        scalars = fl.magnitude(a, kind)
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

    diag = float(np.linalg.norm(V.max(axis=0) - V.min(axis=0))) if len(V) else 1.0
    total_area = float(fl.face_areas(V, F).sum())

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
        table = colormap(colormap_name)
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
        actor.GetProperty().SetColor(*surface_color)
    if lighting:
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
    if lighting:
        prop.SetAmbient(0.25)
        prop.SetDiffuse(0.75)
        prop.SetSpecular(0.1)
    else:
        prop.SetAmbient(1.0)
        prop.SetDiffuse(0.0)
        prop.SetSpecular(0.0)
    if lighting:
        prop.SetInterpolationToGouraud()
    else:
        prop.SetInterpolationToFlat()

    overlays = []
    n_glyphs, n_lines = 0, 0
    if a is not None and style == "glyphs":
        mag = fl.magnitude(a, kind)
        allowed = mag > 1e-12 * (mag.max() if len(mag) else 0.0)
        faces = glyph_faces(V, F, max_glyphs, rng=rng, allowed=allowed)
        arm = 0.8 * glyph_scale * math.sqrt(total_area / max(len(faces), 1))
        if len(faces):
            starts, ends, colors = _glyph_segments(V, F, a, kind, faces, arm, normalize,
                                                   tensor_glyph)
            # Lift glyphs off the surface (along their face's normal) so that the depth test
            # keeps them where the surface curves away under their flat arms.
            lift = max(0.002 * diag, 0.1 * arm)
            per_glyph = len(starts) // len(faces)
            offset = lift * np.repeat(fl.face_normals(V, F)[faces], per_glyph, axis=0)
            overlays.append(_segments_polydata(starts + offset, ends + offset, colors))
            n_glyphs = len(faces)
    elif a is not None and style == "streamlines":
        m = 1 if kind == fl.VECTOR else (4 if kind == fl.TENSOR else a.shape[1])
        families = len(sl.line_families(kind, m))
        count = streamline_count or max(20, width * height // (2500 * families))
        length = streamline_length or 0.12 * diag
        lines = sl.trace_streamlines(V, F, a, kind=kind, count=count, rng=rng,
                                     max_length=length, max_faces=20000,
                                     separation=streamline_separation)
        if len(lines):
            poly = _polylines_polydata(list(lines))
            rgb = np.tile((np.clip(line_color, 0, 1) * 255).astype(np.uint8), (len(lines), 1))
            colors = numpy_to_vtk(rgb, deep=True)
            colors.SetName("colors")
            poly.GetCellData().SetScalars(colors)
            overlays.append(poly)
            n_lines = len(lines)

    with x_display(width, height, use_existing=use_display):
        renderer = vtkRenderer()
        renderer.SetBackground(*background)
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
        aspect = width / height
        if scalar_bar and lut is not None:
            from vtkmodules.vtkRenderingAnnotation import vtkScalarBarActor
            split = 0.86
            renderer.SetViewport(0.0, 0.0, split, 1.0)
            aspect *= split
            legend = vtkRenderer()
            legend.SetViewport(split, 0.0, 1.0, 1.0)
            legend.SetBackground(*background)
            bar = vtkScalarBarActor()
            bar.SetLookupTable(lut)
            bar.SetTitle(title or "magnitude")
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
        bounds = surface.GetBounds()
        state = _apply_camera(renderer, camera, bounds, V, aspect)
        window = vtkRenderWindow()
        window.SetOffScreenRendering(1)
        window.SetMultiSamples(0)
        window.SetSize(width, height)
        window.AddRenderer(renderer)
        if legend is not None:
            window.AddRenderer(legend)
        try:
            pixels = _grab(window, vtkWindowToImageFilter, vtk_to_numpy)
            if style == "lic" and a is not None:
                length = lic_length or max(8, min(width, height) // 30)
                pixels = _lic_pass(window, renderer, legend, actor, mapper, V, F, a, kind,
                                   pixels, width, height, length, rng, numpy_to_vtk,
                                   vtkWindowToImageFilter, vtk_to_numpy)
            if out_png is not None:
                _write_png(out_png, pixels, numpy_to_vtk)
        finally:
            window.Finalize()
    return {"image": pixels, "camera": state, "scalar_range": scalar_range,
            "glyphs": n_glyphs, "lines": n_lines}


def _size(text):
    try:
        w, h = (int(x) for x in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError("size is WIDTHxHEIGHT, e.g. 800x600") from None
    return w, h


def main(argv=None):
    """python3 -m fieldspace.render MESH [FIELD_FILE] --out PNG: draws the mesh and a field file
    of the fieldspace CLI (glyphs, streamlines or colour only) into a PNG, without a display."""
    from . import mesh_io
    from .errors import FieldspaceError

    parser = argparse.ArgumentParser(prog="python3 -m fieldspace.render",
                                     description=main.__doc__)
    mesh_io.add_field_arguments(parser)
    parser.add_argument("--out", required=True, help="the PNG to write")
    parser.add_argument("--style", choices=STYLES, default="glyphs")
    parser.add_argument("--separation", type=float, default=None,
                        help="streamlines: keep lines of a family this far apart")
    parser.add_argument("--size", type=_size, default=(800, 600), help="WIDTHxHEIGHT")
    parser.add_argument("--camera", type=json.loads, default=None,
                        help='JSON, e.g. \'{"direction": [0, -1, 0.3]}\' or position, '
                        'focal_point, view_up, view_angle, parallel_scale, zoom')
    parser.add_argument("--scalar-bar", action="store_true", help="add a colour legend")
    parser.add_argument("--glyphs", type=int, default=3000, help="glyphs at most (about)")
    parser.add_argument("--lines", type=int, default=None, help="streamline seeds")
    parser.add_argument("--line-length", type=float, default=None,
                        help="half length of a streamline (default 12%% of the diagonal)")
    args = parser.parse_args(argv)
    try:
        V, F, field, kind = mesh_io.load_mesh_and_field(
            args.mesh, args.field, args.kind, args.n, server=args.server,
            token=mesh_io.read_token(args.token), tls=mesh_io.tls_arguments(args))
        result = render(V, F, field, kind, out_png=args.out, style=args.style, size=args.size,
                        camera=args.camera, scalar_bar=args.scalar_bar, max_glyphs=args.glyphs,
                        streamline_count=args.lines, streamline_length=args.line_length,
                        streamline_separation=args.separation)
    except (OSError, ValueError, RuntimeError) as e:
        print("fieldspace: render failed: %s" % e, file=sys.stderr)
        return 1
    except FieldspaceError as e:  # a mesh id the server could not give
        print("fieldspace: %s" % e, file=sys.stderr)
        return 1
    print(json.dumps({"out": args.out, "glyphs": result["glyphs"], "lines": result["lines"],
                      "camera": result["camera"], "scalar_range": result["scalar_range"]}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
