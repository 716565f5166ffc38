"""PNG pictures of a segmentation: four views of the cloud, coloured by type and by segment.

Headless: matplotlib's Agg backend, no display needed.  Large clouds are
subsampled deterministically (the same points every run) for drawing speed.
"""

from __future__ import annotations

import os
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from .palette import UNSEGMENTED_COLOR, hex_color, point_colors, type_color, types_present
from .result import Result

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure
    from scipy.spatial import cKDTree

__all__ = ["render_png", "draw_sample", "framed_points", "principal_frame", "local_surface", "splat",
           "splat_radius", "shaded", "close_gaps", "LIGHT", "AMBIENT", "MAX_DRAWN_POINTS", "GAP_SLACK",
           "MIN_FRAMED", "FRAME_REACH", "FRAME_SAMPLE"]

#: Depth, in point spacings, a drawn pixel may lie behind the surface around it before it counts
#: as the far side seen through a gap (:func:`splat`): a surface turned 60 degrees from the view
#: drops about 2.6 spacings across the reach of the closing; two faces of a part lie further apart.
GAP_SLACK = 3.0
#: Points drawn per view at most; more only slow drawing without a visible change.
MAX_DRAWN_POINTS = 30_000

# (title, horizontal axis, vertical axis, viewing axis) of the orthographic views
# in the cloud's principal frame u1, u2, u3 (largest spread first).
_ORTHO_VIEWS = (("view along u3", 0, 1, 2), ("view along u2", 0, 2, 1), ("view along u1", 1, 2, 0))


def draw_sample(n: int, limit: int = MAX_DRAWN_POINTS, seed: int = 0) -> np.ndarray:
    """Sorted indices of at most ``limit`` of ``n`` points, the same ones every call.

    Returns ``arange(n)`` when ``n <= limit``, else a seeded uniform sample
    without replacement, shape (limit,), int64.
    """
    if n <= limit:
        return np.arange(n, dtype=np.int64)
    return np.sort(np.random.default_rng(seed).choice(n, size=limit, replace=False)).astype(np.int64)


#: Segmented points needed before the views frame on the part they outline (:func:`framed_points`):
#: fewer say too little about where the part is, and every point is framed.
MIN_FRAMED = 10
#: Longest neighbour link, as a share of the segmented points' bounding-box diagonal, that still
#: joins a point to the framed part (:func:`framed_points`): well above any point spacing, far
#: below the distance of a scanner's stray points from the part.
FRAME_REACH = 0.05
#: Points on which :func:`framed_points` reads the part's extent at most; the others go with
#: their nearest sample point (all 200,000 points of a report took 3 s, a sample 0.4 s).
FRAME_SAMPLE = 20_000


def framed_points(points: np.ndarray, labels: np.ndarray, k: int = 8) -> np.ndarray:
    """Which points the views frame on: the part, not a few stray points far from it.

    A scanner's outliers far from the part (left unsegmented, rightly) set the bounding box, and
    the part shrank to a dot in the pictures.  The part is what the segments hold, with the
    unsegmented points joined to it through neighbours (an edge, an unfitted patch); a point not
    so joined lies outside the views and is clipped.  The PNG views and the report both frame so.

    Parameters
    ----------
    points : ndarray, shape (N, 3)
        The drawn points, any units.
    labels : ndarray of int, shape (N,)
        Segment of each point, -1 unsegmented (:meth:`Result.labels`).
    k : int
        Neighbours per point that may join it to the part.

    Returns
    -------
    ndarray of bool, shape (N,)
        The points of the connected pieces of the ``k``-nearest-neighbour graph of (a sample of
        :data:`FRAME_SAMPLE` of) the points, its links no longer than a reach (:func:`_linked`),
        that hold a segmented point; a point off the sample goes with its nearest sample point
        within the reach.  Every point when fewer than :data:`MIN_FRAMED` are segmented, or all are.
    """
    from scipy.spatial import cKDTree

    from .normals import tree_query

    seg = np.asarray(labels) >= 0
    n = len(points)
    s = draw_sample(n, FRAME_SAMPLE)
    if seg[s].sum() < MIN_FRAMED or seg.all():
        return np.ones(n, dtype=bool)
    tree = cKDTree(points[s])
    keep_s, reach = _linked(tree, points[s], seg[s], k)
    if len(s) == n:
        return keep_s
    dist, near = tree_query(tree, points, k=1, distance_upper_bound=reach)
    found = np.isfinite(dist)
    keep = np.zeros(n, dtype=bool)
    keep[found] = keep_s[near[found]]
    keep[s] = keep_s
    return keep


def _linked(tree: cKDTree, points: np.ndarray, seg: np.ndarray, k: int) -> tuple[np.ndarray, float]:
    """Which of ``points`` (N, 3), ``tree``'s, are linked to a ``seg`` (N,) bool point through
    ``k``-nearest-neighbour links no longer than the reach, shape (N,) bool; and the reach, in the
    points' units: :data:`FRAME_REACH` of the ``seg`` points' diagonal, at least 3 times the
    median distance to the ``k``-th neighbour (a sparse cloud stays linked)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    from .normals import tree_query

    n = len(points)
    k = min(k, n - 1)
    dist, nbr = tree_query(tree, points, k=k + 1)  # column 0: the point itself
    span = float(np.linalg.norm(points[seg].max(axis=0) - points[seg].min(axis=0)))
    reach = max(FRAME_REACH * span, 3.0 * float(np.median(dist[:, -1])))
    link = dist[:, 1:] <= reach
    rows = np.broadcast_to(np.arange(n)[:, None], link.shape)[link]
    graph = coo_matrix((np.ones(len(rows), dtype=np.int8), (rows, nbr[:, 1:][link])), shape=(n, n))
    _, piece = connected_components(graph, directed=False)
    return np.isin(piece, piece[seg]), reach


def principal_frame(points: np.ndarray, framed: np.ndarray | None = None) -> np.ndarray:
    """Coordinates of ``points`` (N, 3) in the principal frame of ``points[framed]`` (default:
    all of them), shape (N, 3), same units.

    Centred on the framed points' bounding-box centre; axes by decreasing variance, each
    signed so that its largest component is positive (deterministic).  CAD parts
    are usually aligned with these axes, so the three views show faces edge-on; the
    frame is the part's (:func:`framed_points`), stray points far off would tilt it.
    """
    ref = points if framed is None else points[framed]
    c = (ref.min(axis=0) + ref.max(axis=0)) / 2.0
    q = ref - c
    _, vecs = np.linalg.eigh(q.T @ q)
    axes = vecs[:, ::-1]
    axes *= np.sign(axes[np.argmax(np.abs(axes), axis=0), np.arange(3)])
    if np.linalg.det(axes) < 0:  # keep a right-handed frame so views are not mirrored
        axes[:, 2] *= -1.0
    return (points - c) @ axes


def _iso_basis() -> np.ndarray:
    """Rows: screen right, screen up, towards the viewer, for the view from (1, 1, 1) with u3 up."""
    toward = np.array([1.0, 1.0, 1.0]) / np.sqrt(3.0)
    right = np.cross([0.0, 0.0, 1.0], toward)
    right /= np.linalg.norm(right)
    return np.array([right, np.cross(toward, right), toward])


def splat(u: np.ndarray, v: np.ndarray, depth: np.ndarray, colors: np.ndarray, half: float, size: int,
          radius: int = 1, background: int = 255, slack: float | None = None) -> np.ndarray:
    """Draw points as small squares into an RGB image, the nearest point winning each pixel.

    Parameters
    ----------
    u, v : ndarray, shape (N,)
        Screen coordinates (right, up), world units; the image covers
        ``[-half, half]`` in both.
    depth : ndarray, shape (N,)
        Larger is nearer the viewer.
    colors : ndarray of uint8, shape (N, 3)
    half : float
    size : int
        Image side in pixels.
    radius : int
        Each point covers ``(2 radius + 1)^2`` pixels.
    slack : float, optional
        Depth (world units) by which a pixel may lie behind the surface around it. Given, the
        gaps of a sampled surface close: a pixel more than ``slack`` behind the depth map's
        closing (a valley up to ``2 radius + 1`` pixels wide, about the distance to a point's
        6th neighbour, see :func:`close_gaps`) shows the far side through a gap between the near
        side's points, and takes the colour of the nearest pixel that is not hidden.

    Returns
    -------
    ndarray of uint8, shape (size, size, 3)
        Row 0 is the top (``v = half``).  Deterministic: ties go to the point
        listed first.
    """
    scale = (size - 1) / (2.0 * half)
    px = np.rint((u + half) * scale).astype(np.int64)
    py = np.rint((half - v) * scale).astype(np.int64)
    d = np.arange(-radius, radius + 1)
    dx, dy = (g.ravel() for g in np.meshgrid(d, d))
    X = (px[:, None] + dx[None, :]).ravel()
    Y = (py[:, None] + dy[None, :]).ravel()
    point = np.repeat(np.arange(len(u)), len(dx))
    keep = (X >= 0) & (X < size) & (Y >= 0) & (Y < size)
    pixel, point = Y[keep] * size + X[keep], point[keep]
    # Per pixel, the nearest point: sort by pixel, then by decreasing depth, then by point.
    order = np.lexsort((point, -depth[point], pixel))
    first = np.unique(pixel[order], return_index=True)[1]
    shown, winner = pixel[order][first], point[order][first]
    img = np.full((size * size, 3), background, dtype=np.uint8)
    img[shown] = colors[winner]
    img = img.reshape(size, size, 3)
    if slack is None:
        return img
    zbuf = np.full(size * size, -np.inf)
    zbuf[shown] = depth[winner]
    return close_gaps(img, zbuf.reshape(size, size), radius, slack)


def close_gaps(img: np.ndarray, zbuf: np.ndarray, reach: int, slack: float) -> np.ndarray:
    """``img`` (H, W, 3) with the pixels that show a far surface through gaps of a near one
    recoloured from the nearest visible pixel.

    ``zbuf`` (H, W) is each pixel's depth (larger is nearer; -inf where no point is drawn). Its
    grey closing by a disc ``2 reach + 1`` pixels wide fills the valleys narrower than that, the
    gaps, and keeps the steps, the near surface's outline, and any hole wider than the disc
    whole (a square would round off a round hole's rim): a pixel more than ``slack`` below the
    closing is hidden. A gap with no point drawn in it at all is hidden too, and filled.
    """
    from scipy.ndimage import distance_transform_edt, grey_closing

    d = np.arange(-reach, reach + 1)
    disc = d[:, None] ** 2 + d[None, :] ** 2 <= reach * reach
    cover = grey_closing(zbuf, footprint=disc, mode="constant", cval=-np.inf)
    hidden = zbuf < cover - slack
    if not hidden.any():
        return img
    source = np.isfinite(zbuf) & ~hidden
    if not source.any():
        return img
    iy, ix = distance_transform_edt(~source, return_distances=False, return_indices=True)
    out = img.copy()
    out[hidden] = img[iy[hidden], ix[hidden]]
    return out


def render_png(path: str | os.PathLike[str], points: np.ndarray, result: Result, *,
               title: str | None = None, max_points: int = MAX_DRAWN_POINTS, dpi: int = 100) -> None:
    """Draw ``result`` on ``points`` and write a PNG, atomically.

    Parameters
    ----------
    path : str or path-like
        Destination ``.png``; its directory must exist.
    points : array_like, shape (N, 3)
        The cloud in world coordinates, ``N == result.n_points``.
    result : Result
    title : str, optional
        Figure title (default: the result's source and counts).
    max_points : int
        Points drawn per view at most (:func:`draw_sample`).
    dpi : int
        Resolution; the figure is 16 x 8.5 inches (1600 x 850 pixels at 100 dpi).

    The top row colours points by type (base colours), the bottom row by
    segment (a shade of the type colour each); the columns are three
    orthographic views along the principal axes of the cloud
    (:func:`principal_frame`) and an isometric view in that frame.  A legend
    lists the types present and the unsegmented points.  Frame and extent are
    the part's (:func:`framed_points`): stray points far from it are left out.
    """
    # A bare Figure (no pyplot) prints through the Agg canvas: headless, and the
    # caller's pyplot backend and global state are left alone.
    from matplotlib.figure import Figure

    from .io.writers import atomic_write

    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape != (result.n_points, 3):
        raise ValueError(f"points must have shape ({result.n_points}, 3), got {pts.shape}")
    sel = draw_sample(len(pts), max_points)
    # Framed on the part: points outside the views (strays far off) are clipped by splat.
    keep = framed_points(pts[sel], result.labels()[sel])
    P = principal_frame(pts[sel], keep)
    colours = {by: point_colors(result, by, pts)[sel] for by in ("type", "segment")}
    spacing, normals = local_surface(P)
    lo, hi = P[keep].min(axis=0), P[keep].max(axis=0)
    centre = (lo + hi) / 2.0
    # Half the side of a view, with a margin: the largest half-extent for the
    # orthographic views, the half-diagonal for the isometric one.
    half_ortho = max(float((hi - lo).max()) / 2.0, 1e-12) * 1.05
    half_iso = max(float(np.linalg.norm(hi - lo)) / 2.0, 1e-12) * 1.02

    fig = Figure(figsize=(16, 8.5), dpi=dpi)
    # Each view is splatted into an image with numpy (a z-buffer, nearest point wins)
    # and shown with imshow: ten times faster than matplotlib's scatter and 3-D axes.
    panel = int(round(3.4 * dpi))  # pixels per side, about the size of one axes
    views = _views(half_ortho, half_iso)
    for row, by in enumerate(("type", "segment")):
        for col, view in enumerate(views):
            ax = fig.add_subplot(2, 4, 4 * row + col + 1)
            _draw_view(ax, (P - centre) @ view.basis.T, shaded(colours[by], normals @ view.basis.T),
                       view, by, panel, splat_radius(spacing, view.half, panel), GAP_SLACK * spacing)
    _legend(fig, result)
    if title is None:
        src = os.path.basename(result.source) if result.source else "point cloud"
        shown = "" if len(sel) == len(pts) else f", {len(sel)} drawn"
        if not keep.all():  # say so: the views do not show every point
            shown += f", {int((~keep).sum())} stray{'s' if (~keep).sum() > 1 else ''} far off not shown"
        title = (f"{src}: {len(result.segments)} segments, {result.n_points} points{shown} "
                 "(u1, u2, u3: principal axes of the cloud)")
    fig.suptitle(title, fontsize=11)
    fig.subplots_adjust(left=0.03, right=0.99, top=0.92, bottom=0.09, wspace=0.18, hspace=0.22)
    with atomic_write(path, "wb") as f:
        fig.savefig(f, format="png", dpi=dpi)


def local_surface(P: np.ndarray, k: int = 10) -> tuple[float, np.ndarray]:
    """The median distance from a point of ``P`` (N, 3) to its 6th neighbour, and the points'
    unoriented PCA normals over ``k`` neighbours, shape (N, 3): what the views need to close
    the surface between points and to shade it. (The 6th, not the nearest: random samples
    leave gaps about twice their nearest-neighbour distance.)"""
    from scipy.spatial import cKDTree

    from .normals import pca_normals, tree_query

    if len(P) < 3:
        return 0.0, np.zeros((len(P), 3))
    k = min(k, len(P))
    dist, nbr = tree_query(cKDTree(P), P, k=k)
    return float(np.median(dist[:, min(6, k - 1)])), pca_normals(P, np.ascontiguousarray(nbr, dtype=np.int64))[0]


def splat_radius(spacing: float, half: float, size: int) -> int:
    """Pixels each side of a drawn point so that neighbouring points' squares meet, ``spacing``
    the distance to a point's 6th neighbour (:func:`local_surface`) in a view ``2 half`` wide and
    ``size`` pixels: a surface then reads as closed and hides what lies behind it (1 pixel let
    the far side show through the gaps between the near side's points). At most 8: a sparse
    cloud stays a cloud of points."""
    px = spacing * (size - 1) / (2.0 * half)
    return int(np.clip(np.ceil(0.5 * px), 1, 8))


#: Direction of the light in a view's basis (right, up, towards the viewer): from the viewer's
#: upper left, so that faces at different angles get different brightness.
LIGHT = np.array([-0.25, 0.35, 1.0]) / np.linalg.norm([-0.25, 0.35, 1.0])
#: The share of its colour a point keeps facing away from the light: the colours stay those
#: of the palette. The PNG views and the report's shader both shade with these two.
AMBIENT = 0.55


def shaded(colors: np.ndarray, normals: np.ndarray, ambient: float = AMBIENT) -> np.ndarray:
    """``colors`` (N, 3) uint8 darkened by how far each point's surface turns from the light
    (Lambert's law on the unoriented ``normals`` (N, 3) in the view's basis), no darker than
    ``ambient`` of the colour: the shape reads in 3-D and the colours stay recognisable."""
    f = ambient + (1.0 - ambient) * np.abs(normals @ LIGHT)
    return np.clip(np.rint(colors * f[:, None]), 0, 255).astype(np.uint8)


class _View(NamedTuple):
    """One of the four views of :func:`render_png`."""

    name: str
    basis: np.ndarray  # (3, 3), rows: screen right, screen up, towards the viewer
    xlabel: str | None  # axis labels; None for the isometric view (no meaningful values)
    ylabel: str | None
    half: float  # half the side of the view, the cloud's units


def _views(half_ortho: float, half_iso: float) -> list[_View]:
    """The three orthographic views of :data:`_ORTHO_VIEWS` and the isometric one.

    ``half_ortho`` and ``half_iso`` are the half sides of the views, in the cloud's units.
    """
    iso = _iso_basis()
    # Depth = right x up: a view as from outside, never mirrored.
    views = [_View(name, np.array([np.eye(3)[a], np.eye(3)[b], np.cross(np.eye(3)[a], np.eye(3)[b])]),
                   f"u{a + 1}", f"u{b + 1}", half_ortho) for name, a, b, _ in _ORTHO_VIEWS]
    views.append(_View("isometric", iso, None, None, half_iso))
    return views


def _draw_view(ax: Axes, Q: np.ndarray, colors: np.ndarray, view: _View, by: str, panel: int, radius: int,
               slack: float) -> None:
    """Splat one view into ``ax``.

    ``Q`` (N, 3) are the drawn points in the view's basis (horizontal, vertical, towards the
    viewer), ``colors`` (N, 3) uint8, ``panel`` the image side in pixels, ``radius`` the splat
    radius in pixels, ``slack`` the depth a pixel may lie behind its surroundings (:func:`splat`).
    """
    name, _, xl, yl, half = view
    img = splat(Q[:, 0], Q[:, 1], Q[:, 2], colors, half, panel, radius, slack=slack)
    ax.imshow(img, extent=(-half, half, -half, half), interpolation="nearest", origin="upper")
    ax.set_title(f"{name}, by {by}", fontsize=9)
    if xl is None:  # the isometric view has no meaningful axis values
        ax.set_axis_off()
    else:
        ax.set_xlabel(xl, fontsize=7, labelpad=1)
        ax.set_ylabel(yl, fontsize=7, labelpad=1)
        ax.tick_params(labelsize=7)


def _legend(fig: Figure, result: Result) -> None:
    """Legend of the figure: the types present (with their segment counts) and the unsegmented points."""
    from matplotlib.patches import Patch

    handles = [Patch(color=hex_color(type_color(t)),
                     label=f"{t} ({sum(s.type == t for s in result.segments)})") for t in types_present(result)]
    handles.append(Patch(color=hex_color(UNSEGMENTED_COLOR), label=f"unsegmented ({len(result.unsegmented)} pts)"))
    fig.legend(handles=handles, loc="lower center", ncol=min(len(handles), 7), fontsize=9, frameon=False)
