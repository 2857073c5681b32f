#!/usr/bin/env python3
"""Scale out (issue 16): 3 fieldspaced replicas with --shared-store on one store directory behind
nginx (grpc_pass to an upstream with `hash $http_x_fieldspace_key consistent`), driven through the
router by the Python package.

- uploads 3 meshes; builds a basis through the router while the same build is asked of every
  replica directly: it is built exactly once (one "building basis" log line across the replicas'
  logs, the others log that they wait for it);
- builds 5 more bases and runs 12 Design sessions through the router, each with its basis id as
  routing key (checked in nginx's access log);
- SIGKILLs the replica that holds the most sessions; every session then answers a no-op edit
  (watch the same faces): those of the killed replica with `resumed` set, all with the
  coefficients they had before (to 1e-10);
- every stored artifact is still listed and loads (no artifact lost or damaged);
- the CLI's `design` through the router survives the SIGKILL of its replica mid-script: one update
  says "resumed": true, the script runs to its end;
- behind a second router with 2 fresh replicas, the CLI's `design` survives the loss of its
  replica while its `open` is pending (the replica SIGSTOPped as the open reaches it, then
  SIGKILLed): the open's update says "resumed": true and the script's last update equals that of
  the same script run again on the survivor;
- no gRPC C-core log line (`E1127 12:00:00.000 ... hpack_parser.cc ...`) reaches the CLI's stderr.

Exit 77 (skipped) when nginx is absent (.ci/install-deps installs nginx-light) or grpcio is.
"""

import argparse
import getpass
import json
import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from fs_testlib import Daemon, check, icosphere_obj, log, obj_arrays, torus_obj  # noqa: E402

NGINX_CONF = """\
{user}worker_processes 1;
daemon off;
pid {prefix}/nginx.pid;
error_log {prefix}/error.log info;
events {{ worker_connections 1024; }}
http {{
    log_format keyed '$request_uri "$http_x_fieldspace_key" $upstream_addr $status';
    access_log {prefix}/access.log keyed;
    client_body_temp_path {prefix}/client_body;
    proxy_temp_path {prefix}/proxy;
    fastcgi_temp_path {prefix}/fastcgi;
    uwsgi_temp_path {prefix}/uwsgi;
    scgi_temp_path {prefix}/scgi;
    upstream fieldspace {{
        hash $http_x_fieldspace_key consistent;
{servers}
    }}
    server {{
        listen 127.0.0.1:{port} http2;
        client_max_body_size 0;
        grpc_read_timeout 600s;
        grpc_send_timeout 600s;
        location / {{
            grpc_pass grpc://fieldspace;
        }}
    }}
}}
"""


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def start_nginx(nginx, prefix, upstreams):
    port = free_port()
    user = "user %s;\n" % getpass.getuser() if os.geteuid() == 0 else ""
    servers = "\n".join("        server %s max_fails=1 fail_timeout=60s;" % a for a in upstreams)
    conf = os.path.join(prefix, "nginx.conf")
    with open(conf, "w") as f:
        f.write(NGINX_CONF.format(user=user, prefix=prefix, servers=servers, port=port))
    proc = subprocess.Popen([nginx, "-p", prefix, "-c", conf, "-e", prefix + "/error.log"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    deadline = time.time() + 15
    while time.time() < deadline:
        if proc.poll() is not None:
            raise AssertionError("nginx exited %d: %s" % (proc.returncode,
                                                          proc.stderr.read().decode()[-2000:]))
        try:
            socket.create_connection(("127.0.0.1", port), timeout=1).close()
            return proc, "127.0.0.1:%d" % port
        except OSError:
            time.sleep(0.05)
    proc.kill()
    raise AssertionError("nginx did not listen within 15 s")


# The form of gRPC C-core's log lines (severity letter, MMDD, time): never on the CLI's stderr.
CORE_LOG_LINE = re.compile(r"^[EWID]\d{4} ", re.MULTILINE)


def check_no_core_log(err, what):
    check(not CORE_LOG_LINE.search(err), "%s: a gRPC log line on stderr: %s" % (what, err[-2000:]))


def upstream_of_key(access_log, key):
    """The upstream nginx chose for the last GetBasis with routing key `key`."""
    lines = [x for x in read(access_log).splitlines()
             if x.startswith("/fieldspace.v1.FieldSpace/GetBasis \"%s\"" % key)]
    check(lines, "no GetBasis of %s in %s" % (key, access_log))
    return lines[-1].split()[2]


def _numbers(value):
    """The numbers of a JSON value (nested lists and objects), in order."""
    if isinstance(value, dict):
        return [x for v in value.values() for x in _numbers(v)]
    if isinstance(value, list):
        return [x for v in value for x in _numbers(v)]
    return [value] if isinstance(value, (int, float)) else []


def read(path):
    with open(path, errors="replace") as f:
        return f.read()


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--daemon", required=True)
    parser.add_argument("--client", required=True, help="the fieldspace CLI")
    parser.add_argument("--python-dir", required=True, help="the build tree's python/ folder")
    parser.add_argument("--nginx", default=shutil.which("nginx") or "/usr/sbin/nginx")
    args = parser.parse_args()
    if not os.access(args.nginx, os.X_OK):
        print("SKIPPED: nginx not found (%s); .ci/install-deps installs nginx-light" % args.nginx)
        return 77
    try:
        import grpc  # noqa: F401
        import numpy as np
    except ImportError as e:
        print("SKIPPED: %s (python3-grpcio and python3-numpy are needed)" % e)
        return 77
    sys.path.insert(0, args.python_dir)
    import fieldspace as fs

    started = time.time()
    work = tempfile.mkdtemp(prefix="fs_scale_out_")
    store = os.path.join(work, "store")
    replicas, routers = [], []
    try:
        for i in range(3):
            replicas.append(Daemon(args.daemon, store, threads=1,
                                   extra=["--shared-store", "--daemon-id", "r%d" % i],
                                   log=os.path.join(work, "r%d.log" % i)).start())
        by_address = {d.address: d for d in replicas}
        nginx, router = start_nginx(args.nginx, work, [d.address for d in replicas])
        routers.append(nginx)
        log("3 replicas %s behind nginx on %s" % (", ".join(by_address), router))
        client = fs.Client(router, timeout=120)
        check(client.health() == "SERVING", "health through the router")

        # --- 3 meshes.
        meshes = [client.upload(*obj_arrays(icosphere_obj(3)[0]), name="ico3"),
                  client.upload(*obj_arrays(torus_obj(24, 12)[0]), name="torus"),
                  client.upload(*obj_arrays(icosphere_obj(2)[0]), name="ico2")]
        check(len({m.id for m in meshes}) == 3, "3 distinct meshes")

        # --- One basis built once: through the router and, at the same time, directly on every
        # replica (which all must wait for the one that holds the lease).
        results, errors, waited_for = [], [], set()

        def build(address):
            def seen(p):
                if p.waiting_for:
                    waited_for.add(p.waiting_for)
            try:
                with fs.Client(address, timeout=120) as c:
                    results.append(c.build(meshes[0].id, "vector", 100, progress=False,
                                           on_progress=seen))
            except Exception as e:  # noqa: BLE001 (reported below)
                errors.append("%s: %s" % (address, e))

        threads = [threading.Thread(target=build, args=(a,)) for a in [router] + list(by_address)]
        for t in threads:
            t.start()
        for t in threads:
            t.join(180)
        check(not errors, "builds failed: %s" % errors)
        check(len(results) == 4 and len(set(results)) == 1, "one basis id: %s" % results)
        main_basis = results[0]
        logs = {d.address: read(d.log_path) for d in replicas}
        built_lines = [line for text in logs.values() for line in text.splitlines()
                       if "building basis " + main_basis in line]
        waiting_lines = [line for text in logs.values() for line in text.splitlines()
                         if "basis %s: waiting for replica" % main_basis in line]
        check(len(built_lines) == 1, "built once across the replicas: %s" % built_lines)
        check(len(waiting_lines) >= 1, "no replica waited for the build lease")
        builder = built_lines[0].split(" as ")[1].split(",")[0]
        check(waited_for == {builder}, "progress named %s, the builder is %s" %
              (waited_for, builder))
        check(os.listdir(os.path.join(store, "leases")) == [], "leases left behind")
        log("basis %s built once (%s); %d replica(s) waited, their streams said so" %
            (main_basis, builder, len(waiting_lines)))

        # --- 5 more bases (through the router), 12 sessions on the 6 bases.
        bases = [main_basis]
        for mesh, d in ((meshes[0], 40), (meshes[1], 40), (meshes[1], 60), (meshes[2], 40),
                        (meshes[2], 60)):
            bases.append(client.build(mesh.id, "vector", d, progress=False))
        check(len(set(bases)) == 6, "6 distinct bases")
        mesh_faces = {m.id: m.num_faces for m in meshes}
        basis_mesh = {b: client.basis(b).mesh_id for b in bases}
        sessions = []
        rng = np.random.default_rng(16)
        for k in range(12):
            basis = bases[k % 6]
            nf = mesh_faces[basis_mesh[basis]]
            watch = sorted(rng.choice(nf, 3, replace=False).tolist())
            s = client.design(basis, watch=watch)
            for _ in range(3 + k % 3):
                s.add(int(rng.integers(nf)), rng.normal(size=3).tolist())
            s.move(1, int(rng.integers(nf)), rng.normal(size=3).tolist())
            if k % 2:
                s.add(int(rng.integers(nf)), rng.normal(size=3).tolist(), hard=True)
            if k % 3 == 0:
                s.set_weights(mu_b=0.01)
            if k % 4 == 0:
                s.remove(2)
            sessions.append((s, watch, s.coefficients.copy()))

        # Which replica holds which session: the upstream nginx chose for each key.
        for b in bases:
            client.basis(b)
        time.sleep(0.2)
        upstream_of = {}
        access = read(os.path.join(work, "access.log")).splitlines()
        for line in access:
            parts = line.split()
            if parts[0].endswith("/GetBasis") and parts[1].strip('"') in bases:
                upstream_of[parts[1].strip('"')] = parts[2]
        check(set(upstream_of) == set(bases), "no upstream logged for some bases: %s" %
              upstream_of)
        held = {a: sum(1 for s, _, _ in sessions if upstream_of[s.basis_id] == a)
                for a in by_address}
        victim = max(held, key=held.get)
        log("sessions per replica: %s; SIGKILL %s" % (held, victim))
        if held[victim] == 12:
            log("all 12 sessions hashed to one replica (the ring depends on the random ports)")
        victim_proc = by_address[victim]
        victim_proc.proc.kill()
        victim_proc.proc.wait(10)

        # --- Every session answers; those of the dead replica resumed, all with the old solution.
        t0 = time.time()
        resumed = 0
        for s, watch, before in sessions:
            u = s.watch(watch)
            on_victim = upstream_of[s.basis_id] == victim
            check(u.resumed == on_victim, "session on %s: resumed=%s" %
                  (upstream_of[s.basis_id], u.resumed))
            err = float(np.max(np.abs(u.coefficients - before)))
            check(err <= 1e-10, "session on %s (resumed=%s): coefficients moved by %g" %
                  (upstream_of[s.basis_id], u.resumed, err))
            resumed += u.resumed
            v = s.add(0, [1.0, 0.0, 0.0], weight=0.5)  # and it goes on
            check(not v.resumed and v.num_constraints == u.num_constraints + 1, "edit after resume")
            s.close()
        check(resumed == held[victim], "resumed %d of %d" % (resumed, held[victim]))
        log("%d sessions resumed on other replicas, 12 sessions checked in %.2f s" %
            (resumed, time.time() - t0))

        # --- Keys: every Design call through the router carried its basis id.
        access = read(os.path.join(work, "access.log")).splitlines()
        design_keys = [line.split()[1].strip('"') for line in access
                       if line.split()[0].endswith("/Design")]
        check(len(design_keys) >= 12 and all(k in bases for k in design_keys),
              "Design calls without their key: %s" % design_keys)

        # --- Nothing lost or damaged: all listed, all load (a solve loads the basis).
        listed_meshes = {m.id for m in client.meshes()}
        listed_bases = {b.id for b in client.bases()}
        check(listed_meshes == {m.id for m in meshes}, "meshes listed: %s" % listed_meshes)
        check(listed_bases == set(bases), "bases listed: %s" % listed_bases)
        for b in bases:
            solution = client.solve(b, [0], [[1.0, 0.0, 0.0]])
            check(np.all(np.isfinite(solution.coefficients)), "basis %s loads and solves" % b)
        for d in replicas:
            if d is victim_proc:
                continue
            with fs.Client(d.address, timeout=60) as c:
                check({b.id for b in c.bases()} == set(bases), "bases seen by %s" % d.address)
                for m in meshes:
                    c.mesh_geometry(m.id)  # loads the mesh (checksums)

        # --- The CLI: a long design script through the router; SIGKILL its replica midway.
        client.basis(main_basis)
        time.sleep(0.2)
        holder = by_address[upstream_of_key(os.path.join(work, "access.log"), main_basis)]
        check(holder is not victim_proc, "routed to the dead replica")
        script = os.path.join(work, "edits.jsonl")
        edits = 20000
        with open(script, "w") as f:
            for i in range(1, 9):
                f.write('{"add": {"id": %d, "face": %d, "vector": [1, 0, 0]}}\n' % (i, 10 * i))
            for k in range(edits - 8):
                f.write('{"move": {"id": %d, "face": %d, "vector": [0, %d, 1]}}\n' %
                        (1 + k % 8, (37 * k) % 1280, 1 + k % 3))
        cli = subprocess.Popen([args.client, "--server", router, "design", main_basis, "--script",
                                script, "--no-coefficients"], stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True)
        out = []
        while len(out) < 200:
            out.append(cli.stdout.readline())
        holder.proc.kill()
        holder.proc.wait(10)
        # Not communicate(): with both pipes it reads the raw descriptors and skips what
        # readline() has already buffered (a few updates went missing that way).
        rest = cli.stdout.read()
        err = cli.stderr.read()
        cli.wait(120)
        out += rest.splitlines()
        check(cli.returncode == 0, "CLI design exited %d: %s" % (cli.returncode, err[-2000:]))
        check_no_core_log(err, "CLI design with a killed replica")
        check(len(out) == edits + 1, "CLI design printed %d updates of %d" % (len(out), edits + 1))
        resumed_lines = [x for x in out if '"resumed":true' in x.replace(" ", "")]
        check(len(resumed_lines) == 1, "CLI updates marked resumed: %d" % len(resumed_lines))
        log("CLI design: %d updates, replica %s killed after 200, one resumed" %
            (len(out), holder.address))

        # --- The CLI again, its replica lost while the open is pending: 2 fresh replicas (they
        # load the basis from the store on open) behind a second router.
        prefix = os.path.join(work, "router2")
        os.makedirs(prefix)
        fresh = []
        for i in (3, 4):
            fresh.append(Daemon(args.daemon, store, threads=1,
                                extra=["--shared-store", "--daemon-id", "r%d" % i],
                                log=os.path.join(work, "r%d.log" % i)).start())
            replicas.append(fresh[-1])
        nginx2, router2 = start_nginx(args.nginx, prefix, [d.address for d in fresh])
        routers.append(nginx2)
        with fs.Client(router2, timeout=60) as c:
            c.basis(main_basis)
        time.sleep(0.2)
        holder = {d.address: d for d in fresh}[upstream_of_key(
            os.path.join(prefix, "access.log"), main_basis)]
        script = os.path.join(work, "short.jsonl")
        with open(script, "w") as f:
            for i in range(1, 6):
                f.write('{"add": {"id": %d, "face": %d, "vector": [1, %d, 0]}}\n' % (i, 50 * i, i))
            f.write('{"move": {"id": 2, "face": 7, "vector": [0, 0, 1]}}\n')
        design = [args.client, "--server", router2, "design", main_basis, "--script", script,
                  "--watch", "0,1,2"]
        holder.proc.send_signal(signal.SIGSTOP)
        cli = subprocess.Popen(design, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        time.sleep(1.5)  # the open reaches the stopped replica and waits there
        check(cli.poll() is None, "the CLI did not wait for the stopped replica")
        holder.proc.kill()
        holder.proc.wait(10)
        out, err = cli.communicate(timeout=120)
        check(cli.returncode == 0, "CLI design, open lost, exited %d: %s" %
              (cli.returncode, err[-2000:]))
        check_no_core_log(err, "CLI design with its open lost")
        updates = [json.loads(x) for x in out.splitlines()]
        check(len(updates) == 7, "CLI design, open lost: %d updates of 7" % len(updates))
        check(updates[0]["edit"] == "open" and updates[0].get("resumed") is True,
              "the open's update is not marked resumed: %s" % updates[0])
        check(all("resumed" not in u for u in updates[1:]), "a later edit resumed too")
        rc = subprocess.run(design, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            timeout=120)
        check(rc.returncode == 0, "CLI design on the survivor: %s" % rc.stderr[-2000:])
        reference = [json.loads(x) for x in rc.stdout.splitlines()]
        for key in ("coefficients", "watched"):
            a, b = updates[-1][key], reference[-1][key]
            check(json.dumps(a) == json.dumps(b) or
                  np.max(np.abs(np.array(_numbers(a)) - np.array(_numbers(b)))) <= 1e-10,
                  "the resumed session's %s differ from a plain run's" % key)
        log("CLI design: replica %s lost with the open pending; resumed, same result" %
            holder.address)

        client.close()
        log("PASS in %.1f s" % (time.time() - started))
        return 0
    finally:
        for nginx in routers:
            nginx.send_signal(signal.SIGQUIT)
            try:
                nginx.wait(10)
            except subprocess.TimeoutExpired:
                nginx.kill()
        for d in replicas:
            if d.alive():
                d.stop()
        if os.environ.get("FS_KEEP_WORK"):
            log("kept %s" % work)
        else:
            shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
