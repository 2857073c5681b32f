"""fieldspace.streamlines on fields with known integral curves."""

import math
import os
import time
import unittest

import testenv
import numpy as np

from fieldspace import fields as fl
from fieldspace import streamlines as sl
import shapes


class AdjacencyTest(unittest.TestCase):
    def test_neighbours_share_the_edge_opposite_the_corner(self):
        for V, F in (shapes.icosphere(2), shapes.cylinder(12, 5)):
            adj = sl.face_adjacency(F)
            for f in range(len(F)):
                for k in range(3):
                    g = adj[f, k]
                    edge = {F[f, (k + 1) % 3], F[f, (k + 2) % 3]}
                    if g < 0:
                        continue
                    self.assertEqual(len(edge & set(F[g])), 2)
                    self.assertIn(f, adj[g])
        # Closed surface: no boundary; open cylinder: 2 x 12 boundary edges.
        self.assertFalse(np.any(sl.face_adjacency(shapes.icosphere(2)[1]) < 0))
        self.assertEqual(int(np.sum(sl.face_adjacency(shapes.cylinder(12, 5)[1]) < 0)), 24)

    def test_faces_around_vertices(self):
        V, F = shapes.icosphere(1)
        faces = sl.faces_around_vertices(F, [0])
        self.assertEqual(len(faces), 5)
        self.assertTrue(all(0 in F[f] for f in faces))

    def test_samples_are_uniform_by_area(self):
        V, F = shapes.cylinder(8, 4, height=1.0)
        # Stretch the top half: it then holds 3/4 of the area.
        V = V.copy()
        V[:, 2] = np.where(V[:, 2] > 0.5, 0.5 + 3 * (V[:, 2] - 0.5), V[:, 2])
        faces, bary = sl.sample_surface(V, F, 20000, rng=1)
        np.testing.assert_allclose(bary.sum(axis=1), 1)
        self.assertTrue(np.all(bary >= 0))
        points = np.einsum("lk,lkc->lc", bary, V[F[faces]])
        self.assertAlmostEqual(float(np.mean(points[:, 2] > 0.5)), 0.75, delta=0.02)
        again = sl.sample_surface(V, F, 50, rng=1)
        np.testing.assert_array_equal(again[0], sl.sample_surface(V, F, 50, rng=1)[0])


class KnownCurvesTest(unittest.TestCase):
    def test_rotation_about_z_on_a_sphere_keeps_z(self):
        V, F = shapes.icosphere(4)
        # e_z x n_f is tangent to every face and has no z component: exact circles of latitude.
        field = np.cross([0.0, 0.0, 1.0], fl.face_normals(V, F))
        lines = sl.trace_streamlines(V, F, field, count=150, rng=4, max_faces=5000)
        self.assertGreater(len(lines), 100)
        self.assertGreater(float(np.mean(lines.closed)), 0.9)
        for line, closed in zip(lines, lines.closed):
            np.testing.assert_allclose(line[:, 2], line[0, 2], atol=1e-12)
            if closed:
                np.testing.assert_allclose(line[-1], line[0], atol=1e-12)
                radius = math.sqrt(max(1 - line[0, 2] ** 2, 0))
                length = np.sum(np.linalg.norm(np.diff(line, axis=0), axis=1))
                # A closed circle of latitude, on the polyhedron inscribed in the sphere.
                if radius > 0.2:
                    self.assertAlmostEqual(length / (2 * math.pi * radius), 1, delta=0.02)

    def test_axis_field_on_a_cylinder_gives_straight_lines_to_the_boundary(self):
        V, F = shapes.cylinder(24, 10, height=2.0)
        field = np.tile([0.0, 0.0, 1.0], (len(F), 1))
        lines = sl.trace_streamlines(V, F, field, count=80, rng=2)
        self.assertEqual(len(lines), 80)
        for line in lines:
            np.testing.assert_allclose(line[:, :2] - line[0, :2], 0, atol=1e-12)
            self.assertTrue(np.all(np.diff(line[:, 2]) >= -1e-12))
            self.assertAlmostEqual(line[0, 2], 0.0, delta=1e-12)
            self.assertAlmostEqual(line[-1, 2], 2.0, delta=1e-12)

    def test_cross_field_on_a_cylinder_gives_both_families(self):
        V, F = shapes.cylinder(24, 10, height=2.0)
        ez = np.tile([0.0, 0.0, 1.0], (len(F), 1))
        rng = np.random.default_rng(0)
        cross = fl.nfield_from_representative(V, F, ez, 4)
        shuffled = np.stack([np.roll(c, k, axis=0) for c, k in
                             zip(cross, rng.integers(0, 4, len(F)))])
        results = [sl.trace_streamlines(V, F, c, count=40, rng=3, max_length=3.0)
                   for c in (cross, shuffled)]
        canonical = []
        for lines in results:
            self.assertEqual(len(lines), 80)
            vertical = 0
            for line, closed in zip(lines, lines.closed):
                length = np.sum(np.linalg.norm(np.diff(line, axis=0), axis=1))
                if np.ptp(line[:, 2]) > 1e-9:
                    np.testing.assert_allclose(line[:, :2] - line[0, :2], 0, atol=1e-12)
                    self.assertFalse(closed)
                    vertical += 1
                else:
                    np.testing.assert_allclose(line[:, 2], line[0, 2], atol=1e-12)
                    self.assertTrue(closed or length <= 6.0 + 1e-9)
                    if closed:
                        # The circumference of the 24-gon of radius 1.
                        self.assertAlmostEqual(length, 48 * math.sin(math.pi / 24), delta=1e-9)
            self.assertEqual(vertical, 40)
            canonical.append(sorted(np.unique(np.round(x, 9), axis=0).tobytes() for x in lines))
        # Which of the n directions is listed first changes nothing but the lines' orientation.
        self.assertEqual(canonical[0], canonical[1])

    def test_a_helix_passing_its_seed_face_is_not_closed(self):
        V, F = shapes.cylinder(24, 16, height=2.0)
        n = fl.face_normals(V, F)
        ez = np.array([0.0, 0.0, 1.0])
        # Rises 0.005 per unit around: back in the seed face after a turn, 0.03 higher.
        field = np.cross(n, ez) + 0.005 * ez
        lines = sl.trace_streamlines(V, F, field, count=20, rng=7, max_length=20.0,
                                     max_faces=100000)
        self.assertEqual(len(lines), 20)
        for line, closed in zip(lines, lines.closed):
            self.assertFalse(closed)
            self.assertTrue(np.all(np.diff(line[:, 2]) >= -1e-12))
            length = np.sum(np.linalg.norm(np.diff(line, axis=0), axis=1))
            # Up to the boundary at both ends or 20 units each way.
            at_ends = (line[0, 2] < 1e-9 or length > 19.9) and (line[-1, 2] > 2 - 1e-9 or
                                                                length > 19.9)
            self.assertTrue(at_ends, (line[0], line[-1], length))

    def test_space_lines_on_known_lines(self):
        x = np.linspace(0.0, 10.0, 11)[:, None]
        # Parallel lines 0.3 apart, the middle one longest; separation 0.5.
        lines = [np.hstack([x * s, np.full_like(x, 0.3 * i), np.zeros_like(x)])
                 for i, s in zip(range(5), (0.9, 0.8, 1.0, 0.7, 0.6))]
        kept, sources = sl.space_lines(lines, 0.5)
        self.assertEqual(sources.tolist(), [2, 0, 4])
        # A line crossing the kept ones is cut to its longest free piece.
        cross = np.stack([np.full(41, 3.0), np.linspace(-3.0, 1.2, 41), np.zeros(41)], axis=1)
        kept, sources = sl.space_lines([lines[2], cross], 0.5)
        self.assertEqual(sources.tolist(), [0, 1])
        piece = kept[1]
        # lines[2] runs at y = 0.6: the free piece below it ends within 0.5 of it.
        self.assertAlmostEqual(piece[0, 1], -3.0)
        self.assertLess(piece[-1, 1], 0.1 + 1e-9)
        self.assertGreater(piece[-1, 1], 0.1 - 0.25 - 1e-9)
        with self.assertRaises(ValueError):
            sl.space_lines(lines, 0.0)

    def test_evenly_spaced_families(self):
        V, F = shapes.torus(64, 32)
        n = fl.face_normals(V, F)
        v = np.cross([0.0, 0.0, 1.0], n)
        cross = fl.nfield_from_representative(V, F, v + 0.5 * np.cross(n, v), 4)
        sep = 0.1
        lines = sl.trace_streamlines(V, F, cross, count=400, rng=2, max_length=1.0,
                                     separation=sep)
        self.assertEqual(sorted(set(lines.families.tolist())), [0, 1])
        for family in (0, 1):
            members = [a for a, f in zip(lines, lines.families) if f == family]
            self.assertGreater(len(members), 20)
            for i, a in enumerate(members):
                self.assertGreaterEqual(np.sum(np.linalg.norm(np.diff(a, axis=0), axis=1)),
                                        2 * sep - 1e-9)
                self.assertLessEqual(np.linalg.norm(np.diff(a, axis=0), axis=1).max(),
                                     sep / 2 + 1e-9)
                others = np.vstack(members[:i] + members[i + 1:])
                d = np.sqrt(((a[:, None, :] - others[None, :, :]) ** 2).sum(axis=2)).min()
                # Pieces kept later stay away from earlier ones, and the other way round.
                self.assertGreaterEqual(d, sep - 1e-9)
        # The two families cross: some points of family 0 are close to family 1.
        f0 = np.vstack([a for a, f in zip(lines, lines.families) if f == 0])
        f1 = np.vstack([a for a, f in zip(lines, lines.families) if f == 1])
        d = np.sqrt(((f0[:400, None, :] - f1[None, :, :]) ** 2).sum(axis=2)).min()
        self.assertLess(d, sep / 2)

    def test_stops_at_max_length_and_at_stop_faces(self):
        V, F = shapes.cylinder(24, 16, height=2.0)
        field = np.tile([0.0, 0.0, 1.0], (len(F), 1))
        lines = sl.trace_streamlines(V, F, field, count=50, rng=5, max_length=0.3)
        for line in lines:
            length = np.sum(np.linalg.norm(np.diff(line, axis=0), axis=1))
            self.assertLessEqual(length, 0.6 + 1e-12)
        center = V[F].mean(axis=1)
        zero = field.copy()
        zero[center[:, 2] > 1.0] = 0.0
        lines = sl.trace_streamlines(V, F, zero, count=50, rng=5)
        self.assertGreater(len(lines), 10)
        for line in lines:
            self.assertLessEqual(line[:, 2].max(), 1.0 + 1e-12)
            self.assertAlmostEqual(line[-1, 2], 1.0, delta=1e-12)
        listed = sl.trace_streamlines(V, F, field, count=50, rng=5,
                                      stop_faces=np.nonzero(center[:, 2] < 0.5)[0])
        for line in listed:
            self.assertGreaterEqual(line[:, 2].min(), 0.5 - 1e-12)

    def test_sink_stops_the_line(self):
        # Vectors pointing to the ring z = 1 from both sides: lines end there.
        V, F = shapes.cylinder(16, 8, height=2.0)
        center = V[F].mean(axis=1)
        field = np.zeros((len(F), 3))
        field[:, 2] = np.where(center[:, 2] < 1.0, 1.0, -1.0)
        lines = sl.trace_streamlines(V, F, field, count=30, rng=1, both_directions=False)
        for line in lines:
            self.assertAlmostEqual(line[-1, 2], 1.0, delta=1e-12)

    def test_tensor_lines_follow_principal_directions(self):
        V, F = shapes.cylinder(24, 10, height=2.0)
        n = fl.face_normals(V, F)
        ez = np.tile([0.0, 0.0, 1.0], (len(F), 1))
        et = np.cross(n, ez)
        tensor = 2.0 * np.einsum("fi,fj->fij", et, et) + 0.5 * np.einsum("fi,fj->fij", ez, ez)
        lines = sl.trace_streamlines(V, F, tensor, kind="tensor", count=20, rng=1,
                                     max_length=2.0)
        for line, family in zip(lines, lines.families):
            if family == 0:  # maximum direction: horizontal circles
                np.testing.assert_allclose(line[:, 2], line[0, 2], atol=1e-12)
            else:
                np.testing.assert_allclose(line[:, :2] - line[0, :2], 0, atol=1e-12)

    def test_hatching_stroke_length_and_reproducibility(self):
        V, F = shapes.torus(48, 24)
        cross = fl.nfield_from_representative(V, F, np.cross([0.0, 0.0, 1.0],
                                                             fl.face_normals(V, F)), 2)
        a = sl.hatching(V, F, cross, count=300, stroke_length=0.2, rng=9)
        b = sl.hatching(V, F, cross, count=300, stroke_length=0.2, rng=9)
        self.assertEqual(len(a), len(b))
        for x, y in zip(a, b):
            np.testing.assert_array_equal(x, y)
        lengths = [np.sum(np.linalg.norm(np.diff(x, axis=0), axis=1)) for x in a]
        self.assertLessEqual(max(lengths), 0.2 + 1e-12)
        self.assertGreater(float(np.median(lengths)), 0.19)

    def test_large_mesh_in_seconds(self):
        V, F = shapes.icosphere(6)  # 81920 faces
        V2, F2 = shapes.torus(160, 80)  # 25600 faces
        V = np.vstack([V, V2 + [3.0, 0, 0]])
        F = np.vstack([F, F2 + len(shapes.icosphere(6)[0])])
        self.assertGreater(len(F), 100000)
        field = np.cross([0.0, 0.0, 1.0], fl.face_normals(V, F))
        start = time.perf_counter()
        lines = sl.trace_streamlines(V, F, fl.nfield_from_representative(V, F, field, 4),
                                     count=1000, rng=1, max_length=0.5)
        seconds = time.perf_counter() - start
        print("\n%d faces, %d lines, %.2f s" % (len(F), len(lines), seconds))
        self.assertEqual(len(lines), 2000)
        self.assertLess(seconds, 30.0)


class CommandLineTest(unittest.TestCase):
    def test_writes_polylines(self):
        import shutil
        import tempfile
        d = tempfile.mkdtemp()
        try:
            V, F = shapes.cylinder(16, 6, height=1.0)
            mesh = os.path.join(d, "c.obj")
            with open(mesh, "w") as f:
                f.write(shapes.obj_text(V, F))
            field = os.path.join(d, "f.txt")
            fl.write_field_text(field, V, F, np.tile([0.0, 0.0, 2.0], (len(F), 1)))
            out = os.path.join(d, "l.obj")
            self.assertEqual(sl.main([mesh, field, "--out", out, "--count", "7"]), 0)
            with open(out) as f:
                elements = [ln for ln in f if ln.startswith("l ")]
            self.assertEqual(len(elements), 7)
            self.assertEqual(sl.main([mesh, field, "--out", os.path.join(d, "l.vtk"),
                                      "--hatching", "--length", "0.1"]), 0)
            self.assertEqual(sl.main([mesh, "--out", out]), 1)
        finally:
            shutil.rmtree(d)


if __name__ == "__main__":
    testenv.main()
