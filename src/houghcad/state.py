"""The state every pass works on: one label per point, and typed segment records.

:class:`Segmentation` holds ``labels`` (n,), the single truth of which point
belongs to which segment (-1: free), beside a list of
:class:`SegmentRecord`\\ s: a family, its primitive in the standard frame and
the optional typed fields a pass may set (a fillet's ``boundary``, a
``fixed`` primitive). A segment's points are never stored twice: they are
read from the labels (:meth:`Segmentation.indices`), and every write goes
through the methods below, which keep the cache of index arrays in step.

:class:`Candidate` is what recognition proposes before selection: a
primitive with the points it explains and their distances. Candidates may
overlap; segments never do.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import TYPE_CHECKING, Iterator, Protocol

import numpy as np

from .families import Family, Primitive

if TYPE_CHECKING:
    from .associate import RawGroup

#: Environment variable that turns the invariant checks on between passes.
CHECK_ENV = "HOUGHCAD_CHECK"


class Boundary(Protocol):
    """A segment's own boundary, where its unbounded surface would mislead.

    A fillet's rounded corner (:class:`houghcad.blend.Arc`) is the one kind
    today: points its profile puts on the arc are its own, points it puts on
    the faces are at infinity from it.
    """

    def distance(self, P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Distance (m,) of points P (m, 3) and whether the boundary claims them (m,)."""
        ...


@dataclass(frozen=True)
class SegmentRecord:
    """What a segment is, in the standard frame (its points live in the labels).

    Attributes
    ----------
    family : Family
    prim : Primitive
    boundary : Boundary or None
        Bounds the surface for the boundary passes (a fillet's arc).
    fixed : bool
        Keep ``prim`` through every later refit (a fillet whose radius came
        from its tangency to both neighbours).
    """

    family: Family
    prim: Primitive
    boundary: Boundary | None = None
    fixed: bool = False


@dataclass(frozen=True)
class SegmentView:
    """A segment's record with its points: a read-only snapshot.

    ``indices`` (m,) are sorted int64 indices into the cloud.
    """

    family: Family
    prim: Primitive
    indices: np.ndarray
    boundary: Boundary | None = None
    fixed: bool = False

    @property
    def record(self) -> SegmentRecord:
        return SegmentRecord(self.family, self.prim, self.boundary, self.fixed)


@dataclass
class Candidate:
    """A primitive with a dense subset X_i of the points it explains.

    ``indices`` (m,) index the whole cloud; ``distances`` (m,) are theirs to
    the primitive and ``mfe`` follows eq. (1), both in the standard frame.
    """

    family: Family
    prim: Primitive
    indices: np.ndarray
    mfe: float
    distances: np.ndarray

    @property
    def record(self) -> SegmentRecord:
        return SegmentRecord(self.family, self.prim)


def mean_fitting_error(dist: np.ndarray, P: np.ndarray) -> float:
    """Eq. (1): mean distance / diagonal of the axis-aligned bounding box of P (n, 3)."""
    diag = float(np.linalg.norm(np.ptp(P, axis=0)))
    return float(dist.mean() / diag) if diag > 0 else float("inf")


def surface_distance(s: SegmentView | SegmentRecord, P: np.ndarray, signed: np.ndarray | None = None) \
        -> tuple[np.ndarray, np.ndarray | None]:
    """Distance (m,) of points P (m, 3) to segment s's surface, and which of
    them s claims outright (bool (m,)) or None. ``signed``: the points'
    signed distances to s's primitive when the caller has them already.

    A segment with a ``boundary`` (a fillet's arc) is bounded by it: the
    points its rounded corner puts on its faces are at infinity from it, and
    those it puts on the arc are its own, whatever the faces' unbounded
    surfaces say there.
    """
    if s.boundary is not None:
        return s.boundary.distance(P)
    return (s.family.distance(s.prim, P) if signed is None else np.abs(signed)), None


class Segmentation:
    """Point ownership and segment records (see the module docstring).

    Parameters
    ----------
    n : int
        Number of points; every point starts free.

    Attributes
    ----------
    labels : ndarray of int32, shape (n,)
        Segment of each point, -1 for free. Read it; write through the methods.
    records : list of SegmentRecord
        One per segment, in id order.
    version : int
        Counts the writes: a pass that leaves it unchanged changed nothing.
    parts : list of lists of ndarray, or None
        Set by the association (paper §5.4): each segment's connected pieces,
        a partition of its points. Any later write clears it.
    groups : list of RawGroup
        Set by the association: relations between segments (ids).
    """

    def __init__(self, n: int):
        self.labels = np.full(int(n), -1, dtype=np.int32)
        self.records: list[SegmentRecord] = []
        self.version = 0
        self.parts: list[list[np.ndarray]] | None = None
        self.groups: list[RawGroup] = []
        self._cache: dict[int, np.ndarray] = {}

    @classmethod
    def of(cls, n: int, pieces) -> "Segmentation":
        """A state of n points holding ``pieces`` in order: anything with
        ``family``, ``prim`` and ``indices`` (and optionally ``boundary`` and
        ``fixed``), such as candidates or views; later pieces take shared points."""
        out = cls(n)
        for p in pieces:
            out.add(SegmentRecord(p.family, p.prim, getattr(p, "boundary", None), bool(getattr(p, "fixed", False))),
                    p.indices)
        return out

    def copy(self) -> "Segmentation":
        """An independent copy (labels copied, records shared: they are frozen)."""
        out = Segmentation(0)
        out.labels = self.labels.copy()
        out.records = list(self.records)
        out.version = self.version
        out.parts = None if self.parts is None else [list(p) for p in self.parts]
        out.groups = list(self.groups)
        return out

    # ------------------------------------------------------------------ reading
    def __len__(self) -> int:
        return len(self.records)

    def __getitem__(self, k: int) -> SegmentView:
        r = self.records[k]
        return SegmentView(r.family, r.prim, self.indices(k), r.boundary, r.fixed)

    def __iter__(self) -> Iterator[SegmentView]:
        return (self[k] for k in range(len(self.records)))

    @property
    def n_points(self) -> int:
        return len(self.labels)

    def indices(self, k: int) -> np.ndarray:
        """Sorted indices (m,) of segment k's points (int64)."""
        if k not in self._cache:
            self._cache[k] = np.flatnonzero(self.labels == k)
        return self._cache[k]

    def pieces(self, k: int) -> list[np.ndarray]:
        """Segment k's connected pieces: its :attr:`parts` once the association set them, else
        the segment whole (one piece)."""
        return list(self.parts[k]) if self.parts is not None else [self.indices(k)]

    @property
    def free(self) -> np.ndarray:
        """Bool mask (n,) of the points no segment holds (a copy)."""
        return self.labels < 0

    def owner(self) -> np.ndarray:
        """The labels as int64 (n,), for index arithmetic that must not overflow."""
        return self.labels.astype(np.int64)

    def sizes(self) -> np.ndarray:
        """Points per segment, shape (len(self),)."""
        return np.bincount(self.labels[self.labels >= 0], minlength=len(self.records))

    # ------------------------------------------------------------------ writing
    def _touch(self, labels: np.ndarray | None = None) -> None:
        self.version += 1
        self.parts, self.groups = None, []
        if labels is None:
            self._cache.clear()
            return
        for k in np.unique(labels).tolist():
            self._cache.pop(int(k), None)

    def add(self, record: SegmentRecord, idx: np.ndarray) -> int:
        """Append a segment holding the points ``idx`` (taken from whoever held them); its id."""
        k = len(self.records)
        self.records.append(record)
        self.assign(idx, k)
        return k

    def assign(self, idx: np.ndarray, k: int) -> None:
        """Give the points ``idx`` to segment k (-1: free them)."""
        idx = np.asarray(idx, dtype=np.int64)
        if len(idx) == 0:
            return
        old = self.labels[idx]
        self.labels[idx] = k
        self._touch(np.r_[old, k])

    def release(self, idx: np.ndarray) -> None:
        """Free the points ``idx``."""
        self.assign(idx, -1)

    def set_points(self, k: int, idx: np.ndarray) -> None:
        """Segment k holds exactly the points ``idx`` (its others are freed)."""
        self.release(self.indices(k))
        self.assign(idx, k)

    def set_record(self, k: int, record: SegmentRecord) -> None:
        """Replace segment k's record (its points stay)."""
        self.records[k] = record
        self.version += 1
        self.parts, self.groups = None, []

    def relabel(self, labels: np.ndarray) -> None:
        """Replace every label at once (-1: free); shape (n,)."""
        self.labels = np.asarray(labels, dtype=np.int32).copy()
        self._touch()

    def remove(self, ks) -> None:
        """Delete the segments ``ks``: their points are freed and the later ids move down."""
        ks = sorted({int(k) for k in ks})
        if not ks:
            return
        keep = np.ones(len(self.records), bool)
        keep[ks] = False
        new_id = np.full(len(self.records) + 1, -1, dtype=np.int32)  # last slot: free stays free
        new_id[:-1][keep] = np.arange(int(keep.sum()), dtype=np.int32)
        self.labels = new_id[self.labels]
        self.records = [r for r, k in zip(self.records, keep) if k]
        self._touch()

    def rebuild(self, records: list[SegmentRecord], parts: list[np.ndarray]) -> None:
        """Replace every segment: ``records[k]`` holds the points ``parts[k]``
        (disjoint index arrays); every other point is freed."""
        labels = np.full(len(self.labels), -1, dtype=np.int32)
        for k, idx in enumerate(parts):
            labels[idx] = k
        self.records = list(records)
        self.labels = labels
        self._touch()

    def remove_empty(self) -> None:
        """Delete the segments that hold no point."""
        self.remove(np.flatnonzero(self.sizes() == 0))

    # ------------------------------------------------------------------ invariants
    def check(self) -> None:
        """Raise AssertionError unless the state is consistent: labels of
        dtype int32 in [-1, len(records)), every segment holds a point, every
        record is typed, and the cached index arrays agree with the labels."""
        m = len(self.records)
        assert self.labels.dtype == np.int32 and self.labels.ndim == 1, "labels must be (n,) int32"
        assert self.labels.min(initial=-1) >= -1 and self.labels.max(initial=-1) < m, "label out of range"
        sizes = self.sizes()
        assert (sizes > 0).all(), f"empty segments: {np.flatnonzero(sizes == 0).tolist()}"
        for k, r in enumerate(self.records):
            assert isinstance(r, SegmentRecord), f"record {k} is {type(r).__name__}"
            assert isinstance(r.family, Family) and isinstance(r.prim, Primitive), f"record {k} untyped"
        for k, idx in self._cache.items():
            assert np.array_equal(idx, np.flatnonzero(self.labels == k)), f"stale indices of segment {k}"
        if self.parts is not None:
            assert len(self.parts) == m, "one list of parts per segment"
            for k, pieces in enumerate(self.parts):
                joined = np.sort(np.concatenate(pieces))
                assert np.array_equal(joined, self.indices(k)), f"parts of segment {k} do not partition it"
        for g in self.groups:
            assert all(0 <= i < m for i in g.members), f"group {g.kind} names a missing segment"


def checks_enabled() -> bool:
    """Whether ``$HOUGHCAD_CHECK`` asks for the invariant checks."""
    return os.environ.get(CHECK_ENV, "") not in ("", "0")
