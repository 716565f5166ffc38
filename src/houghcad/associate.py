"""Segment association (paper §5.4): maximal primitives, patterns and relations.

After recognition, each segment gets

- *shape* descriptors, independent of its position: the family's own
  (radius, half-angle, radii ...) and the segment's extent (its sorted
  principal ranges);
- a *placement* (:class:`houghcad.families.base.Frame`): normal and offset,
  axis line, centre or apex.

Complete-linkage hierarchical clustering (scipy) on these finds

- ``same_primitive``: segments lying on one surface, adjacent or not. A
  merge is accepted only if one primitive refitted on the union explains
  every member as well as its own fit did (within half the inlier
  threshold), so tolerances on the parameters only propose;
- ``translation``: equal shape descriptors, parallel axes or normals;
- ``reflection``: equal shape, two axis directions that a plane mirror
  exchanges, with the placements mirrored too;
- ``rotation``: equal shape, several axis directions otherwise;
- ``coaxial``: one axis line; ``parallel``: parallel axes or normals (not
  already a coaxial or translation group).

Complete linkage keeps every pair of a group within the tolerances (no
chaining), which is why the paper uses it.

Everything runs in the cloud's standard frame (unit cube); tolerances are
fractions of its diagonal, so they are relative to the model's size.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
from scipy.cluster.hierarchy import fcluster, linkage
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from .errors import InputError
from .families.base import Family, Frame, Primitive, regular_indices, unit
from .adjacency import SegmentGraph
from .bridges import ROW_PERCENTILES, ROW_POINTS, bridged, sampling_gaps
from .state import SegmentView
from .tolerances import AssociationTolerances

__all__ = ["Associator", "Item", "RawGroup", "extent", "pivot"]

#: Extents span the central share of the points, read on a regular subsample, as a row's width
#: does (:mod:`houghcad.bridges`): a few edge points a segment took from its neighbour do not
#: change them.
EXTENT_PERCENTILES = ROW_PERCENTILES
EXTENT_POINTS = ROW_POINTS
#: Stands for an infinite dissimilarity in the linkage.
_FAR = 1e9
#: Integer descriptors are equal or not at all.
_INTEGER_TOL = 0.5
#: Guards a division by a zero span.
_TINY = 1e-12


@dataclass
class Item:
    """A (possibly merged) segment in the standard frame.

    ``parts`` are its connected pieces (index arrays into the cloud); ``members``
    the positions of the raw segments it was made from.
    """

    family: Family
    prim: Primitive
    indices: np.ndarray
    parts: list[np.ndarray]
    members: list[int]
    #: Keep ``prim`` through the final refit (a fillet whose radius came
    #: from its tangency to both neighbours; see :mod:`houghcad.blend`).
    fixed: bool = False


@dataclass
class RawGroup:
    """A group over item positions, with shared descriptors (standard units)."""

    kind: str
    members: list[int]
    descriptors: dict = field(default_factory=dict)


def extent(P: np.ndarray, direction: np.ndarray | None = None) -> np.ndarray:
    """Size of a segment, shape (3,), P's units (P: (n, 3)).

    Without ``direction``: the sorted principal ranges. With the segment's axis
    or normal: the range along it, then the sorted principal ranges across it
    (PCA alone mixes the axis and a diameter when they are of similar length).
    Each range spans the central 95 % of the points, so a few edge points a
    segment took from its neighbour do not change it. Invariant under rigid
    motions: equal features have equal extents.
    """
    if len(P) < 2:
        return np.zeros(3)
    Q = P - P.mean(axis=0)
    Qs = Q[:: max(1, len(Q) // EXTENT_POINTS)]
    if direction is None:
        _, _, vt = np.linalg.svd(Qs, full_matrices=False)
        lo, hi = np.percentile(Qs @ vt.T, EXTENT_PERCENTILES, axis=0)
        return np.sort(hi - lo)[::-1]
    a = unit(np.asarray(direction, float))
    h = Qs @ a
    across = Qs - np.outer(h, a)
    _, _, vt = np.linalg.svd(across, full_matrices=False)
    lo, hi = np.percentile(across @ vt[:2].T, EXTENT_PERCENTILES, axis=0)
    h_lo, h_hi = np.percentile(h, EXTENT_PERCENTILES)
    return np.concatenate([[h_hi - h_lo], np.sort(hi - lo)[::-1]])


def pivot(frame: Frame, P: np.ndarray) -> np.ndarray:
    """A distinguished point of a placed segment, shape (3,): the centre or apex;
    on an axis line, the foot of the points' centroid; on a plane, the centroid."""
    c = P.mean(axis=0)
    if frame.kind == "line":
        a = frame.direction
        return frame.anchor + ((c - frame.anchor) @ a) * a
    if frame.kind == "plane":
        return c
    return np.asarray(frame.anchor, float)


def _angle(a: np.ndarray, b: np.ndarray, oriented: bool) -> float:
    """Angle between two unit directions, radians; sign ignored unless oriented."""
    c = float(a @ b)
    if not oriented:
        c = abs(c)
    return float(np.arccos(np.clip(c, -1.0, 1.0)))


def _line_distance(p: np.ndarray, a: np.ndarray, q: np.ndarray, b: np.ndarray) -> float:
    """Symmetric distance between lines (p, a) and (q, b) measured at their anchors."""
    d1 = np.linalg.norm(np.cross(q - p, a))
    d2 = np.linalg.norm(np.cross(p - q, b))
    return float(max(d1, d2))


def _pairwise(ids: list[int], dist) -> np.ndarray:
    """Symmetric matrix (len(ids), len(ids)) of dist(ids[a], ids[b]), zero diagonal."""
    n = len(ids)
    D = np.zeros((n, n))
    for a in range(n):
        for b in range(a + 1, n):
            D[a, b] = D[b, a] = dist(ids[a], ids[b])
    return D


def _complete_linkage(D: np.ndarray) -> np.ndarray:
    """Cluster labels (n,) of complete linkage cut at distance 1 on a normalised
    dissimilarity matrix D (n, n)."""
    n = len(D)
    if n == 1:
        return np.zeros(1, dtype=np.int64)
    D = np.minimum(np.nan_to_num(D, nan=_FAR, posinf=_FAR), _FAR)
    iu = np.triu_indices(n, 1)
    Z = linkage(D[iu], method="complete")
    return fcluster(Z, t=1.0, criterion="distance").astype(np.int64) - 1


def _clusters(D: np.ndarray, keep: np.ndarray | None = None) -> list[list[int]]:
    """Clusters of two or more among rows of D (complete linkage, cut at 1)."""
    lab = _complete_linkage(D)
    out = []
    for k in np.unique(lab):
        m = np.flatnonzero(lab == k)
        if len(m) >= 2:
            out.append([int(i) for i in m])
    return out


class Associator:
    """Find maximal primitives and relations between segments (paper §5.4).

    Parameters
    ----------
    merge : bool
        Merge segments of one primitive into a maximal primitive. Without it
        the raw segments stay and ``same_primitive`` groups list them.
    tol : AssociationTolerances, optional
        The thresholds (:class:`houghcad.tolerances.AssociationTolerances`:
        ``angle_tol``, ``length_tol``, ``relative_tol``, ``extent_tol``,
        ``contact`` ...).
    **options
        Fields of ``tol`` to set, e.g. ``contact=0.5``.

    Attributes (after :meth:`fit`)
    ----------
    items_ : list of Item
    groups_ : list of RawGroup
    """

    def __init__(self, merge: bool = True, tol: AssociationTolerances | None = None, **options: float | None):
        self.merge = merge
        # Unknown options raise TypeError, as unknown keyword arguments do.
        self.tol = replace(tol or AssociationTolerances(), **options)

    # ------------------------------------------------------------------ entry point
    def fit(self, cands: list[SegmentView], pre, tau: float, link: float) -> "Associator":
        """Associate segments ``cands`` (standard frame) of the preprocessed cloud ``pre``.

        ``tau`` is the inlier threshold and ``link`` the neighbour distance of the
        run, standard units.
        """
        self._pre, self._tau = pre, float(tau)
        diag = float(pre.diagonal)
        t = self.tol
        self._L = (t.length_tol * diag if t.length_tol is not None
                   else max(t.length_floor * diag, t.length_taus * self._tau))
        self._A = np.radians(t.angle_tol)
        self._E = t.extent_floor * diag
        # Parts are compared by their final least-squares fits: the recognition
        # fits of small segments can be a degree or two off.
        cands = [c if c.fixed else replace(c, prim=self._refit(c.family, c.prim, np.sort(c.indices)))
                 for c in cands]
        self._own = [self._mean_residual(c.family, c.prim, c.indices) for c in cands]
        owner = np.full(len(pre.points), -1, dtype=np.int64)  # each point's segment, -1 free
        for k, c in enumerate(cands):
            owner[c.indices] = k
        adjacency = self._adjacency(cands, owner, link)
        surfaces = self._surfaces(cands)

        items: list[Item] = []
        same: list[tuple[list[int], int]] = []  # per merged surface: raw members, number of parts
        for members in surfaces:
            if len(members) == 1:
                c = cands[members[0]]
                items.append(Item(c.family, c.prim, np.sort(c.indices), [np.sort(c.indices)], members, c.fixed))
                continue
            idx = np.sort(np.concatenate([cands[m].indices for m in members]))
            prim = self._refit(cands[members[0]].family, cands[members[0]].prim, idx)
            pieces = [cands[m].indices for m in members]
            gaps = bridged(pieces, self._pre.points, self._pre.tree, cands[members[0]].family, prim, link, self.tol)
            gaps |= sampling_gaps(members, pieces, owner, self._pre.points, self._pre.tree, link, self.tol)
            parts_of = self._parts(members, adjacency | {(members[i], members[j]) for i, j in gaps})
            same.append((members, len(parts_of)))
            parts = [np.sort(np.concatenate([cands[m].indices for m in p])) for p in parts_of]
            items.append(Item(cands[members[0]].family, prim, idx, parts, members))

        groups = self._relations(items)
        if self.merge:
            for i, it in enumerate(items):
                if len(it.parts) > 1:
                    groups.insert(0, RawGroup("same_primitive", [i], {"parts": len(it.parts)}))
            self.items_ = items
        else:
            # Raw segments stay; groups over maximal items expand to their members.
            raw = [Item(c.family, c.prim, np.sort(c.indices), [np.sort(c.indices)], [k], c.fixed)
                   for k, c in enumerate(cands)]
            expanded = [RawGroup(g.kind, sorted(m for i in g.members for m in items[i].members), g.descriptors)
                        for g in groups]
            groups = [RawGroup("same_primitive", sorted(m), {"parts": n_parts}) for m, n_parts in same] + expanded
            self.items_ = raw
        self.groups_ = groups
        return self

    # ------------------------------------------------------------------ geometry helpers
    def _mean_residual(self, fam: Family, prim: Primitive, idx: np.ndarray) -> float:
        return float(np.mean(fam.distance(prim, self._pre.points[idx]))) if len(idx) else 0.0

    def _refit(self, fam: Family, prim: Primitive, idx: np.ndarray) -> Primitive:
        """Least-squares fit on (a deterministic subsample of) the points idx."""
        sel = idx[regular_indices(len(idx), self.tol.refit_points)]
        try:
            out = fam.fit(prim, self._pre.points[sel], self._pre.normals[sel])
        except InputError:  # a user family's function failing: bad input, not a failed fit
            raise
        except (np.linalg.LinAlgError, ValueError):
            out = None
        return out if out is not None else prim

    def _adjacency(self, cands: list[SegmentView], owner: np.ndarray, link: float) -> set[tuple[int, int]]:
        """Pairs (i < j) of segments in contact along a line, not at a point.

        Points closer than ``link`` to the other segment are the contact. Two
        pieces of one face cut apart by the splitting phase share a boundary
        about as long as their width; two CAD faces of one surface that meet
        at a corner touch at a few points. A line contact holds at least
        ``contact`` × √(points of the smaller) points on each side; fewer on
        either side is a point contact, or two faces a little more than
        ``link`` apart that come close at a few points. ``owner`` (n,): each
        point's segment (its position in ``cands``), -1 free.
        """
        if len(cands) < 2:
            return set()
        g = SegmentGraph.build(owner, self._pre.points, link, pairs=self._pre.pairs_within(link))
        sizes = np.array([len(c.indices) for c in cands])
        least = g.contact.min(axis=1)
        u, v = g.edges[:, 0], g.edges[:, 1]
        ok = least >= self.tol.contact * np.sqrt(np.minimum(sizes[u], sizes[v]))
        return {(int(a), int(b)) for a, b in g.edges[ok].tolist()}

    def _parts(self, members: list[int], adjacency: set[tuple[int, int]]) -> list[list[int]]:
        """Connected components of members under adjacency (lists of members)."""
        n = len(members)
        pos = {m: i for i, m in enumerate(members)}
        e = [(pos[a], pos[b]) for a, b in adjacency if a in pos and b in pos]
        if not e:
            return [[m] for m in members]
        r, c = np.array(e).T
        G = coo_matrix((np.ones(len(r)), (r, c)), shape=(n, n))
        k, lab = connected_components(G, directed=False)
        return [[members[i] for i in np.flatnonzero(lab == j)] for j in range(k)]

    # ------------------------------------------------------------------ same primitive
    def _shape(self, fam: Family, prim: Primitive) -> dict[str, float]:
        return {k: float(v) for k, v in fam.descriptors(prim).items()}

    def _tol(self, fam: Family, key: str, a: float, b: float, L: float, A: float) -> float:
        """Tolerance on a shape descriptor: lengths L plus a relative part, angles A,
        integers exact."""
        if key in fam.length_descriptors:
            return L + self.tol.relative_tol * max(abs(a), abs(b))
        if key in fam.integer_descriptors:
            return _INTEGER_TOL
        return A

    def _shape_distance(self, fam: Family, dp: dict, dq: dict, L: float, A: float) -> float:
        """Largest normalised difference between two sets of shape descriptors."""
        return max((abs(dp[k] - dq[k]) / self._tol(fam, k, dp[k], dq[k], L, A) for k in dp), default=0.0)

    def _param_distance(self, fam: Family, p: Primitive, q: Primitive, L: float, A: float) -> float:
        """Normalised dissimilarity of two primitives of one family (≤ 1: may be one surface)."""
        d = self._shape_distance(fam, self._shape(fam, p), self._shape(fam, q), L, A)
        f, g = fam.frame(p), fam.frame(q)
        if f is None or g is None:
            return d
        if f.direction is not None and g.direction is not None:
            d = max(d, _angle(f.direction, g.direction, f.oriented) / A)
        if f.kind == "plane":
            d = max(d, abs(float(f.direction @ (g.anchor - f.anchor))) / L)
        elif f.kind == "line":
            d = max(d, _line_distance(f.anchor, f.direction, g.anchor, g.direction) / L)
        else:
            d = max(d, float(np.linalg.norm(f.anchor - g.anchor)) / L)
        return d

    def _surfaces(self, cands: list[SegmentView]) -> list[list[int]]:
        """Partition of the segments into sets lying on one surface."""
        out: list[list[int]] = []
        by_family: dict[str, list[int]] = {}
        for k, c in enumerate(cands):
            by_family.setdefault(c.family.name, []).append(k)
        # Proposals are generous (a part's own fit may be loose); the union refit decides.
        Lp, Ap = self.tol.propose_lengths * self._L, self.tol.propose_angles * self._A
        for name, ks in by_family.items():
            if len(ks) == 1:
                out.append(ks)
                continue
            fam = cands[ks[0]].family
            D = _pairwise(ks, lambda i, j: self._param_distance(fam, cands[i].prim, cands[j].prim, Lp, Ap))
            lab = _complete_linkage(D)
            for k in np.unique(lab):
                grp = sorted((ks[i] for i in np.flatnonzero(lab == k)), key=lambda m: -len(cands[m].indices))
                out.extend(self._verify(cands, grp))
        return sorted(out, key=lambda m: m[0])

    def _verify(self, cands: list[SegmentView], grp: list[int]) -> list[list[int]]:
        """Split a proposed surface into sets that one refitted primitive explains:
        greedily from the largest, a member joins when the union's fit keeps every
        member within its own residual plus τ/2."""
        rest = list(grp)
        out = []
        while rest:
            acc = [rest.pop(0)]
            fam = cands[acc[0]].family
            for m in list(rest):
                trial = acc + [m]
                idx = np.concatenate([cands[t].indices for t in trial])
                prim = self._refit(fam, cands[acc[0]].prim, idx)
                if all(self._mean_residual(fam, prim, cands[t].indices) <= self._own[t] + self.tol.verify_taus * self._tau
                       for t in trial):
                    acc.append(m)
                    rest.remove(m)
            out.append(sorted(acc))
        return out

    # ------------------------------------------------------------------ relations
    def _relations(self, items: list[Item]) -> list[RawGroup]:
        pts = self._pre.points
        frames = [it.family.frame(it.prim) for it in items]
        shapes = [self._shape(it.family, it.prim) for it in items]
        ext = [extent(pts[it.indices], f.direction if f is not None else None) for f, it in zip(frames, items)]
        piv = [pivot(f, pts[it.indices]) if f is not None else pts[it.indices].mean(axis=0)
               for f, it in zip(frames, items)]
        # An axis fitted on a piece of length h is known to about (length
        # tolerance) / h radians: short holes get a looser angle tolerance.
        span = [e[0] if f is not None and f.kind != "plane" else e[2] for f, e in zip(frames, ext)]
        self._unc = [np.arctan2(self.tol.axis_lengths * self._L, max(h, _TINY)) for h in span]
        fit = [self._mean_residual(it.family, it.prim, it.indices) for it in items]
        groups: list[RawGroup] = []

        # Congruent segments: one family, equal shape descriptors and extents.
        by_family: dict[str, list[int]] = {}
        for i, it in enumerate(items):
            by_family.setdefault(it.family.name, []).append(i)
        for name, ks in by_family.items():
            if len(ks) < 2:
                continue
            fam = items[ks[0]].family

            def congruence(i, j):
                tol_e = np.maximum(self._E, self.tol.extent_tol * np.maximum(ext[i], ext[j]))
                L = self._fit_length(fit[i], fit[j])
                return max(self._shape_distance(fam, shapes[i], shapes[j], L, self._A),
                           float(np.max(np.abs(ext[i] - ext[j]) / tol_e)))

            D = _pairwise(ks, congruence)
            for cl in _clusters(D):
                members = [ks[a] for a in cl]
                groups.extend(self._congruent(items, members, frames, shapes, ext, piv))

        translation_sets = {frozenset(g.members) for g in groups if g.kind == "translation"}

        # Coaxial: one axis line (cylinders, cones, tori ...).
        axial = [i for i, f in enumerate(frames) if f is not None and f.kind in ("line", "point")
                 and f.direction is not None]
        coaxial_sets = set()
        if len(axial) >= 2:
            def off_axis(i, j):
                f, g = frames[i], frames[j]
                return max(_angle(f.direction, g.direction, False) / self._atol(i, j),
                           _line_distance(f.anchor, f.direction, g.anchor, g.direction) / (self.tol.coaxial_lengths * self._L))

            D = _pairwise(axial, off_axis)
            for cl in _clusters(D):
                members = sorted(axial[a] for a in cl)
                coaxial_sets.add(frozenset(members))
                f = frames[members[0]]
                groups.append(RawGroup("coaxial", members, {"axis": f.direction, "axis_point": piv[members[0]]}))

        # Parallel: planes by their normals, axial segments by their axes.
        for kinds in (("plane",), ("line", "point")):
            ks = [i for i, f in enumerate(frames) if f is not None and f.kind in kinds and f.direction is not None]
            if len(ks) < 2:
                continue
            D = _pairwise(ks, lambda i, j: _angle(frames[i].direction, frames[j].direction, False)
                          / self._atol(i, j))
            for cl in _clusters(D):
                members = sorted(ks[a] for a in cl)
                if frozenset(members) in coaxial_sets or frozenset(members) in translation_sets:
                    continue
                key = "normal" if kinds == ("plane",) else "axis"
                groups.append(RawGroup("parallel", members, {key: _mean_direction([frames[m] for m in members])}))
        return groups

    def _fit_length(self, r1: float, r2: float) -> float:
        """Tolerance on equal lengths of two fits whose mean point distances are r1, r2.

        A fit's radius is known about as well as its points lie on it: noisy
        points or a few points of a neighbour loosen it, exact points make it
        exact. A floor on the model's size would let small holes of different
        radii on a large part pass for equal ones.
        """
        if self.tol.length_tol is not None:
            return self._L
        return self.tol.fit_residuals * max(r1, r2, _TINY)

    def _atol(self, i: int, j: int) -> float:
        """Angle tolerance between the axes of items i and j (set by :meth:`_relations`)."""
        return self._A + max(self._unc[i], self._unc[j])

    def _congruent(self, items, members, frames, shapes, ext, piv) -> list[RawGroup]:
        """Translation / rotation / reflection groups among congruent segments."""
        shared = {k: float(np.mean([shapes[m][k] for m in members])) for k in shapes[members[0]]}
        shared["extent"] = np.mean([ext[m] for m in members], axis=0)
        shared["type"] = items[members[0]].family.name
        f0 = frames[members[0]]
        if f0 is None or f0.direction is None:
            return [RawGroup("translation", sorted(members), shared)]
        oriented = f0.oriented
        D = _pairwise(members, lambda i, j: _angle(frames[i].direction, frames[j].direction, oriented)
                      / self._atol(i, j))
        lab = _complete_linkage(D)
        subs = [[members[i] for i in np.flatnonzero(lab == k)] for k in np.unique(lab)]
        out = []
        for s in subs:
            if len(s) >= 2:
                d = _mean_direction([frames[m] for m in s])
                out.append(RawGroup("translation", sorted(s), {**shared, "axis": d}))
        if len(subs) == 2:
            mirror = self._mirror(subs[0], subs[1], frames, piv, oriented)
            if mirror is not None:
                out.append(RawGroup("reflection", sorted(members), {**shared, **mirror}))
                return out
        if len(subs) >= 2:
            out.append(RawGroup("rotation", sorted(members), shared))
        return out

    def _mirror(self, s1, s2, frames, piv, oriented) -> dict | None:
        """The plane mirror exchanging two sets of congruent segments, if any:
        through the middle of their pivots' centroids, normal along the line
        joining them; reported with the normal its directions give.

        A mirror of unit normal n maps a direction d to d − 2(d·n)n, so the two
        sets' directions d1, d2 differ along n: n ∥ d1 − d2. The fitted axes and
        normals are exact on exact points, while the pivots (feet of the points'
        centroids on the axes) slide along the axes with the sampling and tilt
        the normal drawn through them. An unoriented direction leaves two
        bisector planes, d1 ∓ d2: the pivots choose. Directions too close to
        tell a bisector keep the pivots' normal.
        """
        c1 = np.mean([piv[m] for m in s1], axis=0)
        c2 = np.mean([piv[m] for m in s2], axis=0)
        if np.linalg.norm(c2 - c1) < self.tol.mirror_lengths * self._L:
            return None
        m = unit(c2 - c1)
        mid = (c1 + c2) / 2

        def reflect_dir(d):
            return d - 2.0 * (d @ m) * m

        def reflect_pt(p):
            return p - 2.0 * ((p - mid) @ m) * m

        d1 = _mean_direction([frames[k] for k in s1])
        d2 = _mean_direction([frames[k] for k in s2])
        for k in s1:
            if _angle(reflect_dir(frames[k].direction), d2, oriented) > max(self._atol(k, j) for j in s2):
                return None
        tol = self.tol.mirror_lengths * self._L
        for a, b in ((s1, s2), (s2, s1)):
            for k in a:
                p = reflect_pt(piv[k])
                if min(np.linalg.norm(p - piv[j]) for j in b) > tol:
                    return None
        chords = (d1 - d2, d1 + d2)[: 1 if oriented else 2]
        chord = max(chords, key=lambda v: abs(v @ m) / max(np.linalg.norm(v), _TINY))
        if np.linalg.norm(chord) > 2.0 * np.sin(self._A / 2):
            m = unit(chord if chord @ m >= 0 else -chord)
        return {"mirror_normal": m, "mirror_point": mid}


def _mean_direction(frames: list[Frame]) -> np.ndarray:
    """Mean of unit directions, signs aligned with the first, shape (3,)."""
    d0 = frames[0].direction
    acc = np.zeros(3)
    for f in frames:
        d = f.direction
        acc += d if (f.oriented or d @ d0 >= 0) else -d
    return unit(acc)
