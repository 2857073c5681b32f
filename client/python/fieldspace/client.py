"""The fieldspace client: one method per RPC of fieldspace.v1.FieldSpace, numpy in and out."""

import os
import sys
import threading

import grpc
import numpy as np

from . import fields
from . import wire as fld
from ._stubs import health_pb2, pb, pb_grpc
from .errors import FieldspaceError, InvalidArgument, NotFound, from_rpc_error
from .progress import BuildBar
from .types import (BasisInfo, BuildProgress, Curvature, Eigenfields, MeshInfo, Projection,
                    Singularities, Smoothest, Solution, Weights, phase_name)

__all__ = ["Client", "DEFAULT_ADDRESS", "ROUTING_KEY_HEADER", "routing_key"]

DEFAULT_ADDRESS = "127.0.0.1:50051"
_DEFAULT = object()  # "the client's default timeout"
_FORMATS = {".obj": pb.MESH_FORMAT_OBJ, ".off": pb.MESH_FORMAT_OFF, ".ply": pb.MESH_FORMAT_PLY}
_ESTIMATORS = {"jet": pb.CURVATURE_ESTIMATOR_JET,
               "normal-differences": pb.CURVATURE_ESTIMATOR_NORMAL_DIFFERENCES}
_SOLVE_WEIGHTS = Weights(1.0, 0.0, 1.0)   # solve and design, as the CLI
_SMOOTH_WEIGHTS = Weights(0.001, 0.0, 1.0)  # smooth and align, as the CLI
_DATA_TERM_WEIGHTS = Weights(0.001, 0.0, 1.0, 1.0)  # design with a data term, as the server


# The metadata key of the routing key (see Client._metadata_for).
ROUTING_KEY_HEADER = "x-fieldspace-key"


def routing_key(request):
    """The id a request names: its ``basis_id``, else its ``mesh_id``, else "" (also for request
    streams, e.g. uploads, whose mesh id is known only to the server)."""
    descriptor = getattr(request, "DESCRIPTOR", None)
    for name in ("basis_id", "mesh_id"):
        field = descriptor.fields_by_name.get(name) if descriptor is not None else None
        if field is not None and field.type == field.TYPE_STRING and \
                field.label != field.LABEL_REPEATED:
            value = getattr(request, name)
            if value:
                return value
    return ""


def _biharmonic_proto(form, what):
    forms = {"exact": pb.BIHARMONIC_FORM_EXACT, "mixed": pb.BIHARMONIC_FORM_MIXED}
    if form not in forms:
        raise InvalidArgument(what, "biharmonic must be 'exact' or 'mixed', not %r" % (form,))
    return forms[form]


def _id(target):
    """An id from an id string or a MeshInfo / BasisInfo."""
    return target if isinstance(target, str) else target.id


def _pem(source, what):
    """PEM bytes from a path or bytes (None stays None)."""
    if source is None or isinstance(source, bytes):
        return source
    try:
        with open(source, "rb") as f:
            return f.read()
    except OSError as e:
        raise InvalidArgument("Client", "%s %s: cannot read it: %s" % (what, source, e.strerror)) \
            from None


def _timings(message):
    return {f.name: getattr(message, f.name) for f in message.DESCRIPTOR.fields}


class Client:
    """A connection to fieldspaced.

    Args:
        address: ``HOST:PORT`` (default: ``$FIELDSPACE_SERVER``, else ``127.0.0.1:50051``).
        token: sent as ``authorization: Bearer <token>`` on every call (servers started with
            ``--auth-token-file``); surrounding whitespace is stripped, as the server does.
        timeout: the default deadline in seconds of every call except ``build`` and ``design``
            (long-lived streams: they take only their own ``timeout=``); None: no deadline. Every
            method takes ``timeout=`` to override it for one call.
        tls_ca, tls_cert, tls_key: TLS to a server started with ``--tls-cert`` (any of them turns
            TLS on): the CA of the server's certificate (default: the system's roots), and this
            client's certificate and key for a server with ``--tls-client-ca``. Each is a PEM
            file's path or its bytes.
        tls_server_name: the name the server's certificate must carry, instead of the address's
            host (e.g. a certificate issued to ``fieldspaced`` reached as 127.0.0.1).

    Fields are numpy arrays in the ambient encoding unless ``encoding="dof"`` is given (the wire
    protocol's default is DOF; this package, like the CLI, defaults to ambient): see
    ``fieldspace.fields``. Failures raise the FieldspaceError subclass of their gRPC code.
    Connecting is lazy: an unreachable server shows as Unavailable on the first call. A Client is
    thread-safe; close it (or use it as a context manager) to release the channel.
    """

    def __init__(self, address=None, token=None, timeout=None, upload_chunk_bytes=1 << 20,
                 tls_ca=None, tls_cert=None, tls_key=None, tls_server_name=None):
        if address is None:
            address = os.environ.get("FIELDSPACE_SERVER") or DEFAULT_ADDRESS
        if not address:
            raise InvalidArgument("Client", "empty server address")
        self.address = address
        self.timeout = timeout
        self.upload_chunk_bytes = int(upload_chunk_bytes)
        token = token.strip() if token else ""
        self._metadata = (("authorization", "Bearer " + token),) if token else ()
        # Answers can be as large as the server's --max-message-mb (64 MB by default), far above
        # grpc's 4 MB default receive limit.
        options = [("grpc.max_receive_message_length", -1), ("grpc.max_send_message_length", -1)]
        if tls_ca is None and tls_cert is None and tls_key is None and tls_server_name is None:
            self._channel = grpc.insecure_channel(address, options=options)
        else:
            if (tls_cert is None) != (tls_key is None):
                raise InvalidArgument("Client", "tls_cert and tls_key go together")
            if tls_server_name:
                options.append(("grpc.ssl_target_name_override", tls_server_name))
            credentials = grpc.ssl_channel_credentials(
                root_certificates=_pem(tls_ca, "tls_ca"), private_key=_pem(tls_key, "tls_key"),
                certificate_chain=_pem(tls_cert, "tls_cert"))
            self._channel = grpc.secure_channel(address, credentials, options=options)
        self._stub = pb_grpc.FieldSpaceStub(self._channel)
        self._health = self._channel.unary_unary(
            "/grpc.health.v1.Health/Check",
            request_serializer=health_pb2.HealthCheckRequest.SerializeToString,
            response_deserializer=health_pb2.HealthCheckResponse.FromString)
        self._lock = threading.Lock()
        self._basis_cache = {}     # basis id -> (FieldType, mesh id); ids are content hashes
        self._geometry_cache = {}  # mesh id -> face normals

    # -- plumbing ------------------------------------------------------------------------------

    def close(self):
        self._channel.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def __repr__(self):
        return "Client(%r)" % self.address

    def _deadline(self, timeout):
        return self.timeout if timeout is _DEFAULT else timeout

    def _metadata_for(self, key):
        """The call's metadata: the token and, when ``key`` (the basis or mesh id the call names)
        is not empty, the routing key ``x-fieldspace-key`` that a router hashes on (servers ignore
        it; docs/scale-out.md)."""
        return self._metadata + ((ROUTING_KEY_HEADER, key),) if key else self._metadata

    def _unary(self, what, method, request, timeout):
        try:
            return method(request, timeout=self._deadline(timeout),
                          metadata=self._metadata_for(routing_key(request)))
        except grpc.RpcError as e:
            raise from_rpc_error(e, what) from None

    def _collect(self, what, method, request, timeout):
        """All messages of a server-streaming call."""
        call = method(request, timeout=self._deadline(timeout),
                      metadata=self._metadata_for(routing_key(request)))
        try:
            return list(call)
        except grpc.RpcError as e:
            raise from_rpc_error(e, what) from None
        finally:
            call.cancel()  # no-op once the stream ended

    def _basis(self, basis):
        """(FieldType, mesh id) of a basis, from GetBasis once per id."""
        basis_id = _id(basis)
        with self._lock:
            hit = self._basis_cache.get(basis_id)
        if hit is None:
            info = self.basis(basis_id)
            hit = (info.field, info.mesh_id)
            with self._lock:
                self._basis_cache[basis_id] = hit
        return hit

    def _normals(self, mesh_id, faces=None):
        """Unit face normals of a mesh (all faces, or the listed ones), geometry fetched once."""
        with self._lock:
            normals = self._geometry_cache.get(mesh_id)
        if normals is None:
            vertices, tris = self.mesh_geometry(mesh_id)
            normals = fields.face_normals(vertices, tris)
            with self._lock:
                self._geometry_cache[mesh_id] = normals
        return normals if faces is None else normals[faces]

    def _decode(self, values, field_type, mesh_id, encoding, faces=None):
        normals = None
        if encoding == fld.AMBIENT and field_type.kind == "nfield":
            normals = self._normals(mesh_id, faces)
        return fld.decode(values, field_type, encoding, normals)

    # -- health --------------------------------------------------------------------------------

    def health(self, service="", timeout=_DEFAULT):
        """grpc.health.v1 status of the server (``"SERVING"``, ``"NOT_SERVING"``, ...). Without
        any timeout it waits at most 10 s. Needs no token."""
        deadline = self._deadline(timeout)
        try:
            response = self._health(health_pb2.HealthCheckRequest(service=service),
                                    timeout=10.0 if deadline is None else deadline)
        except grpc.RpcError as e:
            raise from_rpc_error(e, "health check") from None
        return health_pb2.HealthCheckResponse.ServingStatus.Name(response.status)

    # -- meshes --------------------------------------------------------------------------------

    def upload(self, mesh, faces=None, name=None, timeout=_DEFAULT):
        """Stores a mesh and returns its MeshInfo (idempotent: the id is a content hash).

        ``upload(V, F)``: arrays, V (#V, 3) floats and F (#F, 3) zero-based vertex indices, sent
        as raw float64 / int32. ``upload(path)``: an .obj, .off or .ply file.
        """
        if faces is None:
            if not isinstance(mesh, (str, os.PathLike)):
                raise InvalidArgument("UploadMesh", "give a file path, or vertex and face arrays")
            return self._upload_file(os.fspath(mesh), name, timeout)
        what = "UploadMesh"
        V = np.asarray(mesh)
        F = np.asarray(faces)
        if V.ndim != 2 or V.shape[1] != 3 or V.shape[0] == 0:
            raise InvalidArgument(what, "vertices must have shape (#V, 3), got %s" % (V.shape,))
        if F.ndim != 2 or F.shape[1] != 3 or F.shape[0] == 0:
            raise InvalidArgument(what, "faces must have shape (#F, 3), got %s" % (F.shape,))
        if not np.issubdtype(F.dtype, np.integer):
            raise InvalidArgument(what, "faces must be integers, got %s" % F.dtype)
        if F.min() < 0 or F.max() >= min(V.shape[0], 2**31 - 1):
            raise InvalidArgument(what, "face indices must be in [0, %d), got [%d, %d]" %
                                  (V.shape[0], F.min(), F.max()))
        data = (np.ascontiguousarray(V, dtype="<f8").tobytes() +
                np.ascontiguousarray(F, dtype="<i4").tobytes())
        header = pb.UploadMeshHeader(name=name or "arrays", format=pb.MESH_FORMAT_RAW,
                                     total_bytes=len(data), num_vertices=V.shape[0],
                                     num_faces=F.shape[0])
        chunk = self.upload_chunk_bytes
        pieces = (data[i:i + chunk] for i in range(0, len(data), chunk))
        return self._upload(what, header, pieces, timeout)

    def _upload_file(self, path, name, timeout):
        what = "upload of %s" % path
        try:
            handle = open(path, "rb")
        except OSError as e:
            raise NotFound(what, "cannot open %s: %s" % (path, e.strerror)) from None
        with handle:
            ext = os.path.splitext(path)[1].lower()
            header = pb.UploadMeshHeader(name=name or os.path.basename(path),
                                         format=_FORMATS.get(ext, pb.MESH_FORMAT_UNSPECIFIED),
                                         total_bytes=os.fstat(handle.fileno()).st_size)
            pieces = iter(lambda: handle.read(self.upload_chunk_bytes), b"")
            return self._upload(what, header, pieces, timeout)

    def _upload(self, what, header, pieces, timeout):
        def requests():
            # The last message is marked (an empty one after the data): the server stores
            # nothing without the mark or an announced size, so a cut-off upload never counts.
            offset = 0
            first = True
            for data in pieces:
                yield pb.UploadMeshRequest(header=header if first else None, offset=offset,
                                           data=data)
                first = False
                offset += len(data)
            yield pb.UploadMeshRequest(header=header if first else None, offset=offset,
                                       last=True)
        return MeshInfo.from_proto(self._unary(what, self._stub.UploadMesh, requests(), timeout))

    def load(self, path, name="", timeout=_DEFAULT):
        """LoadMesh: stores a file below the server's --data-root (``path`` relative to it)."""
        request = pb.LoadMeshRequest(path=os.fspath(path), name=name)
        return MeshInfo.from_proto(self._unary("LoadMesh", self._stub.LoadMesh, request, timeout))

    def meshes(self, timeout=_DEFAULT):
        """All stored meshes (list of MeshInfo)."""
        response = self._unary("ListMeshes", self._stub.ListMeshes, pb.ListMeshesRequest(),
                               timeout)
        return [MeshInfo.from_proto(m) for m in response.meshes]

    def mesh(self, mesh, timeout=_DEFAULT):
        """One mesh's MeshInfo."""
        request = pb.GetMeshRequest(mesh_id=_id(mesh))
        return MeshInfo.from_proto(self._unary("GetMesh", self._stub.GetMesh, request, timeout))

    def mesh_geometry(self, mesh, timeout=_DEFAULT):
        """(V, F): the stored mesh's vertices (#V, 3) float64 and faces (#F, 3) int32."""
        chunks = self._collect("GetMeshGeometry", self._stub.GetMeshGeometry,
                               pb.GetMeshGeometryRequest(mesh_id=_id(mesh)), timeout)
        if not chunks:
            raise FieldspaceError("GetMeshGeometry", "the server sent no chunk",
                                  grpc.StatusCode.INTERNAL)
        nv, nf = chunks[0].num_vertices, chunks[0].num_faces
        V = np.empty((nv, 3))
        F = np.empty((nf, 3), dtype=np.int32)
        for c in chunks:
            k = len(c.vertices) // 3
            V[c.start_vertex:c.start_vertex + k] = np.fromiter(
                c.vertices, np.float64, len(c.vertices)).reshape(-1, 3)
            k = len(c.faces) // 3
            F[c.start_face:c.start_face + k] = np.fromiter(
                c.faces, np.int32, len(c.faces)).reshape(-1, 3)
        return V, F

    def delete_mesh(self, mesh, cascade=False, timeout=_DEFAULT):
        """Deletes a mesh (with ``cascade``: and its bases); returns the deleted basis ids."""
        request = pb.DeleteMeshRequest(mesh_id=_id(mesh), cascade=cascade)
        response = self._unary("DeleteMesh", self._stub.DeleteMesh, request, timeout)
        with self._lock:
            self._geometry_cache.pop(request.mesh_id, None)
        return list(response.deleted_basis_ids)

    # -- bases ---------------------------------------------------------------------------------

    def build(self, mesh, field, dimension, *, n=None, sigma=None, seed=0, fields_per_region=0,
              face_weights=None, coarse_dimension=0, kernel_columns=True, quality="paper",
              progress=None, on_progress=None, cancel_on_interrupt=True, timeout=None):
        """Builds (or joins the identical running build of, or finds) a basis; returns its id.

        Args:
            field: ``"vector"``, ``"nfield"`` (give ``n``) or ``"tensor"``.
            dimension: d, the number of basis fields.
            sigma, seed, fields_per_region, face_weights (#F positive numbers: adaptivity),
                coarse_dimension: as BuildBasisRequest (docs/api.md).
            kernel_columns: append the kernel of the Laplacian (harmonic fields) as extra
                columns (default); False gives the paper's basis exactly.
            quality: ``"paper"`` (default: one level, the paper's construction) or
                ``"low-modes"`` (three levels: low eigenvalues and smooth fields within ~2% at
                d = 2000, for ~1.8x the nonzeros; needs d >= 40 and coarse_dimension 0) or
                ``"smooth"`` (low-modes' levels with clamped local fields: biharmonic design,
                mu_b > 0, follows the full space; 7-9x low-modes' build time, ~4x its memory).
            progress: a tqdm progress bar on stderr: None (default) shows it when stderr is a
                terminal, True always, False never.
            on_progress: called with every BuildProgress (the last one carries ``basis``).
            cancel_on_interrupt: on KeyboardInterrupt (Ctrl-C, or raised by ``on_progress``)
                ask the server to cancel the build (CancelBuild), then re-raise. A build this call
                joined (started by another client, e.g. ``fieldspaced --demo``) is left running.
            timeout: deadline of the stream (default none; the build itself goes on past it).
        """
        what = "BuildBasis"
        request = pb.BuildBasisRequest(
            mesh_id=_id(mesh), field=fld.field_type_proto(field, n, what),
            dimension=int(dimension), seed=int(seed), fields_per_region=int(fields_per_region),
            coarse_dimension=int(coarse_dimension), kernel_columns=bool(kernel_columns))
        qualities = {"paper": pb.BASIS_QUALITY_PAPER, "low-modes": pb.BASIS_QUALITY_LOW_MODES,
                     "smooth": pb.BASIS_QUALITY_SMOOTH}
        if quality not in qualities:
            raise ValueError(
                f"{what}: quality must be 'paper', 'low-modes' or 'smooth', got {quality!r}")
        request.quality = qualities[quality]
        if sigma is not None:
            request.sigma = float(sigma)
        if face_weights is not None:
            request.face_weights.extend(np.asarray(face_weights, dtype=np.float64).ravel())
        bar = BuildBar.create(progress)
        call = self._stub.BuildBasis(request, timeout=timeout,
                                     metadata=self._metadata_for(request.mesh_id))
        basis_id, joined, done = None, False, False
        try:
            for message in call:
                basis_id = message.basis_id or basis_id
                joined = joined or message.joined
                done = message.HasField("basis")
                update = BuildProgress(
                    basis_id=message.basis_id, phase=phase_name(message.phase),
                    fraction=message.fraction,
                    overall=message.overall_fraction,
                    joined=message.joined,
                    basis=BasisInfo.from_proto(message.basis) if done else None,
                    waiting_for=message.waiting_for)
                if bar is not None:
                    bar.update(update)
                if on_progress is not None:
                    on_progress(update)
                if done:
                    break
        except grpc.RpcError as e:
            raise from_rpc_error(e, what) from None
        except KeyboardInterrupt:
            call.cancel()
            if bar is not None:
                bar.close()
                bar = None
            if basis_id and not done:
                if cancel_on_interrupt and not joined:
                    try:
                        self.cancel(basis_id, timeout=10)
                        note = "cancelled on the server"
                    except FieldspaceError as e:  # finished or gone meanwhile
                        note = "not cancelled (%s)" % e
                else:
                    note = ("still running on the server (cancel it with "
                            "Client.cancel(%r))" % basis_id)
                if BuildBar.wanted(progress):
                    print("fieldspace: build %s %s" % (basis_id, note), file=sys.stderr)
            raise
        finally:
            if bar is not None:
                bar.close()
            call.cancel()
        if not done:
            raise FieldspaceError(what, "the stream ended without the basis",
                                  grpc.StatusCode.INTERNAL)
        return basis_id

    def cancel(self, basis, timeout=_DEFAULT):
        """CancelBuild: stops a running build (NotFound when none runs, FailedPrecondition when
        the basis is already built)."""
        self._unary("CancelBuild", self._stub.CancelBuild,
                    pb.CancelBuildRequest(basis_id=_id(basis)), timeout)

    def basis(self, basis, timeout=_DEFAULT):
        """One basis's BasisInfo (built or being built)."""
        request = pb.GetBasisRequest(basis_id=_id(basis))
        return BasisInfo.from_proto(self._unary("GetBasis", self._stub.GetBasis, request,
                                                timeout))

    def bases(self, mesh=None, timeout=_DEFAULT):
        """All bases (and running builds), or those of one mesh."""
        request = pb.ListBasesRequest(mesh_id=_id(mesh) if mesh is not None else "")
        response = self._unary("ListBases", self._stub.ListBases, request, timeout)
        return [BasisInfo.from_proto(b) for b in response.bases]

    def delete_basis(self, basis, timeout=_DEFAULT):
        """Deletes a built basis (FailedPrecondition while it is being built: cancel it)."""
        self._unary("DeleteBasis", self._stub.DeleteBasis,
                    pb.DeleteBasisRequest(basis_id=_id(basis)), timeout)

    # -- subspace methods ----------------------------------------------------------------------

    def _field_values(self, what, basis, values, encoding):
        field_type, _ = self._basis(basis)
        enc, flat = fld.encode(values, field_type, what, encoding)
        message = pb.FieldValues(encoding=enc)
        message.values.extend(flat.ravel())
        return message

    def project(self, basis, field, encoding=None, timeout=_DEFAULT):
        """Projection of a field on all faces into the basis: Projection(coefficients,
        relative_error, seconds). ``field``'s encoding follows from its shape."""
        what = "Project"
        request = pb.ProjectRequest(basis_id=_id(basis),
                                    field=self._field_values(what, basis, field, encoding))
        r = self._unary(what, self._stub.Project, request, timeout)
        return Projection(np.array(r.coefficients), r.relative_error, r.seconds)

    def solve(self, basis, faces=(), values=None, *, groups=(), weights=None,
              constraint_weights=None, hard=False, encoding=None, return_field=False, field_encoding=fld.AMBIENT,
              singularities=False, raw_weights=False, biharmonic="mixed", timeout=_DEFAULT):
        """The reduced model problem with constraints given as arrays.

        Args:
            faces: (k,) constrained faces.
            values: (k, 3) ambient vectors (n-fields: one direction each), (k, 3, 3) or (k, 6)
                tensors, or DOFs (k, 2) / tensors (k, 3) with ``encoding="dof"`` (DOFs
                without it are refused, so that [[1, 0]] is not read as frame coordinates by
                mistake); see ``fieldspace.fields``.
            weights: Weights(mu_s, mu_b, mu_c), a tuple or a dict (default (1, 0, 1)).
            constraint_weights: (k,) soft weights (default 1 each).
            hard: a bool, or (k,) bools: interpolate exactly instead of penalizing.
            groups: the designer's tools, each a ConstraintGroup from ``fieldspace.tools``
                (``stroke``, ``singularity``, ``align_boundary``, ``align_features``): the
                constraints a design session would add for them.
            return_field: also return the lifted field (all faces) in ``field_encoding``.
            singularities: also return the solution's singularities (vector and n-fields).
            raw_weights: the paper's raw weights instead of the scale-free ones (by default a
                soft constraint alone pulls its face >= mu_c w / (1 + mu_c w) of the way, and
                mu_b is relative to the total area; docs/conventions.md).
            biharmonic: ``"mixed"`` (default: the subspace's own biharmonic energy; designs with
                mu_b > 0 follow the full space far more closely) or ``"exact"`` (the lifted
                field's energy, as the paper); docs/conventions.md, "Biharmonic form".
        Returns:
            Solution(coefficients, field, timings, singularities=...).
        """
        what = "Solve"
        field_type, mesh_id = self._basis(basis)
        request = pb.SolveRequest(basis_id=_id(basis),
                                  weights=Weights.of(weights, _SOLVE_WEIGHTS).proto(),
                                  return_field=return_field, singularities=singularities,
                                  raw_weights=raw_weights,
                                  biharmonic=_biharmonic_proto(biharmonic, what),
                                  field_encoding=fld.encoding_proto(field_encoding, what))
        request.constraints.extend(self._constraints(what, field_type, faces, values,
                                                     constraint_weights, hard, encoding))
        for group in groups:
            if not isinstance(group, pb.ConstraintGroup):
                raise TypeError("Solve: groups take ConstraintGroups from fieldspace.tools, got %s"
                                % type(group).__name__)
            request.constraint_groups.add().CopyFrom(group)
        r = self._unary(what, self._stub.Solve, request, timeout)
        field = None
        if return_field:
            field = self._decode(fld.flat_floats([r.field.values], len(r.field.values)),
                                 field_type, mesh_id, field_encoding)
        return Solution(np.array(r.coefficients), field, _timings(r.timings), r.backward_error,
                        singularities=(Singularities.from_proto(r.singularities)
                                       if r.HasField("singularities") else None),
                        iterations=r.iterations)

    @staticmethod
    def _constraints(what, field_type, faces, values, constraint_weights, hard, encoding):
        faces = np.asarray(faces, dtype=np.int64).ravel()
        k = faces.shape[0]
        if k == 0:
            return []
        if values is None:
            raise InvalidArgument(what, "constraints on %d faces need values" % k)
        enc, flat = fld.encode(values, field_type, what, encoding, count=k)
        if encoding is None and enc == fld.encoding_proto(fld.DOF, what):
            # [[1, 0]] reads as frame coordinates, which differ from face to face: say so.
            raise InvalidArgument(what, "%d values per face are face-frame DOFs for a %s basis, "
                                  "not an ambient %s: pass encoding='dof' to mean them" %
                                  (flat.shape[1], field_type,
                                   "tensor (6 values or 3 x 3)" if field_type.kind == "tensor"
                                   else "vector (3 values x y z)"))
        soft = None
        if constraint_weights is not None:
            soft = np.broadcast_to(np.asarray(constraint_weights, dtype=np.float64), (k,))
        hard = np.broadcast_to(np.asarray(hard, dtype=bool), (k,))
        out = []
        for i in range(k):
            c = pb.Constraint(face=int(faces[i]), encoding=enc, hard=bool(hard[i]))
            c.value.extend(flat[i])
            if soft is not None:
                c.weight = float(soft[i])
            out.append(c)
        return out

    def lift(self, basis, coefficients, faces=None, encoding=fld.AMBIENT, chunk_faces=0,
             timeout=_DEFAULT):
        """The field U x on all faces (or the listed ``faces``, in their order): (F, 3)
        vectors, (F, n, 3) n-fields (all n directions), (F, 3, 3) tensors; with
        ``encoding="dof"`` (F, 2) or (F, 3)."""
        what = "Lift"
        field_type, mesh_id = self._basis(basis)
        request = pb.LiftRequest(basis_id=_id(basis), encoding=fld.encoding_proto(encoding, what),
                                 chunk_faces=int(chunk_faces))
        request.coefficients.extend(np.asarray(coefficients, dtype=np.float64).ravel())
        subset = None
        if faces is not None:
            subset = np.asarray(faces, dtype=np.int64).ravel()
            if len(subset) == 0:  # on the wire, no faces means all faces
                return fld.decode(np.zeros(0), field_type, encoding, np.zeros((0, 3)))
            request.faces.extend(subset.tolist())
        chunks = self._collect(what, self._stub.Lift, request, timeout)
        vpf = fld.values_per_face(field_type, encoding)
        if subset is not None:
            total = len(subset)
        else:
            total = chunks[0].total_faces if chunks else 0
            at = 0
            for c in chunks:
                if c.start_face != at:
                    raise FieldspaceError(what, "chunks arrived out of order",
                                          grpc.StatusCode.DATA_LOSS)
                at += len(c.field.values) // vpf
        values = fld.flat_floats([c.field.values for c in chunks], total * vpf)
        return self._decode(values, field_type, mesh_id, encoding, subset)

    def eigen(self, basis, count, timeout=_DEFAULT):
        """The ``count`` lowest reduced eigenpairs: Eigenfields(eigenvalues (k,),
        coefficients (k, d), seconds)."""
        request = pb.EigenfieldsRequest(basis_id=_id(basis), count=int(count))
        r = self._unary("Eigenfields", self._stub.Eigenfields, request, timeout)
        d = r.dimension
        coefficients = np.array(r.coefficients).reshape(-1, d) if d else np.zeros((0, 0))
        return Eigenfields(np.array(r.eigenvalues), coefficients, r.seconds)

    def smoothest(self, basis, return_field=False, encoding=fld.AMBIENT, timeout=_DEFAULT):
        """The smoothest unit-norm field of the basis (its lowest reduced eigenfield, as the
        CLI's ``smoothest``): Smoothest(energy, coefficients, field)."""
        e = self.eigen(basis, 1, timeout=timeout)
        coefficients = e.coefficients[0]
        field = self.lift(basis, coefficients, encoding=encoding,
                          timeout=timeout) if return_field else None
        return Smoothest(float(e.eigenvalues[0]), coefficients, field)

    # -- applications --------------------------------------------------------------------------

    def curvature(self, mesh, encoding=fld.AMBIENT, principal=False, estimator="jet",
                  timeout=_DEFAULT):
        """The per-face shape operator of a mesh (1/length): Curvature(tensor (F, 3, 3) or with
        ``encoding="dof"`` (F, 3); with ``principal``: k1 >= k2 (F,), d1, d2 (F, 3))."""
        what = "Curvature"
        if estimator not in _ESTIMATORS:
            raise InvalidArgument(what, "estimator must be 'jet' or 'normal-differences', not %r"
                                  % (estimator,))
        request = pb.CurvatureRequest(mesh_id=_id(mesh),
                                      encoding=fld.encoding_proto(encoding, what),
                                      principal=principal, estimator=_ESTIMATORS[estimator])
        chunks = self._collect(what, self._stub.Curvature, request, timeout)
        total = chunks[0].total_faces if chunks else 0
        tensor_type = fld.FieldType("tensor")
        vpf = fld.values_per_face(tensor_type, encoding)
        tensor = fld.decode(fld.flat_floats([c.tensor.values for c in chunks], total * vpf),
                            tensor_type, encoding)
        extra = {}
        if principal:
            for name, width in (("k1", 1), ("k2", 1), ("d1", 3), ("d2", 3)):
                a = fld.flat_floats([getattr(c, name) for c in chunks], total * width)
                extra[name] = a if width == 1 else a.reshape(-1, 3)
        return Curvature(tensor, server_ms=chunks[-1].server_ms if chunks else 0.0, **extra)

    def singularities(self, basis, coefficients=None, field=None, zero_tolerance=0.0,
                      encoding=None, timeout=_DEFAULT):
        """Vertex indices of a vector or n-field given by its d ``coefficients`` or its values
        on all faces (``field``); see Singularities."""
        what = "Singularities"
        if (coefficients is None) == (field is None):
            raise InvalidArgument(what, "give exactly one of coefficients and field")
        request = pb.SingularitiesRequest(basis_id=_id(basis),
                                          zero_tolerance=float(zero_tolerance))
        if coefficients is not None:
            request.coefficients.extend(np.asarray(coefficients, dtype=np.float64).ravel())
        else:
            request.field.CopyFrom(self._field_values(what, basis, field, encoding))
        r = self._unary(what, self._stub.Singularities, request, timeout)
        return Singularities.from_proto(r)

    def smooth(self, basis, field, weights=None, face_weights=None, scale_free=True,
               return_field=False, field_encoding=fld.AMBIENT, encoding=None, singularities=False,
               timeout=_DEFAULT):
        """The field of the basis closest to ``field`` (all faces) with harmonic and biharmonic
        fairness: Solution(coefficients, field, timings, backward_error).

        ``weights``: (mu_s, mu_b, mu_c), default (0.001, 0, 1) as the CLI; ``scale_free`` (the
        default, as the CLI): the same weights mean the same on every scale (docs/api.md).
        ``face_weights``: (F,) per-face data weights W >= 0.
        """
        what = "Smooth"
        field_type, mesh_id = self._basis(basis)
        request = pb.SmoothRequest(basis_id=_id(basis),
                                   field=self._field_values(what, basis, field, encoding),
                                   weights=Weights.of(weights, _SMOOTH_WEIGHTS).proto(),
                                   scale_free=scale_free, return_field=return_field,
                                   singularities=singularities,
                                   field_encoding=fld.encoding_proto(field_encoding, what))
        if face_weights is not None:
            request.face_weights.extend(np.asarray(face_weights, dtype=np.float64).ravel())
        r = self._unary(what, self._stub.Smooth, request, timeout)
        return self._smoothed(r, return_field, field_type, mesh_id, field_encoding)

    def align(self, basis, weights=None, estimator="jet", return_field=False,
              field_encoding=fld.AMBIENT, singularities=False, timeout=_DEFAULT):
        """A smooth n-field (n-field basis, n = 2 or 4) aligned to the principal curvature
        directions; ``weights`` (mu_s, mu_b: fairness, mu_c: alignment), default (0.001, 0, 1).
        Returns Solution(coefficients, field, timings, backward_error)."""
        what = "Align"
        if estimator not in _ESTIMATORS:
            raise InvalidArgument(what, "estimator must be 'jet' or 'normal-differences', not %r"
                                  % (estimator,))
        field_type, mesh_id = self._basis(basis)
        request = pb.AlignRequest(basis_id=_id(basis),
                                  weights=Weights.of(weights, _SMOOTH_WEIGHTS).proto(),
                                  estimator=_ESTIMATORS[estimator], return_field=return_field,
                                  singularities=singularities,
                                  field_encoding=fld.encoding_proto(field_encoding, what))
        r = self._unary(what, self._stub.Align, request, timeout)
        return self._smoothed(r, return_field, field_type, mesh_id, field_encoding)

    def _smoothed(self, r, return_field, field_type, mesh_id, field_encoding):
        field = None
        if return_field:
            field = self._decode(fld.flat_floats([r.field.values], len(r.field.values)),
                                 field_type, mesh_id, field_encoding)
        return Solution(np.array(r.coefficients), field, _timings(r.timings), r.backward_error,
                        singularities=(Singularities.from_proto(r.singularities)
                                       if r.HasField("singularities") else None))

    # -- design sessions -----------------------------------------------------------------------

    def design(self, basis, weights=None, watch=None, watch_encoding=fld.AMBIENT, timeout=None,
               *, raw_weights=False, biharmonic="mixed", align_curvature=False, estimator="jet",
               data=None, data_face_weights=None):
        """Opens an interactive design session (a Design stream) and returns it; use it as a
        context manager. ``weights`` default (1, 0, 1); ``watch``: faces whose lifted values
        every update carries. ``timeout``: deadline of the whole session (default none).
        ``raw_weights``, ``biharmonic``: as in solve, for the whole session.

        A data term mu_a (X - X0)^T W M (X - X0) in the session's energy (paper Fig. 16: aligned
        to curvature, then constraints on top): ``align_curvature=True`` (an n-field basis with
        n = 2 or 4; X0, W the curvature-aligned target and its anisotropy, ``estimator`` as in
        curvature) or ``data`` (a field on all faces, as smooth takes it) with optional
        ``data_face_weights`` (#F). Weights then default to (0.001, 0, 1, 1) (mu_a last);
        changing mu_a refactorizes like mu_s and mu_b."""
        from .design import DesignSession
        what = "Design"
        if align_curvature and data is not None:
            raise InvalidArgument(what, "one data term: align_curvature or data")
        if data_face_weights is not None and data is None:
            raise InvalidArgument(what, "data_face_weights weigh the data field")
        data_term = None
        if align_curvature:
            if estimator not in _ESTIMATORS:
                raise InvalidArgument(what, "estimator must be 'jet' or 'normal-differences', "
                                      "not %r" % (estimator,))
            data_term = pb.DataTerm(
                curvature=pb.CurvatureTarget(estimator=_ESTIMATORS[estimator]))
        elif data is not None:
            data_term = pb.DataTerm(field=self._field_values(what, basis, data, None))
            if data_face_weights is not None:
                data_term.face_weights.extend(
                    np.asarray(data_face_weights, dtype=np.float64).ravel().tolist())
        default = _DATA_TERM_WEIGHTS if data_term is not None else _SOLVE_WEIGHTS
        return DesignSession(self, basis, Weights.of(weights, default), watch,
                             watch_encoding, timeout, raw_weights=raw_weights,
                             biharmonic=_biharmonic_proto(biharmonic, what), data_term=data_term)

