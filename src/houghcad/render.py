"""PNG pictures of a segmentation: four views of the cloud, coloured by type and by segment.

Headless: matplotlib's Agg backend, no display needed.  Large clouds are
subsampled deterministically (the same points every run) for drawing speed.
"""

from __future__ import annotations

import os

import numpy as np

from .palette import UNSEGMENTED_COLOR, hex_color, point_colors, type_color, types_present
from .result import Result

__all__ = ["render_png", "draw_sample", "MAX_DRAWN_POINTS"]

#: Points drawn per view at most; more only slow drawing without a visible change.
MAX_DRAWN_POINTS = 30_000

# (title, horizontal axis, vertical axis, depth axis pointing at the viewer) of the
# orthographic views in the cloud's principal frame u1, u2, u3 (largest spread first).
_ORTHO_VIEWS = (("view along u3", 0, 1, 2), ("view along u2", 0, 2, 1), ("view along u1", 1, 2, 0))


def draw_sample(n: int, limit: int = MAX_DRAWN_POINTS, seed: int = 0) -> np.ndarray:
    """Sorted indices of at most ``limit`` of ``n`` points, the same ones every call.

    Returns ``arange(n)`` when ``n <= limit``, else a seeded uniform sample
    without replacement, shape (limit,), int64.
    """
    if n <= limit:
        return np.arange(n, dtype=np.int64)
    return np.sort(np.random.default_rng(seed).choice(n, size=limit, replace=False)).astype(np.int64)


def principal_frame(points: np.ndarray) -> np.ndarray:
    """Coordinates of ``points`` (N, 3) in their principal frame, shape (N, 3), same units.

    Centred on the bounding-box centre; axes by decreasing variance, each
    signed so that its largest component is positive (deterministic).  CAD parts
    are usually aligned with these axes, so the three views show faces edge-on.
    """
    c = (points.min(axis=0) + points.max(axis=0)) / 2.0
    q = points - c
    _, vecs = np.linalg.eigh(q.T @ q)
    axes = vecs[:, ::-1]
    axes *= np.sign(axes[np.argmax(np.abs(axes), axis=0), np.arange(3)])
    if np.linalg.det(axes) < 0:  # keep a right-handed frame so views are not mirrored
        axes[:, 2] *= -1.0
    return q @ axes


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
    orthographic views along the world axes and an isometric view.  A legend
    lists the types present and the unsegmented points.
    """
    # A bare Figure (no pyplot) prints through the Agg canvas: headless, and the
    # caller's pyplot backend and global state are left alone.
    from matplotlib.figure import Figure
    from matplotlib.patches import Patch

    from .io.writers import atomic_write

    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape != (result.n_points, 3):
        raise ValueError(f"points must have shape ({result.n_points}, 3), got {pts.shape}")
    sel = draw_sample(len(pts), max_points)
    P = principal_frame(pts[sel])
    colours = {by: point_colors(result, by)[sel] / 255.0 for by in ("type", "segment")}
    lo, hi = P.min(axis=0), P.max(axis=0)
    centre, half = (lo + hi) / 2.0, max(float((hi - lo).max()) / 2.0, 1e-12) * 1.05
    size = float(np.clip(30000.0 / max(len(P), 1), 1.0, 16.0))  # marker area (pt^2): dense clouds, small dots

    fig = Figure(figsize=(16, 8.5), dpi=dpi)
    iso_dir = np.array([1.0, 1.0, 1.0]) / np.sqrt(3.0)  # azim 45, elev 35.26: the isometric view
    for row, by in enumerate(("type", "segment")):
        C = colours[by]
        for col, (name, a, b, d) in enumerate(_ORTHO_VIEWS):
            ax = fig.add_subplot(2, 4, 4 * row + col + 1)
            order = np.argsort(P[:, d], kind="stable")  # far first, so near points are drawn on top
            ax.scatter(P[order, a], P[order, b], s=size, c=C[order], marker="o", linewidths=0, rasterized=True)
            ax.set_xlim(centre[a] - half, centre[a] + half)
            ax.set_ylim(centre[b] - half, centre[b] + half)
            ax.set_aspect("equal")
            ax.set_title(f"{name}, by {by}", fontsize=9)
            ax.set_xlabel(f"u{a + 1}", fontsize=7, labelpad=1)
            ax.set_ylabel(f"u{b + 1}", fontsize=7, labelpad=1)
            ax.tick_params(labelsize=7)
        ax3 = fig.add_subplot(2, 4, 4 * row + 4, projection="3d", proj_type="ortho")
        order = np.argsort(P @ iso_dir, kind="stable")
        # depthshade off: colours must stay the palette's exactly.
        ax3.scatter(P[order, 0], P[order, 1], P[order, 2], s=size, c=C[order], marker="o", linewidths=0,
                    depthshade=False)
        ax3.view_init(elev=35.26, azim=45)
        for setter, c in zip((ax3.set_xlim, ax3.set_ylim, ax3.set_zlim), centre):
            setter(c - half, c + half)
        ax3.set_box_aspect((1, 1, 1))
        ax3.set_title(f"isometric, by {by}", fontsize=9)
        ax3.tick_params(labelsize=6)

    handles = [Patch(color=hex_color(type_color(t)),
                     label=f"{t} ({sum(s.type == t for s in result.segments)})") for t in types_present(result)]
    handles.append(Patch(color=hex_color(UNSEGMENTED_COLOR), label=f"unsegmented ({len(result.unsegmented)} pts)"))
    fig.legend(handles=handles, loc="lower center", ncol=min(len(handles), 7), fontsize=9, frameon=False)
    if title is None:
        src = os.path.basename(result.source) if result.source else "point cloud"
        shown = "" if len(sel) == len(pts) else f", {len(sel)} drawn"
        title = (f"{src}: {len(result.segments)} segments, {result.n_points} points{shown} "
                 "(u1, u2, u3: principal axes of the cloud)")
    fig.suptitle(title, fontsize=11)
    fig.subplots_adjust(left=0.03, right=0.99, top=0.92, bottom=0.09, wspace=0.18, hspace=0.22)
    with atomic_write(path, "wb") as f:
        fig.savefig(f, format="png", dpi=dpi)
