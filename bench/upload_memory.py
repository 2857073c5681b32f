#!/usr/bin/env python3
"""Peak RSS of fieldspaced while it takes hostile OBJ uploads (issue 22, item 2: an upload's
admitted memory must cover its parse and validation).

Shapes, each a valid OBJ text the parser accepts and TriangleMesh::Create then refuses (or
stores):
  fan:  1000 vertices on a circle, then the 1000-gon "f 1 2 ... 1000" repeated: about 5 bytes of
        text per triangle after fan triangulation (Create refuses the non-manifold edges);
  dup:  3 vertices, then "f 1 2 3" repeated: 8 bytes of text per triangle;
  grid: a valid n x n grid of quads (stored): the honest large upload.
For each shape and size a fresh daemon (--memory-budget-mb, default 1024) takes one upload that
announces its total_bytes; the script prints the daemon's idle VmHWM, its VmHWM after the upload,
and the upload's status.

  bench/upload_memory.py --daemon build/bin/fieldspaced --python-dir build/python \
      --sizes-mb 10,100 --shapes fan,dup
"""

import argparse
import math
import os
import shutil
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "tests", "server"))
from fs_testlib import Daemon  # noqa: E402


def vm_kib(pid, key):
    with open("/proc/%d/status" % pid) as f:
        for line in f:
            if line.startswith(key + ":"):
                return int(line.split()[1])
    raise KeyError(key)


def write_obj(path, shape, size_bytes):
    """Writes an OBJ of `shape` of about size_bytes; returns its size."""
    with open(path, "w") as f:
        if shape == "fan":
            n = 1000
            for i in range(n):
                a = 2 * math.pi * i / n
                f.write("v %.6f %.6f 0\n" % (math.cos(a), math.sin(a)))
            line = "f " + " ".join(str(i + 1) for i in range(n)) + "\n"
            reps = max(1, (size_bytes - f.tell()) // len(line))
            f.write(line * reps)
        elif shape == "dup":
            f.write("v 0 0 0\nv 1 0 0\nv 0 1 0\n")
            reps = max(1, (size_bytes - f.tell()) // 8)
            block = "f 1 2 3\n" * 65536
            for _ in range(reps // 65536):
                f.write(block)
            f.write("f 1 2 3\n" * (reps % 65536))
        elif shape == "grid":
            # Vertex lines "v x y 0" (~20 bytes) and quad lines (~30 bytes): ~50 bytes a quad.
            n = max(2, int(math.sqrt(size_bytes / 50)))
            for j in range(n + 1):
                f.write("".join("v %d %d 0\n" % (i, j) for i in range(n + 1)))
            for j in range(n):
                f.write("".join("f %d %d %d %d\n" % (j * (n + 1) + i + 1, j * (n + 1) + i + 2,
                                                      (j + 1) * (n + 1) + i + 2,
                                                      (j + 1) * (n + 1) + i + 1)
                                for i in range(n)))
        else:
            raise ValueError(shape)
        return f.tell()


def upload_file(pb, stub, path, announce=True, chunk=1 << 20):
    import grpc
    size = os.path.getsize(path)

    def requests():
        header = pb.UploadMeshHeader(name=os.path.basename(path), format=pb.MESH_FORMAT_OBJ,
                                     total_bytes=size if announce else 0)
        with open(path, "rb") as f:
            offset = 0
            while True:
                data = f.read(chunk)
                last = offset + len(data) >= size
                req = pb.UploadMeshRequest(header=header if offset == 0 else None, offset=offset,
                                           data=data)
                if last and not announce:
                    req.last = True
                yield req
                offset += len(data)
                if last:
                    return

    try:
        info = stub.UploadMesh(requests(), timeout=600)
        return "OK (%d faces)" % info.num_faces
    except grpc.RpcError as e:
        return "%s: %s" % (e.code().name, e.details()[:160])


def main():
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--daemon", required=True)
    parser.add_argument("--python-dir", required=True)
    parser.add_argument("--sizes-mb", default="10,100")
    parser.add_argument("--shapes", default="fan,dup")
    parser.add_argument("--budget-mb", type=int, default=1024)
    args = parser.parse_args()
    sys.path.insert(0, args.python_dir)
    import grpc
    from fieldspace.v1 import fieldspace_pb2 as pb
    from fieldspace.v1 import fieldspace_pb2_grpc as pbg

    work = tempfile.mkdtemp(prefix="fs_upload_memory_")
    try:
        print("load average %s" % " ".join(open("/proc/loadavg").read().split()[:3]))
        print("%-5s %8s %10s %10s  %s" % ("shape", "MB", "idle MiB", "peak MiB", "status"))
        for shape in args.shapes.split(","):
            for mb in [float(s) for s in args.sizes_mb.split(",")]:
                path = os.path.join(work, "%s.obj" % shape)
                size = write_obj(path, shape, int(mb * 1e6))
                store = os.path.join(work, "store-%s-%s" % (shape, mb))
                d = Daemon(args.daemon, store, threads=2,
                           extra=["--memory-budget-mb", str(args.budget_mb)]).start()
                try:
                    channel = grpc.insecure_channel(
                        d.address, options=[("grpc.max_send_message_length", -1)])
                    stub = pbg.FieldSpaceStub(channel)
                    time.sleep(0.5)
                    idle = vm_kib(d.proc.pid, "VmHWM")
                    status = upload_file(pb, stub, path)
                    peak = vm_kib(d.proc.pid, "VmHWM")
                    alive = d.alive()
                    channel.close()
                finally:
                    if d.alive():
                        d.stop()
                print("%-5s %8.1f %10.0f %10.0f  %s%s" % (shape, size / 1e6, idle / 1024,
                                                         peak / 1024, status,
                                                         "" if alive else " (daemon died)"),
                      flush=True)
                os.remove(path)
    finally:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
