"""Planar annuli: geometry, sampler, recognition when selected, and coexistence with planes."""

from __future__ import annotations

import numpy as np
import pytest

import houghcad
from houghcad import synth
from houghcad.families import REGISTRY, Primitive

FAM = REGISTRY["annulus"]


def _prim(p):
    return Primitive("annulus", {"center": np.asarray(p["center"], float), "normal": np.asarray(p["normal"], float),
                                 "r_inner": float(p["r_inner"]), "r_outer": float(p["r_outer"])})


def test_distance_inside_outside_and_off_plane():
    prim = _prim({"center": [0, 0, 0], "normal": [0, 0, 1], "r_inner": 0.5, "r_outer": 1.0})
    P = np.array([[0.7, 0, 0], [0, 0.7, 0.2], [0.2, 0, 0], [1.3, 0, 0], [0, 1.3, 0.4]])
    assert np.allclose(FAM.distance(prim, P), [0, 0.2, 0.3, 0.3, 0.5])


def test_sampled_points_lie_on_it():
    cloud = synth.single("annulus", 2, n_points=2000)
    prim = _prim(cloud.primitives[0]["params"])
    assert FAM.distance(prim, cloud.points).max() < 1e-9 * cloud.diagonal()


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_recognised_when_selected(seed):
    """Type and DSC hold on 8/8 seeds; the radii only on 4/8 (measured relative r_inner errors
    0.3-26 %, r_outer 0-1.4 %: the centre from the boundary points is biased by the noise)."""
    cloud = synth.single("annulus", seed, n_points=4000, noise=0.005, missing=0.1)
    gt = cloud.primitives[0]["params"]
    res = houghcad.segment(cloud.points, families="annulus", seed=0)
    s = max(res.segments, key=lambda s: len(s.indices))
    assert s.type == "annulus"
    dsc = 2 * np.sum(cloud.labels[s.indices] == 0) / (len(s.indices) + len(cloud.points))
    assert dsc >= 0.9
    assert s.mfe <= 0.01
    assert abs(s.params["r_outer"] - gt["r_outer"]) <= 0.02 * gt["r_outer"]


@pytest.mark.xfail(reason="measured over seeds 0-7: r_inner within 2 % on 4/8 (errors 0.3, 2.9, 2.0, 1.6, 4.9, 1.2, "
                          "26, 0.3 %); the centre estimate from boundary points is biased at noise 0.005",
                   strict=False)
@pytest.mark.parametrize("seed", [1, 2])
def test_inner_radius_and_centre_when_selected(seed):
    cloud = synth.single("annulus", seed, n_points=4000, noise=0.005, missing=0.1)
    gt = cloud.primitives[0]["params"]
    res = houghcad.segment(cloud.points, families="annulus", seed=0)
    s = max(res.segments, key=lambda s: len(s.indices))
    assert abs(s.params["r_inner"] - gt["r_inner"]) <= 0.02 * gt["r_inner"]
    assert np.linalg.norm(np.subtract(s.params["center"], gt["center"])) <= 0.02 * gt["r_outer"]


def test_plane_keeps_the_annulus_under_all():
    # Documented choice: a plane explains the same points exactly as well and is simpler.
    cloud = synth.single("annulus", 0, n_points=4000, noise=0.005, missing=0.1)
    res = houghcad.segment(cloud.points, families="all", seed=0)
    big = max(res.segments, key=lambda s: len(s.indices))
    assert big.type == "plane" and len(big.indices) >= 0.9 * len(cloud.points)


@pytest.mark.parametrize("family,seed", [("plane", 1), ("cylinder", 2)])
def test_simple_singles_stay_simple(family, seed):
    cloud = synth.single(family, seed, n_points=3000, noise=0.005)
    res = houghcad.segment(cloud.points, families="all", seed=0)
    big = max(res.segments, key=lambda s: len(s.indices))
    assert big.type == family
