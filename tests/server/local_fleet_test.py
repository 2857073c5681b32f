#!/usr/bin/env python3
"""deploy/local-fleet.sh (docs/scale-out.md, "A local fleet"): the script starts 3 replicas and
nginx on loopback; through the router it prints, the CLI checks health, uploads a mesh, builds a
basis and runs a design script; the replica that served the design is SIGKILLed and the same script
through the router gives the same last update (another replica loads the basis from the shared
store); SIGTERM to the script ends nginx and every replica it started and removes its temporary
folder.

Exit 77 (skipped) when nginx is absent (.ci/install-deps installs nginx-light).
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
from fs_testlib import Cli, check, icosphere_obj, log  # noqa: E402

SCRIPT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "deploy",
                      "local-fleet.sh")


def alive(pid):
    """Whether `pid` is a process that has not exited (a zombie counts as gone)."""
    try:
        with open("/proc/%d/stat" % pid) as f:
            return f.read().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


def design_upstreams(work):
    """The upstream address(es) nginx logged for each Design call, in order ("A, B" when the first
    did not answer)."""
    with open(os.path.join(work, "nginx-access.log")) as f:
        lines = f.read().splitlines()
    # $remote_addr $request_uri "$http_x_fieldspace_key" $upstream_addr $status $request_time
    return [x.split(" ", 3)[3].rsplit(" ", 2)[0] for x in lines if " /fieldspace.v1.FieldSpace/Design " in x]


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--bin-dir", required=True, help="holds fieldspaced and fieldspace")
    parser.add_argument("--nginx", default=shutil.which("nginx") or "/usr/sbin/nginx")
    args = parser.parse_args()
    if not os.access(args.nginx, os.X_OK):
        print("SKIPPED: nginx not found (%s); .ci/install-deps installs nginx-light" % args.nginx)
        return 77
    started = time.time()
    tmp = tempfile.mkdtemp(prefix="fs_local_fleet_")
    env = dict(os.environ, NGINX=args.nginx, TMPDIR=tmp)
    fleet = subprocess.Popen([SCRIPT, "-n", "3", "--port", "0", "--bin-dir", args.bin_dir, "--",
                              "--threads", "1"], stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, text=True, env=env)
    # The script's stderr is read in the background (a full pipe would block it).
    err = []
    reader = threading.Thread(target=lambda: err.append(fleet.stderr.read()), daemon=True)
    reader.start()
    replicas, nginx_pid, work, router = {}, None, None, None
    passed = False
    try:
        # --- The lines before `router:`: replicas, nginx, the temporary folder.
        deadline = time.time() + 60
        while router is None:
            check(time.time() < deadline, "no router line within 60 s")
            line = fleet.stdout.readline()
            if not line:
                raise AssertionError("the script ended (%s) before its router line" %
                                     fleet.wait(10))
            key, _, value = line.strip().partition(": ")
            if key == "replica":
                pid, address, name = value.split()
                replicas[address] = int(pid)
            elif key == "nginx":
                nginx_pid = int(value)
            elif key == "work":
                work = value
            elif key == "router":
                router = value
        check(len(replicas) == 3 and nginx_pid and work, "lines before the router's: %s %s %s" %
              (replicas, nginx_pid, work))
        check(os.path.dirname(work) == tmp, "the temporary folder %s is not in $TMPDIR" % work)
        check(router.startswith("127.0.0.1:") and router not in replicas, "router %s" % router)
        log("fleet up in %.1f s: replicas %s, router %s" % (time.time() - started, replicas, router))

        # --- Through the router: health, upload, build, design.
        cli = Cli(os.path.join(args.bin_dir, "fieldspace"), router)
        check(cli.json("health") == {"status": "SERVING"}, "health through the router")
        mesh_file = os.path.join(tmp, "ico2.obj")
        text, faces = icosphere_obj(2)
        with open(mesh_file, "w") as f:
            f.write(text)
        mesh = cli.json("upload", mesh_file)
        check(mesh["num_faces"] == faces, "uploaded %s" % mesh)
        basis = cli.json("build", mesh["id"], "--field", "vector", "--dim", "60", timeout=120)
        check(basis["dimension"] >= 60 and basis["mesh_id"] == mesh["id"], "built %s" % basis)
        script = os.path.join(tmp, "edits.jsonl")
        with open(script, "w") as f:
            for i in range(1, 5):
                f.write('{"add": {"id": %d, "face": %d, "vector": [1, %d, 0]}}\n' % (i, 40 * i, i))
            f.write('{"move": {"id": 2, "face": 7, "vector": [0, 0, 1]}}\n')
            f.write('{"remove": {"id": 3}}\n')
        design = ("design", basis["id"], "--script", script, "--watch", "0,1,2")

        def run_design():
            _, out, _ = cli(*design, timeout=120)
            updates = [json.loads(x) for x in out.splitlines()]
            check(len(updates) == 7, "design printed %d updates of 7" % len(updates))
            return updates

        first = run_design()
        served = design_upstreams(work)
        check(served and served[-1] in replicas, "the Design call in nginx's log: %s" % served)

        # --- SIGKILL the replica that served it; the same script through the router again.
        victim = served[-1]
        os.kill(replicas[victim], signal.SIGKILL)
        deadline = time.time() + 10
        while alive(replicas[victim]):
            check(time.time() < deadline, "replica %s did not die" % victim)
            time.sleep(0.05)
        second = run_design()
        served = design_upstreams(work)
        check(served[-1] != victim and served[-1].split(", ")[-1] in replicas,
              "the second design went to %s (killed: %s)" % (served[-1], victim))
        a, b = ([x for w in u["watched"] for x in w["value"]] + u["coefficients"]
                for u in (first[-1], second[-1]))
        check(len(a) == len(b) and len(a) > 60 and
              max(abs(x - y) for x, y in zip(a, b)) <= 1e-9,
              "the last update differs after the failover:\n%s\n%s" % (first[-1], second[-1]))
        check(cli.json("basis", basis["id"])["id"] == basis["id"], "the basis after the failover")
        log("design served by %s; after its SIGKILL by %s, same last update" %
            (victim, served[-1]))

        # --- SIGTERM: nginx, every replica and the temporary folder gone.
        t0 = time.time()
        fleet.send_signal(signal.SIGTERM)
        rc = fleet.wait(30)
        reader.join(5)
        check(rc == 143, "the script exited %d after SIGTERM: %s" % (rc, "".join(err)[-2000:]))
        left = [p for p in list(replicas.values()) + [nginx_pid] if alive(p)]
        check(not left, "processes left after SIGTERM: %s" % left)
        workers = subprocess.run(["pgrep", "-P", str(nginx_pid)], capture_output=True, text=True)
        check(not workers.stdout.strip(), "nginx workers left: %s" % workers.stdout)
        check(not os.path.exists(work), "the temporary folder %s is left" % work)
        log("SIGTERM: all stopped and removed in %.2f s" % (time.time() - t0))
        log("PASS in %.1f s" % (time.time() - started))
        passed = True
        return 0
    finally:
        if fleet.poll() is None:
            fleet.send_signal(signal.SIGTERM)
            try:
                fleet.wait(30)
            except subprocess.TimeoutExpired:
                fleet.kill()
        for p in list(replicas.values()) + ([nginx_pid] if nginx_pid else []):
            if alive(p):
                os.kill(p, signal.SIGKILL)
        if not passed and err and err[0]:
            sys.stderr.write("--- local-fleet.sh stderr ---\n%s\n" % err[0][-3000:])
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
