"""fieldspace: a Python client of fieldspaced (tangential fields on triangle meshes).

numpy arrays in and out, one call per operation::

    import fieldspace

    client = fieldspace.Client("127.0.0.1:50051")
    mesh = client.upload(V, F)                    # or client.upload("bunny.obj")
    basis = client.build(mesh.id, "vector", 300)  # progress bar on a terminal; Ctrl-C cancels
    with client.design(basis) as s:
        s.add(10, [1, 0, 0])
        field = client.lift(basis, s.coefficients)  # (F, 3)

Fields are ambient arrays by default: (F, 3) vectors, (F, n, 3) n-fields (all n directions),
(F, 3, 3) tensors; ``encoding="dof"`` gives and takes the face-frame DOFs, (F, 2) or (F, 3). The
wire protocol's own default is DOF; this package, like the ``fieldspace`` CLI, defaults to
ambient. Errors are FieldspaceError subclasses named after their gRPC code (NotFound,
InvalidArgument, ...), with ``.code`` and the message ``<what> failed: <CODE>: <message>``.
"""

from . import fields, tools, wire
from .client import DEFAULT_ADDRESS, Client
from .design import DesignSession
from .errors import (Aborted, AlreadyExists, Cancelled, DataLoss, DeadlineExceeded,
                     FailedPrecondition, FieldspaceError, Internal, InvalidArgument, NotFound,
                     OutOfRange, PermissionDenied, ResourceExhausted, Unauthenticated,
                     Unavailable, Unimplemented, Unknown)
from .wire import FieldType
from .types import (BasisInfo, BuildProgress, Curvature, DesignUpdate, Eigenfields, MeshInfo,
                    Projection, Singularities, Smoothest, Solution, Weights)

__version__ = "0.1.0"

__all__ = [
    "Client", "DEFAULT_ADDRESS", "DesignSession", "FieldType", "fields", "Weights",
    "MeshInfo", "BasisInfo", "BuildProgress", "Projection", "Solution", "Eigenfields",
    "Smoothest", "Curvature", "Singularities", "DesignUpdate",
    "FieldspaceError", "Cancelled", "Unknown", "InvalidArgument", "DeadlineExceeded", "NotFound",
    "AlreadyExists", "PermissionDenied", "ResourceExhausted", "FailedPrecondition", "Aborted",
    "OutOfRange", "Unimplemented", "Internal", "Unavailable", "DataLoss", "Unauthenticated",
]
