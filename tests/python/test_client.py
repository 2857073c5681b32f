#!/usr/bin/env python3
"""Tests of the Python package `fieldspace` against live fieldspaced daemons.

Environment (set by tests/python/CMakeLists.txt): FIELDSPACED (the daemon binary) and PYTHONPATH
with the build tree's python/ folder (the package with its generated stubs).
"""

import concurrent.futures
import math
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import textwrap
import time
import unittest

import grpc
import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "server"))
from fs_testlib import Daemon, icosphere_obj, obj_arrays, torus_obj  # noqa: E402

import fieldspace as fs  # noqa: E402

DAEMON = os.environ.get("FIELDSPACED")


def normals_of(V, F):
    n = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    return n / np.linalg.norm(n, axis=1, keepdims=True)


def roughness(field):
    """Mean |X_f - X_g| over the pairs of faces sharing an edge of the sphere."""
    edges = {}
    for f, (a, b, c) in enumerate(SF):
        for u, v in ((a, b), (b, c), (c, a)):
            edges.setdefault((min(u, v), max(u, v)), []).append(f)
    pairs = np.array([fs_ for fs_ in edges.values()])
    return float(np.mean(np.linalg.norm(field[pairs[:, 0]] - field[pairs[:, 1]], axis=1)))


def setUpModule():
    global WORK, DAEMON_PROC, CLIENT, SPHERE, SV, SF, VECTOR, NFIELD, TENSOR
    if not DAEMON:
        raise RuntimeError("set FIELDSPACED to the fieldspaced binary")
    WORK = tempfile.mkdtemp(prefix="fs_python_")
    DAEMON_PROC = Daemon(DAEMON, os.path.join(WORK, "store")).start()
    CLIENT = fs.Client(DAEMON_PROC.address, timeout=60)
    SV, SF = obj_arrays(icosphere_obj(3)[0])
    SPHERE = CLIENT.upload(SV, SF, name="icosphere")
    VECTOR = CLIENT.build(SPHERE.id, "vector", 100, progress=False)
    NFIELD = CLIENT.build(SPHERE.id, "nfield", 60, n=4, progress=False)
    TENSOR = CLIENT.build(SPHERE.id, "tensor", 60, progress=False)


def tearDownModule():
    CLIENT.close()
    try:
        assert DAEMON_PROC.stop() == 0, "daemon exits 0 on SIGTERM"
    finally:
        if DAEMON_PROC.alive():
            DAEMON_PROC.proc.kill()
        shutil.rmtree(WORK, ignore_errors=True)


class MeshTest(unittest.TestCase):
    def test_arrays_round_trip_through_mesh_geometry(self):
        self.assertEqual(SPHERE.num_faces, 1280)
        self.assertEqual(SPHERE.num_vertices, len(SV))
        self.assertEqual(SPHERE.euler_characteristic, 2)
        self.assertTrue(SPHERE.id.startswith("m-"))
        V, F = CLIENT.mesh_geometry(SPHERE.id)
        self.assertEqual(V.dtype, np.float64)
        self.assertEqual(F.dtype, np.int32)
        np.testing.assert_array_equal(V, SV)  # float64 on the wire: bit-exact
        np.testing.assert_array_equal(F, SF)

    def test_file_and_arrays_give_the_same_id(self):
        path = os.path.join(WORK, "sphere.obj")
        with open(path, "w") as f:
            f.write(icosphere_obj(3)[0])
        info = CLIENT.upload(path)
        self.assertEqual(info.id, SPHERE.id)
        self.assertIn(SPHERE.id, [m.id for m in CLIENT.meshes()])
        self.assertEqual(CLIENT.mesh(SPHERE.id).num_faces, 1280)

    def test_delete_mesh_needs_cascade(self):
        V, F = obj_arrays(torus_obj(12, 6)[0])
        mesh = CLIENT.upload(V, F)
        basis = CLIENT.build(mesh, "vector", 10, progress=False)
        with self.assertRaises(fs.FailedPrecondition):
            CLIENT.delete_mesh(mesh.id)
        self.assertEqual(CLIENT.delete_mesh(mesh.id, cascade=True), [basis])
        with self.assertRaises(fs.NotFound):
            CLIENT.mesh(mesh.id)


class FieldTest(unittest.TestCase):
    def coefficients(self, basis, seed):
        d = CLIENT.basis(basis).columns
        return np.random.default_rng(seed).standard_normal(d)

    def test_vector_lift_shapes_and_encodings(self):
        x = self.coefficients(VECTOR, 1)
        field = CLIENT.lift(VECTOR, x)
        self.assertEqual(field.shape, (1280, 3))
        normals = normals_of(SV, SF)
        scale = np.abs(field).max()
        self.assertGreater(scale, 0)
        self.assertLess(np.abs(np.sum(field * normals, axis=1)).max(), 1e-5 * scale)  # tangent
        dofs = CLIENT.lift(VECTOR, x, encoding="dof")
        self.assertEqual(dofs.shape, (1280, 2))
        np.testing.assert_allclose(np.linalg.norm(dofs, axis=1), np.linalg.norm(field, axis=1),
                                   rtol=1e-5, atol=1e-6 * scale)
        subset = CLIENT.lift(VECTOR, x, faces=[7, 3, 7, 1279])
        np.testing.assert_array_equal(subset, field[[7, 3, 7, 1279]])
        self.assertEqual(CLIENT.lift(VECTOR, x, faces=[]).shape, (0, 3))

    def test_nfield_lift_gives_all_n_directions(self):
        x = self.coefficients(NFIELD, 2)
        field = CLIENT.lift(NFIELD, x)
        self.assertEqual(field.shape, (1280, 4, 3))
        normals = normals_of(SV, SF)
        lengths = np.linalg.norm(field, axis=2)
        np.testing.assert_allclose(lengths, lengths[:, :1].repeat(4, axis=1), rtol=1e-9)
        big = lengths[:, 0] > 1e-3 * lengths.max()
        for j in range(4):
            # each direction is tangent; the next is the previous one turned by 90 degrees
            self.assertLess(np.abs(np.sum(field[:, j] * normals, axis=1)).max(),
                            1e-5 * lengths.max())
            turned = np.cross(normals, field[:, j])
            np.testing.assert_allclose(field[big, (j + 1) % 4], turned[big],
                                       atol=1e-12 * lengths.max())
        # The DOFs are the representation vector: angle times 4, the same length.
        dofs = CLIENT.lift(NFIELD, x, encoding="dof")
        np.testing.assert_allclose(np.linalg.norm(dofs, axis=1), lengths[:, 0], rtol=1e-5,
                                   atol=1e-6 * lengths.max())
        # Design sessions watch all four directions too.
        with CLIENT.design(NFIELD, watch=[1, 2]) as s:
            u = s.add(1, field[1, 2], hard=True)
        self.assertEqual(u.watched.shape, (2, 4, 3))
        self.assertEqual(CLIENT.lift(NFIELD, x, faces=[]).shape, (0, 4, 3))
        np.testing.assert_allclose(u.watched, CLIENT.lift(NFIELD, u.coefficients, faces=[1, 2]))
        self.assertLess(np.min(np.linalg.norm(u.watched[0] - field[1, 2], axis=1)),
                        1e-5 * lengths.max())  # the hard constraint holds (in some direction)
        # Any of the four directions, sent back, projects to the same coefficients.
        for j in (0, 3):
            p = CLIENT.project(NFIELD, field[:, j, :])
            np.testing.assert_allclose(p.coefficients, x, rtol=0, atol=1e-4 * np.abs(x).max())

    def test_tensor_lift_is_symmetric_and_tangent(self):
        x = self.coefficients(TENSOR, 3)
        field = CLIENT.lift(TENSOR, x)
        self.assertEqual(field.shape, (1280, 3, 3))
        np.testing.assert_array_equal(field, np.swapaxes(field, 1, 2))
        normals = normals_of(SV, SF)
        scale = np.abs(field).max()
        self.assertLess(np.abs(np.einsum("fij,fj->fi", field, normals)).max(), 1e-5 * scale)
        self.assertEqual(CLIENT.lift(TENSOR, x, encoding="dof").shape, (1280, 3))
        # (F, 3, 3), (F, 6) and (F, 3) DOFs are all accepted and mean the same field.
        six = np.stack([field[:, 0, 0], field[:, 1, 1], field[:, 2, 2], field[:, 0, 1],
                        field[:, 1, 2], field[:, 2, 0]], axis=1)
        a = CLIENT.project(TENSOR, field).coefficients
        b = CLIENT.project(TENSOR, six).coefficients
        c = CLIENT.project(TENSOR, CLIENT.lift(TENSOR, x, encoding="dof")).coefficients
        np.testing.assert_allclose(a, x, atol=1e-4 * np.abs(x).max())
        np.testing.assert_allclose(b, a, atol=1e-9)
        np.testing.assert_allclose(c, x, atol=1e-4 * np.abs(x).max())

    def test_project_and_smooth_recover_a_field_of_the_basis(self):
        x = self.coefficients(VECTOR, 4)
        field = CLIENT.lift(VECTOR, x)
        p = CLIENT.project(VECTOR, field)
        self.assertLess(p.relative_error, 1e-5)
        np.testing.assert_allclose(p.coefficients, x, atol=1e-4 * np.abs(x).max())
        s = CLIENT.smooth(VECTOR, field, weights=(1e-9, 0, 1), return_field=True)
        np.testing.assert_allclose(s.coefficients, x, atol=1e-3 * np.abs(x).max())
        self.assertEqual(s.field.shape, (1280, 3))
        self.assertIn("total_ms", s.timings)
        # Noise on every face: weak smoothing keeps it (as far as the basis can represent it),
        # strong smoothing removes it.
        noisy = field + 0.5 * np.random.default_rng(5).standard_normal(field.shape)
        weak = CLIENT.smooth(VECTOR, noisy, weights=(1e-6, 0, 1), return_field=True)
        strong = CLIENT.smooth(VECTOR, noisy, weights=(0.1, 0, 1), return_field=True)
        self.assertLess(roughness(strong.field), 0.5 * roughness(weak.field))
        self.assertLess(roughness(weak.field), roughness(noisy))

    def test_face_weights_refine_the_basis_where_they_are_high(self):
        # Paper section 4.4 / Fig. 9: adaptivity weights put more, smaller regions where they are
        # high, so a field with detail only there is approximated better than by the uniform
        # basis of the same dimension.
        centers = SV[SF].mean(axis=1)
        high = centers[:, 2] > 0.2
        weights = np.where(high, 4.0, 1.0)
        adaptive = CLIENT.build(SPHERE.id, "vector", 100, face_weights=weights, progress=False)
        self.assertNotEqual(adaptive, VECTOR)
        n = normals_of(SV, SF)
        bump = np.clip((centers[:, 2] - 0.2) / 0.4, 0, 1)[:, None]
        wave = bump * np.stack([np.sin(4 * centers[:, 1]), np.cos(4 * centers[:, 0]),
                                np.sin(4 * centers[:, 0] + 4 * centers[:, 1])], axis=1)
        target = wave - np.sum(wave * n, axis=1, keepdims=True) * n
        uniform_error = CLIENT.project(VECTOR, target).relative_error
        adaptive_error = CLIENT.project(adaptive, target).relative_error
        self.assertLess(adaptive_error, 0.85 * uniform_error)
        with self.assertRaises(fs.InvalidArgument):
            CLIENT.build(SPHERE.id, "vector", 100, face_weights=weights[:-1], progress=False)

    def test_low_modes_quality_level(self):
        low = CLIENT.build(SPHERE.id, "vector", 100, quality="low-modes", progress=False)
        self.assertNotEqual(low, VECTOR)
        self.assertEqual(CLIENT.basis(low).quality, "low-modes")
        self.assertEqual(CLIENT.basis(VECTOR).quality, "paper")
        # The lowest modes (l = 1: 2 on the unit sphere, 6 of them) come out closer.
        paper = CLIENT.eigen(VECTOR, 6).eigenvalues
        levels = CLIENT.eigen(low, 6).eigenvalues
        self.assertLess(np.mean(levels), np.mean(paper))
        with self.assertRaises(ValueError):
            CLIENT.build(SPHERE.id, "vector", 100, quality="best", progress=False)
        with self.assertRaises(fs.InvalidArgument):
            CLIENT.build(SPHERE.id, "vector", 39, quality="low-modes", progress=False)
        # Smooth: the same levels with clamped fields; its lowest modes come closer still to
        # the sphere's l = 1 eigenvalue 2.
        smooth = CLIENT.build(SPHERE.id, "vector", 100, quality="smooth", progress=False)
        self.assertNotIn(smooth, (low, VECTOR))
        self.assertEqual(CLIENT.basis(smooth).quality, "smooth")
        self.assertEqual(CLIENT.basis(smooth).nnz, CLIENT.basis(low).nnz)
        clamped = CLIENT.eigen(smooth, 6).eigenvalues
        self.assertLess(np.abs(clamped - 2).max(), np.abs(levels - 2).max())
        with self.assertRaises(fs.InvalidArgument):
            CLIENT.build(SPHERE.id, "vector", 39, quality="smooth", progress=False)

    def test_eigen_and_smoothest(self):
        e = CLIENT.eigen(VECTOR, 8)
        self.assertEqual(e.eigenvalues.shape, (8,))
        self.assertEqual(e.coefficients.shape, (8, 100))
        self.assertTrue(np.all(np.diff(e.eigenvalues) >= 0))
        s = CLIENT.smoothest(VECTOR, return_field=True)
        self.assertAlmostEqual(s.energy, e.eigenvalues[0], places=9)
        self.assertEqual(s.field.shape, (1280, 3))
        # M-normalized: sum of area |X_f|^2 is 1 (float32 values on the wire).
        V, F = SV, SF
        areas = 0.5 * np.linalg.norm(np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]),
                                     axis=1)
        self.assertAlmostEqual(float(np.sum(areas * np.sum(s.field ** 2, axis=1))), 1.0, places=4)

    def test_singularities_come_with_solve_smooth_and_align_on_request(self):
        s = CLIENT.solve(VECTOR, [5], [[1.0, 0.0, 0.0]], singularities=True)
        self.assertIsNotNone(s.singularities)
        alone = CLIENT.singularities(VECTOR, coefficients=s.coefficients)
        np.testing.assert_array_equal(s.singularities.vertices, alone.vertices)
        np.testing.assert_array_equal(s.singularities.index, alone.index)
        self.assertEqual(s.singularities.index_sum, 2)
        self.assertIsNone(CLIENT.solve(VECTOR, [5], [[1.0, 0.0, 0.0]]).singularities)
        field = CLIENT.lift(VECTOR, s.coefficients)
        smoothed = CLIENT.smooth(VECTOR, field, singularities=True)
        self.assertEqual(smoothed.singularities.index_sum, 2)

    def test_singularities_sum_to_the_euler_characteristic(self):
        s = CLIENT.smoothest(VECTOR)
        sing = CLIENT.singularities(VECTOR, coefficients=s.coefficients)
        self.assertEqual(sing.euler_characteristic, 2)
        self.assertAlmostEqual(sing.index_sum, 2.0, places=9)
        self.assertAlmostEqual(float(np.sum(sing.turns)), 2.0, places=9)
        self.assertEqual(sing.positions.shape, (len(sing.vertices), 3))
        np.testing.assert_allclose(np.linalg.norm(sing.positions, axis=1), 1.0, rtol=1e-9)
        # The 4-field: indices in quarter turns, still summing to 2.
        s4 = CLIENT.smoothest(NFIELD, return_field=True)
        sing4 = CLIENT.singularities(NFIELD, field=s4.field)
        self.assertEqual(sing4.n, 4)
        self.assertAlmostEqual(sing4.index_sum, 2.0, places=9)
        np.testing.assert_allclose(sing4.turns, sing4.index / 4.0)

    def test_curvature_of_the_unit_sphere(self):
        c = CLIENT.curvature(SPHERE.id, principal=True)
        self.assertEqual(c.tensor.shape, (1280, 3, 3))
        normals = normals_of(SV, SF)
        projector = np.eye(3)[None] - normals[:, :, None] * normals[:, None, :]
        # +(1/r) I on the tangent planes, for a unit sphere with outward normals
        self.assertLess(np.abs(c.tensor - projector).max(), 0.05)
        np.testing.assert_allclose(c.k1, 1.0, atol=0.05)
        np.testing.assert_allclose(c.k2, 1.0, atol=0.05)
        self.assertTrue(np.all(c.k1 >= c.k2))
        np.testing.assert_allclose(np.linalg.norm(c.d1, axis=1), 1.0, rtol=1e-5)
        self.assertEqual(CLIENT.curvature(SPHERE.id, encoding="dof").tensor.shape, (1280, 3))

    def test_align_follows_the_principal_directions_of_a_torus(self):
        V, F = obj_arrays(torus_obj(48, 16)[0])
        torus = CLIENT.upload(V, F, name="torus")
        lines = CLIENT.build(torus.id, "nfield", 60, n=2, progress=False)
        aligned = CLIENT.align(lines, return_field=True)
        self.assertEqual(aligned.field.shape, (len(F), 2, 3))
        np.testing.assert_allclose(aligned.field[:, 1], -aligned.field[:, 0], atol=1e-12)
        d1 = CLIENT.curvature(torus.id, principal=True).d1
        u = aligned.field[:, 0] / np.linalg.norm(aligned.field[:, 0], axis=1, keepdims=True)
        cosines = np.abs(np.sum(u * d1, axis=1))
        self.assertGreater(np.median(cosines), 0.98)
        with self.assertRaises(fs.InvalidArgument):  # align needs n = 2 or 4
            CLIENT.align(VECTOR)


class SolveAndDesignTest(unittest.TestCase):
    def test_design_session_matches_solve(self):
        watch = [0, 12, 600]
        with CLIENT.design(VECTOR, fs.Weights(1.0, 0.0, 1.0), watch=watch) as s:
            self.assertTrue(s.last.refactorized or s.last.edit == "open")
            u = s.add(10, [1, 0, 0], weight=2.0)
            self.assertEqual(u.constraint_id, 1)
            self.assertEqual(u.num_constraints, 1)
            self.assertFalse(u.refactorized)
            s.move(u.constraint_id, 12, [0, 1, 0])
            h = s.add(600, [0, 0, 1], hard=True)
            self.assertEqual((h.constraint_id, h.num_hard_constraints), (2, 1))
            t = s.add(30, [0.3, 0.1, 0.2])
            s.remove(t.constraint_id)
            w = s.set_weights(mu_b=0.01)
            self.assertTrue(w.refactorized)
            self.assertEqual(s.weights, fs.Weights(1.0, 0.01, 1.0))
            x = s.coefficients
            watched = s.last.watched
            self.assertEqual(watched.shape, (3, 3))
            np.testing.assert_array_equal(s.last.watched_faces, watch)
        solved = CLIENT.solve(VECTOR, [12, 600], [[0, 1, 0], [0, 0, 1]],
                              weights=(1.0, 0.01, 1.0), constraint_weights=[2.0, 1.0],
                              hard=[False, True], return_field=True)
        self.assertLess(np.linalg.norm(x - solved.coefficients),
                        1e-8 * np.linalg.norm(solved.coefficients))
        np.testing.assert_allclose(watched, solved.field[watch], atol=1e-6)
        # The hard constraint holds in the tangent plane of face 600 (float32 on the wire).
        n600 = normals_of(SV, SF)[600]
        target = np.array([0, 0, 1.0]) - n600[2] * n600
        np.testing.assert_allclose(solved.field[600], target, atol=1e-5)

    def test_scale_free_and_raw_weights(self):
        # One soft constraint at the default (scale-free) weights pulls its face at least half
        # way; raw weights (the paper's) pull less on this basis, and mu_b is area-relative.
        value = np.array([[0.0, 0.0, 1.0]])
        n = normals_of(SV, SF)[77]
        target = value[0] - n.dot(value[0]) * n
        pulls = {}
        for raw in (False, True):
            r = CLIENT.solve(VECTOR, [77], value, raw_weights=raw, return_field=True)
            pulls[raw] = float(r.field[77].dot(target) / target.dot(target))
        self.assertGreaterEqual(pulls[False], 0.5 - 1e-5)
        self.assertLess(pulls[True], pulls[False])
        with self.assertRaises(fs.InvalidArgument):  # mu_a: only with a data term
            CLIENT.solve(VECTOR, [77], value, weights=fs.Weights(1, 0, 1, 1))

    def test_mixed_biharmonic_in_solve_and_design(self):
        # The mixed form (the default) is another energy than the exact one (a different
        # minimizer); a session opened with it reaches the one-shot solve's minimizer through its
        # own solver.
        faces, values = [12, 600], [[0, 1, 0], [0, 0, 1]]
        weights = fs.Weights(0.1, 1.0, 1.0)
        mixed = CLIENT.solve(VECTOR, faces, values, weights=weights, hard=[False, True],
                             biharmonic="mixed")
        exact = CLIENT.solve(VECTOR, faces, values, weights=weights, hard=[False, True],
                             biharmonic="exact")
        default = CLIENT.solve(VECTOR, faces, values, weights=weights, hard=[False, True])
        np.testing.assert_array_equal(default.coefficients, mixed.coefficients)
        scale = np.linalg.norm(mixed.coefficients)
        self.assertGreater(np.linalg.norm(mixed.coefficients - exact.coefficients), 1e-3 * scale)
        self.assertLessEqual(mixed.backward_error, 1e-12)
        self.assertLessEqual(mixed.iterations, 2)  # refinement steps: the partial fractions
        for form in ("mixed", None):  # None: the default
            kwargs = {} if form is None else {"biharmonic": form}
            with CLIENT.design(VECTOR, weights, **kwargs) as s:
                s.add(12, [0, 1, 0])
                u = s.add(600, [0, 0, 1], hard=True)
                x = s.coefficients
            self.assertLess(np.linalg.norm(x - mixed.coefficients), 1e-8 * scale)
            self.assertLessEqual(u.iterations, 4)  # refinement steps in the eigenbasis
            # Checked periodically like the exact form's solves: NaN when this one was not.
            self.assertTrue(math.isnan(u.backward_error) or u.backward_error <= 1e-12)
        for call in (lambda: CLIENT.solve(VECTOR, [5], [[1.0, 0, 0]], biharmonic="lumped"),
                     lambda: CLIENT.design(VECTOR, biharmonic=1)):
            with self.assertRaises(fs.InvalidArgument):
                call()

    def test_design_with_a_curvature_data_term(self):
        V, F = obj_arrays(torus_obj(48, 16)[0])
        torus = CLIENT.upload(V, F, name="torus")
        lines = CLIENT.build(torus.id, "nfield", 60, n=2, progress=False)
        aligned = CLIENT.align(lines)
        with CLIENT.design(lines, align_curvature=True, watch=[100]) as s:
            self.assertEqual(s.weights, fs.Weights(0.001, 0.0, 1.0, 1.0))
            np.testing.assert_allclose(s.coefficients, aligned.coefficients, rtol=0,
                                       atol=1e-8 * np.linalg.norm(aligned.coefficients))
            s.add(100, [0.0, 0.0, 1.0])
            self.assertFalse(s.last.refactorized)
            w = s.set_weights(mu_a=0.25)
            self.assertTrue(w.refactorized)
            self.assertEqual(s.weights.mu_a, 0.25)
        with self.assertRaises(fs.InvalidArgument):  # a curvature target needs n = 2 or 4
            with CLIENT.design(VECTOR, align_curvature=True):
                pass

    def test_dof_constraints_equal_ambient_ones(self):
        ambient = CLIENT.solve(VECTOR, [5], [[1.0, 0.0, 0.0]])
        dofs = CLIENT.lift(VECTOR, ambient.coefficients, faces=[5], encoding="dof")
        # The constraint [1, 0, 0] in DOFs: its frame coordinates.
        V, F = SV, SF
        x_f = V[F[5, 1]] - V[F[5, 0]]
        x_f /= np.linalg.norm(x_f)
        y_f = np.cross(normals_of(V, F)[5], x_f)
        value = [x_f[0], y_f[0]]
        by_dofs = CLIENT.solve(VECTOR, [5], [value], encoding="dof")
        np.testing.assert_allclose(by_dofs.coefficients, ambient.coefficients, atol=1e-9)
        self.assertEqual(dofs.shape, (1, 2))
        # DOFs without encoding="dof" are refused, the message says what they would mean.
        with self.assertRaises(fs.InvalidArgument) as caught:
            CLIENT.solve(VECTOR, [5], [value])
        self.assertIn("face-frame DOFs", str(caught.exception))
        self.assertIn("encoding='dof'", str(caught.exception))

    def test_a_refused_edit_costs_only_that_edit(self):
        s = CLIENT.design(VECTOR)
        before = s.add(3, [1, 0, 0], id=7)
        with self.assertRaises(fs.AlreadyExists) as caught:
            s.add(4, [0, 1, 0], id=7)
        self.assertEqual(caught.exception.code, grpc.StatusCode.ALREADY_EXISTS)
        self.assertTrue(str(caught.exception).startswith("Design add failed: ALREADY_EXISTS: "))
        # The session is open and as it was: the last update is the one before the refused edit,
        # and the next edit applies to it.
        self.assertIs(s.last, before)
        np.testing.assert_array_equal(s.coefficients, before.coefficients)
        removed = s.remove(7)
        self.assertEqual(removed.num_constraints, 0)
        s.close()
        # A bad value is refused before anything is sent; the session goes on.
        with CLIENT.design(VECTOR) as s2:
            with self.assertRaises(fs.InvalidArgument):
                s2.add(3, [1, 0, 0, 0])
            self.assertEqual(s2.add(3, [1, 0, 0]).num_constraints, 1)


def open_box(k):
    """The unit cube without its top, k x k cells of two triangles per side: (V, F)."""
    sides = [((0, 0, 0), (0, 1, 0), (1, 0, 0)), ((0, 0, 0), (0, 0, 1), (0, 1, 0)),
             ((1, 0, 0), (0, 1, 0), (0, 0, 1)), ((0, 0, 0), (1, 0, 0), (0, 0, 1)),
             ((0, 1, 0), (0, 0, 1), (1, 0, 0))]
    index, vertices, faces = {}, [], []

    def at(o, u, v, i, j):
        key = tuple(o[c] * k + i * u[c] + j * v[c] for c in range(3))
        if key not in index:
            index[key] = len(vertices)
            vertices.append([x / k for x in key])
        return index[key]

    for o, u, v in sides:
        for i in range(k):
            for j in range(k):
                a, b = at(o, u, v, i, j), at(o, u, v, i + 1, j)
                c, d = at(o, u, v, i + 1, j + 1), at(o, u, v, i, j + 1)
                faces += [[a, b, c], [a, c, d]]
    return np.array(vertices, dtype=np.float64), np.array(faces, dtype=np.int32)


class RightAngleFramesTest(unittest.TestCase):
    def test_soft_constraints_on_a_four_field_of_a_box_solve(self):
        # A 4-field's frames on a box turn by right angles: basis columns sharing a face can
        # sum to exact zeros in the reduced matrices, so their entry is not in the shared
        # pattern, but a soft constraint couples them (the Solve answered INTERNAL before).
        box = CLIENT.upload(*open_box(8), name="open_box")
        basis = CLIENT.build(box.id, "nfield", 40, n=4, progress=False)
        faces = list(range(0, box.num_faces, 7))
        values = [[np.cos(f), np.sin(f), 0.3] for f in faces]
        solved = CLIENT.solve(basis, faces, values)
        with CLIENT.design(basis) as s:
            for i, (f, v) in enumerate(zip(faces, values)):
                s.add(f, v, id=i)
            session = s.coefficients
        scale = np.linalg.norm(session)
        self.assertGreater(scale, 0.0)
        np.testing.assert_allclose(solved.coefficients, session, rtol=0, atol=1e-9 * scale)


class DesignToolsTest(unittest.TestCase):
    def test_tools_are_groups_moved_and_removed_as_one(self):
        arc = [(np.cos(t), np.sin(t), 0.1) for t in np.linspace(0.0, 1.2, 4)]
        with CLIENT.design(NFIELD, fs.Weights(1.0, 0.0, 1.0), watch=[0]) as s:
            a = s.stroke(arc, weight=2.0)
            self.assertEqual((a.edit, a.constraint_id), ("stroke", 1))
            self.assertGreater(a.num_constraints, 5)  # one per crossed face
            b = s.place_singularity(17, 0.25, weight=10.0)
            self.assertEqual(b.constraint_id, 2)
            self.assertGreater(b.num_constraints, a.num_constraints + 4)  # its 5 or 6 faces
            # A face point stroke replaces the first stroke as one edit.
            m = s.stroke([(3, (0.2, 0.3, 0.5)), (40, (0.3, 0.3, 0.4))], id=1, move=True)
            self.assertEqual(m.edit, "move")
            r = s.remove(2)
            self.assertEqual(r.num_constraints, m.num_constraints - (b.num_constraints
                                                                     - a.num_constraints))
            with self.assertRaises(fs.FailedPrecondition):
                s.align_boundary()  # the sphere has no boundary
        with CLIENT.design(NFIELD) as s:
            with self.assertRaises(fs.InvalidArgument):
                s.place_singularity(17, 0.3)  # not a multiple of 1/4

    def test_solve_with_groups_equals_the_session(self):
        arc = [(np.cos(t), np.sin(t), 0.1) for t in np.linspace(0.0, 1.2, 4)]
        weights = fs.Weights(1.0, 0.0, 1.0)
        stroke = fs.tools.stroke(arc, weight=2.0)
        singularity = fs.tools.singularity(17, 0.25, hard=True)
        with CLIENT.design(NFIELD, weights) as s:
            s.add(30, [0, 0, 1], weight=0.5)
            s.stroke(arc, weight=2.0)
            session = s.place_singularity(17, 0.25, hard=True)
        solved = CLIENT.solve(NFIELD, [30], [[0, 0, 1]], constraint_weights=[0.5],
                              groups=[stroke, singularity], weights=weights)
        scale = np.linalg.norm(session.coefficients)
        self.assertGreater(scale, 0.0)
        np.testing.assert_allclose(solved.coefficients, session.coefficients, rtol=0,
                                   atol=1e-9 * scale)
        # Without the groups the answer differs: they reached the Solve.
        alone = CLIENT.solve(NFIELD, [30], [[0, 0, 1]], constraint_weights=[0.5], weights=weights)
        self.assertGreater(np.linalg.norm(alone.coefficients - session.coefficients), 1e-3 * scale)
        with self.assertRaises(TypeError):
            CLIENT.solve(NFIELD, groups=[{"stroke": arc}])


class RoutingKeyTest(unittest.TestCase):
    def test_calls_that_name_an_id_send_it_as_routing_key(self):
        recorded = []

        class Recorder(grpc.GenericRpcHandler):
            def service(self, details):
                metadata = dict(details.invocation_metadata)
                recorded.append((details.method.rsplit("/", 1)[1],
                                 metadata.get("x-fieldspace-key")))
                return None  # UNIMPLEMENTED

        server = grpc.server(concurrent.futures.ThreadPoolExecutor(2))
        server.add_generic_rpc_handlers((Recorder(),))
        port = server.add_insecure_port("127.0.0.1:0")
        server.start()
        try:
            with fs.Client("127.0.0.1:%d" % port, timeout=10) as c:
                calls = [lambda: c.mesh("m-0000000000000001"), lambda: c.meshes(),
                         lambda: c.basis("b-0000000000000002"),
                         lambda: c.build("m-0000000000000003", "vector", 8, progress=False),
                         lambda: c.delete_basis("b-0000000000000004")]
                for call in calls:
                    with self.assertRaises(fs.FieldspaceError):
                        call()
        finally:
            server.stop(None)
        self.assertEqual(recorded, [("GetMesh", "m-0000000000000001"), ("ListMeshes", None),
                                    ("GetBasis", "b-0000000000000002"),
                                    ("BuildBasis", "m-0000000000000003"),
                                    ("DeleteBasis", "b-0000000000000004")])


class FailoverTest(unittest.TestCase):
    def test_a_drained_session_resumes_on_the_next_daemon_with_the_same_solution(self):
        store = os.path.join(WORK, "shared")
        a = Daemon(DAEMON, store, extra=["--shared-store"]).start()
        b = None
        try:
            with fs.Client(a.address, timeout=60) as c:
                mesh = c.upload(SV, SF, name="icosphere")
                basis = c.build(mesh.id, "vector", 40, progress=False)
                s = c.design(basis, watch=[0, 5])
                s.add(10, [1, 0, 0])
                s.add(20, [0, 1, 0], hard=True)
                moved = s.add(30, [0, 0, 1], weight=3.0)
                s.add(40, [1, 1, 0])
                s.move(moved.constraint_id, 31, [1, 0, 1])
                s.remove(1)
                s.set_weights(mu_b=0.01)
                before = s.coefficients.copy()
                self.assertEqual(a.stop(), 0)  # drains: the session ends UNAVAILABLE
                b = Daemon(DAEMON, store, extra=["--shared-store"], listen=a.address).start()
                u = s.watch([0, 5])  # changes nothing: the resumed solution is the old one
                self.assertTrue(u.resumed)
                self.assertEqual((s.resumes, u.num_constraints, u.num_hard_constraints), (1, 3, 1))
                self.assertLess(np.max(np.abs(u.coefficients - before)), 1e-10)
                v = s.add(50, [0, 0, 1])
                self.assertFalse(v.resumed)
                self.assertEqual(v.constraint_id, 5)
                s.close()
        finally:
            for d in (a, b):
                if d is not None and d.alive():
                    d.stop()


class ErrorTest(unittest.TestCase):
    def test_unknown_ids_are_not_found(self):
        with self.assertRaises(fs.NotFound) as caught:
            CLIENT.mesh("m-0000000000000000")
        e = caught.exception
        self.assertIsInstance(e, fs.FieldspaceError)
        self.assertIsInstance(e, LookupError)
        self.assertEqual(e.code, grpc.StatusCode.NOT_FOUND)
        self.assertEqual(e.what, "GetMesh")
        self.assertEqual(str(e), "GetMesh failed: NOT_FOUND: " + e.details)
        self.assertIn("m-0000000000000000", e.details)
        with self.assertRaises(fs.NotFound):
            CLIENT.lift("b-0000000000000000", [1.0])
        with self.assertRaises(fs.NotFound):
            CLIENT.cancel("b-0000000000000000")  # no running build
        with self.assertRaises(fs.FailedPrecondition):
            CLIENT.cancel(VECTOR)  # built already

    def test_bad_input_is_invalid_argument(self):
        with self.assertRaises(fs.InvalidArgument) as caught:  # the server's mesh validation
            CLIENT.upload(np.eye(3), np.array([[0, 1, 1]]))
        self.assertEqual(caught.exception.code, grpc.StatusCode.INVALID_ARGUMENT)
        self.assertTrue(str(caught.exception).startswith("UploadMesh failed: INVALID_ARGUMENT: "))
        with self.assertRaises(fs.InvalidArgument):  # d coefficients expected (server)
            CLIENT.lift(VECTOR, [1.0, 2.0])
        with self.assertRaises(fs.InvalidArgument):  # face out of range (server)
            CLIENT.solve(VECTOR, [5000], [[1, 0, 0]])
        with self.assertRaises(ValueError):  # shape checked by the client
            CLIENT.solve(VECTOR, [1], [[1, 0, 0, 0]])
        with self.assertRaises(fs.InvalidArgument):
            CLIENT.build(SPHERE.id, "vector", 10, n=3)
        with self.assertRaises(fs.NotFound):
            CLIENT.upload(os.path.join(WORK, "missing.obj"))

    def test_limits_and_states(self):
        with self.assertRaises(fs.FailedPrecondition):  # LoadMesh needs --data-root
            CLIENT.load("sphere.obj")
        with self.assertRaises(fs.ResourceExhausted):
            CLIENT.build(SPHERE.id, "vector", 100000, progress=False)
        with self.assertRaises(fs.FailedPrecondition):  # two hard constraints on one face
            CLIENT.solve(VECTOR, [3, 3], [[1, 0, 0], [0, 1, 0]], hard=True)

    def test_unavailable(self):
        with fs.Client("127.0.0.1:1", timeout=5) as nowhere:
            with self.assertRaises(fs.Unavailable):
                nowhere.meshes()


class BuildTest(unittest.TestCase):
    def test_progress_and_idempotent_builds(self):
        seen = []
        basis = CLIENT.build(SPHERE.id, "vector", 40, seed=3, progress=False,
                             on_progress=seen.append)
        self.assertTrue(basis.startswith("b-"))
        self.assertTrue(all(p.basis_id == basis for p in seen))
        overall = [p.overall for p in seen]
        self.assertEqual(overall, sorted(overall))
        self.assertEqual(seen[-1].phase, "done")
        self.assertEqual(seen[-1].basis.columns, 40)
        info = CLIENT.basis(basis)
        self.assertTrue(info.ready)
        self.assertEqual((info.field.kind, info.dimension, info.seed), ("vector", 40, 3))
        again = []
        self.assertEqual(CLIENT.build(SPHERE.id, "vector", 40, seed=3, progress=False,
                                      on_progress=again.append), basis)
        self.assertEqual(len(again), 1)  # a stored basis: one DONE message
        CLIENT.delete_basis(basis)
        self.assertNotIn(basis, [b.id for b in CLIENT.bases(SPHERE.id)])

    def wait_gone(self, basis):
        """Waits until the server has dropped a cancelled build (it checks every 100 ms)."""
        deadline = time.monotonic() + 10
        while True:
            try:
                info = CLIENT.basis(basis)
            except fs.NotFound:
                return
            self.assertEqual(info.state, "building")
            self.assertLess(time.monotonic(), deadline, "the build was not cancelled")
            time.sleep(0.05)

    def test_deadline_ends_the_stream_not_the_build(self):
        V, F = obj_arrays(icosphere_obj(6)[0])  # 81,920 faces: a build of ~1.5-2 s
        mesh = CLIENT.upload(V, F)
        seen = []
        with self.assertRaises(fs.DeadlineExceeded) as caught:
            CLIENT.build(mesh.id, "vector", 500, seed=1, progress=False, on_progress=seen.append,
                         timeout=0.3)
        self.assertIsInstance(caught.exception, TimeoutError)
        self.assertTrue(str(caught.exception).startswith("BuildBasis failed: DEADLINE_EXCEEDED"))
        basis = seen[0].basis_id
        self.assertEqual(CLIENT.basis(basis).state, "building")  # it goes on
        CLIENT.cancel(basis)
        self.wait_gone(basis)
        CLIENT.delete_mesh(mesh.id, cascade=True)

    def test_keyboard_interrupt_cancels_the_build_on_the_server(self):
        V, F = obj_arrays(icosphere_obj(6)[0])  # 81,920 faces: a build of ~1.5-2 s
        mesh = CLIENT.upload(V, F)
        started = []

        def interrupt(progress):
            started.append(progress)
            raise KeyboardInterrupt

        t0 = time.monotonic()
        with self.assertRaises(KeyboardInterrupt):
            CLIENT.build(mesh.id, "vector", 500, progress=False, on_progress=interrupt)
        basis = started[0].basis_id
        self.assertFalse(started[0].joined)
        self.wait_gone(basis)
        self.assertLess(time.monotonic() - t0, 5.0)
        self.assertEqual(CLIENT.bases(mesh.id), [])
        CLIENT.delete_mesh(mesh.id, cascade=True)

    def test_ctrl_c_cancels_the_build_on_the_server(self):
        """A real SIGINT to a process blocked in build (progress bar on)."""
        V, F = obj_arrays(icosphere_obj(6)[0])  # as above: the build outlasts the signal
        mesh = CLIENT.upload(V, F)
        child = textwrap.dedent("""
            import signal, sys
            import fieldspace
            signal.signal(signal.SIGINT, signal.default_int_handler)
            def started(p):
                if p.basis_id and not getattr(started, "said", False):
                    print(p.basis_id, flush=True)
                    started.said = True
            fieldspace.Client(sys.argv[1]).build(sys.argv[2], "vector", 500, seed=2,
                                                progress=True, on_progress=started)
            """)
        proc = subprocess.Popen([sys.executable, "-c", child, DAEMON_PROC.address, mesh.id],
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        basis = proc.stdout.readline().strip()
        self.assertTrue(basis.startswith("b-"), basis)
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=30)
        self.assertNotEqual(proc.returncode, 0)
        self.assertIn("KeyboardInterrupt", err)
        self.assertIn("fieldspace: build %s cancelled on the server" % basis, err)
        self.wait_gone(basis)
        CLIENT.delete_mesh(mesh.id, cascade=True)


class TokenTest(unittest.TestCase):
    def test_token_is_required_and_accepted(self):
        token_file = os.path.join(WORK, "token")
        with open(token_file, "w") as f:
            f.write("s3cret-token\n")
        d = Daemon(DAEMON, os.path.join(WORK, "store-token"),
                   extra=["--auth-token-file", token_file]).start()
        try:
            with fs.Client(d.address, timeout=30) as anonymous:
                self.assertEqual(anonymous.health(), "SERVING")  # health needs no token
                with self.assertRaises(fs.Unauthenticated) as caught:
                    anonymous.meshes()
                self.assertEqual(caught.exception.code, grpc.StatusCode.UNAUTHENTICATED)
            with fs.Client(d.address, token="wrong", timeout=30) as wrong:
                with self.assertRaises(fs.Unauthenticated):
                    wrong.upload(SV, SF)
            with fs.Client(d.address, token=" s3cret-token\n", timeout=30) as client:
                self.assertEqual(client.upload(SV, SF).id, SPHERE.id)
                basis = client.build(SPHERE.id, "vector", 20, progress=False)
                with client.design(basis) as s:  # streams carry the token too
                    self.assertEqual(s.add(1, [1, 0, 0]).num_constraints, 1)
                self.assertEqual([m.id for m in client.meshes()], [SPHERE.id])
        finally:
            self.assertEqual(d.stop(), 0)
            if d.alive():
                d.proc.kill()


if __name__ == "__main__":
    unittest.main(verbosity=2)
