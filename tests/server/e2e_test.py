#!/usr/bin/env python3
"""End to end: the real fieldspaced, driven by the real fieldspace CLI and by a Python grpcio
client that learns the API through server reflection; stopped with SIGTERM, killed with SIGKILL in
the middle of a basis save, corrupted on disk, and restarted on the same store each time.

Exit 0 on success, 1 on failure, 77 (skip) only if python3-grpcio / protobuf are absent.
"""

import argparse
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from fs_testlib import Cli, Daemon, check, icosphere_obj, log, run, torus_obj  # noqa: E402

try:
    import grpc  # noqa: F401
    from fs_reflection import ReflectionClient
except ImportError as e:  # pragma: no cover
    print("SKIP: python3-grpcio / python3-protobuf not available: %s" % e)
    sys.exit(77)


def read_field_text(path):
    rows = []
    with open(path) as f:
        for line in f:
            line = line.strip()
            if line and not line.startswith("#"):
                rows.append([float(x) for x in line.split()])
    return rows


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--daemon", required=True)
    parser.add_argument("--client", required=True)
    parser.add_argument("--protoc", required=True)
    parser.add_argument("--grpc-proto-dir", required=True)
    args = parser.parse_args()

    work = tempfile.mkdtemp(prefix="fs_e2e_")
    store = os.path.join(work, "store")
    data = os.path.join(work, "data")
    os.makedirs(data)
    torus_text, torus_faces = torus_obj()
    with open(os.path.join(data, "torus.obj"), "w") as f:
        f.write(torus_text)
    ico_text, _ = icosphere_obj(2)
    with open(os.path.join(work, "ico.obj"), "w") as f:
        f.write(ico_text)
    daemons = []
    try:
        # --- 1. a fresh daemon, driven by the CLI -------------------------------------------------
        d = Daemon(args.daemon, store, data).start()
        daemons.append(d)
        cli = Cli(args.client, d.address)
        log("daemon at %s" % d.address)
        check(cli.json("health") == {"status": "SERVING"}, "health")
        # One daemon per port, one daemon per store: the second one exits at once, saying why.
        rc, _, err = run([args.daemon, "--listen", d.address, "--store",
                          os.path.join(work, "other_store")], timeout=60)
        check(rc != 0 and "address already in use" in err, "same port: rc %d, %r" % (rc, err))
        rc, _, err = run([args.daemon, "--listen", "127.0.0.1:0", "--store", store], timeout=60)
        check(rc != 0 and ("pid %d" % d.proc.pid) in err, "same store: rc %d, %r" % (rc, err))
        check(cli.json("health") == {"status": "SERVING"}, "the first daemon is unaffected")
        torus_path = os.path.join(data, "torus.obj")
        mesh = cli.json("upload", torus_path)
        check(re.fullmatch(r"m-[0-9a-f]{16}", mesh["id"]) is not None, "mesh id %s" % mesh["id"])
        check(mesh["num_faces"] == torus_faces and mesh["genus"] == 1, "torus info %s" % mesh)
        check(cli.json("upload", torus_path)["id"] == mesh["id"], "uploads are idempotent")
        check(any(m["id"] == mesh["id"] for m in cli.json("meshes")["meshes"]), "meshes lists it")
        rc, out, err = cli("build", mesh["id"], "--field", "vector", "--dim", "40")
        vector = json.loads(out)
        check(re.fullmatch(r"b-[0-9a-f]{16}", vector["id"]) is not None, "basis id")
        check(vector["state"] == "ready" and vector["mesh_id"] == mesh["id"], "basis %s" % vector)
        check("done" in err, "build progress on stderr: %r" % err[-500:])
        nfield = cli.json("build", mesh["id"], "--field", "nfield", "--n", "4", "--dim", "30")
        tensor = cli.json("build", mesh["id"], "--field", "tensor", "--dim", "30", "--sigma", "30")
        check(nfield["field"] == "nfield4" and tensor["field"] == "tensor", "field types")
        check(len(cli.json("bases")["bases"]) == 3, "three bases")
        log("built %s %s %s" % (vector["id"], nfield["id"], tensor["id"]))
        low = cli.json("build", mesh["id"], "--field", "vector", "--dim", "40",
                       "--quality", "low-modes")
        check(low["quality"] == "low-modes" and vector["quality"] == "paper", "quality %s" % low)
        check(low["id"] != vector["id"] and low["columns"] == vector["columns"],
              "a low-modes basis is another basis with as many columns")
        rc, _, err = cli("build", mesh["id"], "--field", "vector", "--dim", "39",
                         "--quality", "low-modes", expect=1)
        check("d >= 40" in err, "low-modes below d = 40: rc %d, %r" % (rc, err[-300:]))
        smooth = cli.json("build", mesh["id"], "--field", "vector", "--dim", "40",
                          "--quality", "smooth")
        check(smooth["quality"] == "smooth" and smooth["id"] not in (low["id"], vector["id"])
              and smooth["nnz"] == low["nnz"],
              "a smooth basis: low-modes' sparsity, its own id: %s" % smooth)
        rc, _, err = cli("build", mesh["id"], "--field", "vector", "--dim", "40",
                         "--quality", "smoothest", expect=2)
        check("paper, low-modes or smooth" in err, "unknown quality: rc %d, %r" % (rc, err[-300:]))

        # Project a constant ambient field.
        field_path = os.path.join(work, "const.txt")
        with open(field_path, "w") as f:
            f.write("# encoding: ambient\n" + "1 0 0\n" * torus_faces)
        projected = cli.json("project", vector["id"], field_path)
        check(len(projected["coefficients"]) == vector["columns"], "projection size")
        check(0 < projected["relative_error"] < 1, "relative error %s" % projected)

        # Solve with a soft and a hard constraint; export as text (DOF) and as PLY.
        constraints = os.path.join(work, "constraints.jsonl")
        with open(constraints, "w") as f:
            f.write('{"face": 5, "dofs": [0.5, -0.25], "hard": true}\n')
            f.write('{"face": 900, "vector": [0, 0, 1], "weight": 2.0}\n')
        solved_txt = os.path.join(work, "solved.txt")
        solved = cli.json("solve", vector["id"], "--constraints", constraints, "--mu-s", "1",
                          "--mu-b", "0.001", "--mu-c", "1", "--out", solved_txt,
                          "--encoding", "dof")
        rows = read_field_text(solved_txt)
        check(len(rows) == torus_faces, "solved field rows")
        check(abs(rows[5][0] - 0.5) < 1e-4 and abs(rows[5][1] + 0.25) < 1e-4,
              "hard constraint holds: %s" % rows[5])
        # The biharmonic forms: mixed is the default; exact (the paper's) another minimizer
        # through the same flags, hard constraint kept.
        mixed = cli.json("solve", vector["id"], "--constraints", constraints, "--mu-s", "1",
                         "--mu-b", "0.001", "--mu-c", "1", "--biharmonic", "mixed")
        check(mixed["coefficients"] == solved["coefficients"], "the default form is mixed")
        exact_txt = os.path.join(work, "exact.txt")
        exact = cli.json("solve", vector["id"], "--constraints", constraints, "--mu-s", "1",
                         "--mu-b", "0.001", "--mu-c", "1", "--out", exact_txt, "--encoding", "dof",
                         "--biharmonic", "exact")
        exact_rows = read_field_text(exact_txt)
        check(abs(exact_rows[5][0] - 0.5) < 1e-4 and abs(exact_rows[5][1] + 0.25) < 1e-4,
              "exact: hard constraint holds: %s" % exact_rows[5])
        check(max(abs(a - b) for a, b in zip(mixed["coefficients"], exact["coefficients"])) >
              1e-6, "mixed and exact forms give different minimizers")
        check(mixed["backward_error"] <= 1e-12 and exact["backward_error"] <= 1e-12 and
              mixed["iterations"] <= 2 and exact["iterations"] <= 2,
              "solve reports its convergence (refinement steps): %s %s"
              % ((mixed["backward_error"], mixed["iterations"]),
                 (exact["backward_error"], exact["iterations"])))
        rc, _, err = cli("solve", vector["id"], "--constraints", constraints, "--biharmonic",
                         "lumped", expect=2)
        check("--biharmonic" in err, "biharmonic usage error: %s" % err)
        solved_ply = os.path.join(work, "solved.ply")
        cli("solve", vector["id"], "--constraints", constraints, "--out", solved_ply)
        with open(solved_ply, "rb") as f:
            header = f.read(600).split(b"end_header")[0].decode()
        check("element face %d" % torus_faces in header and "property float vx" in header and
              "property float magnitude" in header, "PLY header: %s" % header)

        # Lift the solve's coefficients (its JSON is a coefficients file): same field.
        solve_json = os.path.join(work, "solve.json")
        with open(solve_json, "w") as f:
            json.dump(solved, f)
        lifted_txt = os.path.join(work, "lifted.txt")
        cli("lift", vector["id"], solve_json, "--out", lifted_txt, "--encoding", "dof")
        check(read_field_text(lifted_txt) == rows, "lift reproduces the solve's field")
        subset = cli.json("lift", vector["id"], solve_json, "--faces", "5,6", "--encoding", "dof")
        check([f["face"] for f in subset["faces"]] == [5, 6], "lift subset faces")
        check(all(abs(a - b) < 1e-6 for a, b in zip(subset["faces"][1]["value"], rows[6])),
              "lift subset values")

        eigen = cli.json("eigen", vector["id"], "--count", "4")
        values = eigen["eigenvalues"]
        check(len(values) == 4 and values == sorted(values), "eigenvalues %s" % values)
        # (U^T S U) is PSD: Rayleigh-Ritz values are >= 0 (up to rounding).
        check(values[0] > -1e-8 * max(1.0, values[3]), "eigenvalues >= 0: %s" % values)

        # A design session from the edit format.
        script = os.path.join(work, "edits.jsonl")
        with open(script, "w") as f:
            f.write('{"add": {"id": 1, "face": 10, "vector": [1, 0, 0], "weight": 1.0, '
                    '"hard": false}}\n')
            f.write('{"move": {"id": 1, "face": 12, "vector": [0, 1, 0]}}\n')
            f.write('{"watch": {"faces": [0, 1, 2]}}\n')
            f.write('{"add": {"id": 2, "face": 400, "vector": [0, 0, 1], "hard": true}}\n')
            f.write('{"remove": {"id": 1}}\n')
            f.write('{"weights": {"mu_s": 1.0, "mu_b": 0.001, "mu_c": 1.0}}\n')
        _, out, _ = cli("design", vector["id"], "--script", script)
        updates = [json.loads(line) for line in out.splitlines()]
        check([u["edit"] for u in updates] ==
              ["open", "add", "move", "watch", "add", "remove", "weights"], "edits %s" % updates)
        check([u["refactorized"] for u in updates] ==
              [True, False, False, False, False, False, True], "refactorized flags")
        check(len(updates[3]["watched"]) == 3 and len(updates[3]["watched"][0]["value"]) == 3,
              "watched values")
        check(updates[4]["num_hard_constraints"] == 1 and updates[5]["num_constraints"] == 1,
              "constraint counts")
        check(all(len(u["coefficients"]) == vector["columns"] for u in updates), "coefficients")
        # The same script with the exact biharmonic (the default is mixed): the same answers
        # until mu_b > 0, then another.
        _, out, _ = cli("design", vector["id"], "--script", script, "--biharmonic", "exact")
        exact_updates = [json.loads(line) for line in out.splitlines()]
        check([u["edit"] for u in exact_updates] == [u["edit"] for u in updates],
              "exact design edits")
        gap = lambda a, b: max(abs(p - q) for p, q in zip(a["coefficients"], b["coefficients"]))
        check(gap(exact_updates[5], updates[5]) < 1e-12, "mu_b = 0: the forms are one solve")
        # mu_b = 0.001 (scale-free) is light on this mesh: the forms differ by ~3e-7, not rounding.
        check(gap(exact_updates[6], updates[6]) > 1e-9, "mu_b > 0: the forms differ")

        # CLI errors: clear message, non-zero exit, no crash.
        rc, _, err = cli("mesh", "m-0000000000000000", expect=1)
        check("NOT_FOUND" in err, "not found message: %s" % err)
        rc, _, err = cli("solve", "b-0000000000000000", "--constraints", constraints, expect=1)
        check("NOT_FOUND" in err, "solve on unknown basis: %s" % err)
        rc, _, err = cli("build", mesh["id"], "--field", "vector", "--dim", "0", expect=2)
        check("--dim" in err, "usage error: %s" % err)
        bad_script = os.path.join(work, "bad.jsonl")
        with open(bad_script, "w") as f:
            f.write('{"add": {"id": 1, "face": 10}}\n')
        rc, _, err = cli("design", vector["id"], "--script", bad_script, expect=1)
        check("bad.jsonl:1" in err, "script error names the line: %s" % err)
        # A refused edit (an unknown id, a face out of range) costs only that edit: its line
        # carries the error, the script goes on, the session is as it was, the exit code is 1.
        refused_script = os.path.join(work, "refused.jsonl")
        with open(refused_script, "w") as f:
            f.write('{"add": {"id": 1, "face": 10, "vector": [1, 0, 0]}}\n')
            f.write('{"remove": {"id": 7}}\n')
            f.write('{"add": {"id": 2, "face": 99999999, "vector": [0, 1, 0]}}\n')
            f.write('{"add": {"id": 3, "face": 12, "vector": [0, 1, 0]}}\n')
        rc, out, err = cli("design", vector["id"], "--script", refused_script, expect=1)
        lines = [json.loads(line) for line in out.splitlines()]
        check([l["edit"] for l in lines] == ["open", "add", "remove", "add", "add"],
              "refused edits keep their lines: %s" % lines)
        check(lines[2]["error"]["code"] == "NOT_FOUND" and
              lines[3]["error"]["code"] == "INVALID_ARGUMENT" and "error" not in lines[4],
              "refused edits carry their codes: %s" % lines[2:])
        check(lines[4]["num_constraints"] == 2, "the session went on: %s" % lines[4])
        # The session after the refusals equals one that never saw them.
        clean_script = os.path.join(work, "clean.jsonl")
        with open(clean_script, "w") as f:
            f.write('{"add": {"id": 1, "face": 10, "vector": [1, 0, 0]}}\n')
            f.write('{"add": {"id": 3, "face": 12, "vector": [0, 1, 0]}}\n')
        _, out, _ = cli("design", vector["id"], "--script", clean_script)
        clean = [json.loads(line) for line in out.splitlines()]
        check(max(abs(p - q) for p, q in zip(clean[-1]["coefficients"], lines[4]["coefficients"]))
              < 1e-9, "refusals left the session as it was")
        check("line 2" in err and "NOT_FOUND" in err, "stderr names the refused line: %s" % err)
        rc, _, err = cli("upload", os.path.join(work, "missing.obj"), expect=1)

        # --- 2. a Python grpcio client through reflection -------------------------------------------
        rc_client = ReflectionClient(d.address, args.protoc, args.grpc_proto_dir, work)
        services = rc_client.services()
        for s in ("fieldspace.v1.FieldSpace", "grpc.health.v1.Health",
                  "grpc.reflection.v1alpha.ServerReflection",
                  "grpc.reflection.v1.ServerReflection"):
            check(s in services, "reflection lists %s: %s" % (s, services))
        rc_client.load_symbol("grpc.health.v1.Health")
        rc_client.load_symbol("fieldspace.v1.FieldSpace")
        health, HealthReq = rc_client.method("unary_unary", "grpc.health.v1.Health", "Check",
                                              "grpc.health.v1.HealthCheckRequest",
                                              "grpc.health.v1.HealthCheckResponse")
        check(health(HealthReq(service="fieldspace.v1.FieldSpace"), timeout=10).status == 1,
              "health SERVING through reflection")
        list_meshes, ListReq = rc_client.method("unary_unary", "fieldspace.v1.FieldSpace",
                                                "ListMeshes", "fieldspace.v1.ListMeshesRequest",
                                                "fieldspace.v1.ListMeshesResponse")
        check(mesh["id"] in [m.id for m in list_meshes(ListReq(), timeout=10).meshes],
              "ListMeshes via grpcio")
        lift, LiftReq = rc_client.method("unary_stream", "fieldspace.v1.FieldSpace", "Lift",
                                         "fieldspace.v1.LiftRequest", "fieldspace.v1.FieldChunk")
        chunks = list(lift(LiftReq(basis_id=vector["id"], coefficients=solved["coefficients"],
                                   faces=[5, 6]), timeout=30))
        values = [v for c in chunks for v in c.field.values]
        check(all(abs(a - b) < 1e-6 for a, b in zip(values, rows[5] + rows[6])),
              "Lift via grpcio: %s" % values)
        design, DesignReq = rc_client.method("stream_stream", "fieldspace.v1.FieldSpace", "Design",
                                             "fieldspace.v1.DesignRequest",
                                             "fieldspace.v1.DesignUpdate")
        edits = [
            DesignReq(seq=1, open={"basis_id": vector["id"],
                                   "weights": {"mu_s": 1, "mu_c": 1}, "watch_faces": [7]}),
            DesignReq(seq=2, add={"id": 1, "constraint": {"face": 7, "value": [0.3, 0.1]}}),
            DesignReq(seq=3, move={"id": 1, "face": 7, "value": [0.6, 0.2]}),
        ]
        session = list(design(iter(edits), timeout=60))
        check([u.seq for u in session] == [1, 2, 3], "design updates via grpcio")
        check(not session[2].timings.refactorized, "moves do not refactorize")
        check(abs(session[2].watched.values[0] - 2 * session[1].watched.values[0]) < 1e-6,
              "a soft constraint's response is linear in its value")
        upload, UploadReq = rc_client.method("stream_unary", "fieldspace.v1.FieldSpace",
                                             "UploadMesh", "fieldspace.v1.UploadMeshRequest",
                                             "fieldspace.v1.MeshInfo")
        ico = ico_text.encode()
        msgs = [UploadReq(header={"name": "ico.obj"}, offset=0, data=ico[:1000]),
                UploadReq(offset=1000, data=ico[1000:], last=True)]
        info = upload(iter(msgs), timeout=30)
        check(info.num_faces == 320, "upload via grpcio")
        try:
            upload(iter([msgs[0], UploadReq(offset=5, data=b"x")]), timeout=30)
            check(False, "out-of-order chunk accepted")
        except grpc.RpcError as e:
            check(e.code() == grpc.StatusCode.INVALID_ARGUMENT, "code %s" % e.code())
        get_basis, GetBasisReq = rc_client.method("unary_unary", "fieldspace.v1.FieldSpace",
                                                  "GetBasis", "fieldspace.v1.GetBasisRequest",
                                                  "fieldspace.v1.BasisInfo")
        try:
            get_basis(GetBasisReq(basis_id="nope"), timeout=10)
            check(False, "unknown basis accepted")
        except grpc.RpcError as e:
            check(e.code() == grpc.StatusCode.NOT_FOUND, "code %s" % e.code())
        rc_client.channel.close()
        log("grpcio client through reflection: ok")

        # --- 3. SIGTERM, restart on the same store --------------------------------------------------
        t0 = time.time()
        check(d.stop(signal.SIGTERM) == 0, "SIGTERM exits 0")
        log("SIGTERM: exit 0 after %.2fs" % (time.time() - t0))
        d = Daemon(args.daemon, store, data).start()
        daemons.append(d)
        cli = Cli(args.client, d.address)
        meshes = {m["id"] for m in cli.json("meshes")["meshes"]}
        check(mesh["id"] in meshes and info.id in meshes, "meshes survive a restart")
        bases = {b["id"]: b for b in cli.json("bases")["bases"]}
        check({vector["id"], nfield["id"], tensor["id"]} <= set(bases), "bases survive")
        check(bases[vector["id"]]["nnz"] == vector["nnz"], "basis intact")
        check(bases[low["id"]]["quality"] == "low-modes", "the quality level survives a restart")
        lifted_again = os.path.join(work, "lifted_again.txt")
        cli("lift", vector["id"], solve_json, "--out", lifted_again, "--encoding", "dof")
        check(open(lifted_again).read() == open(lifted_txt).read(),
              "same field from the reloaded basis")
        check(d.stop(signal.SIGTERM) == 0, "SIGTERM exits 0")

        # --- 4. SIGKILL in the middle of a basis save -----------------------------------------------
        d = Daemon(args.daemon, store, data, extra=["--debug-save-pause-ms", "5000"]).start()
        daemons.append(d)
        build = subprocess.Popen([args.client, "--server", d.address, "build", mesh["id"],
                                  "--field", "vector", "--dim", "50"],
                                 stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        bases_dir = os.path.join(store, "bases")
        temp = None
        deadline = time.time() + 120
        while temp is None and time.time() < deadline:
            for name in os.listdir(bases_dir):
                if ".tmp-" in name:
                    temp = name
            time.sleep(0.01)
        check(temp is not None, "a temporary basis file appears during the save")
        killed_id = re.match(r"\.(b-[0-9a-f]{16})\.fsbasis\.tmp-", temp).group(1)
        d.proc.send_signal(signal.SIGKILL)
        d.proc.wait(30)
        d.log.close()
        build.wait(60)
        check(build.returncode != 0, "the client of the killed build fails")
        log("SIGKILL during the save of %s" % killed_id)
        d = Daemon(args.daemon, store, data).start()
        daemons.append(d)
        cli = Cli(args.client, d.address)
        check(not any(".tmp-" in n for n in os.listdir(bases_dir)), "temporary file removed")
        ids = {b["id"] for b in cli.json("bases")["bases"]}
        check(killed_id not in ids, "the interrupted basis is absent, not half there")
        check({vector["id"], nfield["id"], tensor["id"]} <= ids, "the other bases are intact")
        cli("lift", vector["id"], solve_json, "--out", lifted_again, "--encoding", "dof")
        check(open(lifted_again).read() == open(lifted_txt).read(), "intact after SIGKILL")
        rebuilt = cli.json("build", mesh["id"], "--field", "vector", "--dim", "50")
        check(rebuilt["id"] == killed_id and rebuilt["state"] == "ready", "rebuilt after the kill")
        check(d.stop(signal.SIGTERM) == 0, "SIGTERM exits 0")

        # --- 5. a corrupt basis file: DATA_LOSS, never loaded, no crash -----------------------------
        path = os.path.join(bases_dir, tensor["id"] + ".fsbasis")
        with open(path, "r+b") as f:
            f.seek(-64, os.SEEK_END)
            byte = f.read(1)
            f.seek(-64, os.SEEK_END)
            f.write(bytes([byte[0] ^ 0xFF]))
        d = Daemon(args.daemon, store, data).start()
        daemons.append(d)
        cli = Cli(args.client, d.address)
        coeffs = os.path.join(work, "tensor_coeffs.txt")
        with open(coeffs, "w") as f:
            f.write(" ".join(["0.1"] * tensor["columns"]))
        rc, _, err = cli("lift", tensor["id"], coeffs, "--faces", "0", expect=1)
        check("DATA_LOSS" in err, "corrupt basis reported as DATA_LOSS: %s" % err)
        check(cli.json("health") == {"status": "SERVING"}, "still serving")
        cli("lift", vector["id"], solve_json, "--out", lifted_again, "--encoding", "dof")
        check(open(lifted_again).read() == open(lifted_txt).read(), "others unaffected")
        check(d.stop(signal.SIGINT) == 0, "SIGINT exits 0")
        log("PASS")
        return 0
    except Exception:
        for d in daemons:
            if d.alive():
                d.proc.kill()
        for d in daemons:
            try:
                sys.stderr.write("--- daemon log %s ---\n%s\n" %
                                 (d.log_path, open(d.log_path).read()[-4000:]))
            except OSError:
                pass
        raise
    finally:
        for d in daemons:
            if d.alive():
                d.proc.kill()
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
