"""One segment graph with contact counts, read by consolidation, fillets and association."""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from _helpers import context, plane_candidate, rim_rows
from houghcad.adjacency import SegmentGraph, border_points, row_support, smooth_adjacency
from houghcad.families import REGISTRY
from houghcad.families.base import Primitive
from houghcad.state import Segmentation


def _grid(n: int = 20, h: float = 0.05) -> np.ndarray:
    u = np.arange(n) * h
    return np.stack(np.meshgrid(u, u), -1).reshape(-1, 2)


def _folded(angle_deg: float) -> tuple[np.ndarray, np.ndarray]:
    """Two square grids of spacing 0.05 meeting along the y axis at ``angle_deg``
    (180: one plane); labels (n,) 0 and 1, and a third, far segment 2."""
    g = _grid()
    left = np.c_[-g[:, 0] - 0.05, g[:, 1], np.zeros(len(g))]
    a = np.radians(180 - angle_deg)
    right = np.c_[g[:, 0] * np.cos(a), g[:, 1], g[:, 0] * np.sin(a)]
    far = left + [5.0, 0, 0]
    P = np.vstack([left, right, far])
    return P, np.repeat([0, 1, 2], len(g))


def test_all_pairs_graph_counts_the_contact_on_each_side():
    P, lab = _folded(180)
    g = SegmentGraph.build(lab, P, link=0.075)
    assert g.edges.tolist() == [[0, 1]]  # the far segment touches nothing
    # One row of 20 points on each side touches the other (the diagonal neighbours too).
    assert g.contact.tolist() == [[20, 20]]
    assert g.close_pairs[0] == 20 + 2 * 19
    assert (lab[g.cross[:, 0]] == 0).all() and (lab[g.cross[:, 1]] == 1).all()
    assert g.neighbours() == {0: {1}, 1: {0}}


def test_free_points_are_no_contact():
    P, lab = _folded(180)
    lab = lab.copy()
    lab[lab == 1] = -1
    g = SegmentGraph.build(lab, P, link=0.075)
    assert len(g.edges) == 0


def test_nearest_neighbour_graph_reads_contacts_from_the_querying_point():
    P, lab = _folded(180)
    g = SegmentGraph.build(lab, P, link=0.075, k=3)
    assert g.edges.tolist() == [[0, 1]]
    # The querying points of both sides that have a neighbour across.
    assert g.contact[0, 0] > 0 and g.contact[0, 1] > 0
    assert (lab[g.cross[:, 0]] != lab[g.cross[:, 1]]).all()


def test_agreement_tells_a_crease_from_a_smooth_boundary():
    for angle, smooth in ((180, True), (90, False)):
        P, lab = _folded(angle)
        g = SegmentGraph.build(lab, P, link=0.075)
        n = np.zeros_like(P)
        n[lab == 0] = [0, 0, 1.0]
        a = np.radians(180 - angle)
        n[lab == 1] = [-np.sin(a), 0, np.cos(a)]
        n[lab == 2] = [0, 0, 1.0]
        share = g.agreement(n, np.cos(np.radians(10)))
        assert (share[0] == 1.0) == smooth and (share[0] == 0.0) != smooth


def test_smooth_adjacency_joins_coplanar_pieces_not_faces_at_an_edge():
    from houghcad import synth

    cloud = synth.PARTS["block_with_hole_and_slot"](seed=0, n_points=6000)
    ctx = context(cloud.points)
    names = [p["name"] for p in cloud.primitives]
    bottom = np.flatnonzero(cloud.labels == names.index("box -z"))
    wall = np.flatnonzero(cloud.labels == names.index("box -x"))
    x = ctx.pre.points[bottom] @ np.linalg.svd(ctx.pre.points[bottom] - ctx.pre.points[bottom].mean(0))[2][0]
    half = x < np.median(x)
    seg = Segmentation.of(len(cloud.points), [plane_candidate(ctx, bottom[half]), plane_candidate(ctx, bottom[~half]),
                                              plane_candidate(ctx, wall)])
    smooth = {tuple(e) for e in smooth_adjacency(seg, ctx).tolist()}
    anyhow = {tuple(e) for e in smooth_adjacency(seg, ctx, smooth=False).tolist()}
    assert (0, 1) in smooth and not {(0, 2), (1, 2)} & smooth
    assert {(0, 2), (1, 2)} & anyhow


def test_border_points_are_the_neighbouring_faces_rows_and_the_surface_through_them_holds_them():
    pts, (row, a, b) = rim_rows(False)
    ctx = context(pts)
    seg = Segmentation.of(len(pts), [plane_candidate(ctx, a), plane_candidate(ctx, b)])
    border = border_points(row, seg.labels, ctx, 12)
    assert len(border) and np.isin(border, np.r_[a, b]).all()
    P = ctx.pre.points
    # Every point there is within a link of the row, and the discs' edge rows are among them.
    assert (cKDTree(P[row]).query(P[border])[0] <= ctx.link).all()
    edge = np.r_[a, b][np.abs(np.linalg.norm(pts[np.r_[a, b], :2], axis=1) - 10.0) < 1e-9]
    assert np.isin(edge, border).all()
    T = ctx.pre.transform
    cyl = Primitive("cylinder", {"axis_point": T.points(np.zeros((1, 3)))[0],
                                 "axis": T.dirs(np.array([[0.0, 0.0, 1.0]]))[0], "radius": 10.0 * T.scale})
    level = Primitive("plane", {"normal": T.dirs(np.array([[0.0, 0.0, 1.0]]))[0],
                                "offset": float(T.dirs(np.array([[0.0, 0.0, 1.0]]))[0] @ P[row[0]])})
    assert row_support(REGISTRY["cylinder"], cyl, border, ctx) >= len(edge)
    assert row_support(REGISTRY["plane"], level, border, ctx) == 0
    # Points of the row's own segment are not its border.
    seg2 = Segmentation.of(len(pts), [plane_candidate(ctx, a), plane_candidate(ctx, b), plane_candidate(ctx, row)])
    assert not np.isin(border_points(row, seg2.labels, ctx, 12), row).any()


def test_the_run_s_pairs_give_the_graph_of_a_tree_over_the_segmented_points():
    # Three segments and free points at random: the pairs read once over all points, kept to
    # the segmented ones, are the pairs of a tree over those alone.
    rng = np.random.default_rng(3)
    P = rng.random((600, 3))
    lab = rng.integers(-1, 3, len(P))
    link = 0.12
    pairs = cKDTree(P).query_pairs(link, output_type="ndarray").astype(np.int32)
    got = SegmentGraph.build(lab, P, link, pairs=pairs)
    ref = SegmentGraph.build(lab, P, link)
    assert got.edges.tolist() == ref.edges.tolist()
    assert got.close_pairs.tolist() == ref.close_pairs.tolist()
    assert got.contact.tolist() == ref.contact.tolist()
    key = lambda g: sorted(map(tuple, np.c_[g.cross, g.edge_of].tolist()))  # noqa: E731
    assert key(got) == key(ref)  # the same cross pairs, in another order


def test_preprocessed_pairs_are_read_once_per_radius():
    ctx = context(np.random.default_rng(0).random((300, 3)))
    a = ctx.pre.pairs_within(ctx.link)
    assert a.dtype == np.int32 and (a[:, 0] < a[:, 1]).all()
    d = np.linalg.norm(ctx.pre.points[a[:, 0]] - ctx.pre.points[a[:, 1]], axis=1)
    assert (d < ctx.link).all()
    assert len(a) == len(cKDTree(ctx.pre.points).query_pairs(ctx.link))
    assert ctx.pre.pairs_within(ctx.link) is a
