"""The records the client returns: plain dataclasses with numpy arrays, no protobuf."""

from dataclasses import dataclass
from dataclasses import field as _field
from typing import NamedTuple, Optional

import numpy as np

from ._stubs import pb
from .wire import FieldType

_PHASES = {
    pb.BUILD_PHASE_UNSPECIFIED: "unspecified",
    pb.BUILD_PHASE_QUEUED: "queued",
    pb.BUILD_PHASE_OPERATOR: "operator",
    pb.BUILD_PHASE_SAMPLING: "sampling",
    pb.BUILD_PHASE_REGIONS: "regions",
    pb.BUILD_PHASE_EIGENSOLVE: "eigensolve",
    pb.BUILD_PHASE_ASSEMBLY: "assembly",
    pb.BUILD_PHASE_PRECOMPUTE: "precompute",
    pb.BUILD_PHASE_SAVING: "saving",
    pb.BUILD_PHASE_DONE: "done",
}


def phase_name(phase):
    return _PHASES.get(phase, "unspecified")


class Weights(NamedTuple):
    """Weights of the model problem: mu_s X^T S X + mu_b X^T B X + mu_c |C X - c|^2, plus
    mu_a (X - X0)^T W M (X - X0) in a design session opened with a data term."""

    mu_s: float = 1.0
    mu_b: float = 0.0
    mu_c: float = 1.0
    mu_a: float = 0.0

    @classmethod
    def of(cls, weights, default):
        """Weights from None (the default), a Weights, a (mu_s, mu_b, mu_c[, mu_a]) tuple or a
        dict."""
        if weights is None:
            return default
        if isinstance(weights, dict):
            return default._replace(**weights)
        return cls(*weights)

    def proto(self, data_term=False):
        """The wire message; mu_a for a session with a data term, and wherever it is not 0 (the
        server refuses it where there is no data term, rather than ignoring it)."""
        w = pb.Weights(mu_s=float(self.mu_s), mu_b=float(self.mu_b), mu_c=float(self.mu_c))
        if data_term or self.mu_a != 0:
            w.mu_a = float(self.mu_a)
        return w


@dataclass(frozen=True)
class MeshInfo:
    id: str
    name: str
    num_vertices: int
    num_faces: int
    num_edges: int
    num_components: int
    num_boundary_loops: int
    euler_characteristic: int
    genus: int
    total_area: float
    dropped_unreferenced_vertices: int
    polygons_triangulated: int
    loaded: bool
    created_unix_ms: int

    @classmethod
    def from_proto(cls, m):
        return cls(m.id, m.name, m.num_vertices, m.num_faces, m.num_edges, m.num_components,
                   m.num_boundary_loops, m.euler_characteristic, m.genus, m.total_area,
                   m.dropped_unreferenced_vertices, m.polygons_triangulated, m.loaded,
                   m.created_unix_ms)


@dataclass(frozen=True)
class BasisInfo:
    """A basis, built (``state == "ready"``) or being built (``"building"``, with phase and
    fraction of the current phase)."""

    id: str
    mesh_id: str
    field: FieldType
    dimension: int
    sigma: float
    fields_per_region: int
    seed: int
    coarse_dimension: int
    adaptive: bool
    state: str
    dofs: int
    columns: int
    num_regions: int
    radius: float
    nnz: int
    build_seconds: float
    loaded: bool
    memory_bytes: int
    created_unix_ms: int
    phase: str
    fraction: float
    quality: str = "paper"  # "paper", "low-modes" or "smooth" (BuildBasisRequest.quality)

    @property
    def ready(self):
        return self.state == "ready"

    @classmethod
    def from_proto(cls, b):
        state = {pb.BASIS_STATE_READY: "ready", pb.BASIS_STATE_BUILDING: "building"}.get(
            b.state, "unspecified")
        return cls(b.id, b.mesh_id, FieldType.from_proto(b.field), b.dimension, b.sigma,
                   b.fields_per_region, b.seed, b.coarse_dimension, b.adaptive, state, b.dofs,
                   b.columns, b.num_regions, b.radius, b.nnz, b.build_seconds, b.loaded,
                   b.memory_bytes, b.created_unix_ms, phase_name(b.phase), b.fraction,
                   {pb.BASIS_QUALITY_LOW_MODES: "low-modes",
                    pb.BASIS_QUALITY_SMOOTH: "smooth"}.get(b.quality, "paper"))


@dataclass(frozen=True)
class BuildProgress:
    """One message of a build stream. ``fraction`` is of the current phase, ``overall`` an
    estimate of the whole build's (fixed phase weights); ``basis`` is set on the last one.
    ``waiting_for`` names the replica ("HOST/PID/DAEMON_ID") that builds this basis while this
    one waits for it (shared store, phase "queued"); empty otherwise."""

    basis_id: str
    phase: str
    fraction: float
    overall: float
    joined: bool
    basis: Optional[BasisInfo] = None
    waiting_for: str = ""


@dataclass(frozen=True)
class Projection:
    coefficients: np.ndarray  # (d,)
    relative_error: float     # ||X - U x||_M / ||X||_M
    seconds: float


@dataclass(frozen=True)
class Solution:
    """The answer of solve, smooth and align: d coefficients, the lifted field when asked for
    (``return_field=True``), the server's timings in ms, the backward error against the true
    reduced system, the result's singularities when asked for (``singularities=True``) and (solve)
    the refinement steps or, with ``biharmonic="mixed"`` past 256 constraints, conjugate gradient
    iterations."""

    coefficients: np.ndarray
    field: Optional[np.ndarray] = None
    timings: dict = _field(default_factory=dict)
    backward_error: Optional[float] = None
    singularities: Optional["Singularities"] = None  # with ``singularities=True``
    iterations: Optional[int] = None


@dataclass(frozen=True)
class Eigenfields:
    eigenvalues: np.ndarray   # (k,), ascending
    coefficients: np.ndarray  # (k, d): eigenfield i is U @ coefficients[i], M-orthonormal
    seconds: float


@dataclass(frozen=True)
class Smoothest:
    """The smoothest unit-norm field of a basis (its lowest reduced eigenfield)."""

    energy: float             # its Dirichlet energy, the lowest reduced eigenvalue
    coefficients: np.ndarray  # (d,)
    field: Optional[np.ndarray] = None


@dataclass(frozen=True)
class Curvature:
    """Per-face shape operator (1/length): ``tensor`` (F, 3, 3) ambient or (F, 3) DOF; with
    ``principal=True`` also k1 >= k2 (F,) and the unit principal directions d1, d2 (F, 3)."""

    tensor: np.ndarray
    k1: Optional[np.ndarray] = None
    k2: Optional[np.ndarray] = None
    d1: Optional[np.ndarray] = None
    d2: Optional[np.ndarray] = None
    server_ms: float = 0.0


@dataclass(frozen=True)
class Singularities:
    """Vertex indices of a vector or n-field. ``vertices``, ``index`` (in 1/n turns), ``turns``
    (index / n) and ``positions`` (k, 3) describe the interior vertices with a nonzero index;
    ``index_sum`` (turns) equals ``euler_characteristic`` on a closed mesh (Poincare-Hopf)."""

    n: int
    vertices: np.ndarray
    index: np.ndarray
    turns: np.ndarray
    positions: np.ndarray
    index_sum: float
    euler_characteristic: int
    boundary_vertices: np.ndarray
    boundary_turns: np.ndarray
    undefined_vertices: np.ndarray

    @classmethod
    def from_proto(cls, r):
        s = r.singularities
        return cls(
            n=r.n,
            vertices=np.array([x.vertex for x in s], dtype=np.int64),
            index=np.array([x.index for x in s], dtype=np.int64),
            turns=np.array([x.turns for x in s], dtype=np.float64),
            positions=np.array([list(x.position) for x in s], dtype=np.float64).reshape(-1, 3),
            index_sum=r.index_sum, euler_characteristic=r.euler_characteristic,
            boundary_vertices=np.array([x.vertex for x in r.boundary], dtype=np.int64),
            boundary_turns=np.array([x.turns for x in r.boundary], dtype=np.float64),
            undefined_vertices=np.array(r.undefined_vertices, dtype=np.int64))


@dataclass(frozen=True)
class DesignUpdate:
    """The answer to one design edit (or the open): the current solution's coefficients, the
    watched faces' lifted values, counts and the server's timings (ms); ``round_trip_ms`` is
    measured by the client. ``constraint_id`` is the id the edit touched (add, move, remove)."""

    seq: int
    edit: str
    coefficients: np.ndarray
    watched_faces: np.ndarray
    watched: np.ndarray
    num_constraints: int
    num_hard_constraints: int
    refactorized: bool
    timings: dict
    constraint_id: Optional[int] = None
    # True on the one update that answers an edit after the session was reopened (its replica
    # died or drained) and its constraints, weights and watch were replayed; the coefficients
    # are then those of the lost session plus that edit.
    resumed: bool = False
    # Of the session's last solve: backward error (NaN when the server did not check it) and
    # refinement steps (or, with the mixed form and a data term, conjugate gradient iterations).
    backward_error: float = float("nan")
    iterations: int = 0
