#!/usr/bin/env python3
"""Repairs of a damaged store over the wire (issue 15, B7): the real fieldspaced, its store files
damaged between restarts.
- A truncated mesh file: its (undamaged) basis answers DATA_LOSS; uploading the mesh again
  repairs it, and without a restart the basis lifts to its old values and is listed again.
- A mesh file with flipped payload bytes (header intact, so it is listed): an upload of that
  mesh before its first load rewrites the file; after a restart the mesh loads.
- Foreign files (names that are not ids) answer DATA_LOSS; deleting them removes the files, and
  they do not come back after a restart.

Exit 0 on success, 1 on failure, 77 (skip) if python3-grpcio / numpy are absent.
"""

import os
import signal
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from fs_testlib import (Daemon, check, check_listed_usable, client_test_args,  # noqa: E402
                        daemon_workdir, geometry_key, log, perturbed_sphere)


def main():
    args, fs = client_test_args(__doc__)
    if fs is None:
        return 77
    import numpy as np

    daemons = []

    def start(store, daemon_log):
        daemons.append(Daemon(args.daemon, store, log=daemon_log).start())
        return fs.Client(daemons[-1].address, timeout=60)

    def stop(client):
        client.close()
        check(daemons[-1].stop(signal.SIGTERM) == 0, "SIGTERM exits 0")

    def expect_error(error_class, call, *call_args):
        try:
            call(*call_args)
        except fs.FieldspaceError as e:
            check(isinstance(e, error_class), "%s%s: %r" % (call.__name__, call_args, e))
            return
        check(False, "%s%s succeeded" % (call.__name__, call_args))

    with daemon_workdir("fs_store_repair_", daemons) as (_, store, daemon_log):
        client = start(store, daemon_log)
        truncated, flipped = perturbed_sphere(2, 1), perturbed_sphere(2, 2)
        uploaded = {geometry_key(*truncated), geometry_key(*flipped)}
        m1 = client.upload(*truncated).id
        m2 = client.upload(*flipped).id
        basis = client.build(m1, "vector", 12, progress=False)
        x = np.linspace(-1, 1, client.basis(basis).columns)
        before = client.lift(basis, x, encoding="dof")
        stop(client)

        path = os.path.join(store, "meshes", m1 + ".fsmesh")
        os.truncate(path, os.path.getsize(path) // 2)
        with open(os.path.join(store, "meshes", m2 + ".fsmesh"), "r+b") as f:
            f.seek(-8, os.SEEK_END)  # the face array
            f.write(b"\xff" * 4)
        with open(os.path.join(store, "meshes", "foreign-copy.fsmesh"), "wb") as f:
            f.write(b"not a mesh")
        with open(os.path.join(store, "bases", "stray.fsbasis"), "wb") as f:
            f.write(b"not a basis")

        client = start(store, daemon_log)
        # a. The truncated mesh, repaired by an upload: its basis is served again, no restart.
        expect_error(fs.DataLoss, client.lift, basis, x)
        check(client.upload(*truncated).id == m1, "same id")
        check(basis in [b.id for b in client.bases()], "the basis is listed again")
        check(np.array_equal(client.lift(basis, x, encoding="dof"), before), "the same field")
        # b. The payload-damaged mesh, uploaded again before its first load.
        check(client.upload(*flipped).id == m2, "same id")
        # c. Foreign files.
        expect_error(fs.DataLoss, client.mesh, "foreign-copy")
        expect_error(fs.DataLoss, client.basis, "stray")
        client.delete_mesh("foreign-copy")
        client.delete_basis("stray")
        check(not os.path.exists(os.path.join(store, "meshes", "foreign-copy.fsmesh")),
              "the foreign mesh file is deleted")
        check(not os.path.exists(os.path.join(store, "bases", "stray.fsbasis")),
              "the stray basis file is deleted")
        stop(client)

        client = start(store, daemon_log)
        V, F = client.mesh_geometry(m2)
        check(geometry_key(V, F) == geometry_key(*flipped), "the rewritten mesh loads intact")
        expect_error(fs.NotFound, client.mesh, "foreign-copy")
        expect_error(fs.NotFound, client.basis, "stray")
        meshes, bases = check_listed_usable(client, store, uploaded, {basis: before})
        check(sorted(meshes) == sorted([m1, m2]) and bases == [basis],
              "listed: %s %s" % (meshes, bases))
        stop(client)
        log("PASS")
        return 0


if __name__ == "__main__":
    sys.exit(main())
