"""fieldspace.export: every format read back by an independent reader (VTK's readers, meshio,
small parsers written here from the formats' specifications) and compared value by value."""

import math
import os
import shutil
import tempfile
import unittest

import testenv
import numpy as np

from fieldspace import export as ex
from fieldspace import fields as fl
from fieldspace import mesh_io
import shapes

HAVE_VTK = testenv.have_module("vtkmodules.vtkIOXML")
HAVE_MESHIO = testenv.have_module("meshio")
TOL = 1e-6


def sample_fields(V, F, seed=7):
    """A tangent vector field, a 4-field and a 3-field, and a tangential tensor field."""
    rng = np.random.default_rng(seed)
    n = fl.face_normals(V, F)
    v = rng.normal(size=(len(F), 3))
    v -= np.sum(v * n, axis=1)[:, None] * n
    a = rng.normal(size=(len(F), 3, 3))
    return {
        "vector": v,
        "nfield": fl.nfield_from_representative(V, F, np.roll(v, 1, axis=0), 4),
        "nfield3": fl.nfield_from_representative(V, F, v[::-1], 3),
        "tensor": fl.tangential_tensors(V, F, a + np.swapaxes(a, 1, 2)),
    }


def kind_of(key):
    return "nfield" if key.startswith("nfield") else key


def vtk_cell_arrays(data):
    from vtkmodules.util.numpy_support import vtk_to_numpy
    cd = data.GetCellData()
    return {cd.GetArrayName(i): vtk_to_numpy(cd.GetArray(i)) for i in range(
        cd.GetNumberOfArrays())}


def vtk_triangles(data):
    from vtkmodules.util.numpy_support import vtk_to_numpy
    F = []
    for c in range(data.GetNumberOfCells()):
        cell = data.GetCell(c)
        F.append([cell.GetPointId(k) for k in range(cell.GetNumberOfPoints())])
    return vtk_to_numpy(data.GetPoints().GetData()), np.array(F)


class ExportTestBase(unittest.TestCase):
    def setUp(self):
        self.dir = tempfile.mkdtemp()
        self.V, self.F = shapes.torus(16, 8)
        self.fields = sample_fields(self.V, self.F)

    def tearDown(self):
        shutil.rmtree(self.dir)

    def path(self, name):
        return os.path.join(self.dir, name)

    def expected(self, key, name="field"):
        return ex.field_arrays(self.V, self.F, self.fields[key], kind_of(key), name)

    def check_arrays(self, got, key, name="field"):
        want = self.expected(key, name)
        self.assertEqual(sorted(got), sorted(want), key)
        for k, w in want.items():
            g = np.asarray(got[k]).reshape(w.shape)
            np.testing.assert_allclose(g, w, atol=TOL, rtol=0, err_msg="%s %s" % (key, k))


class FieldArraysTest(ExportTestBase):
    def test_meaning_of_the_arrays(self):
        V, F = self.V, self.F
        arrays = self.expected("nfield", "X")
        self.assertEqual(list(arrays), ["X_dir0", "X_dir1", "X_dir2", "X_dir3",
                                        "X_magnitude"])
        normals = fl.face_normals(V, F)
        np.testing.assert_allclose(arrays["X_dir1"], np.cross(normals, arrays["X_dir0"]),
                                   atol=1e-12)
        np.testing.assert_allclose(arrays["X_dir2"], -arrays["X_dir0"], atol=1e-12)
        t = self.expected("tensor", "T")
        self.assertEqual(t["T"].shape, (len(F), 9))
        values = t["T_principal_values"]
        for j, which in enumerate(("max", "min")):
            d = t["T_principal_" + which]
            Td = np.einsum("fij,fj->fi", self.fields["tensor"], d)
            np.testing.assert_allclose(Td, values[:, j, None] * d, atol=1e-12)
        np.testing.assert_allclose(t["T_norm"], np.linalg.norm(t["T"], axis=1), atol=1e-12)
        v = self.expected("vector")
        np.testing.assert_allclose(v["field_magnitude"],
                                   np.linalg.norm(self.fields["vector"], axis=1))

    def test_bad_names_and_shapes(self):
        with self.assertRaises(ValueError):
            ex.field_arrays(self.V, self.F, self.fields["vector"], name="a b")
        with self.assertRaises(ValueError):
            ex.write_vtu(self.path("x.vtu"), self.V, self.F, self.fields["vector"][:-1])
        with self.assertRaises(ValueError):
            ex.write_vtu(self.path("x.vtu"), self.V, self.F, self.fields["vector"],
                         cell_data={"field": np.zeros(len(self.F))})


@unittest.skipUnless(HAVE_VTK, "VTK's Python bindings are not installed (python3-vtk9)")
class VtkReadersTest(ExportTestBase):
    def read_vtu(self, path):
        from vtkmodules.vtkIOXML import vtkXMLUnstructuredGridReader
        r = vtkXMLUnstructuredGridReader()
        r.SetFileName(path)
        r.Update()
        self.assertEqual(r.GetErrorCode(), 0)
        return r.GetOutput()

    def test_vtu_binary_and_ascii(self):
        for binary in (True, False):
            for key in self.fields:
                path = self.path("%s_%d.vtu" % (key, binary))
                ex.write_vtu(path, self.V, self.F, self.fields[key], kind_of(key),
                             binary=binary)
                data = self.read_vtu(path)
                self.assertEqual(data.GetNumberOfCells(), len(self.F))
                V, F = vtk_triangles(data)
                np.testing.assert_allclose(V, self.V, atol=TOL)
                np.testing.assert_array_equal(F, self.F)
                self.assertTrue(all(data.GetCellType(c) == 5 for c in range(len(F))))
                self.check_arrays(vtk_cell_arrays(data), key)

    def test_vtu_active_attributes_and_extra_cell_data(self):
        path = self.path("t.vtu")
        ids = np.arange(len(self.F), dtype=float)
        ex.write_vtu(path, self.V, self.F, self.fields["tensor"], "tensor", name="T",
                     cell_data={"face_id": ids})
        data = self.read_vtu(path)
        cd = data.GetCellData()
        self.assertEqual(cd.GetTensors().GetName(), "T")
        self.assertEqual(cd.GetVectors().GetName(), "T_principal_max")
        from vtkmodules.util.numpy_support import vtk_to_numpy
        np.testing.assert_array_equal(vtk_to_numpy(cd.GetArray("face_id")), ids)

    def test_mesh_without_field(self):
        path = self.path("m.vtu")
        ex.write_vtu(path, self.V, self.F)
        data = self.read_vtu(path)
        self.assertEqual(data.GetCellData().GetNumberOfArrays(), 0)
        self.assertEqual(data.GetNumberOfPoints(), len(self.V))

    def test_legacy_vtk(self):
        from vtkmodules.vtkIOLegacy import vtkUnstructuredGridReader
        for key in self.fields:
            path = self.path(key + ".vtk")
            ex.write_vtk(path, self.V, self.F, self.fields[key], kind_of(key))
            r = vtkUnstructuredGridReader()
            r.SetFileName(path)
            r.Update()
            data = r.GetOutput()
            V, F = vtk_triangles(data)
            np.testing.assert_allclose(V, self.V, atol=TOL)
            np.testing.assert_array_equal(F, self.F)
            self.check_arrays(vtk_cell_arrays(data), key)

    def test_ply_geometry(self):
        from vtkmodules.vtkIOPLY import vtkPLYReader
        path = self.path("v.ply")
        ex.write_ply_ascii(path, self.V, self.F, self.fields["vector"])
        r = vtkPLYReader()
        r.SetFileName(path)
        r.Update()
        V, F = vtk_triangles(r.GetOutput())
        np.testing.assert_allclose(V, self.V, atol=TOL)
        np.testing.assert_array_equal(F, self.F)

    def test_polylines(self):
        from vtkmodules.util.numpy_support import vtk_to_numpy
        from vtkmodules.vtkIOLegacy import vtkPolyDataReader
        from vtkmodules.vtkIOGeometry import vtkOBJReader
        rng = np.random.default_rng(2)
        lines = [rng.normal(size=(k, 3)) for k in (2, 5, 17)]
        ex.write_polylines_vtk(self.path("l.vtk"), lines, line_data={"w": [1.0, 2.0, 3.0]})
        r = vtkPolyDataReader()
        r.SetFileName(self.path("l.vtk"))
        r.Update()
        data = r.GetOutput()
        self.assertEqual(data.GetNumberOfLines(), 3)
        pts = vtk_to_numpy(data.GetPoints().GetData())
        for c, line in enumerate(lines):
            cell = data.GetCell(c)
            ids = [cell.GetPointId(k) for k in range(cell.GetNumberOfPoints())]
            np.testing.assert_allclose(pts[ids], line, atol=TOL)
        arrays = vtk_cell_arrays(data)
        np.testing.assert_allclose(arrays["length"], ex.polyline_lengths(lines), atol=TOL)
        np.testing.assert_array_equal(arrays["line_id"], [0, 1, 2])
        np.testing.assert_array_equal(arrays["w"], [1, 2, 3])
        ex.write_polylines_obj(self.path("l.obj"), lines)
        r = vtkOBJReader()
        r.SetFileName(self.path("l.obj"))
        r.Update()
        data = r.GetOutput()
        self.assertEqual(data.GetNumberOfLines(), 3)
        pts = vtk_to_numpy(data.GetPoints().GetData())
        for c, line in enumerate(lines):
            cell = data.GetCell(c)
            ids = [cell.GetPointId(k) for k in range(cell.GetNumberOfPoints())]
            np.testing.assert_allclose(pts[ids], line, atol=TOL)


@unittest.skipUnless(HAVE_MESHIO, "meshio is not installed (python3-meshio)")
class MeshioReadersTest(ExportTestBase):
    def read(self, path):
        import meshio
        m = meshio.read(path)
        self.assertEqual(len(m.cells), 1)
        self.assertEqual(m.cells[0].type, "triangle")
        np.testing.assert_allclose(m.points, self.V, atol=TOL)
        np.testing.assert_array_equal(m.cells[0].data, self.F)
        return {k: v[0] for k, v in m.cell_data.items()}

    def test_vtu(self):
        for binary in (True, False):
            for key in self.fields:
                path = self.path("%s_%d.vtu" % (key, binary))
                ex.write_vtu(path, self.V, self.F, self.fields[key], kind_of(key), "f",
                             binary=binary)
                self.check_arrays(self.read(path), key, "f")

    def test_legacy_vtk(self):
        for key in self.fields:
            path = self.path(key + ".vtk")
            ex.write_vtk(path, self.V, self.F, self.fields[key], kind_of(key))
            self.check_arrays(self.read(path), key)

    def test_ply_face_properties(self):
        for key in self.fields:
            path = self.path(key + ".ply")
            ex.write_ply_ascii(path, self.V, self.F, self.fields[key], kind_of(key),
                               face_properties={"quality": np.arange(len(self.F))})
            got = self.read(path)
            want = ex.ply_face_properties(self.V, self.F, self.fields[key], kind_of(key))
            want["quality"] = np.arange(len(self.F))
            self.assertEqual(sorted(got), sorted(want))
            for k, w in want.items():
                np.testing.assert_allclose(got[k], w, atol=TOL, err_msg=k)
        field = self.fields["nfield3"]
        got = self.read(self.path("nfield3.ply"))
        for k in range(3):
            np.testing.assert_allclose(np.stack([got["d%d%s" % (k, a)] for a in "xyz"], 1),
                                       field[:, k], atol=TOL)


class DirectionalFormatsTest(ExportTestBase):
    @staticmethod
    def parse_rawfield(path):
        """Directional's read_raw_field: N, #F, then #F x 3N numbers (whitespace-separated)."""
        with open(path) as f:
            tokens = f.read().split()
        n, count = int(tokens[0]), int(tokens[1])
        values = np.array([float(t) for t in tokens[2:]])
        assert len(values) == count * 3 * n, "token count"
        return n, values.reshape(count, n, 3)

    @staticmethod
    def parse_sing(path):
        with open(path) as f:
            tokens = [int(t) for t in f.read().split()]
        n, count = tokens[0], tokens[1]
        pairs = np.array(tokens[2:], dtype=np.int64).reshape(-1, 2)
        assert len(pairs) == count
        return n, pairs

    def test_rawfield(self):
        for key in ("nfield", "nfield3", "vector"):
            path = self.path(key + ".rawfield")
            ex.write_rawfield(path, self.fields[key])
            n, values = self.parse_rawfield(path)
            want = self.fields[key].reshape(len(self.F), -1, 3)
            self.assertEqual(n, want.shape[1])
            np.testing.assert_allclose(values, want, atol=TOL)
            # Consecutive directions turn counter-clockwise by 2 pi / N about the normal.
            normals = fl.face_normals(self.V, self.F)
            for k in range(1, n):
                s = np.sum(np.cross(values[:, k - 1], values[:, k]) * normals, axis=1)
                c = np.sum(values[:, k - 1] * values[:, k], axis=1)
                np.testing.assert_allclose(np.arctan2(s, c), 2 * math.pi / n, atol=1e-9)
        with self.assertRaises(ValueError):
            ex.write_rawfield(self.path("x.rawfield"), self.fields["nfield"], n=2)

    def test_principal_cross_field_as_rawfield(self):
        cross = ex.principal_cross_field(self.V, self.F, self.fields["tensor"])
        ex.write_rawfield(self.path("t.rawfield"), cross)
        n, values = self.parse_rawfield(self.path("t.rawfield"))
        self.assertEqual(n, 4)
        np.testing.assert_allclose(np.linalg.norm(values, axis=2), 1, atol=1e-9)
        _, dirs = fl.principal(self.V, self.F, self.fields["tensor"])
        np.testing.assert_allclose(values[:, 0], dirs[:, 0], atol=TOL)
        np.testing.assert_allclose(values[:, 3], -dirs[:, 1], atol=TOL)

    def test_sing(self):
        class Msg:
            def __init__(self, vertex, index):
                self.vertex, self.index = vertex, index

        forms = [[(3, 1), (10, -1), (7, 0)], {3: 1, 10: -1, 7: 0},
                 [{"vertex": 3, "index": 1}, {"vertex": 10, "index": -1}],
                 [Msg(3, 1), Msg(10, -1)], np.array([[3, 1], [10, -1]])]
        for i, form in enumerate(forms):
            path = self.path("s%d.sing" % i)
            ex.write_sing(path, form, 4)
            n, pairs = self.parse_sing(path)
            self.assertEqual(n, 4)
            np.testing.assert_array_equal(pairs, [[3, 1], [10, -1]])
        ex.write_sing(self.path("empty.sing"), [], 2)
        self.assertEqual(self.parse_sing(self.path("empty.sing"))[1].shape, (0, 2))
        with self.assertRaises(ValueError):
            ex.write_sing(self.path("bad.sing"), [(1.5, 1)], 2)


class PolylineObjTest(ExportTestBase):
    def test_obj_lines_parsed_here(self):
        lines = [np.array([[0, 0, 0], [1, 0, 0.5]]), np.array([[2, 2, 2], [3, 3, 3], [4, 4, 5]])]
        ex.write_polylines_obj(self.path("l.obj"), lines)
        verts, elements = [], []
        with open(self.path("l.obj")) as f:
            for line in f:
                t = line.split()
                if t and t[0] == "v":
                    verts.append([float(x) for x in t[1:]])
                elif t and t[0] == "l":
                    elements.append([int(x) - 1 for x in t[1:]])
        verts = np.array(verts)
        self.assertEqual(len(elements), 2)
        for e, want in zip(elements, lines):
            np.testing.assert_allclose(verts[e], want, atol=0)
        with self.assertRaises(ValueError):
            ex.write_polylines_obj(self.path("x.obj"), [np.zeros((1, 3))])


class MeshFilesTest(ExportTestBase):
    QUADS = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 2 0 0\nv 2 1 0\nv 3 0.5 0\n"

    def test_obj_fan_triangulation_and_index_forms(self):
        with open(self.path("q.obj"), "w") as f:
            f.write(self.QUADS + "# a quad and a pentagon\nf 1/1/1 2/2/2 3 4\n"
                    "f -6 5 7 6 -5\n")
        V, F = mesh_io.read_mesh(self.path("q.obj"))
        self.assertEqual(V.shape, (7, 3))
        np.testing.assert_array_equal(F, [[0, 1, 2], [0, 2, 3], [1, 4, 6], [1, 6, 5],
                                          [1, 5, 2]])

    def test_off_and_ply_round_trips(self):
        V, F = self.V, self.F
        with open(self.path("m.off"), "w") as f:
            f.write("OFF\n# comment\n%d %d 0\n" % (len(V), len(F)))
            f.writelines("%r %r %r\n" % tuple(p) for p in V)
            f.writelines("3 %d %d %d 255 0 0\n" % tuple(t) for t in F)
        for path in (self.path("m.off"), self.path("m.ply")):
            if path.endswith(".ply"):
                ex.write_ply_ascii(path, V, F, self.fields["tensor"])
            V2, F2 = mesh_io.read_mesh(path)
            np.testing.assert_allclose(V2, V, atol=1e-12)
            np.testing.assert_array_equal(F2, F)

    def test_binary_ply(self):
        V, F = self.V, self.F
        for order, name in (("<", "little"), (">", "big")):
            header = ("ply\nformat binary_%s_endian 1.0\nelement vertex %d\nproperty float x\n"
                      "property float y\nproperty float z\nproperty uchar red\n"
                      "element face %d\nproperty list uchar int vertex_indices\n"
                      "property float q\nend_header\n" % (name, len(V), len(F)))
            vt = np.dtype([("p", order + "f4", 3), ("r", "u1")])
            verts = np.zeros(len(V), dtype=vt)
            verts["p"] = V
            ft = np.dtype([("k", "u1"), ("i", order + "i4", 3), ("q", order + "f4")])
            faces = np.zeros(len(F), dtype=ft)
            faces["k"], faces["i"] = 3, F
            path = self.path("b_%s.ply" % name)
            with open(path, "wb") as f:
                f.write(header.encode() + verts.tobytes() + faces.tobytes())
            V2, F2 = mesh_io.read_mesh(path)
            np.testing.assert_allclose(V2, V.astype(np.float32), atol=0)
            np.testing.assert_array_equal(F2, F)

    def test_command_line(self):
        mesh = self.path("t.obj")
        with open(mesh, "w") as f:
            f.write(shapes.obj_text(self.V, self.F))
        field = self.path("n.txt")
        fl.write_field_text(field, self.V, self.F, self.fields["nfield"], encoding="dof")
        self.assertEqual(ex.main([mesh, field, "--out", self.path("n.rawfield")]), 0)
        n, values = DirectionalFormatsTest.parse_rawfield(self.path("n.rawfield"))
        self.assertEqual(n, 4)
        nfield = fl.field_from_text(self.V, self.F, fl.read_field_text(field))
        np.testing.assert_allclose(values, nfield, atol=TOL)
        tensor = self.path("t.txt")
        fl.write_field_text(tensor, self.V, self.F, self.fields["tensor"])
        self.assertEqual(ex.main([mesh, tensor, "--out", self.path("t.vtk"), "--name", "T"]),
                         0)
        if HAVE_MESHIO:
            import meshio
            got = meshio.read(self.path("t.vtk")).cell_data["T"][0]
            np.testing.assert_allclose(got.reshape(-1, 3, 3), self.fields["tensor"], atol=TOL)
        self.assertEqual(ex.main([mesh, tensor, "--out", self.path("t.rawfield")]), 0)
        self.assertEqual(DirectionalFormatsTest.parse_rawfield(self.path("t.rawfield"))[0], 4)
        self.assertEqual(ex.main([mesh, field, "--out", self.path("x.stl")]), 1)
        self.assertEqual(ex.main([mesh, self.path("missing.txt"), "--out",
                                  self.path("x.vtu")]), 1)


if __name__ == "__main__":
    testenv.main()
