"""Result dataclasses shared by the pipeline, the writers and the evaluator.

Parameters are always in the input's own coordinates (world frame).
Parameter names per family (all vectors are lists of 3 floats, angles in radians):

- plane: ``normal`` (unit), ``offset`` (``normal · x = offset``), ``point``
- cylinder: ``axis_point``, ``axis`` (unit), ``radius``
- cone: ``apex``, ``axis`` (unit, from the apex into the opening), ``half_angle``
- sphere: ``center``, ``radius``
- torus: ``center``, ``axis`` (unit), ``major_radius``, ``minor_radius``
"""

from __future__ import annotations

import json
from collections import Counter
from dataclasses import dataclass, field
from typing import Any

import numpy as np

#: The version of the JSON result's layout (its ``"version"``): a reader refuses a newer one.
RESULT_VERSION = 2


class _ByValue:
    """Equality by value, as the JSON holds it (``to_dict``; NaN equal to NaN): the dataclasses'
    generated ``==`` compared numpy arrays and raised. Unhashable, as a mutable dataclass is."""

    def _compared(self) -> dict[str, Any]:
        return self.to_dict()  # type: ignore[attr-defined]

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, type(self)):
            return NotImplemented
        return json.dumps(self._compared(), sort_keys=True) == json.dumps(other._compared(), sort_keys=True)

    __hash__ = None  # type: ignore[assignment]


@dataclass(eq=False)
class Segment(_ByValue):
    """One recognised primitive.

    Attributes
    ----------
    id : int
        Position of the segment in :attr:`Result.segments`.
    type : str
        Lowercase family name (``"plane"``, ``"cylinder"`` ...).
    indices : ndarray of int64, shape (M,)
        0-based indices into the input's point order, sorted.
    params : dict
        Named parameters in world coordinates (see module docstring).
    mfe : float
        Mean fitting error, eq. (1) of the paper: mean distance to the primitive
        divided by the diagonal of the segment's axis-aligned bounding box.
    parts : list of Part
        The connected pieces (faces) of a maximal primitive, when it has more
        than one; empty otherwise (the segment is its own single part).
    descriptors : dict
        Position-independent descriptors (``radius``, ``half_angle``,
        ``extent`` ...), world units.
    edges : ndarray of int64, shape (E,)
        Points that other segments own and that lie on this segment's boundary curves, on both
        surfaces (:func:`houghcad.boundaries.edge_points`; clean clouds), sorted; with parts,
        the union of theirs.
    """

    id: int
    type: str
    indices: np.ndarray
    params: dict[str, Any]
    mfe: float
    parts: list["Part"] = field(default_factory=list)
    descriptors: dict[str, Any] = field(default_factory=dict)
    edges: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))

    def faces(self) -> list[np.ndarray]:
        """Index arrays of the segment's connected pieces (one when it has no parts), each with
        the points of its boundary curves (:attr:`edges`): a CAD face holds its boundary, and a
        point on it is on both faces."""
        if self.parts:
            return [p.with_edges() for p in self.parts]
        return [self.with_edges()]

    def with_edges(self) -> np.ndarray:
        """The segment's points and its boundary curves' (sorted): the maximal primitive as
        ``houghcad evaluate --maximal`` scores it."""
        return _union(self.indices, self.edges)

    def to_dict(self) -> dict[str, Any]:
        d = {
            "id": int(self.id),
            "type": self.type,
            "n_points": int(len(self.indices)),
            "mfe": float(self.mfe),
            "params": _jsonable(self.params),
            "descriptors": _jsonable(self.descriptors),
            "indices": [int(i) for i in self.indices],
            "edge_indices": [int(i) for i in self.edges],
        }
        if self.parts:
            d["parts"] = [p.to_dict() for p in self.parts]
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "Segment":
        """The segment of :meth:`to_dict`'s dict ``d``; ValueError naming the segment when its
        (or a part's) ``params`` are missing (its ``n_points`` is checked by
        :meth:`Result.from_dict`, after the indices' range). The ``type`` is any name: a
        user-defined family's result is read where that family is not registered."""
        sid, kind, indices = _whole(d["id"], "segment id"), str(d["type"]), _indices(d["indices"])
        parts = [Part.from_dict(p) for p in d.get("parts", [])]
        for j, given in enumerate(d.get("parts", [])):
            _params(given, f"segment {sid}, part {j}")
        return cls(
            id=sid,
            type=kind,
            indices=indices,
            params=_params(d, f"segment {sid}"),
            mfe=float(d.get("mfe", float("nan"))),
            parts=parts,
            descriptors=dict(d.get("descriptors", {})),
            edges=_indices(d.get("edge_indices", [])),
        )


@dataclass(eq=False)
class Part(_ByValue):
    """One connected piece of a maximal primitive, with its own fit.

    Attributes
    ----------
    indices : ndarray of int64, shape (M,)
        0-based input indices, sorted.
    params : dict
        The piece's own parameters (world coordinates).
    mfe : float
    edges : ndarray of int64, shape (E,)
        Points other pieces own on this piece's boundary curves (see :attr:`Segment.edges`).
    """

    indices: np.ndarray
    params: dict[str, Any]
    mfe: float
    edges: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))

    def with_edges(self) -> np.ndarray:
        """The piece's points and its boundary curves' (sorted)."""
        return _union(self.indices, self.edges)

    def to_dict(self) -> dict[str, Any]:
        return {"n_points": int(len(self.indices)), "mfe": float(self.mfe),
                "params": _jsonable(self.params), "indices": [int(i) for i in self.indices],
                "edge_indices": [int(i) for i in self.edges]}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "Part":
        # Its params and n_points are checked by Segment.from_dict, which can name the segment.
        return cls(indices=_indices(d["indices"]), params=dict(d.get("params", {})),
                   mfe=float(d.get("mfe", float("nan"))),
                   edges=_indices(d.get("edge_indices", [])))


def _union(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Sorted union of two index arrays (``a`` itself when ``b`` is empty)."""
    return np.union1d(a, b).astype(np.int64) if len(b) else a


#: Kinds of :class:`Group`, in the order they are reported.
GROUP_KINDS = ("same_primitive", "translation", "rotation", "reflection", "coaxial", "parallel")


@dataclass(eq=False)
class Group(_ByValue):
    """A relation between segments found by the association step (paper §5.4).

    Attributes
    ----------
    kind : str
        One of :data:`GROUP_KINDS`.
    members : list of int
        Segment ids, ascending.
    descriptors : dict
        What the members share (``radius``, ``axis`` ...), world units.
    """

    kind: str
    members: list[int]
    descriptors: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return {"kind": self.kind, "members": [int(m) for m in self.members],
                "descriptors": _jsonable(self.descriptors)}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "Group":
        return cls(kind=str(d["kind"]), members=[int(m) for m in d["members"]],
                   descriptors=dict(d.get("descriptors", {})))


@dataclass(eq=False)
class Result(_ByValue):
    """Decomposition of a point cloud into primitives.

    Attributes
    ----------
    n_points : int
        Number of input points.
    segments : list of Segment
    unsegmented : ndarray of int64
        Indices of the points no primitive explains.
    timing : dict
        Wall-clock seconds per stage.
    options : dict
        The options the run used.
    source : str or None
        Path of the input file, when there was one.
    groups : list of Group
        Relations between segments (association step).
    normals : ndarray (n_points, 3) or None
        The unit normals the run used, world axes (not saved in the JSON).
    distances : ndarray (n_points,) or None
        Each point's distance to its segment's fitted surface, world units;
        NaN where unsegmented (not saved in the JSON).
    """

    n_points: int
    segments: list[Segment]
    unsegmented: np.ndarray
    timing: dict[str, float] = field(default_factory=dict)
    options: dict[str, Any] = field(default_factory=dict)
    source: str | None = None
    groups: list[Group] = field(default_factory=list)
    normals: np.ndarray | None = field(default=None, repr=False, compare=False)
    distances: np.ndarray | None = field(default=None, repr=False, compare=False)

    def __repr__(self) -> str:
        # A few lines, not every index array (the dataclass's own repr printed them all).
        kinds = Counter(s.type for s in self.segments)
        made = ", ".join(f"{n} {t}" for t, n in kinds.most_common())
        return (f"Result(n_points={self.n_points}, {len(self.segments)} segments ({made or 'none'}), "
                f"{len(self.unsegmented)} unsegmented, {len(self.groups)} groups, source={self.source!r})")

    def labels(self) -> np.ndarray:
        """Per-point segment id, shape (n_points,), -1 for unsegmented points."""
        lab = np.full(self.n_points, -1, dtype=np.int64)
        for s in self.segments:
            lab[s.indices] = s.id
        return lab

    def group_labels(self) -> np.ndarray:
        """Per-point id of the first translation/rotation/reflection/same-primitive
        group holding the point's segment, shape (n_points,), -1 for none."""
        seg_group = np.full(len(self.segments), -1, dtype=np.int64)
        for g_id, g in enumerate(self.groups):
            if g.kind in ("coaxial", "parallel"):
                continue  # relations, not features: they would hide the patterns
            for m in g.members:
                if 0 <= m < len(seg_group) and seg_group[m] < 0:
                    seg_group[m] = g_id
        lab = self.labels()
        # One entry more for the unsegmented points' -1: a result without segments has them all.
        return np.append(seg_group, -1)[lab]

    def faces(self) -> list[np.ndarray]:
        """Index arrays of every connected piece of every segment (the unit the
        Fit4CAD ground truth uses)."""
        return [f for s in self.segments for f in s.faces()]

    def to_dict(self) -> dict[str, Any]:
        return {
            "format": "houghcad-result",
            "version": RESULT_VERSION,
            "source": self.source,
            "n_points": int(self.n_points),
            "segments": [s.to_dict() for s in self.segments],
            "unsegmented": [int(i) for i in self.unsegmented],
            "timing": {k: float(v) for k, v in self.timing.items()},
            "options": _jsonable(self.options),
            "groups": [g.to_dict() for g in self.groups],
        }

    def _compared(self) -> dict[str, Any]:
        """Points, segments (indices, parameters, errors, parts), groups and options, timing
        aside: a result equals its JSON round trip, and a rerun's."""
        d = self.to_dict()
        d.pop("timing")
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "Result":
        """The result of :meth:`to_dict`'s dict ``d``; ValueError for another format or a newer
        version than this houghcad writes (:func:`check_header`), and for one that is not whole
        (a hand edit): ids that are not the segments' positions, an index out of range, a count
        (``n_points``) or parts that disagree with the indices, missing ``params``, a group of an
        unknown kind or naming no segment. Unsorted index lists and members are read sorted."""
        check_header(d)
        n, segs = d["n_points"], d["segments"]
        if isinstance(n, bool) or not isinstance(n, int) or n < 0:
            raise ValueError(f"n_points must be a whole number of points, got {n!r}")
        if not isinstance(segs, list):
            raise ValueError(f"segments must be a list, got {type(segs).__name__}")
        segments = [Segment.from_dict(s) for s in segs]
        for pos, s in enumerate(segments):
            # labels() and groups use ids as positions: a segment deleted by hand leaves a gap.
            if s.id != pos:
                raise ValueError(f"segment at position {pos} has id {s.id}: ids must be the segments' "
                                 f"positions 0, 1, 2 ... (renumber them, and the groups' members)")
        given = "unsegmented" in d
        unsegmented = _indices(d.get("unsegmented", []))
        if not given:  # another writer may leave it out: the points no segment holds
            held = np.zeros(n, bool)
            for s in segments:
                held[s.indices[(s.indices >= 0) & (s.indices < n)]] = True
            unsegmented = np.flatnonzero(~held).astype(np.int64)
        _check_partition(n, segments, unsegmented)
        _check_counts(segs, segments)
        return cls(
            n_points=n,
            segments=segments,
            unsegmented=unsegmented,
            timing=dict(d.get("timing", {})),
            options=dict(d.get("options", {})),
            source=d.get("source"),
            groups=[_checked_group(i, g, len(segments)) for i, g in enumerate(d.get("groups", []))],
        )

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), separators=(",", ":"))


def _jsonable(x: Any) -> Any:
    """Convert numpy scalars and arrays inside nested containers to plain Python,
    and :class:`~houghcad.families.Family` objects to their names."""
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        return _jsonable(x.tolist())
    if isinstance(x, np.integer):
        return int(x)
    if isinstance(x, np.floating):
        return float(x)
    if isinstance(x, (str, int, float)) or x is None:
        return x
    from .families.base import Family  # lazy: results load without the families

    if isinstance(x, Family) or (isinstance(x, type) and issubclass(x, Family)):
        return x.name  # Segmenter(families=[obj]) records the family by name
    return x


def check_header(d: dict[str, Any]) -> None:
    """ValueError unless the JSON object ``d`` is a houghcad result (its ``format``) of a version
    this houghcad reads (:data:`RESULT_VERSION` or older); both keys may be absent."""
    if d.get("format", "houghcad-result") != "houghcad-result":
        raise ValueError(f"not a houghcad result (format {d.get('format')!r})")
    version = d.get("version", RESULT_VERSION)
    if isinstance(version, bool) or not isinstance(version, int) or version > RESULT_VERSION:
        raise ValueError(f"result format version {version!r}; this houghcad reads up to {RESULT_VERSION}")


def _check_partition(n: int, segments: list[Segment], unsegmented: np.ndarray) -> None:
    """ValueError unless every index is one of the n points (-1 labelled the last point) and each
    segment's parts hold its points (the faces that are scored). A point may be in two segments:
    a ground truth's faces share their boundary points, and scores it against itself as 1."""
    edges = [e for s in segments for e in (s.edges, *(p.edges for p in s.parts))]
    for idx in [s.indices for s in segments] + edges + [unsegmented]:
        bad = idx[(idx < 0) | (idx >= n)]
        if len(bad):
            raise ValueError(f"point index {int(bad[0])} out of range for the result's {n} points")
    for s in segments:
        if s.parts and not np.array_equal(np.unique(np.concatenate([p.indices for p in s.parts])),
                                          np.unique(s.indices)):
            raise ValueError(f"segment {s.id}: its parts do not hold its points")


def _indices(values: Any) -> np.ndarray:
    """Point indices read from JSON as int64; a fraction (1.5 read as 1) is refused."""
    arr = np.asarray(values)
    if arr.size and arr.dtype.kind not in "iu":
        raise ValueError(f"point indices must be whole numbers, got {arr.dtype} values")
    if arr.ndim != 1:
        raise ValueError("point indices must be a flat list")
    # Documented ascending (faces() hands them on as they are); no list is paired with them by
    # position, so sorting a hand-edited one is harmless.
    return np.sort(arr.astype(np.int64))


def _whole(value: Any, what: str) -> int:
    """``value`` when it is a whole number (not a bool, not 1.5 read as 1); ValueError otherwise."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise ValueError(f"{what} must be a whole number, got {value!r}")
    return int(value)


def _params(d: dict[str, Any], where: str) -> dict[str, Any]:
    """The ``params`` of a segment's or part's dict ``d``; ValueError naming ``where`` when they are
    missing or not an object (every writer records them; an empty object when unknown)."""
    if "params" not in d:
        raise ValueError(f"{where}: missing 'params' (an object, empty when unknown)")
    if not isinstance(d["params"], dict):
        raise ValueError(f"{where}: 'params' must be an object, got {type(d['params']).__name__}")
    return dict(d["params"])


def _check_counts(given: list[dict[str, Any]], segments: list[Segment]) -> None:
    """ValueError naming the segment (or part) whose ``n_points`` in its dict is not its number
    of indices; it may be left out (another writer's result: it is the length of ``indices``)."""
    for d, s in zip(given, segments):
        pieces = [(d, s.indices, f"segment {s.id}")]
        pieces += [(p, q.indices, f"segment {s.id}, part {j}")
                   for j, (p, q) in enumerate(zip(d.get("parts", []), s.parts))]
        for raw, indices, where in pieces:
            if "n_points" in raw and _whole(raw["n_points"], f"{where}: n_points") != len(indices):
                raise ValueError(f"{where}: n_points {raw['n_points']} but {len(indices)} indices")


def _checked_group(i: int, d: dict[str, Any], n_segments: int) -> Group:
    """Group ``i`` of a result of ``n_segments`` segments from its dict ``d``; ValueError naming it
    when its kind is unknown (the reports order and describe groups by kind) or a member is not a
    segment id. Members are sorted, as documented."""
    g = Group.from_dict(d)
    if g.kind not in GROUP_KINDS:
        raise ValueError(f"group {i}: unknown kind {g.kind!r} (one of {', '.join(GROUP_KINDS)})")
    for m in d["members"]:
        if not 0 <= _whole(m, f"group {i}: member") < n_segments:
            raise ValueError(f"group {i}: member {m} is not a segment id (the result has {n_segments} segments)")
    g.members.sort()
    return g
