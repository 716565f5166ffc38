"""Each point's sampling scale and off-surface ratio, as preprocessing reads them."""

from __future__ import annotations

import numpy as np

from houghcad import scales, synth
from houghcad.preprocess import preprocess


def test_link_scale_is_one_on_even_sampling_and_chunked_the_same(monkeypatch):
    cloud = synth.single("sphere", n_points=3000, seed=0)
    pre = preprocess(cloud.points, sampling_scales=True)
    assert np.percentile(pre.link_scale, 90) < 1.3
    dist, nbr = pre.tree.query(pre.points, k=16)
    whole = scales.link_scale(dist, nbr)
    monkeypatch.setattr(scales, "LINK_SCALE_CHUNK", 7)
    assert np.array_equal(scales.link_scale(dist, nbr), whole)


def test_off_surface_tells_scattered_points_from_a_sparse_face():
    """A local quadric explains a face's neighbourhoods at any density (about 0), not those of
    points scattered in space (0.1-0.3 of the neighbourhood's radius)."""
    rng = np.random.default_rng(2)
    xy = rng.random((600, 2))
    sparse = preprocess(np.c_[xy, 0.3 * (xy[:, 0] - 0.5) ** 2], sampling_scales=True)
    assert sparse.off_surface.dtype == np.float32 and np.quantile(sparse.off_surface, 0.99) < 0.01
    scattered = preprocess(rng.random((600, 3)), sampling_scales=True)
    assert np.quantile(scattered.off_surface, 0.01) > 0.08
    assert preprocess(rng.random((600, 3))).off_surface is None
