"""Helpers shared by the end-to-end tests: meshes made in code, a daemon process, the CLI."""

import contextlib
import json
import math
import os
import select
import shutil
import signal
import subprocess
import sys
import tempfile
import time


def icosphere_obj(subdivisions):
    """OBJ text of a unit icosphere: 20 * 4**s faces (s = 3: 1280 faces, like sphere_1k.obj)."""
    t = (1.0 + math.sqrt(5.0)) / 2.0
    verts = [(-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0), (0, -1, t), (0, 1, t),
             (0, -1, -t), (0, 1, -t), (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1)]
    verts = [tuple(c / math.sqrt(sum(x * x for x in v)) for c in v) for v in verts]
    faces = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4),
             (11, 10, 2), (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8),
             (3, 8, 9), (4, 9, 5), (2, 4, 11), (6, 2, 10), (8, 6, 7), (9, 8, 1)]
    for _ in range(subdivisions):
        cache = {}

        def midpoint(a, b):
            key = (min(a, b), max(a, b))
            if key not in cache:
                m = [(verts[a][k] + verts[b][k]) / 2 for k in range(3)]
                n = math.sqrt(sum(x * x for x in m))
                verts.append(tuple(x / n for x in m))
                cache[key] = len(verts) - 1
            return cache[key]

        new_faces = []
        for a, b, c in faces:
            ab, bc, ca = midpoint(a, b), midpoint(b, c), midpoint(c, a)
            new_faces += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
        faces = new_faces
    lines = ["v %.17g %.17g %.17g" % v for v in verts]
    lines += ["f %d %d %d" % (a + 1, b + 1, c + 1) for a, b, c in faces]
    return "\n".join(lines) + "\n", len(faces)


def torus_obj(major=48, minor=24, R=1.0, r=0.4):
    """OBJ text of a closed torus of genus 1 with 2 * major * minor faces."""
    lines = []
    for i in range(major):
        u = 2 * math.pi * i / major
        for j in range(minor):
            v = 2 * math.pi * j / minor
            lines.append("v %.17g %.17g %.17g" % ((R + r * math.cos(v)) * math.cos(u),
                                                  (R + r * math.cos(v)) * math.sin(u),
                                                  r * math.sin(v)))
    idx = lambda i, j: (i % major) * minor + (j % minor) + 1
    for i in range(major):
        for j in range(minor):
            a, b, c, d = idx(i, j), idx(i + 1, j), idx(i + 1, j + 1), idx(i, j + 1)
            lines.append("f %d %d %d" % (a, b, c))
            lines.append("f %d %d %d" % (a, c, d))
    return "\n".join(lines) + "\n", 2 * major * minor


def obj_arrays(text):
    """(V, F) numpy arrays of OBJ text with `v` and triangle `f` lines (icosphere_obj, torus_obj)."""
    import numpy as np

    V, F = [], []
    for line in text.splitlines():
        parts = line.split()
        if parts and parts[0] == "v":
            V.append([float(x) for x in parts[1:4]])
        elif parts and parts[0] == "f":
            F.append([int(x) - 1 for x in parts[1:4]])
    return np.array(V), np.array(F, dtype=np.int32)



def with_unknown_field(message, size):
    """`message` (serialized bytes) followed by an unknown length-delimited field (number 999)
    of `size` zero bytes: a valid request of that size, which gRPC's protobuf parses and keeps
    before any handler looks at it."""
    def varint(value):
        out = bytearray()
        while True:
            byte = value & 0x7F
            value >>= 7
            out.append(byte | (0x80 if value else 0))
            if not value:
                return bytes(out)
    return message + varint(999 << 3 | 2) + varint(size) + b"\0" * size


class Daemon:
    """A fieldspaced process on 127.0.0.1 with a free port."""

    def __init__(self, binary, store, data_root=None, extra=(), log=None, listen="127.0.0.1:0",
                 threads=2):
        self.args = [binary, "--listen", listen, "--store", store, "--threads", str(threads)]
        if data_root:
            self.args += ["--data-root", data_root]
        self.args += list(extra)
        self.log_path = log or os.path.join(store + ".log")
        self.proc = None
        self.address = None

    def start(self, timeout=30):
        self.log = open(self.log_path, "ab")
        self.proc = subprocess.Popen(self.args, stdout=subprocess.PIPE, stderr=self.log)
        ready, _, _ = select.select([self.proc.stdout], [], [], timeout)
        if not ready:
            self.proc.kill()
            raise AssertionError("fieldspaced did not print its address within %ds" % timeout)
        line = self.proc.stdout.readline().decode().strip()
        assert line.startswith("listening on 127.0.0.1:"), "first stdout line: %r" % line
        self.address = line[len("listening on "):]
        self.port = int(self.address.rsplit(":", 1)[1])
        assert self.port > 0
        return self

    def stop(self, sig=signal.SIGTERM, timeout=30):
        self.proc.send_signal(sig)
        try:
            rc = self.proc.wait(timeout)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            raise AssertionError("fieldspaced did not exit within %ds of signal %d" % (timeout, sig))
        self.log.close()
        return rc

    def alive(self):
        return self.proc is not None and self.proc.poll() is None


def kill_all(daemons):
    """SIGKILLs the Daemons still running and reaps them (a test's cleanup after a failure)."""
    for d in daemons:
        if d.alive():
            d.proc.kill()
            d.proc.wait()


def run(args, timeout=300, check=None):
    """Runs a command; returns (returncode, stdout, stderr) as text."""
    p = subprocess.run(args, capture_output=True, text=True, timeout=timeout)
    if check is not None and p.returncode != check:
        raise AssertionError("%s exited %d (expected %d)\nstdout: %s\nstderr: %s" %
                             (" ".join(args), p.returncode, check, p.stdout[-2000:],
                              p.stderr[-2000:]))
    return p.returncode, p.stdout, p.stderr


class Cli:
    def __init__(self, binary, address):
        self.binary = binary
        self.address = address

    def __call__(self, *args, expect=0, timeout=300):
        return run([self.binary, "--server", self.address] + list(args), timeout, check=expect)

    def json(self, *args, timeout=300):
        _, out, _ = self(*args, timeout=timeout)
        return json.loads(out)


def check(condition, message):
    if not condition:
        raise AssertionError(message)


def log(message):
    print(message, flush=True)
    sys.stdout.flush()


def client_test_args(description):
    """The arguments of a test that drives fieldspaced through the Python package: --daemon and
    --python-dir, and the package `fieldspace` imported from there; the package is None (after
    printing why the test is skipped) when python3-grpcio or numpy is absent."""
    import argparse

    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("--daemon", required=True)
    parser.add_argument("--python-dir", required=True, help="the build tree's python/ folder")
    args = parser.parse_args()
    try:
        import grpc  # noqa: F401
        import numpy  # noqa: F401
    except ImportError as e:
        print("SKIPPED: %s (python3-grpcio and python3-numpy are needed)" % e)
        return args, None
    sys.path.insert(0, args.python_dir)
    import fieldspace
    return args, fieldspace


@contextlib.contextmanager
def daemon_workdir(prefix, daemons):
    """A temporary folder for a test of daemons: yields (folder, its store/, the daemons' log
    path). On an exception prints the log's tail; at the end kills the daemons in `daemons` (a
    list the test appends its Daemons to) that are still alive and removes the folder."""
    work = tempfile.mkdtemp(prefix=prefix)
    log_path = os.path.join(work, "daemon.log")
    try:
        yield work, os.path.join(work, "store"), log_path
    except BaseException:
        try:
            with open(log_path, errors="replace") as f:
                sys.stderr.write("--- daemon log %s ---\n%s\n" % (log_path, f.read()[-4000:]))
        except OSError:
            pass
        raise
    finally:
        kill_alive(daemons)
        shutil.rmtree(work, ignore_errors=True)


def kill_alive(daemons):
    """SIGKILL to each of `daemons` still alive; waits for them to exit."""
    for d in daemons:
        if d.alive():
            d.proc.kill()
            d.proc.wait(30)


_SPHERES = {}


def perturbed_sphere(subdivisions, seed):
    """(V, F) numpy arrays of icosphere_obj(subdivisions) with every vertex moved by up to 1%
    (seeded): a mesh with its own content hash, hence its own mesh id, for every seed."""
    import numpy as np

    if subdivisions not in _SPHERES:
        _SPHERES[subdivisions] = obj_arrays(icosphere_obj(subdivisions)[0])
    V, F = _SPHERES[subdivisions]
    rng = np.random.default_rng(seed)
    return V * (1 + 0.01 * rng.uniform(-1, 1, (len(V), 1))), F.copy()


def geometry_key(V, F):
    """A digest of a mesh's canonical arrays (float64 vertices, int32 faces): round trips match."""
    import hashlib
    import numpy as np

    return hashlib.sha256(np.ascontiguousarray(V, dtype="<f8").tobytes() +
                          np.ascontiguousarray(F, dtype="<i4").tobytes()).hexdigest()


def store_temp_files(store):
    """Temporary files of saves in progress (or interrupted) in a store's meshes/ and bases/."""
    return sorted(os.path.join(sub, name) for sub in ("meshes", "bases")
                  for name in os.listdir(os.path.join(store, sub)) if ".tmp-" in name)


def check_listed_usable(client, store, uploaded, lifted):
    """Every file in the store is listed (none is damaged: after a crash a file is complete or
    absent) and every mesh and basis the daemon lists is usable: each mesh's geometry is exactly
    one that was uploaded (`uploaded`: geometry_key values) and each basis is ready, on a listed
    mesh, and lifts; a basis lifted before (`lifted`: basis id -> DOF values, filled in here)
    lifts to the same values. Returns (mesh ids, basis ids)."""
    import re
    import numpy as np

    meshes = [m.id for m in client.meshes()]
    bases = client.bases()
    for sub, ext, ids in (("meshes", ".fsmesh", meshes),
                          ("bases", ".fsbasis", [b.id for b in bases])):
        files = sorted(name[:-len(ext)] for name in os.listdir(os.path.join(store, sub))
                       if name.endswith(ext))
        check(files == sorted(ids), "%s: files %s, listed %s" % (sub, files, sorted(ids)))
    for mesh_id in meshes:
        check(re.fullmatch(r"m-[0-9a-f]{16}", mesh_id) is not None, "listed mesh id %r" % mesh_id)
        V, F = client.mesh_geometry(mesh_id)
        check(geometry_key(V, F) in uploaded, "mesh %s holds a geometry never uploaded" % mesh_id)
    for b in bases:
        check(re.fullmatch(r"b-[0-9a-f]{16}", b.id) is not None, "listed basis id %r" % b.id)
        check(b.state == "ready" and b.mesh_id in meshes, "basis %s: %s" % (b.id, b))
        values = client.lift(b.id, np.linspace(-1, 1, b.columns), encoding="dof")
        check(np.all(np.isfinite(values)), "basis %s lifts to non-finite values" % b.id)
        if b.id in lifted:
            check(np.array_equal(lifted[b.id], values), "basis %s lifts differently" % b.id)
        lifted[b.id] = values
    return meshes, [b.id for b in bases]
