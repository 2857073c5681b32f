"""Typed exceptions: one class per gRPC status code, all deriving from FieldspaceError.

Every failed call raises the subclass of its status code, with the message
``<what> failed: <CODE>: <server message>`` (the form the ``fieldspace`` CLI prints). Checks the
client makes before sending anything (array shapes, unknown names) raise the same classes
(mostly InvalidArgument) in the same form.
"""

import grpc

__all__ = [
    "FieldspaceError", "Cancelled", "Unknown", "InvalidArgument", "DeadlineExceeded", "NotFound",
    "AlreadyExists", "PermissionDenied", "ResourceExhausted", "FailedPrecondition", "Aborted",
    "OutOfRange", "Unimplemented", "Internal", "Unavailable", "DataLoss", "Unauthenticated",
    "error_for",
]


class FieldspaceError(Exception):
    """A failed fieldspace call.

    Attributes:
        code: the grpc.StatusCode.
        details: the server's (or the client check's) message.
        what: the operation that failed, e.g. ``"Solve"`` or ``"upload of mesh.obj"``.
    """

    code = grpc.StatusCode.UNKNOWN

    def __init__(self, what, details, code=None):
        if code is not None:
            self.code = code
        self.what = what
        self.details = details
        super().__init__("%s failed: %s: %s" % (what, self.code.name, details))


class Cancelled(FieldspaceError):
    code = grpc.StatusCode.CANCELLED


class Unknown(FieldspaceError):
    code = grpc.StatusCode.UNKNOWN


class InvalidArgument(FieldspaceError, ValueError):
    code = grpc.StatusCode.INVALID_ARGUMENT


class DeadlineExceeded(FieldspaceError, TimeoutError):
    code = grpc.StatusCode.DEADLINE_EXCEEDED


class NotFound(FieldspaceError, LookupError):
    code = grpc.StatusCode.NOT_FOUND


class AlreadyExists(FieldspaceError):
    code = grpc.StatusCode.ALREADY_EXISTS


class PermissionDenied(FieldspaceError):
    code = grpc.StatusCode.PERMISSION_DENIED


class ResourceExhausted(FieldspaceError):
    code = grpc.StatusCode.RESOURCE_EXHAUSTED


class FailedPrecondition(FieldspaceError):
    code = grpc.StatusCode.FAILED_PRECONDITION


class Aborted(FieldspaceError):
    code = grpc.StatusCode.ABORTED


class OutOfRange(FieldspaceError):
    code = grpc.StatusCode.OUT_OF_RANGE


class Unimplemented(FieldspaceError):
    code = grpc.StatusCode.UNIMPLEMENTED


class Internal(FieldspaceError):
    code = grpc.StatusCode.INTERNAL


class Unavailable(FieldspaceError):
    code = grpc.StatusCode.UNAVAILABLE


class DataLoss(FieldspaceError):
    code = grpc.StatusCode.DATA_LOSS


class Unauthenticated(FieldspaceError):
    code = grpc.StatusCode.UNAUTHENTICATED


_BY_CODE = {cls.code: cls for cls in (
    Cancelled, Unknown, InvalidArgument, DeadlineExceeded, NotFound, AlreadyExists,
    PermissionDenied, ResourceExhausted, FailedPrecondition, Aborted, OutOfRange, Unimplemented,
    Internal, Unavailable, DataLoss, Unauthenticated)}


def error_for(code, what, details):
    """The exception for a status code (FieldspaceError itself for codes without a class)."""
    cls = _BY_CODE.get(code)
    if cls is None:
        return FieldspaceError(what, details, code)
    return cls(what, details)


def from_rpc_error(error, what):
    """The typed exception for a grpc.RpcError raised by a call (or a stream) named `what`."""
    code = error.code() if hasattr(error, "code") else grpc.StatusCode.UNKNOWN
    details = error.details() if hasattr(error, "details") else str(error)
    if code is None:
        code = grpc.StatusCode.UNKNOWN
    exc = error_for(code, what, details or "")
    exc.rpc_error = error
    return exc
