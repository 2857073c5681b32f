"""The gRPC modules generated from proto/ by the CMake build (never checked in).

The build writes them into the package's copy in the build tree (build/python/fieldspace/v1/ and
build/python/fieldspace/_gen/), and `cmake --install` installs that copy, so they always sit next
to this file. The package's sources in client/python/ have no generated modules and cannot be
imported from there.
"""

import os

try:
    from .v1 import fieldspace_pb2 as pb  # noqa: F401
    from .v1 import fieldspace_pb2_grpc as pb_grpc  # noqa: F401
    from ._gen.grpc.health.v1 import health_pb2  # noqa: F401
except ImportError as e:
    if getattr(e, "name", None) in ("grpc", "google", "google.protobuf"):
        raise
    raise ImportError(
        "fieldspace: the generated gRPC modules are missing next to %s (v1/fieldspace_pb2.py). "
        "They are made by the CMake build: put the build tree's python/ folder on PYTHONPATH "
        "(e.g. build/python, not client/python) or install the package with "
        "`cmake --install build --prefix P` (see README.md, Python)."
        % os.path.dirname(os.path.abspath(__file__))) from e
