"""Planes for curved segments: a plane takes a curved segment it fits as well,
and planes that fit a loosely fitted curve exactly take it in strips."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from _helpers import context, plane_candidate, rim_rows, wide_cylinder
from houghcad import synth
from houghcad.families import REGISTRY, select
from houghcad.families.base import Primitive
from houghcad.planes import exact_planes, prefer_planes
from houghcad.state import Candidate, Segmentation

def test_noisy_curved_segment_that_a_plane_fits_as_well_becomes_a_plane():
    # A cylinder of radius 50 diagonals on a noisy plane face: flat within the noise.
    cloud = synth.single("plane", 0, n_points=3000, noise=0.005)
    ctx = context(cloud.points)
    P = ctx.pre.points
    flat = plane_candidate(ctx, np.arange(len(P)))
    cyl, _ = wide_cylinder(ctx, flat)
    piece = Candidate(REGISTRY["cylinder"], cyl, flat.indices, 0.0, np.zeros(len(P)))
    seg = Segmentation.of(len(P), [piece])
    assert prefer_planes(seg, select("simple"), ctx) == 1
    assert seg[0].family.name == "plane" and len(seg.indices(0)) == len(P)
    # Without the plane family selected, nothing changes.
    seg = Segmentation.of(len(P), [piece])
    assert prefer_planes(seg, select("cylinder"), ctx) == 0
    # A fixed primitive (a fillet's) keeps its family.
    seg = Segmentation.of(len(P), [piece])
    seg.set_record(0, replace(seg.records[0], fixed=True))
    assert prefer_planes(seg, select("simple"), ctx) == 0
    # A noisy cylinder (its true primitive, in the standard frame) stays one.
    seg, ctx = _true_cylinder_segment(noise=0.005)
    assert prefer_planes(seg, select("simple"), ctx) == 0
    assert seg[0].family.name == "cylinder"


def _true_cylinder_segment(noise: float) -> tuple[Segmentation, object]:
    """A single synthetic cylinder as one segment holding its true primitive (standard frame),
    and the run context."""
    cloud = synth.single("cylinder", 0, n_points=3000, noise=noise)
    ctx = context(cloud.points)
    T = ctx.pre.transform
    g = cloud.primitives[0]["params"]
    prim = Primitive("cylinder", {"axis_point": T.points(np.asarray(g["axis_point"])[None])[0],
                                  "axis": T.dirs(np.asarray(g["axis"])[None])[0], "radius": T.scale * g["radius"]})
    idx = np.flatnonzero(cloud.labels == 0)
    seg = Segmentation.of(len(cloud.points), [Candidate(REGISTRY["cylinder"], prim, idx, 0.0, np.zeros(len(idx)))])
    return seg, ctx


def test_an_exact_strip_two_rows_wide_read_as_a_cylinder_becomes_a_plane():
    # Two rows of exact samples lie on a plane and on every cylinder through both rows; the
    # simpler surface is taken. An exact cylinder over many rows stays a cylinder.
    x = np.arange(40.0)
    strip = np.c_[np.r_[x, x + 0.5], np.r_[np.zeros(40), np.ones(40)], np.zeros(80)]
    gx, gy = np.meshgrid(np.arange(20.0), np.arange(20.0))
    plate = np.c_[gx.ravel(), gy.ravel() + 5.0, np.full(gx.size, 3.0)]
    ctx = context(np.r_[strip, plate])
    P = ctx.pre.points
    idx = np.arange(80)
    Q = P[idx]
    axis = Q[39] - Q[0]
    axis /= np.linalg.norm(axis)
    across = Q[40] - Q[0] - ((Q[40] - Q[0]) @ axis) * axis
    normal = np.cross(axis, across / np.linalg.norm(across))
    w, h = np.linalg.norm(across), 4.0 * np.linalg.norm(across)
    centre = Q[0] + across / 2 - h * normal
    cyl = Primitive("cylinder", {"axis_point": centre, "axis": axis, "radius": float(np.hypot(w / 2, h))})
    assert REGISTRY["cylinder"].distance(cyl, Q).max() < 1e-9
    seg = Segmentation.of(len(P), [Candidate(REGISTRY["cylinder"], cyl, idx, 0.0, np.zeros(80))])
    assert prefer_planes(seg, select("simple"), ctx) == 1
    assert seg[0].family.name == "plane"
    seg, ctx = _true_cylinder_segment(noise=0.0)
    assert prefer_planes(seg, select("simple"), ctx) == 0



def _chamfered_edge(seed: int = 0) -> tuple[np.ndarray, list[np.ndarray]]:
    """Exact random samples (n, 3) of two faces meeting at a 45° chamfer,
    spacing about 0.1: face A (x = 0, z ≤ 0), the chamfer, face B (z = c/√2,
    x ≥ c/√2), all along y in [0, 3]. Returns the points and, for the edge's
    three strips (the faces' rows nearest the chamfer and the chamfer, each
    0.06 wide, under a spacing: a cylinder through them stays within τ),
    their indices."""
    rng = np.random.default_rng(seed)
    c, w, L, m = 0.06, 0.06, 3.0, 18
    d = np.sqrt(0.5)

    def face(origin, across, width, n):
        t, y = rng.uniform(0, width, n), rng.uniform(0, L, n)
        return np.asarray(origin) + t[:, None] * np.asarray(across) + y[:, None] * np.array([0.0, 1.0, 0.0])

    a_far = face([0, 0, -1.0], [0, 0, 1.0], 1.0 - w, 255)     # x = 0, z in [-1, -w]
    a_row = face([0, 0, -w], [0, 0, 1.0], w, m)
    cham = face([0, 0, 0], [d, 0, d], c, m)
    b_row = face([c * d, 0, c * d], [1.0, 0, 0], w, m)
    b_far = face([c * d + w, 0, c * d], [1.0, 0, 0], 1.0 - w, 255)
    pts = np.r_[a_far, a_row, cham, b_row, b_far]
    starts = np.cumsum([0, 255, m, m, m])
    return pts, [np.arange(starts[i], starts[i] + m) for i in (1, 2, 3)]


def _edge_cylinder(ctx, idx):
    """The least-squares cylinder of the points ``idx`` of the chamfered edge
    (a curve fitted to the polygon), seeded along the edge."""
    T = ctx.pre.transform
    seed = Primitive("cylinder", {"axis_point": T.points(np.array([[0.2, 0.0, -0.1]]))[0],
                                  "axis": T.dirs(np.array([[0.0, 1.0, 0.0]]))[0], "radius": 0.2 * T.scale})
    return REGISTRY["cylinder"].fit(seed, ctx.pre.points[idx], ctx.pre.normals[idx])


def _edge_cylinders(ctx, strips, pieces=1):
    """The chamfered edge's three strips as ``pieces`` cylinder segments along
    the edge, each holding the cylinder of all three strips: within τ, but not
    exact."""
    P = ctx.pre.points
    idx = np.concatenate(strips)
    cyl = _edge_cylinder(ctx, idx)
    d = REGISTRY["cylinder"].distance(cyl, P[idx])
    assert d.max() < ctx.tau and d.mean() > 0.1 * ctx.tau, (d.max() / ctx.tau, d.mean() / ctx.tau)
    along = P[idx] @ ctx.pre.transform.dirs(np.array([[0.0, 1.0, 0.0]]))[0]
    part = np.searchsorted(np.quantile(along, np.linspace(0, 1, pieces + 1)[1:-1]), along)
    return Segmentation.of(len(P), [Candidate(REGISTRY["cylinder"], cyl, idx[part == j], 0.0, d[part == j])
                                    for j in range(pieces)])


def _strip_owners(seg, strips):
    """For each strip, the segment holding most of it and the share it holds."""
    out = []
    for s in strips:
        lab = seg.labels[s]
        k = np.bincount(lab[lab >= 0]).argmax()
        out.append((int(k), float((lab == k).mean())))
    return out


def test_a_chamfered_edge_read_as_a_cylinder_goes_to_its_three_planes():
    pts, strips = _chamfered_edge()
    ctx = context(pts)
    for pieces in (1, 3):  # one cylinder, or three short ones along the edge
        seg = _edge_cylinders(ctx, strips, pieces)
        assert prefer_planes(seg, select("simple"), ctx) == pieces
        seg.check()
        assert len(seg) == 3 and all(s.family.name == "plane" for s in seg)
        owners = _strip_owners(seg, strips)
        assert len({k for k, _ in owners}) == 3 and min(share for _, share in owners) >= 0.95
        for k, s in enumerate(seg):
            assert REGISTRY["plane"].distance(s.prim, ctx.pre.points[s.indices]).max() < 0.05 * ctx.tau


def test_exact_planes_finds_the_strips_largest_first():
    pts, strips = _chamfered_edge(seed=1)
    ctx = context(pts)
    Q = ctx.pre.points[np.concatenate(strips)]
    planes = exact_planes(Q, ctx.tol.consolidation.cover_taus * ctx.tau, 8, ctx, np.random.default_rng(0))
    assert len(planes) == 3
    on = [np.sum(REGISTRY["plane"].distance(p, Q) < 0.02 * ctx.tau) for p in planes]
    assert on == sorted(on, reverse=True) and sum(on) >= len(Q) - 2


def test_a_true_cylinder_fitted_loosely_keeps_its_family():
    # Exact samples of a cylinder whose primitive is a third of tau off (a
    # radius refitted with a stray row): loose, but no plane holds more than
    # two of its rows, so no planes take it.
    seg, ctx = _true_cylinder_segment(noise=0.0)
    prim = seg[0].prim
    off = replace(prim, params={**prim.params, "radius": prim.params["radius"] + ctx.tau / 3})
    seg.set_record(0, replace(seg.records[0], prim=off))
    assert prefer_planes(seg, select("simple"), ctx) == 0
    assert len(seg) == 1 and seg[0].family.name == "cylinder"


def test_noisy_edge_strips_are_not_taken_by_planes():
    # On noisy samples no plane holds the points to the rounding of exact fits.
    pts, strips = _chamfered_edge(seed=2)
    pts = pts + np.random.default_rng(0).normal(0, 0.01, pts.shape)
    ctx = context(pts)
    idx = np.concatenate(strips)
    cyl = _edge_cylinder(ctx, idx)
    seg = Segmentation.of(len(pts), [Candidate(REGISTRY["cylinder"], cyl, idx, 0.0, np.zeros(len(idx)))])
    prefer_planes(seg, select("simple"), ctx)
    assert len(seg) <= 1



def test_a_rows_surface_is_the_one_its_neighbours_boundary_rows_lie_on():
    # The middle row of a rim whose edge rows went to the discs beside it lies on its own level
    # plane and on the rim's cylinder alike: the discs' edge rows lie on the cylinder, so it stays.
    # The same row between two coplanar faces (a flat land): their rows lie on the plane, which
    # takes it.
    for flat_land, kept in ((False, "cylinder"), (True, "plane")):
        pts, (row, a, b) = rim_rows(flat_land)
        ctx = context(pts)
        P, T = ctx.pre.points, ctx.pre.transform
        cyl = Primitive("cylinder", {"axis_point": T.points(np.zeros((1, 3)))[0],
                                     "axis": T.dirs(np.array([[0.0, 0.0, 1.0]]))[0], "radius": 10.0 * T.scale})
        assert REGISTRY["cylinder"].distance(cyl, P[row]).max() < 1e-9
        planes = [plane_candidate(ctx, idx) for idx in (a, b)]
        seg = Segmentation.of(len(P), [Candidate(REGISTRY["cylinder"], cyl, row, 0.0, np.zeros(len(row))), *planes])
        prefer_planes(seg, select("simple"), ctx)
        assert seg[0].family.name == kept, flat_land
