"""fieldspace.render: pictures checked pixel by pixel (coverage for a known camera, colours of
the magnitude, glyphs and lines drawn), with and without a DISPLAY."""

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
        result = rd.render(self.V, self.F, field, out_png=out, size=(320, 240), scalar_bar=True)
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
                           camera=camera, lighting=False)
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
                        camera=camera)["image"].astype(int)
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
        result = rd.render(V, F, v, style="surface", size=(200, 150), lighting=False)
        image = result["image"].astype(int)
        middle = np.round(255 * rd.map_colors([3.0], result["scalar_range"])[0]).astype(int)
        mask = foreground(result["image"])
        self.assertLessEqual(int(np.abs(image[mask] - middle).max()), 3)

    def test_streamlines_style(self):
        V, F = shapes.cylinder(48, 20, height=2.0)
        field = np.tile([0.0, 0.0, 1.0], (len(F), 1))
        size = (300, 300)
        camera = {"direction": (1.0, 0.0, 0.0)}
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
        camera = {"direction": (1.0, 0.0, 0.0)}
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
            # Inside the picture, not touching its border, filling the limiting dimension.
            self.assertGreater(rows[0], 0)
            self.assertGreater(cols[0], 0)
            self.assertLess(rows[-1], size[1] - 1)
            self.assertLess(cols[-1], size[0] - 1)
            fill = max((rows[-1] - rows[0]) / size[1], (cols[-1] - cols[0]) / size[0])
            self.assertGreater(fill, 0.8)
            middle = ((rows[0] + rows[-1]) / 2 / size[1], (cols[0] + cols[-1]) / 2 / size[0])
            np.testing.assert_allclose(middle, (0.5, 0.5), atol=0.08)

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
            result = render.render(V, F, None, style="surface", size=(64, 48), out_png=%r)
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
