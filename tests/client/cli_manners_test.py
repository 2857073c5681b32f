"""The CLI's manners against a live daemon: per-command --help, errors in the README's form
(`fieldspace: <what> failed: <CODE>: <message>`; a local file: `fieldspace: cannot open FILE:
<reason>`), flags that do not apply rejected, --out's format by its extension (or a refusal before
any call), `load` below the daemon's --data-root, the default server, one overall build progress
that only goes up, and Ctrl-C during `build` (the build goes on and the CLI says how to cancel it,
with --server; --cancel-on-exit cancels it)."""

import argparse
import glob
import json
import os
import re
import select
import signal
import subprocess
import sys
import tempfile
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "server"))
from fs_testlib import Cli, Daemon, check, icosphere_obj, log, run, torus_obj  # noqa: E402


def interrupted_build(client, address, mesh_id, seed, extra=()):
    """Starts `fieldspace build`, sends SIGINT after its first progress line naming the basis;
    returns (exit code, stderr, basis id)."""
    args = [client, "--server", address, "build", mesh_id, "--field", "vector", "--dim", "1500",
            "--seed", str(seed)] + list(extra)
    proc = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    err = ""
    basis_id = None
    deadline = time.time() + 60
    while basis_id is None and time.time() < deadline:
        ready, _, _ = select.select([proc.stderr], [], [], 1.0)
        if ready:
            line = proc.stderr.readline()
            if not line:
                break
            err += line
            m = re.match(r"build (b-[0-9a-f]{16}): ", line)
            if m:
                basis_id = m.group(1)
    check(basis_id is not None, "no progress line naming the build: %r" % err)
    proc.send_signal(signal.SIGINT)
    out, rest = proc.communicate(timeout=60)
    return proc.returncode, err + rest, basis_id


def read_ply_header(path):
    """The header lines of a PLY file (up to end_header)."""
    lines = []
    with open(path, "rb") as f:
        for raw in f:
            lines.append(raw.decode("ascii", "replace").strip())
            if lines[-1] == "end_header":
                return lines
    raise AssertionError("%s: no end_header" % path)


def check_field_file(path, faces, per_face, what):
    """`path` is a field file as its extension says: text with `faces` lines of `per_face` numbers,
    or binary PLY with `faces` faces and `per_face` float face properties (+ magnitude)."""
    if path.endswith(".ply"):
        header = read_ply_header(path)
        check(header[0] == "ply" and header[1] == "format binary_little_endian 1.0",
              "%s: not binary PLY: %s" % (what, header[:2]))
        check("element face %d" % faces in header, "%s: faces: %s" % (what, header))
        names = [h.split()[-1] for h in header if h.startswith("property float")
                 and h.split()[-1] not in ("x", "y", "z")]
        check(len(names) in (per_face, per_face + 1), "%s: face properties %s" % (what, names))
    else:
        with open(path) as f:
            text = f.read()
        check(text.startswith("# fieldspace field:"), "%s: not a text field file" % what)
        rows = [line.split() for line in text.splitlines() if line and not line.startswith("#")]
        check(len(rows) == faces and all(len(r) == per_face for r in rows),
              "%s: %d rows" % (what, len(rows)))


def check_field_outputs(cli, work, mesh, basis, coefficients):
    """--out of solve, lift, smoothest, smooth, align and curvature: .txt gives text, .ply binary
    PLY, and any other extension is refused (exit 2, naming the accepted ones) before any call."""
    faces = mesh["num_faces"]
    constraints = os.path.join(work, "one.jsonl")
    with open(constraints, "w") as f:
        f.write('{"face": 3, "vector": [1, 0, 0]}\n')
    lines = cli.json("build", mesh["id"], "--field", "nfield", "--n", "2", "--dim", "20")
    target = os.path.join(work, "target.txt")
    cli("lift", basis["id"], coefficients, "--out", target)
    runs = {
        "solve": (["solve", basis["id"], "--constraints", constraints], 3),
        "lift": (["lift", basis["id"], coefficients], 3),
        "smoothest": (["smoothest", basis["id"]], 3),
        "smooth": (["smooth", basis["id"], target], 3),
        "align": (["align", lines["id"], "--curvature"], 3),
        "curvature": (["curvature", mesh["id"]], 6),
    }
    for name, (command, per_face) in runs.items():
        for ext in (".txt", ".ply"):
            path = os.path.join(work, "%s_out%s" % (name, ext))
            cli(*command, "--out", path)
            check_field_file(path, faces, per_face, "%s --out %s" % (name, ext))
        for ext in (".vtu", ".vtk", ".rawfield", ".obj", ".png", ".json", ""):
            path = os.path.join(work, "%s_refused%s" % (name, ext))
            rc, out, err = cli(*command, "--out", path, expect=2)
            check(err.startswith("fieldspace: %s failed: INVALID_ARGUMENT: --out %s: a field "
                                 "file is .txt" % (name, path)) and ".ply" in err,
                  "%s --out %s: %r" % (name, ext, err))
            check(out == "" and not glob.glob(path + "*"), "%s --out %s wrote something" %
                  (name, ext))
        # For the formats `export` writes, the refusal says how.
        _, _, err = cli(*command, "--out", os.path.join(work, "x.vtu"), expect=2)
        check("fieldspace export" in err, "%s --out x.vtu: no hint: %r" % (name, err))
    log("--out: .txt and .ply for all 6 commands, 7 other extensions refused")


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--daemon", required=True)
    parser.add_argument("--client", required=True)
    args = parser.parse_args()

    # --help per command needs no server.
    rc, out, err = run([args.client, "build", "--help"], timeout=30)
    check(rc == 0 and "--cancel-on-exit" in out and "build MESH_ID" in out, "build --help: %r" % out)
    check("upload MESH" not in out and "design BASIS_ID" not in out,
          "build --help shows only build: %r" % out)
    rc, out, _ = run([args.client, "smooth", "-h"], timeout=30)
    check(rc == 0 and "smooth BASIS_ID FIELD_FILE" in out and "--mu-s" in out, "smooth -h: %r" % out)
    # Every flag a command's usage shows is one it parses, and the other way round: the usage is
    # made from the same table. `--help` lists every command; each one's flags parse.
    rc, _, err = run([args.client, "--help"], timeout=30)
    check(rc == 0 and "  load PATH" in err and "127.0.0.1:50051" in err, "--help: %r" % err)
    rc, out, _ = run([args.client, "design", "--help"], timeout=30)
    design_flags = re.findall(r"\[?--([a-z-]+)", out.split("\n\n")[1])
    check({"script", "align-curvature", "data", "face-weights", "mu-a", "estimator"} <=
          set(design_flags), "design --help: %r" % out)
    for flag in design_flags:
        rc, _, err = run([args.client, "--server", "127.0.0.1:1", "design", "b-0", "--" + flag,
                          "x", "--script", "/nonexistent.jsonl"], timeout=30)
        check("unknown flag" not in err, "design --help shows --%s, which it refuses" % flag)

    with tempfile.TemporaryDirectory() as work:
        d = Daemon(args.daemon, os.path.join(work, "store"), data_root=work).start()
        try:
            cli = Cli(args.client, d.address)
            torus = os.path.join(work, "torus.obj")
            with open(torus, "w") as f:
                f.write(torus_obj(major=192, minor=96)[0])  # 36,864 faces
            mesh = cli.json("upload", torus)

            # Usage errors name the command in the README's form, exit 2, then its usage.
            rc, _, err = cli("build", mesh["id"], "--field", "vector", "--n", "4", "--dim", "10",
                             expect=2)
            check(err.startswith("fieldspace: build failed: INVALID_ARGUMENT: --n applies only to "
                                 "--field nfield"), "--n on a vector build: %r" % err)
            check("build MESH_ID" in err and "upload MESH" not in err, "build usage after it")
            # Local failures read as such: "fieldspace: cannot open FILE: <reason>", no code.
            missing = os.path.join(work, "missing.txt")
            rc, _, err = cli("project", "b-0000000000000000", missing, expect=1)
            check(err == "fieldspace: cannot open %s: No such file or directory\n" % missing,
                  "local failure form: %r" % err)
            rc, _, err = cli("upload", os.path.join(work, "missing.obj"), expect=1)
            check(err == "fieldspace: cannot open %s: No such file or directory\n" %
                  os.path.join(work, "missing.obj"), "upload of a missing file: %r" % err)
            rc, _, err = cli("mesh", "m-0000000000000000", expect=1)
            check(err.startswith("fieldspace: GetMesh failed: NOT_FOUND: "), "RPC failure: %r" % err)

            # upload --format: a mesh file whose name does not say its format.
            unnamed = os.path.join(work, "torus.mesh")
            with open(torus) as src, open(unnamed, "w") as dst:
                dst.write(src.read())
            rc, _, err = cli("upload", unnamed, expect=1)
            check("extension" in err, "upload of an unnamed format: %r" % err)
            check(cli.json("upload", unnamed, "--format", "obj")["id"] == mesh["id"],
                  "upload --format obj gives the same mesh")
            cli("upload", unnamed, "--format", "stl", expect=2)

            # load: a file below the daemon's --data-root, the same mesh as its upload.
            check(cli.json("load", "torus.obj")["id"] == mesh["id"], "load of the uploaded file")
            os.makedirs(os.path.join(work, "sub"))
            with open(os.path.join(work, "sub", "ico.obj"), "w") as f:
                f.write(icosphere_obj(1)[0])
            loaded = cli.json("load", "sub/ico.obj", "--name", "ico")
            check(loaded["num_faces"] == 80 and loaded["name"] == "ico", "load: %s" % loaded)
            rc, _, err = cli("load", "../outside.obj", expect=1)
            check(err.startswith("fieldspace: LoadMesh failed: "), "load outside the root: %r" % err)
            rc, _, err = cli("load", "nothing.obj", expect=1)
            check("LoadMesh failed: NOT_FOUND" in err, "load of a missing file: %r" % err)

            # No --server and no $FIELDSPACE_SERVER: 127.0.0.1:50051, as the Python package.
            env = {k: v for k, v in os.environ.items() if k != "FIELDSPACE_SERVER"}
            p = subprocess.run([args.client, "--timeout", "5", "health"], env=env, text=True,
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, timeout=60)
            check(p.returncode == 0 or (p.returncode == 1 and "127.0.0.1:50051" in p.stderr),
                  "no --server: rc %d %r" % (p.returncode, p.stderr))

            # build --face-weights FILE: an adaptive basis (its own id); a wrong count is refused.
            small = cli.json("build", mesh["id"], "--field", "vector", "--dim", "40")
            weights_path = os.path.join(work, "weights.txt")
            with open(weights_path, "w") as f:
                f.write("\n".join("4" if i % 96 < 24 else "1" for i in range(mesh["num_faces"])))
            adaptive = cli.json("build", mesh["id"], "--field", "vector", "--dim", "40",
                                "--face-weights", weights_path)
            check(adaptive["id"] != small["id"] and adaptive["adaptive"] is True,
                  "adaptive basis %s" % adaptive)
            with open(weights_path, "w") as f:
                f.write("1 2 3")
            rc, _, err = cli("build", mesh["id"], "--field", "vector", "--dim", "40",
                             "--face-weights", weights_path, expect=1)
            check("INVALID_ARGUMENT" in err and "face_weights" in err, "weights count: %r" % err)

            # lift --mode K: one eigenfield of `eigen --coefficients`, the same as its numbers.
            eigen_path = os.path.join(work, "eigen.json")
            rc, out, _ = cli("eigen", small["id"], "--count", "3", "--coefficients")
            with open(eigen_path, "w") as f:
                f.write(out)
            mode2 = os.path.join(work, "mode2.json")
            with open(mode2, "w") as f:
                json.dump(json.loads(out)["coefficients"][2], f)
            by_mode = cli.json("lift", small["id"], eigen_path, "--mode", "2", "--faces", "0,7,99")
            by_numbers = cli.json("lift", small["id"], mode2, "--faces", "0,7,99")
            check(by_mode == by_numbers and len(by_mode["faces"]) == 3,
                  "lift --mode 2: %s vs %s" % (by_mode, by_numbers))
            rc, _, err = cli("lift", small["id"], eigen_path, "--faces", "0", expect=1)
            check("pick one with --mode" in err, "eigen file without --mode: %r" % err)
            rc, _, err = cli("lift", small["id"], eigen_path, "--mode", "3", "--faces", "0",
                             expect=1)
            check("out of range" in err, "--mode out of range: %r" % err)

            check_field_outputs(cli, work, mesh, small, mode2)

            # export / render: the Python package's tools, run by the CLI with the server's
            # geometry for a mesh id. The .vtu is read back by VTK's own reader.
            lifted = os.path.join(work, "lifted.txt")
            cli("lift", small["id"], mode2, "--out", lifted)
            vtu = os.path.join(work, "field.vtu")
            rc, _, err = cli("export", mesh["id"], lifted, "--out", vtu, expect=None)
            try:
                import vtk  # noqa: F401
                have_vtk = True
            except ImportError:
                have_vtk = False
            if have_vtk:
                check(rc == 0, "fieldspace export: %r" % err)
                from vtkmodules.util.numpy_support import vtk_to_numpy
                reader = vtk.vtkXMLUnstructuredGridReader()
                reader.SetFileName(vtu)
                reader.Update()
                grid = reader.GetOutput()
                check(grid.GetNumberOfCells() == mesh["num_faces"], "vtu cells")
                vectors = vtk_to_numpy(grid.GetCellData().GetArray("field"))
                rows = [[float(x) for x in line.split()] for line in open(lifted)
                        if line.strip() and not line.startswith("#")]
                worst = max(abs(a - b) for r, v in zip(rows, vectors) for a, b in zip(r, v))
                check(worst < 1e-5, "vtu values differ from the lifted field by %g" % worst)
                png = os.path.join(work, "field.png")
                rc, out, err = cli("render", mesh["id"], lifted, "--out", png, "--size",
                                   "160x120", expect=None)
                check(rc == 0 and os.path.getsize(png) > 1000, "fieldspace render: %r" % err)
                log("export and render through the CLI: ok")
            # render writes PNG or JPEG by extension; another extension is refused before anything
            # runs.
            jpg = os.path.join(work, "field.jpg")
            rc, _, err = cli("render", mesh["id"], lifted, "--out", jpg, "--size", "160x120",
                             expect=None)
            check(rc == 0 and open(jpg, "rb").read(3) == b"\xff\xd8\xff",
                  "render .jpg writes JPEG: %r" % err)
            gif = os.path.join(work, "field.gif")
            rc, _, err = cli("render", mesh["id"], lifted, "--out", gif, expect=2)
            check("render writes PNG" in err and not os.path.exists(gif), "render .gif: %r" % err)
            rc, _, err = cli("export", "m-0000000000000000", lifted, "--out", vtu, expect=None)
            check(rc == 1 and "NOT_FOUND" in err, "export of an unknown mesh: %r" % err)

            # Non-TTY progress: plain lines whose overall percentage never goes down.
            rc, out, err = cli("build", mesh["id"], "--field", "vector", "--dim", "300")
            percents = [int(p) for p in re.findall(r"^build b-[0-9a-f]{16}: \w+ (\d+)%", err,
                                                   re.MULTILINE)]
            check(len(percents) >= 3 and percents[-1] == 100, "progress lines: %r" % err[-800:])
            check(all(a <= b for a, b in zip(percents, percents[1:])),
                  "overall progress goes down: %s" % percents)

            # Ctrl-C: the build goes on on the server, and the CLI prints how to cancel it.
            rc, err, basis_id = interrupted_build(args.client, d.address, mesh["id"], seed=11)
            check(rc == 130, "Ctrl-C exit code %d: %r" % (rc, err[-500:]))
            check(("goes on on the server; cancel it with: fieldspace --server %s cancel %s" %
                   (d.address, basis_id)) in err, "Ctrl-C message: %r" % err[-500:])
            info = cli.json("basis", basis_id)
            check(info["state"] in ("building", "ready"), "the build went on: %s" % info["state"])
            rc, _, _ = cli("cancel", basis_id, expect=None)
            log("Ctrl-C left %s %s" % (basis_id, info["state"]))

            # --cancel-on-exit: Ctrl-C cancels the build on the server. Low-modes, ~1.5 s of
            # build here (the paper's 0.6 s is close to what a loaded machine takes to signal).
            rc, err, basis_id = interrupted_build(args.client, d.address, mesh["id"], seed=12,
                                                  extra=["--cancel-on-exit", "--quality",
                                                         "low-modes"])
            check(rc == 130 and ("build %s cancelled on the server" % basis_id) in err,
                  "--cancel-on-exit: rc %d %r" % (rc, err[-500:]))
            gone = False
            for _ in range(100):
                rc, out, err = cli("basis", basis_id, expect=None)
                if rc != 0 and "NOT_FOUND" in err:
                    gone = True
                    break
                time.sleep(0.1)
            check(gone, "the cancelled build is gone: %r %r" % (out, err))
            check(basis_id not in [b["id"] for b in cli.json("bases")["bases"]],
                  "bases no longer lists the cancelled build")
        finally:
            d.stop()
    log("cli manners: ok")


if __name__ == "__main__":
    main()
