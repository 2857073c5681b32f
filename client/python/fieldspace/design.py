"""Interactive design sessions (the Design stream) as context managers."""

import collections
import queue
import time

import grpc
import numpy as np

from . import tools
from . import wire as fld
from ._stubs import pb
from .errors import FailedPrecondition, FieldspaceError, error_for, from_rpc_error
from .types import DesignUpdate, Weights

# The Design edit that adds each kind of ConstraintGroup (the group's oneof field -> the edit).
_ADD_EDIT = {"stroke": "add_stroke", "singularity": "place_singularity",
             "align_boundary": "align_boundary", "align_features": "align_features"}

_END = object()
# How often, and after which pauses (s), a session whose stream failed with UNAVAILABLE is
# reopened before the error is raised.
_RESUME_PAUSES = (0.0, 0.1, 0.3, 0.6, 1.0, 2.0)


def _replica_lost(error):
    """Whether a failed Design stream lost its replica (so that reopening may help): UNAVAILABLE
    (the replica drained, or is unreachable), or the stream reset at the transport level, which
    is what a router does when the replica behind it dies (nginx: RST_STREAM INTERNAL_ERROR). An
    INTERNAL status sent by a server has its own message and is not retried."""
    code = error.code()
    if code == grpc.StatusCode.UNAVAILABLE:
        return True
    if code == grpc.StatusCode.UNKNOWN and not error.details():
        return True  # gRPC's own, on a channel whose server went away
    return code == grpc.StatusCode.INTERNAL and "RST_STREAM" in (error.details() or "")


def _status_code(number):
    """The grpc.StatusCode numbered `number` (an EditError's code); UNKNOWN for others."""
    for code in grpc.StatusCode:
        if code.value[0] == number:
            return code
    return grpc.StatusCode.UNKNOWN


class DesignSession:
    """One session on one basis: every edit is answered by a DesignUpdate (the solution's
    coefficients, the watched faces' values, timings), in order.

    ::

        with client.design(basis_id, (1.0, 0.0, 1.0), watch=[0, 1]) as s:
            u = s.add(10, [1, 0, 0])           # constraint id u.constraint_id (here 1)
            s.move(u.constraint_id, 12, [0, 1, 0])
            s.remove(u.constraint_id)
            s.set_weights(mu_b=0.001)          # refactorizes (mu_s or mu_b changed)
            x = s.coefficients

    Values are ambient by default ((3,) vectors or n-field directions, (3, 3) or (6,) tensors) or
    DOFs ((2,), tensors (3,)) by shape, as in Client.solve. Leaving the ``with`` block closes the
    session (an exception inside it cancels the stream). An edit the server refuses raises its
    error (InvalidArgument for a face out of range or a bad value or weight, NotFound for an
    unknown id, AlreadyExists for a duplicate id) and costs only that edit: the session stays
    open and as it was. When the stream itself fails, the session is over and further edits raise
    FailedPrecondition.

    Failover: the session sends its basis id as routing key (``x-fieldspace-key``), so that a
    router keeps it on one replica. When the stream fails because its replica died or drained
    (UNAVAILABLE, or a stream reset by the router), the edit in flight reopens the session
    (through a router: on another replica), replays the open (current weights and watch) and the
    constraints in the order they were added, sends the edit again and returns its update with
    ``resumed=True``.
    ``resumes`` counts how often that happened.
    """

    def __init__(self, client, basis, weights, watch, watch_encoding, timeout, *,
                 raw_weights=False, biharmonic=pb.BIHARMONIC_FORM_MIXED, data_term=None):
        self._client = client
        self.basis_id = basis if isinstance(basis, str) else basis.id
        self.field_type, self.mesh_id = client._basis(self.basis_id)
        self.weights = weights
        self._watch = np.zeros(0, dtype=np.int64) if watch is None else \
            np.asarray(watch, dtype=np.int64).ravel()
        self._watch_encoding = watch_encoding
        self._data_term = data_term is not None
        open_message = pb.OpenDesign(basis_id=self.basis_id,
                                     weights=weights.proto(self._data_term),
                                     watch_encoding=fld.encoding_proto(watch_encoding, "Design"),
                                     raw_weights=raw_weights, biharmonic=biharmonic)
        if data_term is not None:
            open_message.data.CopyFrom(data_term)
        open_message.watch_faces.extend(self._watch.tolist())
        self._timeout = timeout
        self._seq = 0
        self._ids = set()
        self._next_id = 1
        self._closed = False
        self.last = None
        self.resumes = 0
        # What a reopened session replays: the open (kept up to date with weights and watch) and
        # the constraints by id, in the order they were added, as the server last confirmed.
        self._open = pb.OpenDesign()
        self._constraints = collections.OrderedDict()
        self._tools = collections.OrderedDict()  # tool edits by id (see _remember_tool)
        self._start_call()
        self._send("open", pb.DesignRequest(open=open_message), None)

    def _start_call(self):
        self._requests = queue.Queue()
        self._call = self._client._stub.Design(
            iter(self._requests.get, _END), timeout=self._timeout,
            metadata=self._client._metadata_for(self.basis_id))

    # -- edits ---------------------------------------------------------------------------------

    def add(self, face, value, *, weight=None, hard=False, id=None, encoding=None):
        """Adds a constraint on ``face``; ``id`` defaults to the next unused one (the update's
        ``constraint_id``). ``weight``: soft weight (default 1); ``hard``: interpolate exactly."""
        if id is None:
            while self._next_id in self._ids:
                self._next_id += 1
            id = self._next_id
        enc, flat = fld.encode(value, self.field_type, "Design add", encoding, single=True)
        c = pb.Constraint(face=int(face), encoding=enc, hard=bool(hard))
        c.value.extend(flat[0])
        if weight is not None:
            c.weight = float(weight)
        update = self._send("add", pb.DesignRequest(add=pb.AddConstraint(id=int(id),
                                                                         constraint=c)), id)
        self._ids.add(int(id))
        return update

    def move(self, id, face, value, *, encoding=None):
        """Moves constraint ``id`` to ``face`` with a new value (keeps its weight and kind)."""
        enc, flat = fld.encode(value, self.field_type, "Design move", encoding, single=True)
        move = pb.MoveConstraint(id=int(id), face=int(face), encoding=enc)
        move.value.extend(flat[0])
        return self._send("move", pb.DesignRequest(move=move), id)

    def remove(self, id):
        update = self._send("remove", pb.DesignRequest(remove=pb.RemoveConstraint(id=int(id))),
                            id)
        self._ids.discard(int(id))
        return update

    def set_weights(self, weights=None, **kwargs):
        """New weights: a Weights / tuple / dict, or keywords (mu_s=, mu_b=, mu_c=, mu_a=)
        changing only those. Changing mu_s, mu_b or (with a data term) mu_a refactorizes."""
        new = Weights.of(weights, self.weights)._replace(**kwargs)
        update = self._send("weights",
                            pb.DesignRequest(set_weights=new.proto(self._data_term)), None)
        self.weights = new
        return update

    def watch(self, faces, encoding=fld.AMBIENT):
        """Replaces the watched faces (solves nothing)."""
        faces = np.asarray(faces, dtype=np.int64).ravel()
        message = pb.WatchFaces(encoding=fld.encoding_proto(encoding, "Design watch"))
        message.faces.extend(faces.tolist())
        return self._send("watch", pb.DesignRequest(watch=message), None, faces, encoding)

    # -- the designer's tools: one constraint group each, under one id --------------------------

    def stroke(self, points, *, hard=False, weight=None, anisotropy=None, id=None, move=False):
        """Adds ``fieldspace.tools.stroke(points, ...)`` as tool ``id`` (a new id when None);
        ``move=True`` replaces the tool ``id`` instead (one edit)."""
        return self._tool(tools.stroke(points, hard=hard, weight=weight, anisotropy=anisotropy),
                          id, move)

    def place_singularity(self, vertex, index, *, hard=False, weight=None, id=None, move=False):
        """Adds ``fieldspace.tools.singularity(vertex, index, ...)``: the field turns ``index``
        whole turns around interior ``vertex``."""
        return self._tool(tools.singularity(vertex, index, hard=hard, weight=weight), id, move)

    def align_boundary(self, mode="tangent", *, loops=None, hard=False, weight=None, id=None,
                       move=False):
        """Adds ``fieldspace.tools.align_boundary(mode, ...)``: the boundary faces along their
        boundary edges (``"tangent"``) or the edges' in-plane normals (``"normal"``)."""
        return self._tool(tools.align_boundary(mode, loops=loops, hard=hard, weight=weight), id,
                          move)

    def align_features(self, angle_degrees=60.0, *, hard=False, weight=None, id=None,
                       move=False):
        """Adds ``fieldspace.tools.align_features(angle_degrees, ...)``: the faces along edges
        sharper than ``angle_degrees`` aligned to those edges."""
        return self._tool(tools.align_features(angle_degrees, hard=hard, weight=weight), id, move)

    def _tool(self, group, id, move):
        """Sends a tool's ConstraintGroup as its add edit (or, with `move`, as the move of the
        group `id`)."""
        kind = group.WhichOneof("tool")
        if move:
            if id is None:
                raise ValueError("Design %s: move=True needs the id of the tool to replace" % kind)
            return self._send("move", pb.DesignRequest(move=pb.MoveConstraint(
                id=int(id), group=group)), id)
        if id is None:
            while self._next_id in self._ids:
                self._next_id += 1
            id = self._next_id
        message = getattr(group, kind)
        message.id = int(id)
        update = self._send(kind, pb.DesignRequest(**{_ADD_EDIT[kind]: message}), id)
        self._ids.add(int(id))
        return update

    def _remember_tool(self, kind, request):
        """Keeps the tools a reopened session replays; whether `request` was a tool's edit."""
        edit = request.WhichOneof("edit")
        if edit in _ADD_EDIT.values():
            self._tools[getattr(request, edit).id] = (kind, request)
            return True
        if edit == "move" and request.move.HasField("group"):
            tool = request.move.group.WhichOneof("tool")  # = the kind of its add
            field = _ADD_EDIT[tool]
            replay = pb.DesignRequest(**{field: getattr(request.move.group, tool)})
            getattr(replay, field).id = request.move.id
            self._tools[request.move.id] = (tool, replay)
            return True
        if edit == "remove":
            self._tools.pop(request.remove.id, None)
        return False

    @property
    def coefficients(self):
        """The current solution's d coefficients (of the last update)."""
        return self.last.coefficients

    # -- the stream ----------------------------------------------------------------------------

    def _exchange(self, kind, request):
        """Sends one request and returns the server's answer; raises grpc.RpcError as is and
        FieldspaceError(UNAVAILABLE) when the server ended the stream without an answer."""
        request.seq = self._seq
        self._seq += 1
        self._requests.put(request)
        try:
            return next(self._call)
        except StopIteration:
            raise FieldspaceError("Design %s" % kind, "the server ended the session",
                                  grpc.StatusCode.UNAVAILABLE) from None

    def _resume(self, kind, request, lost):
        """Reopens the session after `lost` (see _replica_lost), replays it and sends `request`
        again; the answer to it. Raises `lost` when every attempt failed."""
        for pause in _RESUME_PAUSES:
            time.sleep(pause)
            self._call.cancel()
            self._requests.put(_END)
            self._start_call()
            try:
                if kind != "open":
                    self._exchange("open", pb.DesignRequest(open=self._open))
                    for cid, constraint in self._constraints.items():
                        self._exchange("add", pb.DesignRequest(
                            add=pb.AddConstraint(id=cid, constraint=constraint)))
                    for tool_kind, tool in self._tools.values():
                        self._exchange(tool_kind, tool)
                message = self._exchange(kind, request)
            except grpc.RpcError as e:
                if not _replica_lost(e):
                    raise
                continue
            self.resumes += 1
            return message
        raise lost

    def _remember(self, kind, request):
        """Keeps the state a reopened session replays, once the server confirmed `request`."""
        if self._remember_tool(kind, request):
            return
        if kind == "open":
            self._open.CopyFrom(request.open)
        elif kind == "add":
            self._constraints[request.add.id] = pb.Constraint()
            self._constraints[request.add.id].CopyFrom(request.add.constraint)
        elif kind == "move":
            c = self._constraints.get(request.move.id)
            if c is not None:
                c.face = request.move.face
                c.encoding = request.move.encoding
                del c.value[:]
                c.value.extend(request.move.value)
        elif kind == "remove":
            self._constraints.pop(request.remove.id, None)
        elif kind == "weights":
            # Weights an edit leaves out keep the session's values (where the proto tracks their
            # presence; otherwise every value is sent).
            for name in ("mu_s", "mu_b", "mu_c", "mu_a"):
                try:
                    present = request.set_weights.HasField(name)
                except ValueError:
                    present = True
                if present:
                    setattr(self._open.weights, name, getattr(request.set_weights, name))
        elif kind == "watch":
            del self._open.watch_faces[:]
            self._open.watch_faces.extend(request.watch.faces)
            self._open.watch_encoding = request.watch.encoding

    def _send(self, kind, request, constraint_id, watch=None, watch_encoding=None):
        if self._closed:
            raise FailedPrecondition("Design %s" % kind, "the session is closed")
        sent = time.perf_counter()
        resumed = False
        try:
            try:
                message = self._exchange(kind, request)
            except grpc.RpcError as e:
                if not _replica_lost(e):
                    raise
                message = self._resume(kind, request, e)
                resumed = True
        except FieldspaceError:
            self._end()
            raise
        except grpc.RpcError as e:
            self._end()
            raise from_rpc_error(e, "Design %s" % kind) from None
        except BaseException:
            self.cancel()
            raise
        if message.HasField("error"):
            # The server refused this edit: the session is as it was, and stays open.
            raise error_for(_status_code(message.error.code), "Design %s" % kind,
                            message.error.message)
        round_trip_ms = 1000.0 * (time.perf_counter() - sent)
        self._remember(kind, request)
        if watch is not None:
            self._watch, self._watch_encoding = watch, watch_encoding
        timings = {"edit_ms": message.timings.edit_ms, "lift_ms": message.timings.lift_ms,
                   "total_ms": message.timings.total_ms, "round_trip_ms": round_trip_ms}
        watched_faces = np.array(message.watched.faces, dtype=np.int64)
        if len(watched_faces) == 0 and len(message.watched.values) > 0:
            watched_faces = self._watch
        watched = np.zeros((0,))
        if len(message.watched.values):
            watched = self._client._decode(
                fld.flat_floats([message.watched.values], len(message.watched.values)),
                self.field_type, self.mesh_id, self._watch_encoding, watched_faces)
        self.last = DesignUpdate(
            seq=message.seq, edit=kind, coefficients=np.array(message.coefficients),
            watched_faces=watched_faces, watched=watched,
            num_constraints=message.num_constraints,
            num_hard_constraints=message.num_hard_constraints,
            refactorized=message.timings.refactorized, timings=timings,
            constraint_id=None if constraint_id is None else int(constraint_id), resumed=resumed,
            backward_error=message.backward_error, iterations=message.iterations)
        return self.last

    def _end(self):
        self._closed = True
        self._requests.put(_END)

    def close(self):
        """Ends the session (half-closes the stream) and waits for the server's OK; raises the
        session's error otherwise. Closing twice is harmless."""
        if self._closed:
            return
        self._end()
        try:
            for _ in self._call:  # the server answers nothing more after the half-close
                pass
        except grpc.RpcError as e:
            raise from_rpc_error(e, "Design") from None

    def cancel(self):
        """Ends the session at once (cancels the stream)."""
        if not self._closed:
            self._end()
        self._call.cancel()

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb):
        if exc_type is None:
            self.close()
        else:
            self.cancel()
        return False

    def __repr__(self):
        return "DesignSession(%r, %s)" % (self.basis_id, "closed" if self._closed else "open")

