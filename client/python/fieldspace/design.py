"""Interactive design sessions (the Design stream) as context managers."""

import queue
import time

import grpc
import numpy as np

from . import wire as fld
from ._stubs import pb
from .errors import FailedPrecondition, FieldspaceError, from_rpc_error
from .types import DesignUpdate, Weights

_END = object()


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
    session (an exception inside it cancels the stream). After a failed edit the session is
    over (the server ends the stream) and further edits raise FailedPrecondition.
    """

    def __init__(self, client, basis, weights, watch, watch_encoding, timeout):
        self._client = client
        self.basis_id = basis if isinstance(basis, str) else basis.id
        self.field_type, self.mesh_id = client._basis(self.basis_id)
        self.weights = weights
        self._watch = np.zeros(0, dtype=np.int64) if watch is None else \
            np.asarray(watch, dtype=np.int64).ravel()
        self._watch_encoding = watch_encoding
        open_message = pb.OpenDesign(basis_id=self.basis_id, weights=weights.proto(),
                                     watch_encoding=fld.encoding_proto(watch_encoding, "Design"))
        open_message.watch_faces.extend(self._watch.tolist())
        self._requests = queue.Queue()
        self._call = client._stub.Design(iter(self._requests.get, _END), timeout=timeout,
                                         metadata=client._metadata)
        self._seq = 0
        self._ids = set()
        self._next_id = 1
        self._closed = False
        self.last = None
        self._send("open", pb.DesignRequest(open=open_message), None)

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
        """New weights: a Weights / tuple / dict, or keywords (mu_s=, mu_b=, mu_c=) changing only
        those. Changing mu_s or mu_b refactorizes."""
        new = Weights.of(weights, self.weights)._replace(**kwargs)
        update = self._send("weights", pb.DesignRequest(set_weights=new.proto()), None)
        self.weights = new
        return update

    def watch(self, faces, encoding=fld.AMBIENT):
        """Replaces the watched faces (solves nothing)."""
        faces = np.asarray(faces, dtype=np.int64).ravel()
        message = pb.WatchFaces(encoding=fld.encoding_proto(encoding, "Design watch"))
        message.faces.extend(faces.tolist())
        return self._send("watch", pb.DesignRequest(watch=message), None, faces, encoding)

    @property
    def coefficients(self):
        """The current solution's d coefficients (of the last update)."""
        return self.last.coefficients

    # -- the stream ----------------------------------------------------------------------------

    def _send(self, kind, request, constraint_id, watch=None, watch_encoding=None):
        if self._closed:
            raise FailedPrecondition("Design %s" % kind, "the session is closed")
        request.seq = self._seq
        self._seq += 1
        sent = time.perf_counter()
        self._requests.put(request)
        try:
            message = next(self._call)
        except StopIteration:
            self._end()
            raise FieldspaceError("Design %s" % kind, "the server ended the session",
                                  grpc.StatusCode.UNAVAILABLE) from None
        except grpc.RpcError as e:
            self._end()
            raise from_rpc_error(e, "Design %s" % kind) from None
        except BaseException:
            self.cancel()
            raise
        round_trip_ms = 1000.0 * (time.perf_counter() - sent)
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
            constraint_id=None if constraint_id is None else int(constraint_id))
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

