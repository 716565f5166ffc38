"""Features aligned with their neighbours (our extension of the splitting phase, paper §5.3).

A small hole, a counterbore's bore and step, a band a few rows high between two faces: no point's
neighbourhood lies on such a face alone, so its PCA normals are blends of the faces around it, and
neither the axis estimate nor the vote places it. On CAD parts such features are mostly coaxial
with, or perpendicular to, a neighbour. With a neighbour's axis or normal as the direction, what
is left of the standard form is found from the points alone, no normals needed: cylinders about
the direction are circles in the plane across it, planes across it are levels along it, and a
cone about a known axis line (a countersink or a chamfer round a hole) is a line in the meridian
plane, radius against height. The features of a cluster are taken in turn, each the largest one
left.
"""

from __future__ import annotations

import numpy as np

from .adjacency import border_points, row_support
from .context import Context
from .families import Family
from .bridges import row_axis
from .families.base import Primitive, axial, unit
from .preprocess import rotation_to_z
from .clusters import dense_subsets
from .recognize import select
from .state import Candidate, Segmentation, mean_fitting_error


def aligned_features(cl: np.ndarray, families: list[Family], seg: Segmentation, ctx: Context) -> list[Candidate]:
    """Cylinders coaxial with, and planes across, the axes and normals of the segments adjacent
    to the cluster ``cl`` (global indices), and cones about the adjacent and found cylinders'
    axis lines, for a cluster the normals could not place.

    Features are taken in turn, each the largest aligned circle, level or cone among the points
    the ones before it left (at most ``aligned_pieces``); their pieces are dense subsets of at
    least ``ctx.min_points`` and together hold ``aligned_cover`` of the cluster, or leave fewer
    than ``ctx.min_points`` of it; short of that, only the cylinders exact over more than one
    ring of points stay (:func:`_exact_over_rings`). A cluster that is a straight row takes
    instead the plane its neighbours' boundary rows choose (:func:`_row_plane`) when that
    explains it in larger pieces than they do."""
    fams = {f.name: f for f in families}
    cyl, plane = fams.get("cylinder"), fams.get("plane")
    # On a noisy cloud one cylinder of all the points is fitted (see one_aligned_cylinder): a
    # cone's two parameters on a band ±τ would be a chance fit there too.
    cone = None if ctx.policy.one_aligned_cylinder else fams.get("cone")
    if (cyl is None and plane is None) or not len(seg) or len(cl) < ctx.min_points:
        return []
    t = ctx.tol.splitting
    adj, border = _adjacent(cl, seg, ctx)
    axes = _distinct_axes(adj, seg, ctx)
    lines = [] if cone is None else _axis_lines([seg.records[j].prim for j in adj])
    out: list[Candidate] = []
    # Seeded by the cluster, so that a cluster gets the same answer in any order.
    rng = np.random.default_rng([ctx.seed, int(cl[0])])
    rest = cl
    for _ in range(1 if ctx.policy.one_aligned_cylinder else t.aligned_pieces):
        if len(rest) < ctx.min_points:
            break
        best = _largest_feature(rest, border, axes, cyl, plane, rng, ctx)
        if cone is not None:
            alt = _largest_cone(ctx.pre.points[rest], ctx.pre.normals[rest], lines, cone, rng, ctx)
            if alt is not None and (best is None or alt[2].sum() > best[2].sum()):
                best = alt
        if best is None:
            break
        fam, prim, on = best
        got = _pieces(fam, prim, rest[on], ctx)
        if not got:
            break
        out += got
        rest = rest[~on]
        if cone is not None:
            lines += _axis_lines([prim])
    # What the features leave must be a small share of the cluster, or fewer points than any
    # segment holds: a counterbore's step a few points wide is no feature of its own. Short of
    # that, the cylinders that fit exactly over more than one ring are features all the same (a
    # bore beside the chamfer of an edge, whose rows fit no aligned feature).
    left = len(cl) - sum(len(c.indices) for c in out)
    if out and left > (1.0 - t.aligned_cover) * len(cl) and left >= ctx.min_points:
        out = [e for e in (_exact_over_rings(c, ctx) for c in out) if e is not None]
    out = select(out, seg.free, ctx) if out else []
    # A straight row's plane explains it in a larger piece than the levels do (two middle rows of
    # a chamfer four rows wide, each level holding one; the splitting phase's measure, the sum
    # of squared sizes): taken instead. On a tie the features stay: a short row of a narrow cone
    # or cylinder band is nearly straight, and a plane through it holds a few points of the edge
    # rows on both sides as well.
    row = _row_plane(cl, border, plane, ctx) if plane is not None else None
    if row is not None and len(row.indices) ** 2 > sum(len(c.indices) ** 2 for c in out):
        return select([row], seg.free, ctx)
    return out


def _row_plane(cl: np.ndarray, border: np.ndarray, plane: Family, ctx: Context) -> Candidate | None:
    """The plane through the cluster ``cl`` (global indices) when it is a straight row of points,
    chosen by the boundary points ``border`` of the faces beside it; None when it is no row or no
    such plane holds boundary points on both of its sides.

    A chamfer two or three rows wide keeps only its middle row once its edge rows went to the
    faces beside it, and lies across neither face's normal: no level finds it, and every plane
    through the row fits the row. Seen along the row, the row is one point and each row of the
    neighbours' boundary points one more: the chamfer's plane is the line through the row that
    holds an edge row on either side of it (its points within τ, as
    :func:`houghcad.adjacency.row_support` counts them)."""
    P = ctx.pre.points
    X = P[cl]
    a = row_axis(X, ctx.link)
    if a is None or len(border) < 2:
        return None
    c0 = X.mean(axis=0)
    e1 = unit(np.cross(a, [1.0, 0.0, 0.0] if abs(a[0]) < 0.9 else [0.0, 1.0, 0.0]))
    e2 = np.cross(a, e1)
    u, v = (P[border] - c0) @ e1, (P[border] - c0) @ e2
    # One candidate line per boundary point (angle modulo π); each holds the points within τ.
    phi = np.mod(np.arctan2(v, u), np.pi)
    cs, sn = np.cos(phi)[:, None], np.sin(phi)[:, None]
    on = np.abs(cs * v - sn * u) <= ctx.tau
    along = cs * u + sn * v
    sides = np.minimum((on & (along > 0)).sum(axis=1), (on & (along < 0)).sum(axis=1))
    best = int(np.argmax(sides * (len(border) + 1) + on.sum(axis=1)))
    if sides[best] < 1:
        return None
    normal = -np.sin(phi[best]) * e1 + np.cos(phi[best]) * e2
    if np.abs((X - c0) @ normal).max() > ctx.tau:
        return None
    prim = Primitive("plane", {"normal": normal, "offset": float(normal @ c0)})
    ext = np.concatenate([cl, border[on[best]]])
    fit = plane.fit(prim, P[ext], ctx.pre.normals[ext])
    if fit is not None and plane.valid(fit, ctx) and plane.distance(fit, P[ext]).max() <= ctx.tau:
        prim = fit
    d = plane.distance(prim, X)
    keep = d <= ctx.tau
    if keep.sum() < ctx.min_points:
        return None
    return Candidate(plane, prim, cl[keep], mean_fitting_error(d[keep], X[keep]), d[keep])


def _exact_over_rings(c: Candidate, ctx: Context) -> Candidate | None:
    """``c`` refitted on its own points when it is a cylinder that fits them to the rounding of
    an exact fit and reaches over more than one ring of them along its axis (evidence of its
    own, where one ring lies on every cylinder through it); else None. The aligned fit also
    took the neighbours' boundary rows: refitted on the piece alone it is exact or no cylinder.
    Under noise no fit is exact (σ is a third of τ)."""
    t = ctx.tol.splitting
    if c.family.name != "cylinder":
        return None
    P = ctx.pre.points[c.indices]
    prim = c.family.fit(c.prim, P, ctx.pre.normals[c.indices])
    if prim is None or not c.family.valid(prim, ctx):
        return None
    d = c.family.distance(prim, P)
    h, _ = axial(P, prim.params["axis_point"], prim.params["axis"])
    if d.mean() > t.aligned_exact_taus * ctx.tau or np.ptp(h) < t.aligned_rings_spacings * ctx.pre.spacing:
        return None
    return Candidate(c.family, prim, c.indices, mean_fitting_error(d, P), d)


def _pieces(fam: Family, prim: Primitive, sel: np.ndarray, ctx: Context) -> list[Candidate]:
    """Candidates of ``prim`` on the dense subsets (at least ``ctx.min_points``) of the points
    ``sel`` (global indices)."""
    P = ctx.pre.points[sel]
    d = fam.distance(prim, P)
    return [Candidate(fam, prim, sel[c], mean_fitting_error(d[c], P[c]), d[c])
            for c in dense_subsets(P, ctx.link, ctx.min_points, ctx.tol.recognition.dense_min_samples)]


def _largest_feature(rest: np.ndarray, border: np.ndarray, axes: list[np.ndarray], cyl: Family | None,
                     plane: Family | None, rng: np.random.Generator, ctx: Context) \
        -> tuple[Family, Primitive, np.ndarray] | None:
    """The aligned cylinder or plane with the most of the points ``rest`` (global indices)
    within τ, as ``(family, primitive, inlier mask (m,))``, or None when none holds
    ``ctx.min_points``; cylinders refitted with the boundary points ``border``
    (:func:`_refined`). Of two that hold as many, the one the boundary points hold more of
    (:func:`houghcad.adjacency.row_support`), then a level: a plane is the simpler surface."""
    X = ctx.pre.points[rest]
    noisy = ctx.policy.one_aligned_cylinder
    found = []
    for a in axes:
        R = rotation_to_z(a)
        Q = X @ R.T
        if plane is not None and not noisy:
            level, on = _best_level(Q[:, 2], ctx.tau)
            found.append((plane, Primitive("plane", {"normal": a.copy(), "offset": float(level)}), on))
        circle = None if cyl is None else _circle_of_all(Q[:, :2], ctx) if noisy else _best_circle(Q[:, :2], rng, ctx)
        if circle is not None:
            c, r, on = circle
            # The axis point at the foot of the points' centroid, as the family's fit keeps it.
            foot = np.array([c[0], c[1], Q[on if on.any() else slice(None), 2].mean()])
            prim = Primitive("cylinder", {"axis_point": R.T @ foot, "axis": a.copy(), "radius": r})
            found.append((cyl, *_refined(cyl, prim, on, rest, border, ctx)))
    # A row of points (a band two or three rows high, its edge rows gone to the faces beside it)
    # lies on its level and on the cylinder through it alike: the boundary rows beside it decide.
    best, key = None, (ctx.min_points, -1)
    for fam, prim, on in found:
        k = (int(on.sum()), row_support(fam, prim, border, ctx))
        if k > key:
            best, key = (fam, prim, on), k
    return best


def _best_level(h: np.ndarray, tau: float) -> tuple[float, np.ndarray]:
    """The level along the direction with the most heights h (m,) within τ, refined to their
    mean, and the mask (m,) of the heights within τ of it."""
    s = np.sort(h)
    count = np.searchsorted(s, s + tau, side="right") - np.searchsorted(s, s - tau, side="left")
    i = int(np.argmax(count))
    on = np.abs(h - s[i]) <= tau
    level = float(h[on].mean())
    return level, np.abs(h - level) <= tau


def _best_circle(Q: np.ndarray, rng: np.random.Generator, ctx: Context) \
        -> tuple[np.ndarray, float, np.ndarray] | None:
    """The circle through the most of the points Q (m, 2) within τ, from circles through three
    of them drawn at random (``aligned_samples``), refitted on its points: ``(centre (2,),
    radius, mask (m,))``, or None. Written here because the direction is given: a 2-D circle
    RANSAC over a few hundred points needs no library's 3-D machinery."""
    m = len(Q)
    if m < 3:
        return None
    tri = rng.integers(0, m, size=(ctx.tol.splitting.aligned_samples, 3))
    c, r = _circumcircles(Q[tri[:, 0]], Q[tri[:, 1]], Q[tri[:, 2]])
    ok = np.isfinite(r) & (r > 0) & (r < ctx.max_radius)
    if not ok.any():
        return None
    c, r = c[ok], r[ok]
    d = np.abs(np.linalg.norm(Q[None, :, :] - c[:, None, :], axis=2) - r[:, None])
    k = int(np.argmax((d <= ctx.tau).sum(axis=1)))
    on = d[k] <= ctx.tau
    fit = _kasa(Q[on])
    if fit is not None and fit[1] < ctx.max_radius:
        on2 = np.abs(np.linalg.norm(Q - fit[0], axis=1) - fit[1]) <= ctx.tau
        if on2.sum() >= on.sum():
            return fit[0], fit[1], on2
    return c[k], float(r[k]), on


def _circle_of_all(Q: np.ndarray, ctx: Context) -> tuple[np.ndarray, float, np.ndarray] | None:
    """The least-squares circle of all the points Q (m, 2) and the mask (m,) of those within τ,
    or None."""
    fit = _kasa(Q)
    if fit is None or fit[1] >= ctx.max_radius:
        return None
    return fit[0], fit[1], np.abs(np.linalg.norm(Q - fit[0], axis=1) - fit[1]) <= ctx.tau


def _circumcircles(A: np.ndarray, B: np.ndarray, C: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Centres (k, 2) and radii (k,) of the circles through the points A, B, C (k, 2) each;
    radius inf where the three lie on a line."""
    b, c = B - A, C - A
    den = 2 * (b[:, 0] * c[:, 1] - b[:, 1] * c[:, 0])
    bb, cc = (b**2).sum(1), (c**2).sum(1)
    with np.errstate(divide="ignore", invalid="ignore"):
        u = np.stack([(c[:, 1] * bb - b[:, 1] * cc) / den, (b[:, 0] * cc - c[:, 0] * bb) / den], axis=1)
    r = np.where(den != 0, np.linalg.norm(u, axis=1), np.inf)
    return A + np.nan_to_num(u), r


def _kasa(Q: np.ndarray) -> tuple[np.ndarray, float] | None:
    """The least-squares circle (Kasa's algebraic fit) of the points Q (m, 2): centre, radius."""
    if len(Q) < 3:
        return None
    A = np.c_[2 * Q, np.ones(len(Q))]
    sol = np.linalg.lstsq(A, (Q**2).sum(1), rcond=None)[0]
    r2 = sol[2] + sol[:2] @ sol[:2]
    return (sol[:2], float(np.sqrt(r2))) if r2 > 0 else None


def _axis_lines(prims: list[Primitive]) -> list[tuple[np.ndarray, np.ndarray]]:
    """The axis lines ``(point (3,), unit direction (3,))`` of the cylinders among ``prims``.
    (A cone's points left beside a cone on the same axis are mostly that cone's own: a second
    cone fitted to a few of them would split its face.)"""
    out = []
    for p in prims:
        if p.family == "cylinder":
            a = np.asarray(p.params["axis"], float)
            out.append((np.asarray(p.params["axis_point"], float), a / np.linalg.norm(a)))
    return out


def _largest_cone(X: np.ndarray, N: np.ndarray, lines: list[tuple[np.ndarray, np.ndarray]], cone: Family,
                  rng: np.random.Generator, ctx: Context) -> tuple[Family, Primitive, np.ndarray] | None:
    """The cone about one of the axis ``lines`` with the most of the points X (m, 3) (normals
    N (m, 3)) within τ, as ``(family, primitive, inlier mask (m,))``, or None when none holds
    ``ctx.min_points``.

    About a known axis a cone is a line ρ = c₀ + c₁ h in the meridian plane (height h along the
    axis, distance ρ from it): lines through two points drawn at random (``aligned_samples``),
    the best refitted by least squares on its points, then the cone refitted with its axis free
    (the line it came from was fitted to a hole's few points). Written here for the same reason
    as :func:`_best_circle`: two parameters over a few dozen points."""
    m = len(X)
    best, count = None, ctx.min_points - 1
    if m < 2:
        return None
    t = ctx.tol.splitting
    for point, a in lines:
        V = X - point
        h = V @ a
        rho = np.linalg.norm(V - h[:, None] * a, axis=1)
        pair = rng.integers(0, m, size=(t.aligned_samples, 2))
        dh = h[pair[:, 1]] - h[pair[:, 0]]
        ok = np.abs(dh) > ctx.tau
        if not ok.any():
            continue
        c1 = (rho[pair[ok, 1]] - rho[pair[ok, 0]]) / dh[ok]
        c0 = rho[pair[ok, 0]] - c1 * h[pair[ok, 0]]
        d = np.abs(rho[None, :] - c0[:, None] - c1[:, None] * h[None, :]) / np.sqrt(1 + c1[:, None] ** 2)
        k = int(np.argmax((d <= ctx.tau).sum(axis=1)))
        on = d[k] <= ctx.tau
        if on.sum() <= count:
            continue
        c1k, c0k = np.polyfit(h[on], rho[on], 1)
        if c1k == 0:
            continue
        # Apex where the radius vanishes; the axis opens towards the growing radius.
        prim = Primitive("cone", {"apex": point - c0k / c1k * a, "axis": np.sign(c1k) * a,
                                  "half_angle": float(np.arctan(abs(c1k)))})
        if not cone.valid(prim, ctx):
            continue
        dc = cone.distance(prim, X)
        on = dc <= ctx.tau
        for _ in range(t.aligned_refits):
            fit = cone.fit(prim, X[on], N[on]) if on.sum() >= ctx.min_points else None
            if fit is None or not cone.valid(fit, ctx):
                break
            d2 = cone.distance(fit, X)
            if (d2 <= ctx.tau).sum() < on.sum():
                break
            prim, dc, on = fit, d2, d2 <= ctx.tau
        # Exact samples of a cone lie on it once its axis is free; a short arc of a torus
        # fillet, or a crease between a plane and a cylinder, fits a cone only to a share of τ.
        if on.sum() > count and dc[on].mean() <= t.aligned_cone_taus * ctx.tau:
            best, count = (cone, prim, on), int(on.sum())
    return best


def _adjacent(cl: np.ndarray, seg: Segmentation, ctx: Context) -> tuple[list[int], np.ndarray]:
    """The segments with a point within ``ctx.link`` of the cluster ``cl``, and those points
    (global indices)."""
    border = border_points(cl, seg.labels, ctx, ctx.tol.splitting.aligned_neighbours)
    return np.unique(seg.labels[border]).tolist(), border


def _refined(cyl: Family, prim: Primitive, on: np.ndarray, rest: np.ndarray, border: np.ndarray,
             ctx: Context) -> tuple[Primitive, np.ndarray]:
    """The cylinder ``prim`` refitted, axis free, on the points left (``rest``) and the adjacent
    segments' boundary points within ``aligned_band_taus`` × τ of it (``aligned_refits``
    times), with its mask (τ) over ``rest``; the fit as given when the refit holds fewer of them.
    A hole's boundary rows went to the faces around it, and under noise its free rows alone
    fix neither its radius nor a tilt."""
    t = ctx.tol.splitting
    P, N = ctx.pre.points, ctx.pre.normals
    ext = np.concatenate([rest, border])
    new = prim
    for _ in range(t.aligned_refits):
        band = ext[cyl.distance(new, P[ext]) < t.aligned_band_taus * ctx.tau]
        fit = cyl.fit(new, P[band], N[band]) if len(band) >= ctx.min_points else None
        if fit is None or not cyl.valid(fit, ctx):
            break
        new = fit
    on2 = cyl.distance(new, P[rest]) < ctx.tau
    return (new, on2) if new is not prim and on2.sum() >= on.sum() else (prim, on)


def _distinct_axes(adj: list[int], seg: Segmentation, ctx: Context) -> list[np.ndarray]:
    """The distinct axes or normals (unit (3,)) of the segments ``adj``."""
    axes: list[np.ndarray] = []
    for j in adj:
        fr = seg.records[j].family.frame(seg.records[j].prim)
        if fr is None or fr.direction is None:
            continue
        a = np.asarray(fr.direction, float)
        a = a / np.linalg.norm(a)
        if all(abs(a @ b) < np.cos(np.radians(ctx.tol.splitting.aligned_axis_deg)) for b in axes):
            axes.append(a)
    return axes
