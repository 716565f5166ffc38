"""Multi-resolution segmentation: the even subsample, the propagation to every point, and a big cloud."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from houghcad import synth
from houghcad.errors import InputError
from houghcad.evaluate import classification_measures
from houghcad.multires import _candidates, distinct_points, voxel_subsample
from houghcad.pipeline import Segmenter


def _dsc(result, cloud) -> float:
    pred = [s.indices for s in result.segments]
    return float(classification_measures(pred, cloud.segments(), len(cloud.points))["DSC"])


def test_voxel_subsample_is_bounded_even_and_seeded():
    cloud = synth.block_with_hole_and_slot(seed=1, n_points=60000)
    sub = voxel_subsample(cloud.points, 8000, seed=3)
    idx = sub.indices
    assert 0.4 * 8000 <= len(idx) <= 8000
    assert np.all(np.diff(idx) > 0)  # sorted, no repeats
    # Even over the surface: every input point has a subsample point within about two voxels.
    d, _ = cKDTree(cloud.points[idx]).query(cloud.points)
    assert d.max() <= 2 * np.sqrt(3) * sub.voxel
    # One point per voxel.
    cells = np.floor((cloud.points[idx] - cloud.points.min(axis=0)) / sub.voxel).astype(np.int64)
    assert len(np.unique(cells, axis=0)) == len(idx)
    np.testing.assert_array_equal(voxel_subsample(cloud.points, 8000, seed=3).indices, idx)
    assert not np.array_equal(voxel_subsample(cloud.points, 8000, seed=4).indices, idx)


def test_candidates_are_distinct_segments_nearest_first():
    labels = np.array([[2, -1, 2, 0], [-1, -1, -1, -1], [1, 1, 1, 1]])
    nb = np.array([[10, 11, 12, 13], [20, 21, 22, 23], [30, 31, 32, 33]])
    rows, segs, near = _candidates(labels, nb)
    got = sorted(zip(rows.tolist(), segs.tolist(), near.tolist()))
    assert got == [(0, 0, 13), (0, 2, 10), (2, 1, 30)]


@pytest.fixture(scope="module")
def block():
    return synth.block_with_hole_and_slot(seed=2, n_points=40000)


@pytest.fixture(scope="module")
def full_and_multires(block):
    full = Segmenter(full_resolution=True).fit(block.points).result_
    multi = Segmenter(max_points=10000).fit(block.points).result_
    return full, multi


def test_subsample_then_propagation_matches_full_resolution(block, full_and_multires):
    full, multi = full_and_multires
    assert full.options["derived"]["subsample_points"] is None
    m = multi.options["derived"]["subsample_points"]
    assert 4000 <= m <= 10000
    assert {"subsample", "propagate"} <= set(multi.timing)
    assert sorted(s.type for s in multi.segments) == sorted(s.type for s in full.segments)
    assert _dsc(multi, block) >= _dsc(full, block) - 0.02
    # Labels over every input point, each point in at most one segment, MFE on all of them.
    owned = np.concatenate([s.indices for s in multi.segments] + [multi.unsegmented])
    assert len(owned) == len(block.points) and len(np.unique(owned)) == len(owned)
    assert len(multi.unsegmented) <= 0.005 * len(block.points)
    assert multi.normals.shape == block.points.shape
    assert np.isfinite(multi.distances[np.setdiff1d(np.arange(len(owned)), multi.unsegmented)]).all()


def test_the_files_normals_are_used_for_every_point(block, full_and_multires):
    _, multi = full_and_multires
    given = Segmenter(max_points=10000).fit(block.points, block.normals).result_
    assert given.options["normals_used"] == "input"
    np.testing.assert_allclose(np.abs(np.einsum("ij,ij->i", given.normals, block.normals)), 1.0, atol=1e-9)
    assert _dsc(given, block) >= _dsc(multi, block) - 0.01


def test_multires_is_deterministic(block, full_and_multires):
    _, multi = full_and_multires
    again = Segmenter(max_points=10000).fit(block.points).result_
    for a, b in zip(multi.segments, again.segments, strict=True):
        np.testing.assert_array_equal(a.indices, b.indices)
        assert a.params == b.params


def test_noisy_part_keeps_its_accuracy_on_a_quarter_of_the_points():
    cloud = synth.plate_with_holes(seed=1, n_points=40000, noise=0.002)
    full = Segmenter(full_resolution=True).fit(cloud.points).result_
    multi = Segmenter(max_points=10000).fit(cloud.points).result_
    assert multi.options["derived"]["subsample_points"] <= 10000
    assert _dsc(multi, cloud) >= _dsc(full, cloud) - 0.02
    assert len(multi.unsegmented) <= 0.01 * len(cloud.points)


def test_untrusted_normals_do_not_veto_crease_points():
    """At a crease PCA averages two faces: such points still join the nearest surface."""
    cloud = synth.block_with_hole_and_slot(seed=2, n_points=40000)
    strict = Segmenter(max_points=10000, tolerances={"resolution.flat_variation": 1.0}).fit(cloud.points).result_
    lenient = Segmenter(max_points=10000).fit(cloud.points).result_
    assert len(lenient.unsegmented) < len(strict.unsegmented) / 5


def test_points_inside_a_segment_take_their_subsample_neighbours_normal(block):
    """Only points whose subsample neighbours disagree estimate a normal of their own."""
    seg = Segmenter(max_points=10000)
    result = seg.fit(block.points).result_
    sub_idx = voxel_subsample(block.points, 10000, seed=0).indices
    labels = seg.segmentation_.labels
    tree = cKDTree(block.points[sub_idx])
    _, nb = tree.query(block.points, k=8)
    lab = labels[sub_idx][nb]
    inside = (lab[:, 0] >= 0) & (lab == lab[:, :1]).all(axis=1)
    assert 0.5 < inside.mean() < 1.0
    same = np.abs(np.einsum("ij,ij->i", result.normals, result.normals[sub_idx][nb[:, 0]]))
    np.testing.assert_allclose(same[inside], 1.0, atol=1e-9)
    # Along the edges the points' own normals: not all equal to a neighbour's.
    assert np.mean(same[~inside] > 1 - 1e-9) < 0.9


def test_points_off_the_surface_inside_a_segment_stay_unsegmented():
    """Inside a segment the normal is not checked, the distance still is."""
    cloud = synth.block_with_hole_and_slot(seed=2, n_points=40000)
    clean = Segmenter(max_points=10000).fit(cloud.points).result_
    eps = clean.options["derived"]["epsilon"]
    sub = voxel_subsample(cloud.points, 10000, seed=0).indices
    # Points lifted off the interior of the largest face, by 3 ε, pulled towards its centre so
    # that they stay over it; the subsample keeps its points (a lifted point is in a voxel of its
    # own, and a few extra points do not move the voxel size much).
    face = np.setdiff1d(clean.segments[0].indices, sub)
    centre = cloud.points[clean.segments[0].indices].mean(axis=0)
    rng = np.random.default_rng(0)
    lifted = rng.choice(face, 100, replace=False)
    pts = cloud.points.copy()
    pts[lifted] = centre + 0.5 * (pts[lifted] - centre) + 3 * eps * cloud.normals[lifted]
    result = Segmenter(max_points=10000).fit(pts).result_
    off = np.setdiff1d(lifted, voxel_subsample(pts, 10000, seed=0).indices)
    assert len(off) >= 10
    assert np.isin(off, result.unsegmented).mean() >= 0.9  # a few may land near another surface (the hole)


def test_distinct_points_and_their_twins():
    P = np.random.default_rng(0).normal(size=(50, 3))
    assert distinct_points(P) is None
    Q = np.vstack([P[:10], P[3:5], P[10:], P[0:1]])
    d = distinct_points(Q)
    assert d is not None and d.voxel == 0.0
    np.testing.assert_array_equal(Q[d.indices], P)  # first occurrences, in input order
    np.testing.assert_array_equal(Q[d.indices][d.twin], Q)
    assert d.twin[10] == 3 and d.twin[11] == 4 and d.twin[-1] == 0


@pytest.mark.parametrize("copies", [1.0, 0.6])
def test_exact_copies_take_their_twins_segments(block, copies):
    # A cloud stored twice over read a spacing of zero: no segment at all, or a crash.
    P = block.points
    one = Segmenter(seed=0).fit(P).result_
    extra = P[: int(copies * len(P))]
    both = Segmenter(seed=0).fit(np.vstack([P, extra])).result_
    assert both.options["derived"]["copies"] == len(extra)
    # The same segments (largest first: copies may reorder them), each holding its points' copies.
    n = len(P)
    twins = np.concatenate([np.arange(n), np.arange(len(extra))])
    assert len(both.segments) == len(one.segments)
    for s in both.segments:
        own = s.indices[s.indices < n]
        match = [t for t in one.segments if np.array_equal(t.indices, own)]
        assert len(match) == 1 and match[0].type == s.type
        np.testing.assert_array_equal(np.sort(twins[s.indices]), np.sort(np.concatenate([own, own[own < len(extra)]])))


def test_small_clouds_stay_whole_and_bad_sizes_are_refused(block):
    pts = block.points[:3000]
    r = Segmenter(max_points=5000).fit(pts).result_
    assert r.options["derived"]["subsample_points"] is None
    with pytest.raises(InputError, match="max_points must be a whole number of at least 1000"):
        Segmenter(max_points=10).fit(pts)


def test_cli_options(tmp_path, capsys):
    import json

    from houghcad.cli import main

    cloud = synth.plate_with_holes(seed=0, n_points=6000)
    path = tmp_path / "plate.xyz"
    np.savetxt(path, cloud.points)
    out = tmp_path / "r.json"
    assert main(["segment", str(path), "-o", str(out), "--max-points", "10", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "--max-points: must be >= 1000, got 10" in err and err.count("\n") == 1  # before reading
    assert not out.exists()
    assert main(["segment", str(path), "-o", str(out), "--max-points", "2000", "--quiet"]) == 0
    doc = json.loads(out.read_text())
    assert doc["options"]["max_points"] == 2000 and doc["options"]["derived"]["subsample_points"] <= 2000
    assert main(["segment", str(path), "-o", str(out), "--max-points", "2000", "--full-resolution", "--quiet"]) == 0
    doc = json.loads(out.read_text())
    assert doc["options"]["full_resolution"] and doc["options"]["derived"]["subsample_points"] is None


def test_two_million_points():
    """A 2M-point part goes through the subsample and the propagation (the scale benchmark times it)."""
    cloud = synth.gear_like(seed=0, n_points=2_000_000)
    small = synth.gear_like(seed=0, n_points=100_000)
    result = Segmenter().fit(cloud.points).result_
    reference = Segmenter().fit(small.points).result_
    assert result.options["derived"]["subsample_points"] <= 100_000
    assert len(result.segments) == len(reference.segments) == len(cloud.primitives)
    assert sorted(s.type for s in result.segments) == sorted(p["type"] for p in cloud.primitives)
    assert _dsc(result, cloud) >= _dsc(reference, small) - 0.01
    assert len(result.unsegmented) <= 0.005 * len(cloud.points)


def test_a_trace_of_a_subsampled_run_shows_the_subsample_with_its_input_rows(tmp_path):
    """The passes run on the subsample: the trace's PLYs hold its points, each with its input
    row (the CLI's --trace raised on them after the whole run, and no result was written)."""
    from plyfile import PlyData

    pts = synth.PARTS["filleted_block"](seed=0, n_points=5000).points
    seg = Segmenter(max_points=2000, trace=tmp_path / "trace").fit(pts)
    files = sorted((tmp_path / "trace").glob("*.ply"))
    assert files and files[0].name == "01_recognition.ply"
    v = PlyData.read(str(files[-1]))["vertex"].data
    rows = np.asarray(v["input_index"])
    assert 1000 < len(rows) <= 2000 and len(np.unique(rows)) == len(rows) and rows.max() < len(pts)
    np.testing.assert_allclose(np.c_[v["x"], v["y"], v["z"]], pts[rows], rtol=1e-12)
    assert seg.result_.n_points == len(pts)
