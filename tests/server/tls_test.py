#!/usr/bin/env python3
"""TLS in the daemon (issue 15): certificates made here by deploy/make-certs.sh (the openssl CLI):
a CA with a server certificate for localhost / 127.0.0.1 and a client certificate, and a second
such set whose CA nobody trusts.

- fieldspaced --tls-cert --tls-key: the Python package with tls_ca lists meshes and checks health;
  a plaintext client and a client trusting the other CA get UNAVAILABLE; the CLI with --tls-ca
  uploads, lists and checks health; the CLI in plaintext is told to pass --tls-ca; no gRPC
  C-core log line (`E1127 12:00:00.000 ... ssl_transport_security.cc ...`) reaches the CLI's
  stderr; reflection works over TLS; with --auth-token-file on top, a
  call without the token is UNAUTHENTICATED and one with it succeeds;
- --tls-client-ca (mutual TLS): a client without a certificate gets UNAVAILABLE, one with a
  certificate of the other CA too, one with a certificate of the CA succeeds (CLI and Python);
- bad TLS options (missing file, key without certificate, key of another certificate, a file that
  holds no PEM, a client CA without a certificate) make the daemon exit 2 before listening, with
  a message naming the flag and the file.

Exit 77 (skipped) without python3-grpcio or the openssl CLI (.ci/install-deps installs both).
"""

import argparse
import os
import re
import shutil
import sys
import tempfile

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from fs_testlib import Cli, Daemon, check, icosphere_obj, kill_all, log, run  # noqa: E402

# The form of gRPC C-core's log lines (severity letter, MMDD, time): never on the CLI's stderr.
CORE_LOG_LINE = re.compile(r"^[EWID]\d{4} ", re.MULTILINE)


def cli_failure(cli, *args):
    """Runs the CLI, which must fail with exit 1 and UNAVAILABLE, and no C-core log line."""
    _, _, err = cli(*args, expect=1, timeout=60)
    check("UNAVAILABLE" in err, "CLI %s: %s" % (" ".join(args), err))
    check(not CORE_LOG_LINE.search(err), "CLI %s: a gRPC log line on stderr: %s" %
          (" ".join(args), err))
    return err


def make_certs(script, folder):
    """deploy/make-certs.sh into `folder`: {"ca": (cert, key), "server": ..., "client": ...}."""
    run(["sh", script, folder], timeout=60, check=0)
    path = lambda name: os.path.join(folder, name)  # noqa: E731
    return {"ca": (path("ca.crt"), path("ca.key")), "server": (path("tls.crt"), path("tls.key")),
            "client": (path("client.crt"), path("client.key"))}


def expect_code(fs, code, what, call):
    """`call()` must raise the FieldspaceError of grpc status `code`."""
    try:
        call()
    except fs.FieldspaceError as e:
        check(e.code == code, "%s: %s expected, got %s (%s)" % (what, code, e.code, e))
        return
    raise AssertionError("%s: succeeded, %s expected" % (what, code))


def check_bad_options(daemon, work, store, server, other_server_key, ca):
    not_pem = os.path.join(work, "not.pem")
    with open(not_pem, "w") as f:
        f.write("not a certificate\n")
    missing = os.path.join(work, "missing.pem")
    cases = [
        (["--tls-cert", missing, "--tls-key", server[1]], ["--tls-cert", missing]),
        (["--tls-cert", server[0], "--tls-key", missing], ["--tls-key", missing]),
        (["--tls-key", server[1]], ["--tls-key", server[1], "needs --tls-cert"]),
        (["--tls-cert", server[0]], ["--tls-cert", server[0], "needs --tls-key"]),
        (["--tls-cert", server[0], "--tls-key", other_server_key],
         ["--tls-key", other_server_key, "is not the key of --tls-cert", server[0]]),
        (["--tls-cert", not_pem, "--tls-key", server[1]], ["--tls-cert", not_pem, "no PEM"]),
        (["--tls-cert", server[0], "--tls-key", server[0]], ["--tls-key", server[0], "no PEM"]),
        (["--tls-cert", server[0], "--tls-key", server[1], "--tls-client-ca", not_pem],
         ["--tls-client-ca", not_pem, "no PEM"]),
        (["--tls-client-ca", ca[0]], ["--tls-client-ca needs --tls-cert"]),
    ]
    for extra, words in cases:
        rc, out, err = run([daemon, "--listen", "127.0.0.1:0", "--store", store] + extra,
                           timeout=30)
        check(rc == 2, "%s: exit %d, expected 2 (stderr: %s)" % (extra, rc, err))
        check("listening on" not in out, "%s: listened before failing: %s" % (extra, out))
        for word in words:
            check(word in err, "%s: the message %r does not name %r" % (extra, err, word))
    log("bad TLS options: %d cases exit 2 before listening, naming the flag and file" %
        len(cases))


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--daemon", required=True)
    parser.add_argument("--client", required=True, help="the fieldspace CLI")
    parser.add_argument("--python-dir", required=True, help="the build tree's python/ folder")
    parser.add_argument("--protoc", required=True)
    parser.add_argument("--grpc-proto-dir", required=True)
    parser.add_argument("--make-certs", required=True, help="deploy/make-certs.sh")
    args = parser.parse_args()
    try:
        import grpc
        from fs_reflection import ReflectionClient
        missing = None if shutil.which("openssl") else "the openssl CLI"
    except ImportError as e:
        missing = "%s (python3-grpcio, python3-protobuf)" % e
    if missing:
        print("SKIPPED: %s is missing; .ci/install-deps installs it" % missing)
        return 77
    sys.path.insert(0, args.python_dir)
    import fieldspace as fs

    work = tempfile.mkdtemp(prefix="fs_tls_")
    store = os.path.join(work, "store")
    daemons = []
    try:
        ours = make_certs(args.make_certs, os.path.join(work, "ours"))
        theirs = make_certs(args.make_certs, os.path.join(work, "theirs"))
        ca, server, client_cert = ours["ca"], ours["server"], ours["client"]
        other_ca, stranger = theirs["ca"], theirs["client"]
        other_server_key = theirs["server"][1]
        mesh = os.path.join(work, "sphere.obj")
        with open(mesh, "w") as f:
            f.write(icosphere_obj(2)[0])
        token = os.path.join(work, "token")
        with open(token, "w") as f:
            f.write("tls-test-token\n")

        check_bad_options(args.daemon, work, store, server, other_server_key, ca)

        # Server TLS with a token on top.
        d = Daemon(args.daemon, store, extra=["--tls-cert", server[0], "--tls-key", server[1],
                                               "--auth-token-file", token]).start()
        daemons.append(d)
        # The certificate names localhost and 127.0.0.1: the address as the daemon printed it.
        with fs.Client(d.address, token="tls-test-token", tls_ca=ca[0], timeout=30) as c:
            check(c.health() == "SERVING", "health over TLS")
            check(c.meshes() == [], "an empty store lists no mesh")
        with open(ca[0], "rb") as f:
            ca_bytes = f.read()
        with fs.Client("localhost:%d" % d.port, token="tls-test-token", tls_ca=ca_bytes,
                       timeout=30) as c:
            check(c.meshes() == [], "TLS by host name, the CA given as bytes")
        with fs.Client(d.address, tls_ca=ca[0], timeout=30) as c:
            expect_code(fs, grpc.StatusCode.UNAUTHENTICATED, "TLS without the token", c.meshes)
        with fs.Client(d.address, token="tls-test-token", timeout=10) as c:
            expect_code(fs, grpc.StatusCode.UNAVAILABLE, "plaintext client", c.meshes)
        with fs.Client(d.address, token="tls-test-token", tls_ca=other_ca[0], timeout=10) as c:
            expect_code(fs, grpc.StatusCode.UNAVAILABLE, "client trusting another CA", c.meshes)
        log("server TLS: the CA's client works (token still required), plaintext and other-CA "
            "clients get UNAVAILABLE")

        cli = Cli(args.client, d.address)
        tls_cli = ["--tls-ca", ca[0], "--token", token]
        check(cli.json(*tls_cli, "health")["status"] == "SERVING", "CLI health over TLS")
        uploaded = cli.json(*tls_cli, "upload", mesh)
        listed = cli.json(*tls_cli, "meshes")
        check(uploaded["id"] in str(listed), "CLI meshes over TLS lists the upload: %s" % listed)
        err = cli_failure(cli, "--token", token, "meshes")
        check("pass --tls-ca FILE" in err, "CLI in plaintext: no hint: %s" % err)
        err = cli_failure(cli, "--tls-ca", other_ca[0], "--token", token, "meshes")
        check("--tls-ca FILE" not in err, "CLI over TLS given the plaintext hint: %s" % err)
        _, _, err = cli("--tls-ca", os.path.join(work, "missing.pem"), "health", expect=2)
        check("missing.pem" in err, "CLI with a missing CA file names it: %s" % err)
        # --tls-server-name replaces the address's host in the certificate check.
        check(cli.json("--tls-ca", ca[0], "--tls-server-name", "localhost", "health")["status"]
              == "SERVING", "CLI with --tls-server-name localhost")
        cli_failure(cli, "--tls-ca", ca[0], "--tls-server-name", "elsewhere.example", "health")
        # export runs the Python package, which gets the --tls-* options passed on.
        vtu = os.path.join(work, "sphere.vtu")
        cli(*tls_cli, "export", uploaded["id"], "--out", vtu, timeout=120)
        check(os.path.getsize(vtu) > 0, "CLI export of a server mesh over TLS")
        log("CLI over TLS: health, upload, meshes, export; plaintext and other CA fail")

        reflection = ReflectionClient(d.address, args.protoc, args.grpc_proto_dir, work,
                                      credentials=grpc.ssl_channel_credentials(ca_bytes))
        services = reflection.services()
        check("fieldspace.v1.FieldSpace" in services and "grpc.health.v1.Health" in services,
              "reflection over TLS lists the services: %s" % services)
        log("reflection over TLS: %s" % ", ".join(sorted(services)))
        check(d.stop() == 0, "TLS daemon drains and exits 0")
        daemons.remove(d)

        # Mutual TLS.
        d = Daemon(args.daemon, store, extra=["--tls-cert", server[0], "--tls-key", server[1],
                                               "--tls-client-ca", ca[0]]).start()
        daemons.append(d)
        with fs.Client(d.address, tls_ca=ca[0], tls_cert=client_cert[0], tls_key=client_cert[1],
                       timeout=30) as c:
            check(c.health() == "SERVING", "mTLS health with the CA's client certificate")
            check([m.id for m in c.meshes()] == [uploaded["id"]], "mTLS lists the mesh")
        with fs.Client(d.address, tls_ca=ca[0], timeout=10) as c:
            expect_code(fs, grpc.StatusCode.UNAVAILABLE, "mTLS without a client certificate",
                        c.meshes)
        with fs.Client(d.address, tls_ca=ca[0], tls_cert=stranger[0], tls_key=stranger[1],
                       timeout=10) as c:
            expect_code(fs, grpc.StatusCode.UNAVAILABLE, "mTLS with another CA's certificate",
                        c.meshes)
        cli = Cli(args.client, d.address)
        listed = cli.json("--tls-ca", ca[0], "--tls-cert", client_cert[0], "--tls-key",
                          client_cert[1], "meshes")
        check(uploaded["id"] in str(listed), "CLI over mTLS: %s" % listed)
        cli_failure(cli, "--tls-ca", ca[0], "meshes")
        _, _, err = cli("--tls-ca", ca[0], "--tls-cert", client_cert[0], "meshes", expect=2)
        check("--tls-key" in err, "CLI with a certificate but no key: %s" % err)
        log("mutual TLS: the CA's client certificate works (CLI, Python); none or another CA's: "
            "UNAVAILABLE")
        check(d.stop() == 0, "mTLS daemon drains and exits 0")
        daemons.remove(d)
        log("PASS")
        return 0
    finally:
        kill_all(daemons)
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
