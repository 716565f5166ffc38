"""The part of the paper's noise experiment (its Table 5): two planes at k = ±1.28, a cylinder of
radius 1.80 and tori (R, r) = (1.49, 0.72) and (1.05, 0.79), in the paper's own units
(:func:`table5_block`)."""

from __future__ import annotations

from typing import Callable

import numpy as np

from ._faces import _cyl_face, _disc_face, _Face, _frame, _part, _radial
from .primitives import SynthCloud, _Streams

Array = np.ndarray

#: The primitives' parameters as the paper's Table 5 gives them ("Original" column).
K, CYLINDER_R = 1.28, 1.80
TORUS1 = (1.49, 0.72)  # (R, r): a bead on the top face
TORUS2 = (1.05, 0.79)  # a groove round the waist
#: Height of the groove's centre: low enough that the two tubes stay apart (their centre circles
#: are 1.59 apart, the tubes' radii sum to 1.51).
GROOVE_Z = -0.25


def table5_block(
    seed: int = 0,
    n_points: int = 25000,
    noise: float = 0.0,
    pose: bool = False,
    *,
    outliers: float = 0.0,
    scale: float | None = None,
) -> SynthCloud:
    """The 5-primitive part of the paper's noise experiment (its Fig. 7 (b) and Table 5).

    The paper gives the parameters, not the drawing; this part puts them together so that, as in
    the paper, the cylinder comes in two pieces that only the maximal primitive joins. Part frame:
    axis z. A cylinder of radius 1.80 between the planes z = -1.28 (bottom, a full disc) and
    z = +1.28 (top); round the waist (z = -0.25) a groove, the tube of the torus (1.05, 0.79), cuts
    the cylinder in two, leaving a neck of radius 0.26; on the top face a bead, the tube of the torus
    (1.49, 0.72), leaves the top plane a disc of radius 0.77 and overhangs the wall.

    Primitives (5): 0 bottom plane (k = -1.28), 1 top plane (k = +1.28), 2 cylinder (2 pieces),
    3 torus 1 (bead), 4 torus 2 (groove). Unposed by default, with the paper's 25,000 points, so
    that the parameters read as the paper's; ``noise`` is σ as a fraction of the bounding-box
    diagonal, like every synth part (the paper's σ in its units: divide by :meth:`diagonal` of
    the noise-free part). See :func:`~houghcad.synth.single` for the other options.
    """
    st = _Streams.from_seed(seed, "table5_block")
    (R1, r1), (R2, r2) = TORUS1, TORUS2

    def solid(p: Array) -> Array:
        rho, z = _radial(p), p[:, 2]
        body = (rho < CYLINDER_R) & (np.abs(z) < K)
        groove = np.hypot(rho - R2, z - GROOVE_Z) < r2
        bead = np.hypot(rho - R1, z - K) < r1
        return (body & ~groove) | bead

    faces = [
        _disc_face("bottom plane", (0, 0, -K), CYLINDER_R, (0, 0, -1)),
        _disc_face("top plane", (0, 0, K), CYLINDER_R, (0, 0, 1)),
        _cyl_face("cylinder", (0, 0, 0), CYLINDER_R, 2 * K),
        _Face("torus 1 (bead)", "torus", {"major": R1, "minor": r1}, _frame((0, 0, 1)),
              np.array([0, 0, K])),
        _Face("torus 2 (groove)", "torus", {"major": R2, "minor": r2}, _frame((0, 0, 1)),
              np.array([0, 0, GROOVE_Z])),
    ]
    return _part(st, f"table5_block-{seed}", faces, solid, n_points, noise, outliers, pose, scale)


#: The paper's parts (name → generator, like :data:`~houghcad.synth.PARTS`).
PAPER_PARTS: dict[str, Callable[..., SynthCloud]] = {"table5_block": table5_block}
