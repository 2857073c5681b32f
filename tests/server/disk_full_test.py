#!/usr/bin/env python3
"""Disk full (issue 15, D): fieldspaced with its store on an 8 MB tmpfs. Uploads (ever smaller
meshes) until the store is full; then:
- uploads and builds fail with RESOURCE_EXHAUSTED saying "No space left on device", the daemon
  stays up and serving;
- exactly the uploads answered OK are listed, no temporary file is left, and every listed mesh and
  basis loads (its geometry round-trips, the basis lifts to the same values as before);
- after a mesh is deleted, an upload and the build that failed succeed, and all of it survives a
  restart.

Needs root (to mount the tmpfs): otherwise exit 77 (skipped), saying so.
"""

import os
import signal
import subprocess
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from fs_testlib import (Daemon, check, check_listed_usable, client_test_args,  # noqa: E402
                        daemon_workdir, geometry_key, kill_alive, log, perturbed_sphere,
                        store_temp_files)

TMPFS_SIZE = "8m"


def main():
    args, fs = client_test_args(__doc__)
    if fs is None:
        return 77

    daemons = []
    with daemon_workdir("fs_disk_full_", daemons) as (work, _, daemon_log):
        mount_point = os.path.join(work, "tmpfs")
        os.makedirs(mount_point)
        mounted = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=" + TMPFS_SIZE, "tmpfs",
                                  mount_point], capture_output=True, text=True)
        if mounted.returncode != 0:
            print("SKIPPED: cannot mount a tmpfs of %s for the store (needs root or "
                  "CAP_SYS_ADMIN): %s" % (TMPFS_SIZE, mounted.stderr.strip()))
            return 77
        try:
            # The daemon's log is not on the full file system.
            return fill_and_check(args.daemon, fs, os.path.join(mount_point, "store"), daemon_log,
                                  daemons)
        finally:
            kill_alive(daemons)  # before the unmount: the daemon holds the store open
            if subprocess.run(["umount", mount_point]).returncode != 0:
                subprocess.run(["umount", "-l", mount_point])


def fill_and_check(daemon, fs, store, daemon_log, daemons):
    started = time.time()
    d = Daemon(daemon, store, log=daemon_log).start()
    daemons.append(d)
    client = fs.Client(d.address, timeout=60)
    uploaded, lifted, acknowledged = set(), {}, {}  # acknowledged: mesh id -> subdivisions

    def upload(subdivisions, seed):
        V, F = perturbed_sphere(subdivisions, seed)
        uploaded.add(geometry_key(V, F))
        info = client.upload(V, F, name="s%d-%d" % (subdivisions, seed))
        acknowledged[info.id] = subdivisions
        return info.id

    def check_full(error, what):
        check(isinstance(error, fs.ResourceExhausted), "%s: %r" % (what, error))
        check("no space left on device" in str(error).lower(), "%s: %s" % (what, error))
        check(store not in str(error), "%s: the store path is redacted: %s" % (what, error))

    first = upload(2, 0)
    basis = client.build(first, "vector", 10, progress=False)
    # Fill the store: large meshes first, then ever smaller ones, each size until it fails.
    seed = 1
    failures = 0
    for subdivisions in (5, 4, 3, 2, 1):
        while True:
            seed += 1
            try:
                upload(subdivisions, seed)
            except fs.FieldspaceError as e:
                check_full(e, "upload into a full store")
                if not failures:
                    log("first refusal: %s" % e)
                failures += 1
                break
    log("store full after %d uploads (%d refused): %s" %
        (len(acknowledged), failures, subprocess.run(
            ["df", "-k", os.path.dirname(store)], capture_output=True, text=True).stdout.split("\n")[1]))
    try:
        client.build(first, "vector", 12, progress=False)
        check(False, "a build into a full store succeeded")
    except fs.FieldspaceError as e:
        check_full(e, "build into a full store")
        log("build refused: %s" % e)
    check(d.alive() and client.health() == "SERVING", "the daemon serves on")
    check(store_temp_files(store) == [], "temporary files left: %s" % store_temp_files(store))
    meshes, bases = check_listed_usable(client, store, uploaded, lifted)
    check(set(meshes) == set(acknowledged), "listed %d meshes, answered OK %d" %
          (len(meshes), len(acknowledged)))
    check(bases == [basis], "bases listed: %s" % bases)

    # Room again: delete a large mesh; an upload and the refused build now succeed.
    largest = max(acknowledged, key=acknowledged.get)
    client.delete_mesh(largest)
    del acknowledged[largest]
    upload(3, 0)
    rebuilt = client.build(first, "vector", 12, progress=False)
    meshes, bases = check_listed_usable(client, store, uploaded, lifted)
    check(set(meshes) == set(acknowledged) and set(bases) == {basis, rebuilt},
          "after freeing space: %d meshes, bases %s" % (len(meshes), bases))
    client.close()
    check(d.stop(signal.SIGTERM) == 0, "SIGTERM exits 0")

    d = Daemon(daemon, store, log=daemon_log).start()
    daemons.append(d)
    client = fs.Client(d.address, timeout=60)
    meshes, bases = check_listed_usable(client, store, uploaded, lifted)
    check(set(meshes) == set(acknowledged) and set(bases) == {basis, rebuilt},
          "after a restart: %d meshes, bases %s" % (len(meshes), bases))
    client.close()
    check(d.stop(signal.SIGTERM) == 0, "SIGTERM exits 0")
    log("PASS (%.1f s)" % (time.time() - started))
    return 0


if __name__ == "__main__":
    sys.exit(main())
