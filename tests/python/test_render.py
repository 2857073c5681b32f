"""fieldspace.render: pictures checked pixel by pixel (coverage for a known camera, colours of
the magnitude, glyphs and lines drawn), with and without a DISPLAY."""

import contextlib
import io
import json
import math
import os
import shutil
import subprocess
import sys
import tempfile
import textwrap
import time
import unittest

import testenv
import numpy as np

from fieldspace import fields as fl
import shapes

REASON = testenv.can_render()
if REASON is None:
    from fieldspace import render as rd

WHITE = (1.0, 1.0, 1.0)


def read_png(path):
    """The PNG read back by VTK's reader: (h, w, 3) uint8, top row first."""
    from vtkmodules.util.numpy_support import vtk_to_numpy
    from vtkmodules.vtkIOImage import vtkPNGReader
    r = vtkPNGReader()
    r.SetFileName(path)
    r.Update()
    img = r.GetOutput()
    w, h, _ = img.GetDimensions()
    return vtk_to_numpy(img.GetPointData().GetScalars()).reshape(h, w, -1)[::-1, :, :3]


def foreground(image, background=(255, 255, 255), threshold=10):
    return np.any(np.abs(image.astype(int) - np.array(background)) > threshold, axis=2)


def luminance(image):
    return image.astype(float) @ np.array([0.299, 0.587, 0.114])


def bounding_box(mask):
    """(top, bottom, left, right) rows and columns of a mask's pixels."""
    rows = np.nonzero(mask.any(axis=1))[0]
    cols = np.nonzero(mask.any(axis=0))[0]
    return rows[0], rows[-1], cols[0], cols[-1]


def line_field(V, F, direction):
    """The tangential part of a fixed direction as a 2-field (a line field)."""
    n = fl.face_normals(V, F)
    d = np.asarray(direction, dtype=np.float64)
    return fl.nfield_from_representative(V, F, d - (n @ d)[:, None] * n, 2)


def dome(up="z"):
    """A low dome on a flat round base (2.4 wide, 0.9 high): its thinnest axis is its up axis,
    so only the base says which way is up."""
    V, F = shapes.icosphere(4)
    V = V * [1.2, 1.1, 0.9]
    V[:, 2] = np.maximum(V[:, 2], 0.0)
    if up == "y":
        V = np.stack([V[:, 0], V[:, 2], -V[:, 1]], axis=1)
    return V, F


def unit_tangent_field(V, F, magnitude):
    """The frame axes x_f scaled per face: a tangent vector field of the given magnitudes."""
    x, _, _ = fl.face_frames(V, F)
    return x * magnitude[:, None]


@unittest.skipIf(REASON is not None, REASON or "")
class RenderTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.dir = tempfile.mkdtemp()
        cls.V, cls.F = shapes.icosphere(4)
        cls.centers = cls.V[cls.F].mean(axis=1)
        cls.normals = fl.face_normals(cls.V, cls.F)

    @classmethod
    def tearDownClass(cls):
        shutil.rmtree(cls.dir)

    def path(self, name):
        return os.path.join(self.dir, name)

    def test_png_is_written_and_matches_the_returned_image(self):
        field = unit_tangent_field(self.V, self.F, 1.0 + self.centers[:, 2])
        out = self.path("sphere.png")
        result = rd.render(self.V, self.F, field, out=out, size=(320, 240), scalar_bar=True,
                           color="magnitude")
        self.assertTrue(os.path.getsize(out) > 1000)
        image = read_png(out)
        self.assertEqual(image.shape, (240, 320, 3))
        np.testing.assert_array_equal(image, result["image"])
        # Not blank: a good part of the picture is the object, and it is not one flat colour.
        self.assertGreater(float(foreground(image).mean()), 0.2)
        self.assertGreater(len(np.unique(image.reshape(-1, 3), axis=0)), 100)

    def test_covered_area_for_a_known_camera(self):
        # Looking down the z axis with a parallel projection of half height s: the sphere's
        # projection covers (projected area) / (2 s)^2 of a square picture.
        up = self.normals[:, 2] > 0
        areas = fl.face_areas(self.V, self.F)
        projected = float(np.sum(areas[up] * self.normals[up, 2]))
        for scale in (2.0, 1.5):
            camera = {"position": (0, 0, 10), "focal_point": (0, 0, 0), "view_up": (0, 1, 0),
                      "parallel_scale": scale}
            result = rd.render(self.V, self.F, None, style="surface", size=(400, 400),
                               camera=camera, lighting=False, background=(0, 0, 0))
            fraction = float(foreground(result["image"], (0, 0, 0)).mean())
            self.assertAlmostEqual(fraction / (projected / (2 * scale) ** 2), 1.0, delta=0.02)
            self.assertEqual(result["camera"]["parallel_scale"], scale)

    def test_colours_map_the_magnitude(self):
        magnitude = 2.0 + self.centers[:, 2]
        field = unit_tangent_field(self.V, self.F, magnitude)
        scale, size = 1.2, 400
        camera = {"position": (10, 0, 0), "focal_point": (0, 0, 0), "view_up": (0, 0, 1),
                  "parallel_scale": scale}
        result = rd.render(self.V, self.F, field, style="surface", size=(size, size),
                           camera=camera, lighting=False, color="magnitude")
        image = result["image"].astype(int)
        lo, hi = result["scalar_range"]
        self.assertAlmostEqual(lo, magnitude.min())
        self.assertAlmostEqual(hi, magnitude.max())
        # Screen right is +y, up is +z; faces turned to the camera are seen at their centres.
        facing = np.nonzero(self.normals[:, 0] > 0.95)[0]
        self.assertGreater(len(facing), 50)
        col = np.round(size / 2 + self.centers[facing, 1] / scale * size / 2 - 0.5).astype(int)
        row = np.round(size / 2 - self.centers[facing, 2] / scale * size / 2 - 0.5).astype(int)
        want = np.round(255 * rd.map_colors(magnitude[facing], (lo, hi))).astype(int)
        got = image[row, col]
        self.assertLessEqual(int(np.abs(got - want).max()), 6)
        # The top of the sphere is the colormap's high end, the bottom its low end.
        table = np.round(255 * rd.colormap("viridis")).astype(int)
        top = image[int(size / 2 - 0.95 / scale * size / 2), size // 2]
        bottom = image[int(size / 2 + 0.95 / scale * size / 2), size // 2]
        self.assertLess(np.abs(top - table[-1]).max(), 25)
        self.assertLess(np.abs(bottom - table[0]).max(), 25)
        # With lighting the hues stay: yellow above (blue lowest), purple below (green lowest).
        lit = rd.render(self.V, self.F, field, style="surface", size=(size, size),
                        camera=camera, color="magnitude")["image"].astype(int)
        top = lit[int(size / 2 - 0.8 / scale * size / 2), size // 2]
        bottom = lit[int(size / 2 + 0.8 / scale * size / 2), size // 2]
        self.assertGreater(min(top[0], top[1]) - top[2], 80)
        self.assertGreater(min(bottom[0], bottom[2]) - bottom[1], 15)

    def test_glyphs_for_each_kind(self):
        V, F = shapes.torus(48, 24)
        n = fl.face_normals(V, F)
        v = np.cross([0.0, 0.0, 1.0], n)
        et = v / np.linalg.norm(v, axis=1)[:, None]
        ev = np.cross(n, et)
        tensor = 2.0 * np.einsum("fi,fj->fij", et, et) + 0.5 * np.einsum("fi,fj->fij", ev, ev)
        size = (400, 300)
        plain = rd.render(V, F, v, style="surface", size=size)["image"]
        for kind, field in (("vector", v), ("nfield", fl.nfield_from_representative(V, F, v, 4)),
                            ("nfield", fl.nfield_from_representative(V, F, v, 3)),
                            ("tensor", tensor)):
            result = rd.render(V, F, field, kind=kind, size=size, max_glyphs=600)
            self.assertGreater(result["glyphs"], 300)
            self.assertLessEqual(result["glyphs"], 750)
            image = result["image"].astype(int)
            changed = np.any(np.abs(image - plain) > 40, axis=2)
            self.assertGreater(float(changed.mean()), 0.02, kind)
            if kind == "tensor":
                red = (image[:, :, 0] > 150) & (image[:, :, 1] < 80) & (image[:, :, 2] < 80)
                blue = (image[:, :, 2] > 150) & (image[:, :, 0] < 80) & (image[:, :, 1] < 120)
                self.assertGreater(int(red.sum()), 200)
                self.assertGreater(int(blue.sum()), 50)
                # Arms are proportional to the principal values: more red than blue.
                self.assertGreater(int(red.sum()), 2 * int(blue.sum()))
            else:
                dark = np.all(image < 40, axis=2)
                self.assertGreater(int(dark.sum()), 300, kind)

    def test_tensor_ellipses(self):
        V, F = shapes.torus(48, 24)
        n = fl.face_normals(V, F)
        v = np.cross([0.0, 0.0, 1.0], n)
        et = v / np.linalg.norm(v, axis=1)[:, None]
        ev = np.cross(n, et)
        negative = -2.0 * np.einsum("fi,fj->fij", et, et) - np.einsum("fi,fj->fij", ev, ev)
        images = {}
        for glyph in ("cross", "ellipse"):
            images[glyph] = rd.render(V, F, -negative, "tensor", size=(300, 200),
                                      max_glyphs=200, tensor_glyph=glyph)["image"].astype(int)
        red = [int(((im[:, :, 0] > 150) & (im[:, :, 1] < 80) & (im[:, :, 2] < 80)).sum())
               for im in images.values()]
        self.assertGreater(red[1], 200)
        self.assertGreater(np.mean(np.any(images["cross"] != images["ellipse"], axis=2)), 0.01)
        # k1 < 0: blue ellipses.
        im = rd.render(V, F, negative, "tensor", size=(300, 200), max_glyphs=200,
                       tensor_glyph="ellipse")["image"].astype(int)
        blue = (im[:, :, 2] > 150) & (im[:, :, 0] < 80) & (im[:, :, 1] < 120)
        self.assertGreater(int(blue.sum()), 200)
        with self.assertRaises(ValueError):
            rd.render(V, F, negative, "tensor", tensor_glyph="box")

    def test_constant_magnitude_is_the_colormap_middle(self):
        V, F = shapes.torus(24, 12)
        n = fl.face_normals(V, F)
        v = np.cross([0.0, 0.0, 1.0], n)
        v = 3.0 * v / np.linalg.norm(v, axis=1)[:, None]
        result = rd.render(V, F, v, style="surface", size=(200, 150), lighting=False,
                           color="magnitude")
        image = result["image"].astype(int)
        middle = np.round(255 * rd.map_colors([3.0], result["scalar_range"])[0]).astype(int)
        mask = foreground(result["image"])
        self.assertLessEqual(int(np.abs(image[mask] - middle).max()), 3)

    def test_streamlines_style(self):
        V, F = shapes.cylinder(48, 20, height=2.0)
        field = np.tile([0.0, 0.0, 1.0], (len(F), 1))
        size = (300, 300)
        camera = {"direction": (1.0, 0.0, 0.0), "view_up": (0.0, 0.0, 1.0)}
        plain = rd.render(V, F, field, style="surface", size=size, camera=camera)["image"]
        result = rd.render(V, F, field, style="streamlines", size=size, camera=camera,
                           streamline_count=40)
        self.assertEqual(result["lines"], 40)
        image = result["image"].astype(int)
        dark = np.all(image < 40, axis=2) & ~np.all(plain < 40, axis=2)
        self.assertGreater(int(dark.sum()), 500)
        # Vertical lines: dark pixels line up in columns.
        columns = dark.sum(axis=0)
        self.assertGreater(int(columns.max()), 100)

    def test_lic_streaks_follow_the_field(self):
        h, w = 60, 80
        mask = np.ones((h, w), dtype=bool)
        horizontal = np.zeros((1, h, w, 2))
        horizontal[..., 0] = 1.0
        texture = rd.lic(horizontal, mask, length=10, rng=3)
        inner = texture[5:-5, 12:-12]
        along = np.abs(np.diff(inner, axis=1)).mean()
        across = np.abs(np.diff(inner, axis=0)).mean()
        self.assertLess(along, 0.3 * across)
        # Two crossing families: which one a pixel lists first does not matter.
        rng = np.random.default_rng(4)
        cross = np.zeros((2, h, w, 2))
        cross[0, ..., 0] = 1.0
        cross[1, ..., 1] = 1.0
        swap = rng.random((h, w)) < 0.5
        swapped = cross.copy()
        swapped[0][swap], swapped[1][swap] = cross[1][swap], cross[0][swap]
        noise = rng.random((h, w))
        np.testing.assert_allclose(rd.lic(cross, mask, 10, noise=noise),
                                   rd.lic(swapped, mask, 10, noise=noise), atol=1e-12)

    def test_lic_style(self):
        V, F = shapes.cylinder(64, 24, height=2.0)
        size = (240, 240)
        camera = {"direction": (1.0, 0.0, 0.0), "view_up": (0.0, 0.0, 1.0)}
        n = fl.face_normals(V, F)
        ez = np.tile([0.0, 0.0, 1.0], (len(F), 1))
        et = np.cross(n, ez)
        for field, streaks in ((ez, "down"), (et, "right"), (ez + et, "diagonal")):
            result = rd.render(V, F, field, style="lic", size=size, camera=camera,
                               lic_length=12)
            image = result["image"].astype(float)
            mask = foreground(result["image"])
            rows = np.nonzero(mask.any(axis=1))[0]
            cols = np.nonzero(mask.any(axis=0))[0]
            # The middle of the cylinder's visible side, away from its outline.
            r0, r1 = rows[0] + 30, rows[-1] - 30
            c0, c1 = (cols[0] + cols[-1]) // 2 - 30, (cols[0] + cols[-1]) // 2 + 30
            lum = image[r0:r1, c0:c1].mean(axis=2)
            down = np.abs(np.diff(lum, axis=0)).mean()
            right = np.abs(np.diff(lum, axis=1)).mean()
            if streaks == "down":
                self.assertLess(down, 0.5 * right)
            elif streaks == "right":
                self.assertLess(right, 0.5 * down)
            else:
                # Seen from +x with z up, e_theta points left on the screen: ez + et runs up
                # and left, i.e. along the image's main diagonal (row and column together).
                main = np.abs(lum[1:, 1:] - lum[:-1, :-1]).mean()
                anti = np.abs(lum[1:, :-1] - lum[:-1, 1:]).mean()
                self.assertLess(main, 0.6 * anti)
        self.assertEqual(result["lines"], 0)

    def test_automatic_camera_frames_the_mesh(self):
        V, F = shapes.torus(48, 24)
        V = V * 7.0 + [100.0, -50.0, 3.0]
        for size in ((400, 300), (300, 400)):
            result = rd.render(V, F, None, style="surface", size=size)
            mask = foreground(result["image"])
            rows = np.nonzero(mask.any(axis=1))[0]
            cols = np.nonzero(mask.any(axis=0))[0]
            # Inside the picture, not touching its border, filling 80% of the limiting dimension.
            self.assertGreater(rows[0], 0)
            self.assertGreater(cols[0], 0)
            self.assertLess(rows[-1], size[1] - 1)
            self.assertLess(cols[-1], size[0] - 1)
            fill = max((rows[-1] - rows[0]) / size[1], (cols[-1] - cols[0]) / size[0])
            self.assertGreater(fill, 0.75)
            self.assertLess(fill, 0.85)
            middle = ((rows[0] + rows[-1]) / 2 / size[1], (cols[0] + cols[-1]) / 2 / size[0])
            np.testing.assert_allclose(middle, (0.5, 0.5), atol=0.08)

    def test_automatic_view_stands_y_up_and_z_up_shapes_upright(self):
        size = (400, 300)
        # Semi-axes (x, y, z) of a z-up scan: standing tall (long axis up) and lying (long axis
        # along x, the middle one up). The y-up copy of a shape is the same picture.
        for semi, tall in (((1.2, 0.6, 3.0), True), ((3.0, 0.6, 1.2), False)):
            images = {}
            for up in ("z", "y"):
                V, F = shapes.ellipsoid(semi, 4, up=up)
                up_axis = np.array([0.0, 0.0, 1.0]) if up == "z" else np.array([0.0, 1.0, 0.0])
                direction, view_up = rd.automatic_view(V, F)
                np.testing.assert_allclose(view_up, up_axis)
                # From the side, a little above: never from above or below.
                self.assertLess(abs(float(direction @ up_axis)), math.sin(math.radians(20)))
                result = rd.render(V, F, None, style="surface", size=size)
                image = result["image"]
                top, bottom, left, right = bounding_box(foreground(image))
                height, width = (bottom - top) / size[1], (right - left) / size[0]
                # The object fills about 80% of the picture's limiting dimension, centred.
                self.assertGreater(max(height, width), 0.7, (semi, up))
                self.assertLess(max(height, width), 0.9, (semi, up))
                self.assertAlmostEqual((top + bottom) / 2 / size[1], 0.5, delta=0.05)
                self.assertAlmostEqual((left + right) / 2 / size[0], 0.5, delta=0.05)
                # The long axis: upright when standing (its top end drawn at the top), across
                # the picture when lying.
                ends = V[[np.argmax(V @ up_axis), np.argmin(V @ up_axis)]]
                rows = rd.project(ends, result["camera"], size)[:, 1]
                self.assertLess(rows[0], rows[1])
                if tall:
                    self.assertGreater(bottom - top, 2.0 * (right - left), up)
                else:
                    self.assertGreater(right - left, 2.0 * (bottom - top), up)
                images[up] = image.astype(int)
            self.assertLess(float(np.mean(np.abs(images["z"] - images["y"]) > 30)), 0.002)

    def test_a_flat_base_tells_up_when_the_shape_is_low(self):
        for up in ("z", "y"):
            V, F = dome(up)
            up_axis = np.array([0.0, 0.0, 1.0]) if up == "z" else np.array([0.0, 1.0, 0.0])
            self.assertGreater(rd.base_area(V, F, up_axis), 0.2)
            self.assertLess(rd.base_area(V, F, up_axis[[0, 2, 1]]), 0.005)
            direction, view_up = rd.automatic_view(V, F)
            np.testing.assert_allclose(view_up, up_axis)
            self.assertLess(abs(float(direction @ up_axis)), math.sin(math.radians(20)))
            result = rd.render(V, F, None, style="surface", size=(300, 300))
            top, bottom, left, right = bounding_box(foreground(result["image"]))
            # Seen from the side (15 degrees up), the dome is 1.65 times as wide as high; from
            # above it would be round.
            self.assertGreater(right - left, 1.4 * (bottom - top))

    def test_glyphs_have_an_even_visible_length(self):
        # A field whose magnitude spans three decades, as a smoothest field's does: drawn by
        # magnitude most glyphs would be specks.
        V, F = shapes.ellipsoid((1.2, 0.6, 3.0), 4)
        centers = V[F].mean(axis=1)
        field = unit_tangent_field(V, F, 10.0 ** (-3.0 + 3.0 * (centers[:, 2] > 2.5)))
        size = (400, 300)
        plain = rd.render(V, F, None, style="surface", size=size)["image"]
        dark = {}
        for mode in ("even", "magnitude"):
            result = rd.render(V, F, field, size=size, glyph_length=mode)
            image = result["image"]
            dark[mode] = int((np.all(image < 60, axis=2) & ~np.all(plain < 60, axis=2)).sum())
            glyphs = result["glyphs"]
        self.assertGreater(glyphs, 100)
        # An arrow of even length is about 0.8 glyph spacings long: several pixels each.
        self.assertGreater(dark["even"] / glyphs, 5.0)
        self.assertGreater(dark["even"], 4 * dark["magnitude"])

    def test_no_glyph_fringes_the_outline(self):
        # Looking at the unit sphere with a parallel camera: its outline is the unit circle.
        # Glyphs on faces seen edge-on would stick out of it by their half arm; they are left
        # out, and the ones drawn cover the disc.
        size, scale = 300, 1.25
        camera = {"position": (0, 0, 10), "focal_point": (0, 0, 0), "view_up": (0, 1, 0),
                  "parallel_scale": scale}
        field = unit_tangent_field(self.V, self.F, np.ones(len(self.F)))
        cross = fl.nfield_from_representative(self.V, self.F, field, 4)
        result = rd.render(self.V, self.F, cross, "nfield", size=(size, size), camera=camera,
                           max_glyphs=600)
        dark = np.all(result["image"] < 60, axis=2)
        rows, cols = np.nonzero(dark)
        radius = np.hypot(cols + 0.5 - size / 2, size / 2 - rows - 0.5) / (size / 2) * scale
        self.assertGreater(len(radius), 1000)
        self.assertLess(float(radius.max()), 1.0)
        self.assertGreater(float(np.mean(radius > 0.7)), 0.2)

    def test_singularity_markers_sit_on_their_vertices(self):
        V, F = shapes.ellipsoid((1.2, 0.6, 3.0), 4, up="y")
        size = (400, 300)
        result = rd.render(V, F, None, style="surface", size=size)
        camera = result["camera"]
        eye = np.array(camera["position"])
        normals = np.zeros_like(V)
        np.add.at(normals, F.reshape(-1), np.repeat(fl.face_normals(V, F), 3, axis=0))
        facing = np.einsum("ij,ij->i", normals, eye - V) / np.linalg.norm(eye - V, axis=1) \
            / np.linalg.norm(normals, axis=1)
        # Vertices turned to the camera, spread along the shape: + and - indices alternate.
        visible = np.nonzero(facing > 0.6)[0]
        chosen = visible[np.argsort(V[visible, 1])][np.linspace(5, len(visible) - 5, 6)
                                                    .astype(int)]
        index = np.array([1, -1, 2, -2, 1, -1])
        field = unit_tangent_field(V, F, np.ones(len(F)))
        marked = rd.render(V, F, field, size=size, singularities=list(zip(chosen, index)))
        self.assertEqual(marked["singularities"], 6)
        self.assertEqual(marked["camera"], camera)
        image = marked["image"].astype(int)
        pixels = np.round(rd.project(V[chosen], camera, size) - 0.5).astype(int)
        for (col, row), k in zip(pixels, index):
            r, g, b = image[row, col]
            if k > 0:
                self.assertTrue(r > 150 and g < 90 and b < 90, (k, r, g, b))
            else:
                self.assertTrue(b > 150 and r < 90, (k, r, g, b))
        # Nothing red or blue without them; a Singularities-like answer works too.
        red = lambda im: (im[:, :, 0] > 150) & (im[:, :, 1] < 90) & (im[:, :, 2] < 90)  # noqa
        unmarked = rd.render(V, F, field, size=size)["image"].astype(int)
        self.assertEqual(int(red(unmarked).sum()), 0)
        self.assertGreater(int(red(image).sum()), 30)

        class Answer:
            vertices, index = chosen[:1], np.array([-1])
        one = rd.render(V, F, None, style="surface", size=size, singularities=Answer())
        self.assertEqual(one["singularities"], 1)
        with self.assertRaises(ValueError):
            rd.render(V, F, None, style="surface", singularities=[(len(V), 1)])

    def test_hatching_and_lic_have_contrast_on_a_plain_surface(self):
        V, F = shapes.ellipsoid((1.2, 0.6, 3.0), 4)
        # Magnitudes over three decades (a smoothest field's): the colour must not hide it.
        centers = V[F].mean(axis=1)
        field = line_field(V, F, (0.3, 0.2, 1.0)) * (10.0 ** (-3.0 + centers[:, 2]))[:, None,
                                                                                     None]
        size = (300, 300)
        for style in ("hatching", "lic"):
            result = rd.render(V, F, field, "nfield", style=style, size=size)
            image = result["image"]
            mask = foreground(image)
            # Erode the outline away: the contrast inside the object is the texture's.
            inner = mask[2:-2, 2:-2] & mask[:-4, 2:-2] & mask[4:, 2:-2] & mask[2:-2, :-4] \
                & mask[2:-2, 4:]
            lum = luminance(image[2:-2, 2:-2])[inner]
            self.assertGreater(float(lum.std()), 30.0, style)
            self.assertGreater(float(lum.mean()), 90.0, style)
            # No colouring unless asked: grey levels (hatching's paper is barely warm).
            spread = image[2:-2, 2:-2][inner].astype(int)
            self.assertLess(float(np.mean(spread.max(axis=1) - spread.min(axis=1))), 25.0)
            if style == "hatching":
                self.assertGreater(result["lines"], 500)
                dark = np.mean(lum < 80)
                self.assertGreater(dark, 0.03)
        coloured = rd.render(V, F, field, "nfield", style="hatching", size=size,
                             color="magnitude")["image"].astype(int)
        saturation = coloured.max(axis=2) - coloured.min(axis=2)
        self.assertGreater(float(saturation[foreground(coloured)].mean()), 60.0)

    def test_jpeg_by_extension_and_other_extensions_refused(self):
        from vtkmodules.util.numpy_support import vtk_to_numpy
        from vtkmodules.vtkIOImage import vtkJPEGReader
        out = self.path("sphere.jpg")
        result = rd.render(self.V, self.F, None, style="surface", size=(160, 120), out=out)
        with open(out, "rb") as f:
            self.assertEqual(f.read(3), b"\xff\xd8\xff")
        reader = vtkJPEGReader()
        reader.SetFileName(out)
        reader.Update()
        img = reader.GetOutput()
        w, h, _ = img.GetDimensions()
        back = vtk_to_numpy(img.GetPointData().GetScalars()).reshape(h, w, -1)[::-1, :, :3]
        self.assertEqual(back.shape, (120, 160, 3))
        self.assertLess(float(np.abs(back.astype(int) - result["image"]).mean()), 3.0)
        png = self.path("sphere.PNG")
        rd.render(self.V, self.F, None, style="surface", size=(16, 12), out=png)
        with open(png, "rb") as f:
            self.assertEqual(f.read(4), b"\x89PNG")
        for bad in ("sphere.gif", "sphere", "sphere.png.txt"):
            with self.assertRaisesRegex(ValueError, r"\.png, \.jpg, \.jpeg"):
                rd.render(self.V, self.F, None, out=self.path(bad))
            self.assertFalse(os.path.exists(self.path(bad)))

    def test_options_are_one_dataclass(self):
        defaults = rd.RenderOptions()
        self.assertEqual((defaults.style, defaults.color, defaults.glyph_length, defaults.fill),
                         ("glyphs", "none", "even", 0.8))
        options = rd.RenderOptions(style="surface", size=(64, 48), lighting=False,
                                   background=(0, 0, 0))
        a = rd.render(self.V, self.F, None, options=options)["image"]
        b = rd.render(self.V, self.F, None, style="surface", size=(64, 48), lighting=False,
                      background=(0, 0, 0))["image"]
        np.testing.assert_array_equal(a, b)
        # Keywords override the options object for one call.
        self.assertEqual(rd.render(self.V, self.F, None, options=options,
                                   size=(32, 24))["image"].shape, (24, 32, 3))
        with self.assertRaises(TypeError):
            rd.render(self.V, self.F, None, normalize=False)
        for bad in ({"style": "watercolour"}, {"color": "rainbow"}, {"glyph_length": "long"},
                    {"fill": 0.0}, {"max_glyphs": 0}, {"size": (10, 0)}):
            with self.assertRaises(ValueError, msg=str(bad)):
                rd.RenderOptions(**bad)
        # Every flag of the command line lands on its field; the others keep their defaults.
        import argparse
        parser = argparse.ArgumentParser()
        rd.RenderOptions.add_arguments(parser)
        parsed = rd.RenderOptions.from_arguments(parser.parse_args(
            ["--style", "hatching", "--color", "magnitude", "--glyph-length", "magnitude",
             "--size", "320x200", "--fill", "0.7", "--glyphs", "90", "--lines", "12",
             "--line-length", "0.5", "--lic-length", "9", "--tensor-glyph", "ellipse",
             "--scalar-bar", "--camera", '{"zoom": 2}', "--seed", "3",
             "--singularity-radius", "0.02", "--glyph-scale", "2", "--colormap", "gray",
             "--separation", "0.1"]))
        self.assertEqual(parsed, rd.RenderOptions(
            style="hatching", color="magnitude", glyph_length="magnitude", size=(320, 200),
            fill=0.7, max_glyphs=90, streamline_count=12, streamline_length=0.5, lic_length=9,
            tensor_glyph="ellipse", scalar_bar=True, camera={"zoom": 2}, rng=3,
            singularity_radius=0.02, glyph_scale=2.0, colormap="gray",
            streamline_separation=0.1))
        self.assertEqual(rd.RenderOptions.from_arguments(parser.parse_args([])), defaults)

    def test_large_mesh_is_fast(self):
        V, F = shapes.torus(360, 160)
        self.assertGreater(len(F), 100000)
        v = np.cross([0.0, 0.0, 1.0], fl.face_normals(V, F))
        for style in ("glyphs", "streamlines"):
            start = time.perf_counter()
            result = rd.render(V, F, fl.nfield_from_representative(V, F, v, 4), style=style,
                               size=(640, 480))
            seconds = time.perf_counter() - start
            print("\n%s on %d faces: %.2f s" % (style, len(F), seconds))
            self.assertLess(seconds, 60.0)
            self.assertGreater(result["glyphs"] + result["lines"], 100)

    def test_command_line(self):
        V, F = shapes.torus(24, 12)
        mesh = self.path("torus.obj")
        with open(mesh, "w") as f:
            f.write(shapes.obj_text(V, F))
        field = self.path("cross.txt")
        v = np.cross([0.0, 0.0, 1.0], fl.face_normals(V, F))
        fl.write_field_text(field, V, F, fl.nfield_from_representative(V, F, v, 4),
                            encoding="dof")
        out = self.path("cli.png")
        self.assertEqual(rd.main([mesh, field, "--out", out, "--style", "streamlines",
                                  "--size", "160x120", "--camera", '{"direction": [0, 0, 1]}',
                                  "--lines", "30"]), 0)
        image = read_png(out)
        self.assertEqual(image.shape, (120, 160, 3))
        self.assertGreater(float(foreground(image).mean()), 0.2)
        with self.assertRaises(SystemExit):
            rd.main([mesh, "--out", out, "--size", "12by4"])
        self.assertEqual(rd.main([mesh, "--out", out, "--camera", '{"fov": 1}']), 1)
        # Hatching into a JPEG with the singularities `fieldspace singularities` printed (whole
        # turns) or a Directional .sing file (1/n turns).
        printed = self.path("sing.json")
        with open(printed, "w") as f:
            json.dump({"basis_id": "b-1", "n": 4, "singularities": [
                {"vertex": 3, "index": 0.25, "turns": 0.25}, {"vertex": 40, "index": -0.25}],
                "index_sum": 0.0, "euler_characteristic": 0}, f)
        sing = self.path("field.sing")
        with open(sing, "w") as f:
            f.write("4 3\n3 1\n40 -1\n41 2\n")
        nested = self.path("solved.json")  # solve / smooth / align --singularities
        with open(nested, "w") as f:
            json.dump({"coefficients": [1.0], "singularities": {
                "n": 4, "singularities": [{"vertex": 7, "index": -0.5}], "index_sum": -0.5}},
                f, indent=2)
        for given, count in ((printed, 2), (sing, 3), (nested, 1)):
            stdout = io.StringIO()
            with contextlib.redirect_stdout(stdout):
                code = rd.main([mesh, field, "--out", self.path("hatch.jpg"), "--style",
                                "hatching", "--size", "160x120", "--singularities", given])
            self.assertEqual(code, 0)
            report = json.loads(stdout.getvalue())
            self.assertEqual(report["singularities"], count)
            self.assertGreater(report["lines"], 50)
            with open(self.path("hatch.jpg"), "rb") as f:
                self.assertEqual(f.read(3), b"\xff\xd8\xff")
        stderr = io.StringIO()
        with contextlib.redirect_stderr(stderr):
            self.assertEqual(rd.main([mesh, field, "--out", self.path("x.gif")]), 1)
            self.assertEqual(rd.main([mesh, field, "--out", out, "--singularities", mesh]), 1)
        self.assertIn("the extension must be one of .png, .jpg, .jpeg", stderr.getvalue())
        self.assertIn("neither the JSON of `fieldspace singularities` nor a .sing file",
                      stderr.getvalue())
        self.assertFalse(os.path.exists(self.path("x.gif")))

    def test_errors(self):
        with self.assertRaises(ValueError):
            rd.render(self.V, self.F, None, style="watercolour")
        with self.assertRaises(ValueError):
            rd.render(self.V, self.F, None, size=(0, 10))
        with self.assertRaises(ValueError):
            rd.render(self.V, self.F, np.zeros((3, 3)))
        with self.assertRaises(ValueError):
            rd.render(self.V, self.F, None, style="surface", camera={"fov": 3})

    def test_without_a_display_a_private_xvfb_is_started_and_stopped(self):
        if shutil.which("Xvfb") is None:
            self.skipTest("Xvfb is not installed")
        script = textwrap.dedent("""
            import os, sys
            sys.path[:0] = [%r, %r]
            import numpy as np
            import shapes
            from fieldspace import display, render
            V, F = shapes.icosphere(2)
            result = render.render(V, F, None, style="surface", size=(64, 48), out=%r)
            assert "DISPLAY" not in os.environ, "DISPLAY leaked"
            server = display._server
            assert server is not None, "no private server"
            pid = server.proc.pid
            display.stop_private_display()
            assert server.proc.poll() is not None, "Xvfb still running"
            assert not os.path.exists(server.dir), "auth directory left"
            print("ok", result["image"].shape)
        """) % (os.path.dirname(os.path.dirname(os.path.abspath(fl.__file__))),
                testenv.HERE, self.path("nodisplay.png"))
        env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "XAUTHORITY")}
        # No DISPLAY, and a DISPLAY naming a local server that does not exist (VTK would abort).
        dead = next(":%d" % d for d in range(900, 1000)
                    if not os.path.exists("/tmp/.X11-unix/X%d" % d))
        for extra in ({}, {"DISPLAY": dead}):
            p = subprocess.run([sys.executable, "-c", script.replace(
                'assert "DISPLAY" not in os.environ', "assert os.environ.get('DISPLAY') == %r"
                % extra.get("DISPLAY"))], env=dict(env, **extra), capture_output=True,
                text=True, timeout=120)
            self.assertEqual(p.returncode, 0, p.stderr[-3000:])
            self.assertIn("ok (48, 64, 3)", p.stdout)
            self.assertEqual(read_png(self.path("nodisplay.png")).shape, (48, 64, 3))
            os.remove(self.path("nodisplay.png"))


if __name__ == "__main__":
    testenv.main()
