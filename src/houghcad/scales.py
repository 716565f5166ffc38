"""Each point's sampling scale and how far its neighbourhood is from a surface.

Both read the k-neighbourhoods that preprocessing already holds; the dense subsets link each point
at its own scale (:func:`houghcad.clusters.dbscan`, :meth:`houghcad.context.Context.link_scales`).
"""

from __future__ import annotations

import numpy as np


#: Rows per chunk of :func:`link_scale`'s gather: bounds its (rows, k) temporaries.
LINK_SCALE_CHUNK = 1 << 18


def link_scale(dist: np.ndarray, nbr: np.ndarray) -> np.ndarray:
    """Each point's sampling scale relative to the cloud's, at least 1: float32 (n,).

    ``dist`` and ``nbr`` (n, k) are each point's k nearest distances and indices, itself first.
    A point's scale is the median, over its neighbourhood, of the 6th-neighbour distance,
    divided by the cloud's median 6th-neighbour distance. A scan sees a part from one side:
    the faces turned away or farther off are sampled several times more sparsely, and a
    cloud-wide link, set by the median spacing, cuts such a face into fragments too small to
    stand as segments. The neighbourhood's median, not the point's own distance, so that one
    gap (a crease, a hole's rim) does not read as sparse sampling. Never below 1: where the
    sampling is denser than the median the cloud's link already connects it, and a shorter
    link would split the noise-spread points of a dense face.
    """
    n, k = dist.shape
    d6 = dist[:, min(6, k - 1)].astype(np.float32)
    ref = float(np.median(d6)) if n else 0.0
    out = np.ones(n, np.float32)
    if ref <= 0 or not np.isfinite(ref):
        return out
    for a in range(0, n, LINK_SCALE_CHUNK):
        local = np.median(d6[nbr[a:a + LINK_SCALE_CHUNK]], axis=1)
        out[a:a + LINK_SCALE_CHUNK] = np.maximum(local / ref, 1.0)
    return out


def off_surface(dist: np.ndarray, qres: np.ndarray | None) -> np.ndarray | None:
    """How far each point's neighbourhood is from a surface: float32 (n,), or None without ``qres``.

    ``dist`` (n, k) are the k nearest distances, ``qres`` (n,) the RMS residuals of a local quadric
    through the same neighbourhoods (:func:`houghcad.normals.quadric_residuals`). Their ratio to
    the neighbourhood's radius is scale-free: about 0 on a smooth face at any sampling density, a
    few hundredths where a neighbourhood straddles a crease, and 0.1-0.3 for points scattered in
    space (uniform outliers), whose neighbourhoods no surface explains. Sparse outliers read as
    sparse sampling too (:func:`link_scale`); this tells them from a face sampled sparsely.
    """
    if qres is None:
        return None
    r = dist[:, -1]
    with np.errstate(divide="ignore", invalid="ignore"):
        out = np.where(r > 0, qres / r, 0.0)
    return out.astype(np.float32)
