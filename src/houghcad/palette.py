"""The one colour palette and the integer type codes of every picture houghcad makes.

The coloured PLY (:func:`houghcad.io.writers.write_result_ply`), the PNG views
(:mod:`houghcad.render`) and the HTML report (:mod:`houghcad.htmlreport`) all
take their colours from here, so a cylinder is the same green everywhere.

Colours follow the paper's figures: planes red, cylinders green, cones blue,
spheres magenta, tori black; the complex families have their own colours and
unsegmented points are yellow. Each family declares its colour and PLY type
code in its own file (:attr:`houghcad.families.Family.color`, ``type_code``);
the tables here are live views of the registered families. In the "by
segment" views, segments take colours of a palette spread in CIELAB, and
adjacent segments clearly different ones (:func:`segment_colors`).
"""

from __future__ import annotations

import functools
from collections.abc import Mapping

import numpy as np

from .families import FamilyTable
from .result import Result

__all__ = ["TYPE_CODES", "TYPE_COLORS", "UNSEGMENTED_COLOR", "OTHER_COLOR", "type_code", "type_color",
           "GROUP_COLORS", "NO_GROUP_COLOR", "group_color", "segment_colors", "point_colors", "point_type_codes", "hex_color", "types_present"]

#: Integer code of each family in the PLY ``type`` field (:attr:`Family.type_code`; -1: unsegmented,
#: 0: a family without a code). A live view of the registered families.
TYPE_CODES: Mapping[str, int] = FamilyTable("type_code")
UNSEGMENTED_CODE = -1
OTHER_CODE = 0

#: Base colour (uint8 RGB) of each family (:attr:`Family.color`); the first shade of a type is
#: exactly this colour. A live view of the registered families.
TYPE_COLORS: Mapping[str, tuple[int, int, int]] = FamilyTable("color")
#: Points no segment explains.
UNSEGMENTED_COLOR: tuple[int, int, int] = (255, 215, 0)  # yellow
#: A family without a colour of its own, or not registered.
OTHER_COLOR: tuple[int, int, int] = (190, 190, 190)  # light grey

#: Colours of the association groups (cycled by group id), distinct from one another;
#: segments in no group are drawn in :data:`NO_GROUP_COLOR`.
GROUP_COLORS: tuple[tuple[int, int, int], ...] = (
    (31, 119, 180), (255, 127, 14), (44, 160, 44), (214, 39, 40), (148, 103, 189),
    (140, 86, 75), (227, 119, 194), (23, 190, 207), (188, 189, 34), (127, 127, 127),
)
NO_GROUP_COLOR: tuple[int, int, int] = (215, 215, 215)

def type_code(type_name: str) -> int:
    """Integer code of a family name (:data:`TYPE_CODES`; 0 for an unknown family)."""
    return TYPE_CODES.get(type_name, OTHER_CODE)


def type_color(type_name: str) -> tuple[int, int, int]:
    """Base uint8 RGB colour of a family (:data:`OTHER_COLOR` for an unknown one)."""
    return TYPE_COLORS.get(type_name, OTHER_COLOR)


def group_color(group_id: int) -> tuple[int, int, int]:
    """Colour of a group id (:data:`GROUP_COLORS` cycled); -1 (no group) is :data:`NO_GROUP_COLOR`."""
    return NO_GROUP_COLOR if group_id < 0 else GROUP_COLORS[group_id % len(GROUP_COLORS)]


def hex_color(rgb) -> str:
    """``#rrggbb`` of a uint8 RGB triple."""
    r, g, b = (int(c) for c in rgb)
    return f"#{r:02x}{g:02x}{b:02x}"


def srgb_to_lab(rgb: np.ndarray) -> np.ndarray:
    """CIELAB (D65) of uint8 sRGB colours, shape (..., 3) -> (..., 3).

    The standard formulas, written out: none of the project's libraries
    (numpy, matplotlib) converts to Lab, and these few lines are all it takes.
    """
    c = np.asarray(rgb, dtype=np.float64) / 255.0
    lin = np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)
    M = np.array([[0.4124564, 0.3575761, 0.1804375],
                  [0.2126729, 0.7151522, 0.0721750],
                  [0.0193339, 0.1191920, 0.9503041]])
    xyz = lin @ M.T / np.array([0.95047, 1.0, 1.08883])
    eps, kappa = 216 / 24389, 24389 / 27
    f = np.where(xyz > eps, np.cbrt(xyz), (kappa * xyz + 16) / 116)
    return np.stack([116 * f[..., 1] - 16, 500 * (f[..., 0] - f[..., 1]), 200 * (f[..., 1] - f[..., 2])], axis=-1)


#: Colours of the "by segment" view: this many, each as far in CIELAB from the others as a
#: farthest-point choice among sRGB colours gives.
SEGMENT_PALETTE_SIZE = 24
#: Lightness range of the segment colours: darker ones hide the shading, lighter ones vanish on white.
_SEGMENT_L = (30.0, 85.0)
#: Adjacent segments' colours differ by at least this (ΔE, CIELAB) while the palette allows.
_APART = 30.0
#: A segment colour stays this far (ΔE, CIELAB) from the unsegmented points' yellow.
_FROM_UNSEGMENTED = 35.0


@functools.lru_cache(maxsize=1)
def segment_palette() -> np.ndarray:
    """The segment colours, shape (SEGMENT_PALETTE_SIZE, 3) uint8, in order of choice:
    each the sRGB colour farthest in CIELAB from those before it (the first is the plane red)."""
    levels = np.linspace(0, 255, 9)
    cand = np.stack(np.meshgrid(levels, levels, levels, indexing="ij"), -1).reshape(-1, 3).round()
    lab = srgb_to_lab(cand)
    keep = (lab[:, 0] >= _SEGMENT_L[0]) & (lab[:, 0] <= _SEGMENT_L[1])
    keep &= np.linalg.norm(lab - srgb_to_lab(np.array(UNSEGMENTED_COLOR)), axis=1) >= _FROM_UNSEGMENTED
    cand, lab = cand[keep], lab[keep]
    first = np.array(TYPE_COLORS.get("plane", (228, 26, 28)), dtype=np.float64)
    chosen = [first]
    dist = np.linalg.norm(lab - srgb_to_lab(first), axis=1)
    while len(chosen) < SEGMENT_PALETTE_SIZE:
        j = int(np.argmax(dist))
        chosen.append(cand[j])
        dist = np.minimum(dist, np.linalg.norm(lab - lab[j], axis=1))
    return np.array(chosen, dtype=np.uint8)


def segment_colors(types: list[str], edges: np.ndarray | None = None,
                   sizes: np.ndarray | None = None) -> np.ndarray:
    """Colour of each segment for the "by segment" view: adjacent segments clearly differ.

    Parameters
    ----------
    types : list of str, length S
        The segments' types in id order (their number is what matters here).
    edges : ndarray (k, 2), optional
        Pairs of adjacent segment ids (:func:`segment_edges`). None: every
        pair counts as adjacent, so the colours all differ while the palette lasts.
    sizes : ndarray (S,), optional
        Points per segment: larger segments choose first.

    Returns
    -------
    ndarray of uint8, shape (S, 3)
        RGB from :func:`segment_palette`, chosen greedily, larger segments
        first: each takes, among the colours at least 30 ΔE (CIELAB) from its
        coloured neighbours' (or the farthest ones), the least used so far.
        Deterministic.
    """
    n = len(types)
    pal = segment_palette()
    lab = srgb_to_lab(pal)
    dist = np.linalg.norm(lab[:, None] - lab[None], axis=-1)
    order = np.argsort(-np.asarray(sizes), kind="stable") if sizes is not None else np.arange(n)
    nbrs: list[list[int]] = [[] for _ in range(n)]
    if edges is not None:
        for a, b in np.asarray(edges, dtype=np.int64).reshape(-1, 2).tolist():
            nbrs[a].append(b)
            nbrs[b].append(a)
    choice = np.full(n, -1, dtype=np.int64)
    used = np.zeros(len(pal), np.int64)
    for rank, i in enumerate(order.tolist()):  # one iteration per segment, not per point
        near = [choice[j] for j in (nbrs[i] if edges is not None else order[:rank].tolist()) if choice[j] >= 0]
        worst = dist[:, near].min(axis=1) if near else np.full(len(pal), np.inf)
        # Any colour clearly apart from the neighbours' will do; among those the least used
        # (the segment list stays varied), the earliest among equals.
        ok = worst >= min(worst.max(), _APART)
        choice[i] = int(np.flatnonzero(ok)[np.argmin(used[ok])])
        used[choice[i]] += 1
    return pal[choice]


#: Points :func:`segment_edges` reads at most (evenly spread over the cloud's rows).
EDGE_SAMPLE = 300_000


def segment_edges(result: Result, points: np.ndarray) -> np.ndarray:
    """Pairs (k, 2) of segment ids of ``result`` that touch in the cloud ``points`` (n, 3):
    a point of one within 2.5 median point spacings of a point of the other."""
    from scipy.spatial import cKDTree

    from .adjacency import SegmentGraph

    pts = np.asarray(points, dtype=np.float64)
    if len(result.segments) < 2 or len(pts) < 2:
        return np.zeros((0, 2), np.int64)
    # On a bounded even sample: which segments touch needs no scan's every point (all 3 M points
    # took 6.8 s, and the PNG, the PLY and the report each ask), only a segment of a few points
    # can drop out of it (and then share a neighbour's shade).
    labels = result.labels()
    if len(pts) > EDGE_SAMPLE:
        from .families._geometry import regular_indices

        keep = regular_indices(len(pts), EDGE_SAMPLE)
        pts, labels = pts[keep], labels[keep]
    sample = pts[:: max(1, len(pts) // 20000)]
    spacing = float(np.median(cKDTree(pts).query(sample, k=2)[0][:, 1]))
    return SegmentGraph.build(labels, pts, 2.5 * spacing).edges


def types_present(result: Result) -> list[str]:
    """The result's families in :data:`TYPE_CODES` order, unknown ones after them alphabetically."""
    names = {s.type for s in result.segments}
    return sorted(names, key=lambda t: (TYPE_CODES.get(t, 99), t))


def point_colors(result: Result, by: str = "segment", points: np.ndarray | None = None) -> np.ndarray:
    """Per-point colours of a result.

    Parameters
    ----------
    result : Result
    by : {"segment", "type"}
        ``"segment"``: colours from :func:`segment_colors`, adjacent segments
        (in ``points``, when given) clearly apart; ``"type"``: every segment
        in its type's colour.
    points : ndarray (n_points, 3), optional
        The cloud, to find which segments touch.

    Returns
    -------
    ndarray of uint8, shape (n_points, 3)
        RGB; unsegmented points are :data:`UNSEGMENTED_COLOR`.
    """
    types = [s.type for s in result.segments]
    if by == "segment":
        edges = segment_edges(result, points) if points is not None else None
        table = segment_colors(types, edges, np.array([len(s.indices) for s in result.segments]))
    elif by == "type":
        table = np.array([type_color(t) for t in types], dtype=np.uint8).reshape(-1, 3)
    else:
        raise ValueError(f"by must be 'segment' or 'type', not {by!r}")
    # Row S of the lookup table is the unsegmented colour, so label -1 indexes it.
    table = np.vstack([table, np.array(UNSEGMENTED_COLOR, dtype=np.uint8)])
    return table[result.labels()]


def point_type_codes(result: Result) -> np.ndarray:
    """Per-point type code, shape (n_points,), int32 (:data:`TYPE_CODES`, -1 unsegmented)."""
    codes = np.array([type_code(s.type) for s in result.segments] + [UNSEGMENTED_CODE], dtype=np.int32)
    return codes[result.labels()]
