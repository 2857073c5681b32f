#!/usr/bin/env python3
"""Aborted client streams commit nothing (issue 22, item 1): the real fieldspaced driven by raw
HTTP/2 frames (python3-h2) and by grpcio.

An UploadMesh that does not announce total_bytes (the API allows 0) and whose first message holds
a mesh that parses on its own (so a server that stored what it had would store a valid mesh) is
ended in each way a client can end it without finishing it:
- grpcio cancels the call mid-stream;
- an HTTP/2 RST_STREAM;
- the TCP connection closed;
- a message whose gRPC compressed flag is set on a call that negotiated no compression;
- a truncated last message followed by END_STREAM. gRPC (1.51) drops the partial message without
  telling the server, so the stream looks cleanly half-closed: with total_bytes announced the server
  refuses it as short; without, the message marked `last` never arrived, and the server refuses an
  unannounced upload that half-closes unmarked (INVALID_ARGUMENT both ways, nothing stored). A
  stream that half-closes after complete but unmarked messages is refused the same way.
After each: ListMeshes unchanged, the client saw an error, and a complete upload then works.
A Design stream whose last edit is truncated answers only the complete edits (no edit is made of a
partial message) and the session's next stream works.

Exit 0 on success, 1 on failure, 77 (skip) if python3-grpcio / numpy / python3-h2 are absent.
"""

import os
import socket
import struct
import sys
import threading
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from fs_testlib import (Daemon, check, client_test_args, daemon_workdir, icosphere_obj,  # noqa: E402
                        log)

UPLOAD = "/fieldspace.v1.FieldSpace/UploadMesh"
DESIGN = "/fieldspace.v1.FieldSpace/Design"


def grpc_frame(payload, compressed=False):
    """A gRPC length-prefixed message: flag byte, 4-byte big-endian length, payload."""
    return struct.pack(">BI", 1 if compressed else 0, len(payload)) + payload


class RawCall:
    """One gRPC call on its own HTTP/2 connection, frame by frame (python3-h2)."""

    def __init__(self, address, path):
        import h2.config
        import h2.connection

        host, port = address.rsplit(":", 1)
        self.sock = socket.create_connection((host, int(port)), timeout=30)
        self.conn = h2.connection.H2Connection(
            h2.config.H2Configuration(client_side=True, header_encoding="utf-8"))
        self.conn.initiate_connection()
        self.stream = self.conn.get_next_available_stream_id()
        self.conn.send_headers(self.stream, [
            (":method", "POST"), (":scheme", "http"), (":path", path), (":authority", address),
            ("content-type", "application/grpc"), ("te", "trailers")])
        self.flush()
        self.headers = {}
        self.data = b""
        self.ended = False
        self.reset = False

    def flush(self):
        self.sock.sendall(self.conn.data_to_send())

    def send(self, data, end_stream=False):
        self.conn.send_data(self.stream, data, end_stream=end_stream)
        self.flush()

    def rst(self):
        self.conn.reset_stream(self.stream)
        self.flush()

    def close(self):
        self.sock.close()

    def wait_end(self, timeout=60):
        """Reads until the stream ends; returns (grpc-status or None, grpc-message, data)."""
        import h2.events

        deadline = time.time() + timeout
        while not self.ended and not self.reset:
            self.sock.settimeout(max(0.1, deadline - time.time()))
            chunk = self.sock.recv(65536)
            if not chunk:
                break
            for event in self.conn.receive_data(chunk):
                if isinstance(event, (h2.events.ResponseReceived, h2.events.TrailersReceived)):
                    self.headers.update(dict(event.headers))
                elif isinstance(event, h2.events.DataReceived):
                    self.data += event.data
                    self.conn.acknowledge_received_data(event.flow_controlled_length,
                                                        event.stream_id)
                elif isinstance(event, h2.events.StreamEnded):
                    self.ended = True
                elif isinstance(event, h2.events.StreamReset):
                    self.reset = True
            self.flush()
        status = self.headers.get("grpc-status")
        return (None if status is None else int(status)), self.headers.get("grpc-message", ""), \
            self.data


def split_messages(data):
    """The payloads of gRPC length-prefixed messages."""
    out = []
    while data:
        _, n = struct.unpack(">BI", data[:5])
        out.append(data[5:5 + n])
        data = data[5 + n:]
    return out


def main():
    args, fs = client_test_args(__doc__)
    if fs is None:
        return 77
    try:
        import h2  # noqa: F401
    except ImportError as e:
        print("SKIPPED: %s (python3-h2 is needed: .ci/install-deps installs it)" % e)
        return 77
    import grpc
    from fieldspace.v1 import fieldspace_pb2 as pb

    # The mesh in two messages: the first holds the vertices and the first half of the faces, so
    # that on its own it is a valid mesh too (what a server storing a prefix would store).
    text, _ = icosphere_obj(2)
    lines = text.splitlines(keepends=True)
    first_face = next(i for i, line in enumerate(lines) if line.startswith("f "))
    cut = first_face + (len(lines) - first_face) // 2
    part1 = "".join(lines[:cut]).encode()
    part2 = "".join(lines[cut:]).encode()
    assert len(part1) + len(part2) < 60000  # within HTTP/2's initial flow-control window

    def message(offset, data, total=0, with_header=True, last=False):
        request = pb.UploadMeshRequest(offset=offset, data=data, last=last)
        if with_header:
            request.header.CopyFrom(pb.UploadMeshHeader(name="aborted.obj",
                                                        format=pb.MESH_FORMAT_OBJ,
                                                        total_bytes=total))
        return request.SerializeToString()

    m1 = grpc_frame(message(0, part1))
    m2 = grpc_frame(message(len(part1), part2, with_header=False, last=True))
    failures = []

    daemons = []
    with daemon_workdir("fs_aborted_", daemons) as (work, store, daemon_log):
        d = Daemon(args.daemon, store, log=daemon_log)
        daemons.append(d.start())
        client = fs.Client(d.address)

        def mesh_ids():
            return sorted(m.id for m in client.meshes())

        def expect_nothing_stored(what, before):
            """Records a failure if meshes were added since `before`, and deletes them (so that
            the next case starts from the same store)."""
            added = sorted(set(mesh_ids()) - set(before))
            if added:
                failures.append("%s: stored %s" % (what, added))
                for mesh_id in added:
                    client.delete_mesh(mesh_id)
            else:
                log("ok: %s: nothing stored" % what)

        # The prefix on its own is a valid mesh: a server that committed it would list it.
        prefix_only = RawCall(d.address, UPLOAD)
        prefix_only.send(grpc_frame(message(0, part1, last=True)), end_stream=True)
        status, msg, _ = prefix_only.wait_end()
        check(status == 0, "the first message alone is a valid upload: %s %s" % (status, msg))
        prefix_id = mesh_ids()
        client.delete_mesh(prefix_id[0])
        prefix_only.close()

        # The same message unmarked, then END_STREAM: nothing says the upload is whole.
        before = mesh_ids()
        call = RawCall(d.address, UPLOAD)
        call.send(m1, end_stream=True)
        status, msg, _ = call.wait_end()
        call.close()
        check(status == grpc.StatusCode.INVALID_ARGUMENT.value[0] and "marked last" in msg,
              "unannounced, unmarked half-close: grpc-status %s (%s)" % (status, msg))
        expect_nothing_stored("unannounced, unmarked half-close", before)

        for round_ in range(3):
            # grpcio cancels mid-stream (the API's own abort).
            before = mesh_ids()
            sent_first = threading.Event()

            def requests():
                yield pb.UploadMeshRequest.FromString(message(0, part1))
                sent_first.set()
                time.sleep(30)  # never gets here in time: cancelled
                yield pb.UploadMeshRequest.FromString(message(len(part1), part2, False))

            stub_call = client._stub.UploadMesh.future(requests(), timeout=60)
            sent_first.wait(10)
            time.sleep(0.3)  # the first message reaches the server
            stub_call.cancel()
            try:
                stub_call.result()
                failures.append("grpcio cancel: the call succeeded")
            except grpc.FutureCancelledError:
                pass
            except grpc.RpcError as e:
                check(e.code() != grpc.StatusCode.OK, "cancel: %s" % e)
            time.sleep(0.3)
            expect_nothing_stored("grpcio cancel %d" % round_, before)

            # RST_STREAM after the first message.
            before = mesh_ids()
            call = RawCall(d.address, UPLOAD)
            call.send(m1)
            time.sleep(0.2)
            call.rst()
            time.sleep(0.5)
            call.close()
            expect_nothing_stored("RST_STREAM %d" % round_, before)

            # TCP close after the first message.
            before = mesh_ids()
            call = RawCall(d.address, UPLOAD)
            call.send(m1)
            time.sleep(0.2)
            call.close()
            time.sleep(0.5)
            expect_nothing_stored("TCP close %d" % round_, before)

            # A last message with the compressed flag set; no grpc-encoding was negotiated.
            before = mesh_ids()
            call = RawCall(d.address, UPLOAD)
            call.send(m1)
            call.send(grpc_frame(message(len(part1), part2, with_header=False), compressed=True),
                      end_stream=True)
            status, msg, _ = call.wait_end()
            call.close()
            if status == 0:
                failures.append("compressed flag %d: answered OK" % round_)
            log("compressed flag: grpc-status %s (%s)" % (status, msg))
            expect_nothing_stored("compressed flag %d" % round_, before)

            # A truncated last message + END_STREAM, total_bytes announced: refused.
            before = mesh_ids()
            announced = grpc_frame(message(0, part1, total=len(part1) + len(part2)))
            call = RawCall(d.address, UPLOAD)
            call.send(announced)
            call.send(m2[:len(m2) // 2], end_stream=True)
            status, msg, _ = call.wait_end()
            call.close()
            if status != grpc.StatusCode.INVALID_ARGUMENT.value[0]:
                failures.append("truncated, announced %d: grpc-status %s (%s)" %
                                (round_, status, msg))
            expect_nothing_stored("truncated, announced %d" % round_, before)

            # Unannounced: the truncated message was the one marked last; gRPC drops it unseen,
            # so the server sees an unmarked half-close and refuses it.
            for cut in (len(m2) // 2, len(m2) - 1, 3):
                call = RawCall(d.address, UPLOAD)
                call.send(m1)
                call.send(m2[:cut], end_stream=True)
                status, msg, _ = call.wait_end()
                call.close()
                if status != grpc.StatusCode.INVALID_ARGUMENT.value[0]:
                    failures.append("truncated at %d, unannounced %d: grpc-status %s (%s)" %
                                    (cut, round_, status, msg))
                expect_nothing_stored("truncated at %d, unannounced %d" % (cut, round_), before)

        # The daemon serves on: a complete upload over raw frames and over grpcio.
        before = mesh_ids()
        call = RawCall(d.address, UPLOAD)
        call.send(m1)
        call.send(m2, end_stream=True)
        status, msg, data = call.wait_end()
        call.close()
        check(status == 0, "complete raw upload: %s %s" % (status, msg))
        info = pb.MeshInfo.FromString(split_messages(data)[0])
        check(info.num_faces == 320, "complete upload: %d faces" % info.num_faces)
        check(info.id in mesh_ids(), "complete upload not listed")
        path = os.path.join(work, "sphere.obj")
        with open(path, "w") as f:
            f.write(text)
        check(client.upload(path).id == info.id, "grpcio upload of the same mesh: another id")

        # Design: an open, a complete edit, then a truncated edit + END_STREAM: two answers.
        basis = client.build(info.id, "vector", 40, progress=False)
        opened = pb.DesignRequest(seq=1)
        opened.open.basis_id = basis
        add = pb.DesignRequest(seq=2)
        add.add.id = 1
        add.add.constraint.face = 0
        add.add.constraint.value.extend([1.0, 0.0])
        add2 = pb.DesignRequest(seq=3)
        add2.add.id = 2
        add2.add.constraint.face = 5
        add2.add.constraint.value.extend([0.0, 1.0])
        truncated = grpc_frame(add2.SerializeToString())
        call = RawCall(d.address, DESIGN)
        call.send(grpc_frame(opened.SerializeToString()))
        call.send(grpc_frame(add.SerializeToString()))
        call.send(truncated[:len(truncated) - 3], end_stream=True)
        status, msg, data = call.wait_end()
        call.close()
        answers = [pb.DesignUpdate.FromString(m) for m in split_messages(data)]
        check([a.seq for a in answers] == [1, 2],
              "design: answers %s (status %s %s)" % ([a.seq for a in answers], status, msg))
        check(answers[1].num_constraints == 1, "design: %d constraints after one add" %
              answers[1].num_constraints)
        log("ok: design stream with a truncated edit answered its 2 complete messages only "
            "(grpc-status %s)" % status)
        # Design reset mid-session: the daemon serves on.
        call = RawCall(d.address, DESIGN)
        call.send(grpc_frame(opened.SerializeToString()))
        time.sleep(0.3)
        call.rst()
        call.close()
        with client.design(basis) as session:
            session.add(0, [1.0, 0.0, 0.0])
            check(len(session.coefficients) == len(answers[1].coefficients), "design after reset")
        check(d.stop() == 0, "daemon did not exit 0 on SIGTERM")

        if failures:
            raise AssertionError("\n".join(failures))
    log("aborted streams: all passed")
    return 0


if __name__ == "__main__":
    sys.exit(main())
