"""Streamlines and hatching strokes traced on per-face constant fields (paper section 8, Fig. 17).

A field constant on each face moves a point along a straight segment until it leaves the face
through an edge; the line then continues in the neighbour across that edge. For an n-field the
direction taken in the next face is the one of its n directions closest to the incoming one
(n-fields have no global orientation); a vector field is followed forwards and backwards. All
lines advance together, one face crossing per numpy step, so the cost is (number of lines) x
(faces crossed by the longest line) in vectorized operations.

A line stops at a boundary edge, at ``max_length``, after ``max_faces`` face crossings, on
entering a *stop face* (a face whose field is below ``zero_tolerance`` times the largest
magnitude, or one listed in ``stop_faces``, e.g. faces around singular vertices:
:func:`faces_around_vertices`), where the field turns by more than ``max_turn_degrees`` between
two faces, where the next face's direction points back across the shared edge, and when it comes
back to the face of its seed heading for the seed (a closed loop, closed at the seed point).
"""

import argparse
import json
import os
import sys
from dataclasses import dataclass, field as dataclass_field

import numpy as np

from . import fields as fl


def face_adjacency(F):
    """``(F, 3)``: the face across the edge opposite corner k (between corners k+1 and k+2), or
    -1 on the boundary (and at non-manifold edges)."""
    F = np.asarray(F, dtype=np.int64)
    nf = len(F)
    a = F[:, [1, 2, 0]].reshape(-1)
    b = F[:, [2, 0, 1]].reshape(-1)
    nv = int(F.max()) + 1 if nf else 0
    key = np.minimum(a, b) * nv + np.maximum(a, b)
    order = np.argsort(key, kind="stable")
    sk = key[order]
    adj = np.full(3 * nf, -1, dtype=np.int64)
    if len(sk) > 1:
        same = sk[1:] == sk[:-1]
        # An edge shared by exactly two face corners: neither neighbour of the run is equal.
        before = np.concatenate([[False], same[:-1]])
        after = np.concatenate([same[1:], [False]])
        pair = same & ~before & ~after
        i = order[:-1][pair]
        j = order[1:][pair]
        adj[i] = j // 3
        adj[j] = i // 3
    return adj.reshape(nf, 3)


def faces_around_vertices(F, vertices):
    """Indices of the faces that touch any of ``vertices`` (e.g. singular vertices)."""
    F = np.asarray(F, dtype=np.int64)
    vertices = np.asarray(vertices, dtype=np.int64).reshape(-1)
    mark = np.zeros(int(max(F.max() + 1 if F.size else 0, vertices.max() + 1 if vertices.size
                            else 0)), dtype=bool)
    mark[vertices] = True
    return np.nonzero(mark[F].any(axis=1))[0]


def sample_surface(V, F, count, rng=None, allowed=None):
    """``count`` points uniformly distributed by area: ``(faces (count,), barycentrics
    (count, 3))``. ``rng``: a numpy Generator or a seed; ``allowed``: boolean mask of faces that
    may hold a point."""
    V, F = fl.as_mesh(V, F)
    rng = np.random.default_rng(rng)
    areas = fl.face_areas(V, F)
    if allowed is not None:
        areas = np.where(allowed, areas, 0.0)
    total = areas.sum()
    if count <= 0 or total <= 0:
        return np.zeros(0, dtype=np.int64), np.zeros((0, 3))
    faces = rng.choice(len(F), size=count, p=areas / total)
    r1 = np.sqrt(rng.random(count))
    r2 = rng.random(count)
    bary = np.stack([1.0 - r1, r1 * (1.0 - r2), r1 * r2], axis=1)
    return faces, bary


@dataclass
class Streamlines:
    """Traced lines: ``lines`` a list of ``(k, 3)`` polylines; per line ``seed_faces``,
    ``families`` (which of the field's line families it follows: direction index for n-fields)
    and ``closed`` (it came back to its seed face; the last point repeats the first)."""

    lines: list
    seed_faces: np.ndarray = dataclass_field(default_factory=lambda: np.zeros(0, np.int64))
    families: np.ndarray = dataclass_field(default_factory=lambda: np.zeros(0, np.int64))
    closed: np.ndarray = dataclass_field(default_factory=lambda: np.zeros(0, bool))

    def __len__(self):
        return len(self.lines)

    def __iter__(self):
        return iter(self.lines)

    def __getitem__(self, i):
        return self.lines[i]


def _unit_directions(V, F, field, kind):
    """Unit tangent directions ``(F, m, 3)`` to follow and the per-face magnitude: vectors
    (m = 1), the n directions of an n-field, the two principal directions (max, min) of a
    tensor as a 4-field."""
    a, kind, n = fl.check_field(V, F, field, kind)
    if kind == fl.VECTOR:
        d = a[:, None, :]
        mag = np.linalg.norm(a, axis=1)
    elif kind == fl.NFIELD:
        d = a
        mag = np.linalg.norm(a[:, 0, :], axis=1)
    else:
        values, directions = fl.principal(V, F, a)
        d = np.stack([directions[:, 0], directions[:, 1], -directions[:, 0],
                      -directions[:, 1]], axis=1)
        mag = np.abs(values[:, 0] - values[:, 1])
    normals = fl.face_normals(V, F)
    d = d - np.sum(d * normals[:, None, :], axis=2)[:, :, None] * normals[:, None, :]
    length = np.linalg.norm(d, axis=2)
    unit = d / np.where(length > 0, length, 1.0)[:, :, None]
    return unit, mag, kind


def line_families(kind, m):
    """Direction indices that start distinct families of lines for ``m`` directions per face:
    a vector field has one; an n-field with even n has n / 2 (d and -d give the same lines);
    odd n has n; a tensor's principal 4-field has two (max and min curvature lines)."""
    if kind == fl.VECTOR:
        return [0]
    return list(range(m // 2)) if m % 2 == 0 else list(range(m))


def trace_streamlines(V, F, field, kind=None, count=500, seeds=None, rng=0, families=None,
                      max_length=None, max_faces=2000, zero_tolerance=1e-6, stop_faces=None,
                      max_turn_degrees=60.0, both_directions=True, separation=None):
    """Traces streamlines of a per-face field; returns :class:`Streamlines`.

    - ``field``: vectors ``(F, 3)``, n-fields ``(F, n, 3)`` or tensors ``(F, 3, 3)`` (lines of
      principal directions); ``kind`` as in fieldspace.fields.
    - ``seeds``: ``(faces, barycentrics)`` or None for ``count`` seeds uniform by area, drawn
      with ``rng`` (a seed or numpy Generator), never on stop faces.
    - ``families``: direction indices to trace from each seed (default :func:`line_families`:
      both families of a cross field).
    - ``max_length``: length cap of each half line (None: unbounded); ``max_faces``: faces
      crossed per half line.
    - ``both_directions``: trace backwards from each seed too and join the halves.
    - ``separation``: keep the lines of each family at least this far apart
      (:func:`space_lines`: longest first, others cut to their longest free piece); None keeps
      every line whole.
    """
    V, F = fl.as_mesh(V, F)
    dirs, mag, kind = _unit_directions(V, F, field, kind)
    nf, m = dirs.shape[0], dirs.shape[1]
    stop = mag <= zero_tolerance * (mag.max() if nf else 0.0)
    if stop_faces is not None:
        stop_faces = np.asarray(stop_faces)
        if stop_faces.dtype == bool:
            stop = stop | stop_faces
        else:
            stop[stop_faces.astype(np.int64)] = True
    if families is None:
        families = line_families(kind, m)
    families = [int(j) for j in families]
    if any(not 0 <= j < m for j in families):
        raise ValueError("families must be direction indices in [0, %d)" % m)
    if seeds is None:
        seed_f, seed_b = sample_surface(V, F, count, rng, allowed=~stop)
    else:
        seed_f = np.asarray(seeds[0], dtype=np.int64).reshape(-1)
        seed_b = np.asarray(seeds[1], dtype=np.float64).reshape(-1, 3)
        if len(seed_f) != len(seed_b):
            raise ValueError("seeds: as many faces as barycentric rows")
        keep = ~stop[seed_f]
        seed_f, seed_b = seed_f[keep], seed_b[keep]
    signs = [1.0, -1.0] if both_directions else [1.0]

    # One job per (seed, family, sign).
    ns, nfam, nsign = len(seed_f), len(families), len(signs)
    job_seed = np.repeat(np.arange(ns), nfam * nsign)
    job_family = np.tile(np.repeat(np.array(families, dtype=np.int64), nsign), ns)
    job_sign = np.tile(np.array(signs), ns * nfam)
    tracer = _Tracer(V, F, dirs, stop, max_length, max_faces, max_turn_degrees)
    records, closed = tracer.run(seed_f[job_seed], seed_b[job_seed], job_family, job_sign)

    # Assemble each job's points in step order, then join the two halves of each line.
    job_ids, points = records
    order = np.argsort(job_ids, kind="stable")
    job_ids, points = job_ids[order], points[order]
    bounds = np.searchsorted(job_ids, np.arange(len(job_seed) + 1))
    halves = [points[bounds[j]:bounds[j + 1]] for j in range(len(job_seed))]
    lines, out_seeds, out_families, out_closed = [], [], [], []
    for s in range(ns):
        for fi in range(nfam):
            base = (s * nfam + fi) * nsign
            forward = halves[base]
            is_closed = bool(closed[base])
            if nsign == 2 and not is_closed:
                backward = halves[base + 1]
                line = np.vstack([backward[::-1], forward[1:]])
            else:
                line = forward
            if len(line) >= 2:
                lines.append(line)
                out_seeds.append(seed_f[s])
                out_families.append(families[fi])
                out_closed.append(is_closed)
    out_seeds = np.array(out_seeds, dtype=np.int64)
    out_families = np.array(out_families, dtype=np.int64)
    out_closed = np.array(out_closed, dtype=bool)
    if separation is not None:
        # Spaced family by family: the lines of a cross field's two families cross each other.
        spaced, keep = [], []
        for family in families:
            members = np.nonzero(out_families == family)[0]
            kept, sources = space_lines([lines[i] for i in members], separation)
            spaced += kept
            keep.append(members[sources])
        keep = np.concatenate(keep) if keep else np.zeros(0, dtype=np.int64)
        lines = spaced
        out_seeds, out_families = out_seeds[keep], out_families[keep]
        # A cut loop is no longer closed.
        out_closed = out_closed[keep] & np.array(
            [len(a) > 2 and np.allclose(a[0], a[-1]) for a in lines], dtype=bool)
    return Streamlines(lines, out_seeds, out_families, out_closed)


def _densify(line, step):
    """The polyline with points inserted so that no segment is longer than ``step``."""
    seg = np.diff(line, axis=0)
    pieces = np.maximum(np.ceil(np.linalg.norm(seg, axis=1) / step).astype(np.int64), 1)
    first = np.cumsum(pieces) - pieces
    start = np.repeat(np.arange(len(seg)), pieces)
    t = (np.arange(int(pieces.sum())) - first[start]) / pieces[start]
    return np.vstack([line[start] + t[:, None] * seg[start], line[-1:]])


class _PointGrid:
    """Points hashed by cells of size ``h``; answers "which query points have a stored point
    closer than h" with sorted cell keys (numpy only)."""

    _OFFSETS = np.array([(i, j, k) for i in (-1, 0, 1) for j in (-1, 0, 1)
                         for k in (-1, 0, 1)], dtype=np.int64)

    def __init__(self, h, origin):
        self.h = h
        self.origin = origin
        self.keys = np.zeros(0, dtype=np.int64)
        self.points = np.zeros((0, 3))

    def _cells(self, pts):
        return np.floor((pts - self.origin) / self.h).astype(np.int64) + 1

    @staticmethod
    def _key(cells):
        # 21 bits per axis: cells are within [0, 2^21) of the origin (checked by the caller).
        return (cells[..., 0] << 42) | (cells[..., 1] << 21) | cells[..., 2]

    def near(self, pts):
        """Boolean per query point: a stored point lies closer than ``h``."""
        out = np.zeros(len(pts), dtype=bool)
        if len(self.keys) == 0 or len(pts) == 0:
            return out
        keys = self._key(self._cells(pts)[:, None, :] + self._OFFSETS[None, :, :]).reshape(-1)
        lo = np.searchsorted(self.keys, keys, side="left")
        hi = np.searchsorted(self.keys, keys, side="right")
        counts = hi - lo
        total = int(counts.sum())
        if total == 0:
            return out
        query = np.repeat(np.arange(len(keys)) // 27, counts)
        first = np.cumsum(counts) - counts
        stored = np.repeat(lo - first, counts) + np.arange(total)
        d2 = np.sum((pts[query] - self.points[stored]) ** 2, axis=1)
        out[query[d2 < self.h * self.h]] = True
        return out

    def add(self, pts):
        keys = self._key(self._cells(pts))
        self.keys = np.concatenate([self.keys, keys])
        self.points = np.vstack([self.points, pts])
        order = np.argsort(self.keys, kind="stable")
        self.keys, self.points = self.keys[order], self.points[order]


def space_lines(lines, separation, min_length=None):
    """Evenly spaced lines: keeps the longest lines first and cuts every other line to its
    longest piece whose points stay at least ``separation`` away from the lines kept before it
    (Jobard and Lefer's criterion, applied after tracing). Pieces shorter than ``min_length``
    (default ``2 separation``) are dropped. Returns ``(kept lines, indices of their sources)``;
    the kept lines have points at most ``separation / 2`` apart."""
    sep = float(separation)
    if sep <= 0:
        raise ValueError("separation must be > 0")
    min_length = 2.0 * sep if min_length is None else float(min_length)
    lines = [np.asarray(a, dtype=np.float64) for a in lines]
    if not lines:
        return [], np.zeros(0, dtype=np.int64)
    everything = np.vstack(lines)
    origin = everything.min(axis=0) - sep
    if np.any((everything.max(axis=0) - origin) / sep >= 2 ** 21 - 2):
        raise ValueError("separation is too small for the lines' extent")
    lengths = np.array([float(np.sum(np.linalg.norm(np.diff(a, axis=0), axis=1)))
                        for a in lines])
    grid = _PointGrid(sep, origin)
    kept, sources = [], []
    for index in np.argsort(-lengths, kind="stable"):
        if lengths[index] < min_length:
            break
        pts = _densify(lines[index], 0.5 * sep)
        blocked = grid.near(pts)
        # The longest run of free points.
        free = np.concatenate([[False], ~blocked, [False]])
        runs = np.flatnonzero(free[1:] != free[:-1]).reshape(-1, 2)
        if len(runs) == 0:
            continue
        arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1))])
        run_lengths = arc[runs[:, 1] - 1] - arc[runs[:, 0]]
        best = int(np.argmax(run_lengths))
        if run_lengths[best] < min_length:
            continue
        piece = pts[runs[best, 0]:runs[best, 1]]
        kept.append(piece)
        sources.append(int(index))
        grid.add(piece)
    return kept, np.array(sources, dtype=np.int64)


def hatching(V, F, field, kind=None, count=2000, stroke_length=None, rng=0, **options):
    """Hatching strokes (paper Fig. 17): short streamlines of a 2-field (or both families of a
    4-field, cross-hatching, or a tensor's principal directions) from ``count`` seeds uniform by
    area. ``stroke_length`` is the full length of a stroke (default 3% of the bounding box
    diagonal); further options as :func:`trace_streamlines`."""
    V, F = fl.as_mesh(V, F)
    if stroke_length is None:
        stroke_length = 0.03 * float(np.linalg.norm(V.max(axis=0) - V.min(axis=0)))
    return trace_streamlines(V, F, field, kind=kind, count=count, rng=rng,
                             max_length=0.5 * stroke_length, **options)


class _Tracer:
    """The vectorized walk across faces shared by all jobs."""

    def __init__(self, V, F, dirs, stop, max_length, max_faces, max_turn_degrees):
        self.V, self.F, self.dirs, self.stop = V, F, dirs, stop
        self.adj = face_adjacency(F)
        self.max_length = np.inf if max_length is None else float(max_length)
        self.max_faces = int(max_faces)
        self.cos_turn = np.cos(np.radians(max_turn_degrees))
        # grad of barycentric k: n x (p_{k+2} - p_{k+1}) / (2 area), (F, 3, 3).
        p = V[F]
        normals = fl.face_normals(V, F)
        twice_area = np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)
        twice_area = np.where(twice_area > 0, twice_area, 1.0)
        edges = p[:, [2, 0, 1]] - p[:, [1, 2, 0]]
        self.grad = np.cross(normals[:, None, :], edges) / twice_area[:, None, None]
        self.size = np.sqrt(twice_area)

    def _pick(self, faces, incoming, sign):
        """The direction of ``faces`` closest to ``incoming`` (times ``sign``) and its dot."""
        cand = self.dirs[faces] * sign[:, None, None]
        dots = np.einsum("lkc,lc->lk", cand, incoming)
        best = np.argmax(dots, axis=1)
        rows = np.arange(len(faces))
        return cand[rows, best], dots[rows, best]

    def run(self, face, bary, family, sign):
        V, F = self.V, self.F
        n_jobs = len(face)
        bary = bary / bary.sum(axis=1)[:, None]
        direction = self.dirs[face, family] * sign[:, None]
        length = np.zeros(n_jobs)
        seed_face = face.copy()
        closed = np.zeros(n_jobs, dtype=bool)
        ids = [np.arange(n_jobs)]
        pts = [np.einsum("lk,lkc->lc", bary, V[F[face]])]
        seed_points = pts[0]
        active = np.arange(n_jobs)
        f, b, d = face.copy(), bary.copy(), direction.copy()
        for step in range(self.max_faces):
            if len(active) == 0:
                break
            db = np.einsum("lkc,lc->lk", self.grad[f], d)
            with np.errstate(divide="ignore", invalid="ignore"):
                t = np.where(db < -1e-12, np.maximum(b, 0.0) / -db, np.inf)
            k = np.argmin(t, axis=1)
            rows = np.arange(len(active))
            t = t[rows, k]
            ok = np.isfinite(t)
            remaining = self.max_length - length[active]
            capped = t > remaining
            t = np.where(capped, remaining, t)
            t = np.where(ok, t, 0.0)
            b = b + t[:, None] * db
            b[rows[~capped], k[~capped]] = 0.0
            b = np.maximum(b, 0.0)
            b = b / b.sum(axis=1)[:, None]
            p = np.einsum("lk,lkc->lc", b, V[F[f]])
            length[active] += t
            ids.append(active[ok])
            pts.append(p[ok])
            g = self.adj[f, k]
            go = ok & ~capped & (g >= 0)
            go[go] &= ~self.stop[g[go]]
            if not go.any():
                break
            sel = np.nonzero(go)[0]
            fs, ks, gs = f[sel], k[sel], g[sel]
            va = F[fs, (ks + 1) % 3]
            vb = F[fs, (ks + 2) % 3]
            ia = np.argmax(F[gs] == va[:, None], axis=1)
            ib = np.argmax(F[gs] == vb[:, None], axis=1)
            nb = np.zeros((len(sel), 3))
            r = np.arange(len(sel))
            nb[r, ia] = b[sel, (ks + 1) % 3]
            nb[r, ib] = b[sel, (ks + 2) % 3]
            entry = 3 - ia - ib
            new_d, dot = self._pick(gs, d[sel], sign[active[sel]])
            inward = np.einsum("lc,lc->l", self.grad[gs, entry], new_d) > 1e-12
            cont = (dot >= self.cos_turn) & inward
            # Back in the seed face, heading for the seed along the seed's direction: close the
            # loop at the seed point (within 5% of the face's size across the line).
            jobs = active[sel]
            home = cont & (gs == seed_face[jobs]) & (step > 0)
            if home.any():
                h = np.nonzero(home)[0]
                to_seed = seed_points[jobs[h]] - p[sel[h]]
                along = np.einsum("lc,lc->l", to_seed, new_d[h])
                across = np.linalg.norm(to_seed - along[:, None] * new_d[h], axis=1)
                same = np.einsum("lc,lc->l", new_d[h], direction[jobs[h]]) > 0.99
                close = same & (along >= -1e-12) & (across <= 0.05 * self.size[gs[h]])
                h = h[close]
                if len(h):
                    ids.append(jobs[h])
                    pts.append(seed_points[jobs[h]])
                    closed[jobs[h]] = True
                    cont[h] = False
            sel = sel[cont]
            active = active[sel]
            f, b, d = gs[cont], nb[cont], new_d[cont]
        return (np.concatenate(ids), np.concatenate(pts)), closed


def main(argv=None):
    """python3 -m fieldspace.streamlines MESH FIELD_FILE --out LINES: traces streamlines (or,
    with --hatching, short strokes) of a field file of the fieldspace CLI and writes them as
    legacy VTK polylines (.vtk) or OBJ lines (.obj)."""
    from . import export, mesh_io

    parser = argparse.ArgumentParser(prog="python3 -m fieldspace.streamlines",
                                     description=main.__doc__)
    mesh_io.add_field_arguments(parser)
    parser.add_argument("--out", required=True, help=".vtk or .obj")
    parser.add_argument("--count", type=int, default=500, help="seeds (uniform by area)")
    parser.add_argument("--length", type=float, default=None,
                        help="streamlines: half length cap; hatching: stroke length")
    parser.add_argument("--hatching", action="store_true", help="short strokes (Fig. 17)")
    parser.add_argument("--seed", type=int, default=0, help="random seed")
    args = parser.parse_args(argv)
    try:
        V, F, field, kind = mesh_io.load_mesh_and_field(args.mesh, args.field, args.kind,
                                                        args.n)
        if field is None:
            raise ValueError("streamlines need a field file")
        if args.hatching:
            lines = hatching(V, F, field, kind, count=args.count, stroke_length=args.length,
                             rng=args.seed)
        else:
            lines = trace_streamlines(V, F, field, kind, count=args.count,
                                      max_length=args.length, rng=args.seed)
        ext = os.path.splitext(args.out)[1].lower()
        if ext == ".vtk":
            export.write_polylines_vtk(args.out, list(lines),
                                       line_data={"family": lines.families,
                                                  "closed": lines.closed.astype(float)})
        elif ext == ".obj":
            export.write_polylines_obj(args.out, list(lines))
        else:
            raise ValueError("unknown output extension %r (.vtk .obj)" % ext)
    except (OSError, ValueError) as e:
        print("streamlines failed: %s" % e, file=sys.stderr)
        return 1
    print(json.dumps({"out": args.out, "lines": len(lines)}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
