#!/usr/bin/env python3
"""Shutdown under load: SIGTERM while 16 design sessions edit and a basis build runs.

Each of ITERATIONS rounds restarts fieldspaced on the same store (the basis reloads from it), starts
16 design sessions (8 grpcio streams that send a move / watch / set_weights edit every 10 ms, so
that a drain often finds a stream waiting for its next message, and 8 `fieldspace design` clients
that send edits as fast as the server answers), starts a basis build, and sends SIGTERM. The daemon must exit 0 within the drain bound
every time, the clients must end (UNAVAILABLE, or done), and the store must still serve the basis
afterwards. Before the fix of a DesignReactor race, a failed read during the drain queued work on a
finished call and the daemon died with SIGABRT in most rounds.
"""

import argparse
import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from fs_testlib import Cli, Daemon, check, log, torus_obj  # noqa: E402

CLI_SESSIONS = 8
PACED_SESSIONS = 8
DRAIN_SECONDS = 5

try:
    import grpc
    from fs_reflection import ReflectionClient
except ImportError as e:  # pragma: no cover
    print("SKIP: python3-grpcio / python3-protobuf not available: %s" % e)
    sys.exit(77)


def paced_session(design, Req, basis_id, faces, stop, outcome, index):
    """One Design stream that sends an edit every 10 ms until `stop` is set."""
    def requests():
        yield Req(seq=1, open={"basis_id": basis_id, "weights": {"mu_s": 1, "mu_c": 1},
                               "watch_faces": [index, index + 5]})
        yield Req(seq=2, add={"id": 1, "constraint": {"face": index, "value": [1, 0],
                                                        "hard": True}})
        seq = 3
        while not stop.is_set():
            time.sleep(0.01)
            k = seq % 3
            if k == 0:
                yield Req(seq=seq, move={"id": 1, "face": (seq * 7 + index) % faces,
                                         "value": [0.5, 0.5]})
            elif k == 1:
                yield Req(seq=seq, watch={"faces": [seq % faces, (seq * 3) % faces]})
            else:
                yield Req(seq=seq, set_weights={"mu_s": 1, "mu_b": 0.001 * (seq % 4), "mu_c": 1})
            seq += 1

    try:
        for _ in design(requests(), timeout=60):
            pass
        outcome[index] = "OK"
    except grpc.RpcError as e:
        outcome[index] = e.code().name


def edit_script(path, faces, edits):
    lines = ['{"add": {"id": 1, "face": 3, "vector": [1, 0, 0], "hard": true}}',
             '{"add": {"id": 2, "face": 50, "vector": [0, 1, 0], "weight": 2.0}}']
    for i in range(edits):
        k = i % 4
        if k == 0:
            lines.append('{"move": {"id": 2, "face": %d, "vector": [0, 1, 0]}}' % ((7 * i) % faces))
        elif k == 1:
            lines.append('{"watch": {"faces": [%d, %d, %d]}}' % (i % faces, (i + 9) % faces,
                                                               (i * 13) % faces))
        elif k == 2:
            lines.append('{"weights": {"mu_s": 1.0, "mu_b": %g, "mu_c": 1.0}}' %
                         (0.001 * (1 + i % 3)))
        else:
            lines.append('{"move": {"id": 1, "face": %d, "vector": [1, 0, 0]}}' % ((5 * i + 1) % faces))
    with open(path, "w") as f:
        f.write("\n".join(lines) + "\n")


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--daemon", required=True)
    parser.add_argument("--client", required=True)
    parser.add_argument("--protoc", required=True)
    parser.add_argument("--grpc-proto-dir", required=True)
    parser.add_argument("--iterations", type=int, default=20)
    args = parser.parse_args()

    work = tempfile.mkdtemp(prefix="fs_shutdown_")
    store = os.path.join(work, "store")
    mesh_text, faces = torus_obj(major=96, minor=48)  # 9216 faces
    mesh_path = os.path.join(work, "torus.obj")
    with open(mesh_path, "w") as f:
        f.write(mesh_text)
    script = os.path.join(work, "edits.jsonl")
    edit_script(script, faces, 4000)
    daemons = []
    try:
        d = Daemon(args.daemon, store, extra=["--drain-seconds", str(DRAIN_SECONDS)]).start()
        daemons.append(d)
        cli = Cli(args.client, d.address)
        mesh = cli.json("upload", mesh_path)
        basis = cli.json("build", mesh["id"], "--field", "vector", "--dim", "200")
        check(d.stop() == 0, "first daemon exits 0")
        crashes = []
        for it in range(args.iterations):
            d = Daemon(args.daemon, store, extra=["--drain-seconds", str(DRAIN_SECONDS)]).start()
            daemons.append(d)
            cli = Cli(args.client, d.address)
            reflection = ReflectionClient(d.address, args.protoc, args.grpc_proto_dir, work)
            reflection.load_symbol("fieldspace.v1.FieldSpace")
            design, Req = reflection.method("stream_stream", "fieldspace.v1.FieldSpace", "Design",
                                            "fieldspace.v1.DesignRequest",
                                            "fieldspace.v1.DesignUpdate")
            stop = threading.Event()
            outcome = {}
            paced = [threading.Thread(target=paced_session,
                                      args=(design, Req, basis["id"], faces, stop, outcome, i))
                     for i in range(PACED_SESSIONS)]
            for t in paced:
                t.start()
            clients = [subprocess.Popen([args.client, "--server", d.address, "design", basis["id"],
                                         "--script", script, "--no-coefficients"],
                                        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
                       for _ in range(CLI_SESSIONS)]
            # A build that is still running at SIGTERM (a new seed gives a new basis each round).
            build = subprocess.Popen([args.client, "--server", d.address, "build", mesh["id"],
                                      "--field", "vector", "--dim", "400", "--seed", str(100 + it)],
                                     stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
            time.sleep(0.6 + 0.05 * (it % 7))  # sessions are open and editing
            start = time.monotonic()
            d.proc.send_signal(signal.SIGTERM)
            try:
                rc = d.proc.wait(DRAIN_SECONDS + 10)
            except subprocess.TimeoutExpired:
                d.proc.kill()
                rc = "hung"
            took = time.monotonic() - start
            d.log.close()
            stop.set()
            for t in paced:
                t.join(30)
            reflection.channel.close()
            for i in range(PACED_SESSIONS):
                if outcome.get(i) not in ("UNAVAILABLE", "CANCELLED"):
                    crashes.append("round %d: paced session %d ended with %s" %
                                   (it, i, outcome.get(i)))
            for c in clients + [build]:
                try:
                    c.wait(30)
                except subprocess.TimeoutExpired:
                    c.kill()
                    crashes.append("round %d: a client hung after the daemon exited" % it)
            for c in clients:
                err = c.stderr.read().decode()
                c.stderr.close()
                if c.returncode not in (0, 1) or (c.returncode == 1 and "UNAVAILABLE" not in err
                                                   and "CANCELLED" not in err):
                    crashes.append("round %d: client rc %s: %s" % (it, c.returncode, err[-300:]))
            if rc != 0 or took > DRAIN_SECONDS + 3:
                crashes.append("round %d: daemon rc %s after %.2f s (log: %s)" %
                               (it, rc, took, open(d.log_path).read()[-1500:]))
            log("round %d: rc %s in %.2f s" % (it, rc, took))
        check(not crashes, "\n".join(crashes))
        # The store is intact: the basis still answers.
        d = Daemon(args.daemon, store).start()
        daemons.append(d)
        cli = Cli(args.client, d.address)
        check(cli.json("basis", basis["id"])["state"] == "ready", "basis intact")
        check(d.stop() == 0, "last daemon exits 0")
        log("PASS: %d rounds" % args.iterations)
        return 0
    finally:
        for d in daemons:
            if d.alive():
                d.proc.kill()
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
