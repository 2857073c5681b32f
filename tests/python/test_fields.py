"""fieldspace.fields: face frames and encodings against docs/conventions.md, and against field
files the C++ CLI writes (when FIELDSPACE_BIN_DIR names a directory with fieldspaced and
fieldspace)."""

import json
import math
import os
import shutil
import sys
import tempfile
import unittest

import testenv
import numpy as np

from fieldspace import fields as fl
import shapes


# A 4 x 3 grid of slightly bent quads and a pentagon on its side (all counter-clockwise).
POLYGON_OBJ = "".join(
    "v %r %r %r\n" % (i, j, 0.1 * i * j) for i in range(5) for j in range(4)) + (
    "v 5 0 0\nv 5.5 0.5 0.2\nv 5 1 0.3\n") + "".join(
    "f %d %d %d %d\n" % (4 * i + j + 1, 4 * (i + 1) + j + 1, 4 * (i + 1) + j + 2, 4 * i + j + 2)
    for i in range(4) for j in range(3)) + "f 18 17 21 22 23\n"


def assert_same_nfield(test, a, b, atol):
    """Equal n-fields: the same set of directions per face (in the same cyclic order)."""
    test.assertEqual(a.shape, b.shape)
    n = a.shape[1]
    errors = np.stack([np.abs(np.roll(a, k, axis=1) - b).max(axis=(1, 2)) for k in range(n)])
    test.assertLessEqual(float(errors.min(axis=0).max()), atol)


def random_tangent(V, F, rng, shape=()):
    n = fl.face_normals(V, F)
    v = rng.normal(size=(len(F),) + shape + (3,))
    if shape:
        return v - np.sum(v * n[:, None, :], axis=-1)[..., None] * n[:, None, :]
    return v - np.sum(v * n, axis=1)[:, None] * n


class FramesTest(unittest.TestCase):
    def setUp(self):
        self.V, self.F = shapes.torus(12, 8)
        self.rng = np.random.default_rng(3)

    def test_frames_follow_the_conventions(self):
        x, y, n = fl.face_frames(self.V, self.F)
        p = self.V[self.F]
        e1 = p[:, 1] - p[:, 0]
        np.testing.assert_allclose(x, e1 / np.linalg.norm(e1, axis=1)[:, None], atol=1e-15)
        for a, b in ((x, y), (y, n), (n, x)):
            np.testing.assert_allclose(np.sum(a * b, axis=1), 0, atol=1e-14)
        for a in (x, y, n):
            np.testing.assert_allclose(np.linalg.norm(a, axis=1), 1, atol=1e-14)
        np.testing.assert_allclose(np.cross(x, y), n, atol=1e-14)
        # Outward normals on the torus (its faces are oriented outwards).
        c = p.mean(axis=1)
        ring = c.copy()
        ring[:, 2] = 0
        ring = ring / np.linalg.norm(ring, axis=1)[:, None]
        self.assertTrue(np.all(np.sum(n * (c - ring), axis=1) > 0))

    def test_cyclic_corner_rotation_rotates_the_dofs(self):
        v = random_tangent(self.V, self.F, self.rng)
        d = fl.dofs_from_vectors(self.V, self.F, v)
        F2 = self.F[:, [1, 2, 0]]
        d2 = fl.dofs_from_vectors(self.V, F2, v)
        np.testing.assert_allclose(np.linalg.norm(d, axis=1), np.linalg.norm(d2, axis=1),
                                   rtol=1e-12)
        np.testing.assert_allclose(fl.vectors_from_dofs(self.V, F2, d2), v, atol=1e-12)

    def test_vector_round_trip_drops_the_normal_part(self):
        v = random_tangent(self.V, self.F, self.rng)
        n = fl.face_normals(self.V, self.F)
        d = fl.dofs_from_vectors(self.V, self.F, v + 0.7 * n)
        np.testing.assert_allclose(fl.vectors_from_dofs(self.V, self.F, d), v, atol=1e-12)

    def test_nfield_directions_and_representation(self):
        for n in (1, 2, 3, 4, 6):
            rep = random_tangent(self.V, self.F, self.rng)
            dirs = fl.nfield_from_representative(self.V, self.F, rep, n)
            self.assertEqual(dirs.shape, (len(self.F), n, 3))
            normals = fl.face_normals(self.V, self.F)
            for k in range(n):
                # Direction k is direction 0 turned by 2 pi k / n counter-clockwise.
                c = np.sum(dirs[:, k] * dirs[:, 0], axis=1) / np.sum(rep * rep, axis=1)
                s = np.sum(np.cross(dirs[:, 0], dirs[:, k]) * normals, axis=1) / np.sum(
                    rep * rep, axis=1)
                np.testing.assert_allclose(c, math.cos(2 * math.pi * k / n), atol=1e-12)
                np.testing.assert_allclose(s, math.sin(2 * math.pi * k / n), atol=1e-12)
            u = fl.nfield_dofs(self.V, self.F, dirs)
            # Every one of the n directions gives the same representation vector.
            for k in range(n):
                np.testing.assert_allclose(
                    fl.nfield_dofs(self.V, self.F, np.roll(dirs, -k, axis=1)), u, atol=1e-12)
            back = fl.nfield_from_dofs(self.V, self.F, u, n)
            np.testing.assert_allclose(fl.nfield_dofs(self.V, self.F, back), u, atol=1e-12)
            # The representative's frame angle is in (-pi/n, pi/n].
            a = fl.dofs_from_vectors(self.V, self.F, back[:, 0])
            phi = np.arctan2(a[:, 1], a[:, 0])
            self.assertTrue(np.all(phi <= math.pi / n + 1e-12))
            self.assertTrue(np.all(phi > -math.pi / n - 1e-12))
            np.testing.assert_allclose(np.linalg.norm(back[:, 0], axis=1),
                                       np.linalg.norm(rep, axis=1), rtol=1e-12)

    def test_tensors(self):
        a = self.rng.normal(size=(len(self.F), 3, 3))
        a = a + np.swapaxes(a, 1, 2)
        t = fl.tangential_tensors(self.V, self.F, a)
        normals = fl.face_normals(self.V, self.F)
        np.testing.assert_allclose(np.einsum("fij,fj->fi", t, normals), 0, atol=1e-12)
        d = fl.tensor_dofs(self.V, self.F, t)
        # The DOFs' Euclidean norm is the Frobenius norm (Mandel-Voigt).
        np.testing.assert_allclose(np.linalg.norm(d, axis=1), fl.magnitude(t, "tensor"),
                                   rtol=1e-12)
        np.testing.assert_allclose(fl.tensors_from_dofs(self.V, self.F, d), t, atol=1e-12)
        np.testing.assert_allclose(fl.tensors_from_six(fl.six_from_tensors(t)), t, atol=0)
        values, dirs = fl.principal(self.V, self.F, t)
        self.assertTrue(np.all(values[:, 0] >= values[:, 1]))
        rebuilt = (values[:, 0, None, None] * np.einsum("fi,fj->fij", dirs[:, 0], dirs[:, 0])
                   + values[:, 1, None, None] * np.einsum("fi,fj->fij", dirs[:, 1], dirs[:, 1]))
        np.testing.assert_allclose(rebuilt, t, atol=1e-12)
        np.testing.assert_allclose(np.cross(normals, dirs[:, 0]), dirs[:, 1], atol=1e-12)

    def test_kind_inference_and_errors(self):
        nf = len(self.F)
        self.assertEqual(fl.infer_kind(np.zeros((nf, 3))), ("vector", 1))
        self.assertEqual(fl.infer_kind(np.zeros((nf, 4, 3))), ("nfield", 4))
        sym = np.tile(np.eye(3), (nf, 1, 1))
        self.assertEqual(fl.infer_kind(sym), ("tensor", 3))
        dirs = fl.nfield_from_representative(self.V, self.F, random_tangent(
            self.V, self.F, self.rng), 3)
        self.assertEqual(fl.infer_kind(dirs), ("nfield", 3))
        self.assertEqual(fl.infer_kind(sym, "nfield"), ("nfield", 3))
        with self.assertRaises(ValueError):
            fl.infer_kind(np.zeros((nf, 2)))
        with self.assertRaises(ValueError):
            fl.infer_kind(np.zeros((nf, 3)), "tensor")
        with self.assertRaises(ValueError):
            fl.check_field(self.V, self.F, np.zeros((nf + 1, 3)))
        bad = np.zeros((nf, 3))
        bad[5, 1] = np.nan
        with self.assertRaisesRegex(ValueError, "face 5"):
            fl.check_field(self.V, self.F, bad)
        with self.assertRaises(ValueError):
            fl.as_mesh(self.V, self.F + len(self.V))


class TextFilesTest(unittest.TestCase):
    def setUp(self):
        self.V, self.F = shapes.icosphere(1)
        self.rng = np.random.default_rng(5)
        self.dir = tempfile.mkdtemp()

    def tearDown(self):
        shutil.rmtree(self.dir)

    def test_round_trips_in_both_encodings(self):
        V, F = self.V, self.F
        a = self.rng.normal(size=(len(F), 3, 3))
        cases = [
            ("vector", random_tangent(V, F, self.rng)),
            ("nfield", fl.nfield_from_representative(V, F, random_tangent(V, F, self.rng), 4)),
            ("tensor", fl.tangential_tensors(V, F, a + np.swapaxes(a, 1, 2))),
        ]
        for kind, field in cases:
            for encoding in ("ambient", "dof"):
                path = os.path.join(self.dir, "%s_%s.txt" % (kind, encoding))
                fl.write_field_text(path, V, F, field, kind, encoding)
                text = fl.read_field_text(path)
                self.assertEqual(text.encoding, encoding)
                self.assertEqual(text.kind, kind)
                back = fl.field_from_text(V, F, text)
                if kind == "nfield":
                    assert_same_nfield(self, back, field, 1e-12)
                else:
                    np.testing.assert_allclose(back, field, atol=1e-12, err_msg=path)

    def test_parser_grammar_and_errors(self):
        t = fl.parse_field_text("# a comment\n1, 2 3\n\n4\t5 6\n")
        self.assertEqual(t.encoding, "ambient")
        self.assertIsNone(t.type)
        np.testing.assert_array_equal(t.values, [[1, 2, 3], [4, 5, 6]])
        for bad, message in (("1 2 3\n4 5\n", "line 2"), ("# encoding: polar\n1 2\n", "line 1"),
                             ("1 x 3\n", "line 1"), ("# nothing\n", "no values"),
                             ("1 nan 2\n", "line 1")):
            with self.assertRaisesRegex(ValueError, message):
                fl.parse_field_text(bad)
        with self.assertRaisesRegex(ValueError, "needs n"):
            fl.field_from_text(self.V, self.F,
                               fl.parse_field_text("1 0 0\n" * len(self.F)), kind="nfield")
        with self.assertRaisesRegex(ValueError, "faces"):
            fl.field_from_text(self.V, self.F, fl.parse_field_text("1 0 0\n"))


@unittest.skipUnless(os.environ.get("FIELDSPACE_BIN_DIR"),
                     "FIELDSPACE_BIN_DIR (fieldspaced and fieldspace) not set")
class CliFilesTest(unittest.TestCase):
    """Files written by the C++ CLI in both encodings convert to the same arrays."""

    @classmethod
    def setUpClass(cls):
        sys.path.insert(0, os.path.join(testenv.REPO, "tests", "server"))
        import fs_testlib
        bin_dir = os.environ["FIELDSPACE_BIN_DIR"]
        cls.dir = tempfile.mkdtemp()
        cls.V, cls.F = shapes.torus(24, 12)
        mesh = os.path.join(cls.dir, "torus.obj")
        with open(mesh, "w") as f:
            f.write(shapes.obj_text(cls.V, cls.F))
        daemon = fs_testlib.Daemon(os.path.join(bin_dir, "fieldspaced"),
                                   os.path.join(cls.dir, "store")).start()
        try:
            cli = fs_testlib.Cli(os.path.join(bin_dir, "fieldspace"), daemon.address)
            mesh_id = json.loads(cli("upload", mesh)[1])["id"]
            rng = np.random.default_rng(11)
            coefficients = os.path.join(cls.dir, "c.txt")
            for kind, extra in (("vector", []), ("nfield", ["--n", "4"]), ("tensor", [])):
                info = json.loads(cli("build", mesh_id, "--field", kind, *extra, "--dim", "24")[1])
                basis = info["id"]
                # d = 24 local columns plus the kernel columns (harmonic fields of the torus).
                np.savetxt(coefficients, rng.normal(size=info["columns"]))
                for encoding in ("ambient", "dof"):
                    cli("lift", basis, coefficients, "--encoding", encoding, "--out",
                        os.path.join(cls.dir, "%s_%s.txt" % (kind, encoding)))
                if kind == "nfield":
                    cls.singularities = cli("singularities", basis, coefficients)[1]
            cli("curvature", mesh_id, "--out", os.path.join(cls.dir, "curvature.txt"),
                "--principal", os.path.join(cls.dir, "principal.txt"))
            # A mesh of quads and a hexagon: the server's fan triangulation and its binary PLY.
            polygons = os.path.join(cls.dir, "polygons.obj")
            with open(polygons, "w") as f:
                f.write(POLYGON_OBJ)
            polygons_id = json.loads(cli("upload", polygons)[1])["id"]
            basis = json.loads(cli("build", polygons_id, "--field", "vector", "--dim", "4")[1])
            np.savetxt(coefficients, rng.normal(size=4))
            for out in ("polygons_field.ply", "polygons_field.txt"):
                cli("lift", basis["id"], coefficients, "--out", os.path.join(cls.dir, out))
        finally:
            daemon.stop()
            daemon.proc.stdout.close()

    @classmethod
    def tearDownClass(cls):
        shutil.rmtree(cls.dir)

    def read(self, name):
        return fl.read_field_text(os.path.join(self.dir, name))

    def test_ambient_and_dof_files_agree(self):
        for kind, n in (("vector", None), ("nfield", 4), ("tensor", None)):
            ambient, dof = self.read(kind + "_ambient.txt"), self.read(kind + "_dof.txt")
            self.assertEqual(ambient.kind, kind)
            self.assertEqual(ambient.n, n)
            a = fl.field_from_text(self.V, self.F, ambient)
            d = fl.field_from_text(self.V, self.F, dof)
            scale = np.abs(a).max()
            self.assertGreater(scale, 0)
            # Values travel as float32: agreement to float precision.
            np.testing.assert_allclose(a, d, atol=1e-6 * scale, err_msg=kind)
            if kind == "nfield":
                # The CLI's ambient line is the representative direction of the DOFs.
                np.testing.assert_allclose(fl.nfield_representative(self.V, self.F, d),
                                           ambient.values, atol=1e-6 * scale)
            if kind == "tensor":
                np.testing.assert_allclose(fl.tensor_dofs(self.V, self.F, a), dof.values,
                                           atol=1e-6 * scale)

    def test_polygon_mesh_and_binary_ply(self):
        from fieldspace import mesh_io
        V, F = mesh_io.read_mesh(os.path.join(self.dir, "polygons.obj"))
        Vs, Fs = mesh_io.read_mesh(os.path.join(self.dir, "polygons_field.ply"))
        np.testing.assert_array_equal(Fs, F)
        np.testing.assert_allclose(Vs, V, atol=1e-6)
        text = self.read("polygons_field.txt")
        field = fl.field_from_text(V, F, text)
        self.assertEqual(field.shape, (len(F), 3))
        # The field file's faces are the mesh's triangles, in the same order.
        self.assertEqual(len(text.values), len(Fs))

    def test_singularities_to_directional(self):
        from fieldspace import export as ex
        n, pairs = ex.singularities_from_cli(self.singularities)
        self.assertEqual(n, 4)
        self.assertGreater(len(pairs), 0)
        # Poincare-Hopf on the torus: the indices (in 1/n turns) sum to n * chi = 0.
        self.assertEqual(int(pairs[:, 1].sum()), 0)
        path = os.path.join(self.dir, "f.sing")
        ex.write_sing(path, pairs, n)
        with open(path) as f:
            tokens = [int(t) for t in f.read().split()]
        self.assertEqual(tokens[:2], [4, len(pairs)])
        np.testing.assert_array_equal(np.array(tokens[2:]).reshape(-1, 2), pairs)
        with self.assertRaisesRegex(ValueError, "singularities_from_cli"):
            ex.write_sing(path, json.loads(self.singularities)["singularities"], n)

    def test_principal_curvatures_match(self):
        t = fl.field_from_text(self.V, self.F, self.read("curvature.txt"))
        p = self.read("principal.txt").values
        values, dirs = fl.principal(self.V, self.F, t)
        np.testing.assert_allclose(values, p[:, :2], atol=1e-5 * np.abs(p[:, :2]).max())
        aniso = p[:, 0] - p[:, 1] > 1e-3
        dot1 = np.sum(dirs[:, 0] * p[:, 2:5], axis=1)
        dot2 = np.sum(dirs[:, 1] * p[:, 5:8], axis=1)
        np.testing.assert_allclose(np.abs(dot1[aniso]), 1, atol=1e-5)
        # d2 = n x d1 on both sides: the two signs agree.
        np.testing.assert_allclose(dot1[aniso], dot2[aniso], atol=1e-5)


if __name__ == "__main__":
    testenv.main()
