#!/usr/bin/env python3
"""Crash consistency (issue 15, D): 30 times, fieldspaced uploads small meshes and builds and saves
bases on one store while it is killed with SIGKILL, at a random moment on even rounds and at a
random moment inside a save on odd rounds (--debug-save-pause-ms pauses every save halfway through
its payload, so saves are long enough to be hit). After each kill the daemon restarts on the store
and:
- no temporary file is left, and every listed id is a proper id;
- every upload and build that was answered OK before the kill is listed (persist, then answer);
- every listed mesh's geometry is exactly one that was uploaded, every listed basis lifts, and to
  the same values as after earlier restarts.
Seeds are fixed (round r uses seed 1000 + r), so a failure reproduces. Prints how many kills
landed in the middle of a write (a temporary file on disk after the kill).

Exit 0 on success, 1 on failure, 77 (skip) if python3-grpcio / numpy are absent.
"""

import os
import random
import signal
import sys
import threading
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from fs_testlib import (Daemon, check, check_listed_usable, client_test_args,  # noqa: E402
                        daemon_workdir, geometry_key, log, perturbed_sphere, store_temp_files)

ROUNDS = 30
PAUSE_MS = 150  # each save's pause: long enough to be hit, short enough for 30 rounds


def main():
    args, fs = client_test_args(__doc__)
    if fs is None:
        return 77

    started = time.time()
    uploaded = set()       # geometry keys of every mesh ever sent
    acknowledged = set()   # mesh and basis ids answered OK
    lifted = {}            # basis id -> DOF values of its first lift after a restart
    listed = []            # mesh ids listed after the last restart
    kills = {"total": 0, "mid_write": 0, "mesh": 0, "basis": 0}
    daemons = []
    with daemon_workdir("fs_crash_", daemons) as (_, store, daemon_log):
        for r in range(ROUNDS):
            rng = random.Random(1000 + r)
            d = Daemon(args.daemon, store, log=daemon_log,
                       extra=["--debug-save-pause-ms", str(PAUSE_MS)]).start()
            daemons.append(d)
            client = fs.Client(d.address, timeout=30)
            first_upload = threading.Event()
            fresh = []

            def upload(seed):
                V, F = perturbed_sphere(2, seed)
                uploaded.add(geometry_key(V, F))
                try:
                    info = client.upload(V, F, name="s%d" % seed)
                    acknowledged.add(info.id)
                    fresh.append(info.id)
                except fs.FieldspaceError:
                    pass  # killed
                finally:
                    first_upload.set()

            def build(mesh_id, dimension, seed):
                if mesh_id is None:  # nothing stored yet: build on this round's upload
                    first_upload.wait(10)
                    if not fresh:
                        return
                    mesh_id = fresh[0]
                try:
                    acknowledged.add(client.build(mesh_id, "vector", dimension, seed=seed,
                                                  progress=False, timeout=30))
                except fs.FieldspaceError:
                    pass  # killed

            work_items = [threading.Thread(target=upload, args=(100 * r + k,)) for k in range(2)]
            work_items += [threading.Thread(target=build, args=(
                rng.choice(listed) if listed else None, rng.randint(6, 14), rng.randint(0, 99)))
                for _ in range(2)]
            for t in work_items:
                t.start()
            if r % 2 == 0:
                time.sleep(rng.uniform(0.0, 0.6))
            else:
                deadline = time.time() + 10
                while not store_temp_files(store) and time.time() < deadline:
                    time.sleep(0.002)
                time.sleep(rng.uniform(0.0, 0.8 * PAUSE_MS / 1000))
            d.proc.send_signal(signal.SIGKILL)
            d.proc.wait(30)
            d.log.close()
            temps = store_temp_files(store)
            kills["total"] += 1
            kills["mid_write"] += bool(temps)
            kills["mesh"] += any(t.startswith("meshes") for t in temps)
            kills["basis"] += any(t.startswith("bases") for t in temps)
            for t in work_items:
                t.join(60)
            client.close()

            d = Daemon(args.daemon, store, log=daemon_log).start()
            daemons.append(d)
            client = fs.Client(d.address, timeout=60)
            check(store_temp_files(store) == [], "temporary files left after the restart: %s" %
                  store_temp_files(store))
            listed, bases = check_listed_usable(client, store, uploaded, lifted)
            missing = acknowledged - set(listed) - set(bases)
            check(not missing, "round %d: answered OK before the kill, gone after it: %s" %
                  (r, sorted(missing)))
            log("round %2d: killed %s (%s), then %d meshes and %d bases listed, all usable" %
                (r, "mid-write" if temps else "between writes", ", ".join(temps) or "-",
                 len(listed), len(bases)))
            client.close()
            check(d.stop(signal.SIGTERM) == 0, "SIGTERM exits 0")
        log("%d kills, %d in the middle of a write (%d during a mesh save, %d during a basis "
            "save); %d artifacts acknowledged, all listed and usable; %.1f s" %
            (kills["total"], kills["mid_write"], kills["mesh"], kills["basis"],
             len(acknowledged), time.time() - started))
        check(kills["mid_write"] >= ROUNDS // 2, "too few kills landed mid-write: %s" % kills)
        log("PASS")
        return 0


if __name__ == "__main__":
    sys.exit(main())
