"""Peak RSS of basis builds in fieldspaced (issue 22, item 2: calibrating the build estimate).

Usage: bench/build_memory.py DAEMON PYTHON_DIR SUBDIVISIONS|MESH_FILE FIELD:D:M:QUALITY...
builds each basis on an icosphere of SUBDIVISIONS (5: 20,480 faces), or on a mesh file, in one
daemon (2 threads,
a budget of 100 GB), resetting VmHWM (/proc/PID/clear_refs) before each and deleting it after;
prints the VmRSS before (base) and the VmHWM during each build. M = 0: the default.
"""
import os
import sys
import tempfile
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tests",
                                "server"))
sys.path.insert(0, sys.argv[2])
from fs_testlib import Daemon, icosphere_obj, obj_arrays  # noqa: E402
import fieldspace as fs  # noqa: E402


def hwm(pid):
    with open("/proc/%d/status" % pid) as f:
        return next(int(line.split()[1]) for line in f if line.startswith("VmHWM")) / 1024


def reset(pid):
    with open("/proc/%d/clear_refs" % pid, "w") as f:
        f.write("5")


work = tempfile.mkdtemp()
d = Daemon(sys.argv[1], work + "/store", threads=2, extra=["--memory-budget-mb", "100000"]).start()
c = fs.Client(d.address)
if sys.argv[3].isdigit():
    V, F = obj_arrays(icosphere_obj(int(sys.argv[3]))[0])
    mesh = c.upload(V, F)
else:
    mesh = c.upload(sys.argv[3])  # a mesh file
print("faces", mesh.num_faces, "idle", hwm(d.proc.pid))
for spec in sys.argv[4:]:
    field, dim, m, q = spec.split(":")
    reset(d.proc.pid); base = hwm(d.proc.pid)
    t = time.time()
    kw = dict(n=4) if field == "nfield" else {}
    try:
        b = c.build(mesh.id, field, int(dim), fields_per_region=int(m), quality=q, progress=False, **kw)
        st = "ok"
        c.delete_basis(b)
    except Exception as e:
        st = str(e)[:200]
    print(spec, "base %.0f peak %.0f MiB %.1fs %s" % (base, hwm(d.proc.pid), time.time() - t, st), flush=True)
d.stop()
