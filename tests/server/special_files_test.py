#!/usr/bin/env python3
"""LoadMesh of anything but a regular file under the data root is refused at once and holds no
compute thread (issue 22, item 3): the real fieldspaced with --threads 2 and --data-root.
- A FIFO no one writes to, a symlink to it, and (when the test may make one: root) a character
  device node: INVALID_ARGUMENT within 1 s each. Before, opening the FIFO blocked a compute thread
  until a writer came; two such calls took the whole pool.
- Four concurrent FIFO loads with 5 s deadlines while a Solve and a regular LoadMesh run: all
  answered within 2 s.
- SIGTERM right after another round of FIFO loads: the daemon exits 0 within --drain-seconds (3)
  plus a second (before: it hung until a second signal).

Exit 0 on success, 1 on failure, 77 (skip) if python3-grpcio / numpy are absent.
"""

import os
import signal
import sys
import threading
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from fs_testlib import (Daemon, check, client_test_args, daemon_workdir, icosphere_obj,  # noqa: E402
                        log)

DRAIN_SECONDS = 3


def main():
    args, fs = client_test_args(__doc__)
    if fs is None:
        return 77
    import numpy as np

    daemons = []
    with daemon_workdir("fs_special_files_", daemons) as (work, store, daemon_log):
        root = os.path.join(work, "data")
        os.makedirs(os.path.join(root, "sub"))
        with open(os.path.join(root, "sphere.obj"), "w") as f:
            f.write(icosphere_obj(2)[0])
        os.mkfifo(os.path.join(root, "sub", "pipe.obj"))
        os.symlink("pipe.obj", os.path.join(root, "sub", "link.obj"))
        special = ["sub/pipe.obj", "sub/link.obj"]
        try:
            os.mknod(os.path.join(root, "zero.obj"), 0o644 | 0o020000, os.makedev(1, 5))
            special.append("zero.obj")
        except (PermissionError, OSError) as e:
            log("no device node (%s): FIFOs only" % e)

        d = Daemon(args.daemon, store, data_root=root, log=daemon_log, threads=2,
                   extra=["--drain-seconds", str(DRAIN_SECONDS)])
        daemons.append(d.start())
        client = fs.Client(d.address)
        mesh = client.load("sphere.obj")
        basis = client.build(mesh.id, "vector", 40, progress=False)

        for path in special:
            start = time.monotonic()
            try:
                client.load(path, timeout=5)
                raise AssertionError("LoadMesh(%s) succeeded" % path)
            except fs.InvalidArgument as e:
                check("not a regular file" in str(e), "LoadMesh(%s): %s" % (path, e))
            took = time.monotonic() - start
            check(took < 1.0, "LoadMesh(%s) took %.2f s" % (path, took))
            log("ok: LoadMesh(%s): INVALID_ARGUMENT in %.3f s" % (path, took))

        # Concurrent FIFO loads while other calls are served.
        results = {}

        def load(i):
            start = time.monotonic()
            try:
                client.load("sub/pipe.obj", timeout=5)
                results[i] = ("OK", time.monotonic() - start)
            except fs.FieldspaceError as e:
                results[i] = (e.code.name, time.monotonic() - start)

        threads = [threading.Thread(target=load, args=(i,)) for i in range(4)]
        for t in threads:
            t.start()
        start = time.monotonic()
        solution = client.solve(basis, faces=[0, 7], values=np.array([[1.0, 0, 0], [0, 1.0, 0]]),
                                timeout=5)
        check(len(solution.coefficients) > 0, "solve gave no coefficients")
        again = client.load("sphere.obj", timeout=5)
        check(again.id == mesh.id, "the regular file loaded as another mesh")
        served = time.monotonic() - start
        for t in threads:
            t.join(10)
        check(served < 2.0, "Solve and LoadMesh next to FIFO loads took %.2f s" % served)
        for i, (code, took) in sorted(results.items()):
            check(code == "INVALID_ARGUMENT" and took < 2.0,
                  "concurrent FIFO load %d: %s after %.2f s" % (i, code, took))
        check(len(results) == 4, "FIFO loads unanswered: %d of 4" % (4 - len(results)))
        log("ok: 4 concurrent FIFO loads refused; a Solve and a LoadMesh next to them in %.3f s" %
            served)

        # SIGTERM right after FIFO loads: a prompt drain.
        threads = [threading.Thread(target=load, args=(10 + i,)) for i in range(2)]
        for t in threads:
            t.start()
        time.sleep(0.2)
        start = time.monotonic()
        d.proc.send_signal(signal.SIGTERM)
        try:
            rc = d.proc.wait(DRAIN_SECONDS + 1)
        except Exception:
            raise AssertionError("no exit within %d s of SIGTERM" % (DRAIN_SECONDS + 1))
        took = time.monotonic() - start
        for t in threads:
            t.join(10)
        check(rc == 0, "exit status %s after SIGTERM" % rc)
        log("ok: SIGTERM drained in %.2f s (--drain-seconds %d)" % (took, DRAIN_SECONDS))
    log("special files: all passed")
    return 0


if __name__ == "__main__":
    sys.exit(main())
