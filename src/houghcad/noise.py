"""The noise policy: everything a noisy cloud changes, listed in one place.

A cloud is noisy when its points scatter about their surface instead of lying
on it: the estimated noise σ is at least :data:`NOISY_SPACINGS` point
spacings (the 188 Fit4CAD training samples read at most 0.09, 99 % of them
under 0.04). ``Segmenter(noise="auto"|"clean"|"noisy")`` chooses once; every
pass reads the fields of the chosen :class:`NoisePolicy`, never σ against a
threshold of its own. Preprocessing alone decides before the policy exists, as it
estimates σ: it widens the normals' neighbourhood from its own 16-neighbour estimate
(:data:`houghcad.preprocess.WIDE_NORMALS_SPACINGS`), and skips crease voting when this
policy would read the cloud as noisy.
"""

from __future__ import annotations

from dataclasses import dataclass

#: σ / spacing from which ``noise="auto"`` reads a cloud as noisy.
NOISY_SPACINGS = 0.15
NOISE_CHOICES = ("auto", "clean", "noisy")


@dataclass(frozen=True)
class NoisePolicy:
    """What the pipeline does differently on a noisy cloud (one field per change).

    Attributes
    ----------
    name : str
        ``"clean"`` or ``"noisy"``.
    trim_to_noise : bool
        Evaluation: refit on the inliers within 2 σ (trims both sides of a
        face alike), instead of on the closer half until the fit is exact.
    compete_above_noise : bool
        Competition: a point leaves a candidate only for one better by 2 σ.
    floor_selection : bool
        Selection compares candidates by their mean distance in excess of
        the noise's own (no surface fits noisy points better than the noise).
    cluster_families_first : bool
        The families voted per cluster (cone, torus) join the whole-cloud
        round: a slice of a cone by a simpler family fits within the noise.
    absorb_after_recognition : bool
        Leftover points join their neighbours' segments right after the
        whole-cloud round. On exact samples that takes the rows of small
        faces tangent to large ones before the splitting phase can see them
        (ablation: +0.0013 mean DSC on Fit4CAD without it, +0.003 on the
        clean synthetic parts); under noise it gathers the scatter about the
        large faces (−0.013 on the parts at σ = 0.5 % without it).
    wide_removal : bool
        Accepted primitives take the points within 2 τ (``noisy_epsilon_taus``),
        not τ: noise scatters a face's points past the inlier distance, while
        on exact samples the wider band takes neighbouring faces' rows.
    absorb_within_tau : bool
        Leftover points join a segment within τ of it, not ε (6 σ is another
        surface's band).
    strict_cover : bool
        A primitive covers a piece only if it fits all the piece's points as
        well as the piece's own primitive, not just the inliers within τ.
    group_planes : bool
        Consolidation's cone and torus votes on groups of segments take planes
        in the groups: a plane fits a slice of a noisy cone or torus within
        τ, while on exact samples the slice gate keeps planes whole faces
        (and voting the planes along costs time, not accuracy: ablation).
    revote_creases : bool
        Consolidation also groups segments joined up to the normals' tolerance
        (planes slicing a noisy curved surface meet at wide creases).
    nearest_edges : bool
        Boundaries go where the surfaces cross (nearest surface, with the
        sides of each edge), then poor fits are revisited; on clean clouds
        the boundary rows, which lie on both faces, go to the face with the
        smaller core.
    torus_grid_from_points : bool
        The torus accumulator's major radii stop at the points' own distances
        from the axis. On exact samples they reach on to where the points'
        normal lines meet when that is further (a band on the inside of the
        tube); noisy normals place that meeting point at random, and a grid
        stretched to it coarsens every torus vote (ablation: a noisy shaft
        with a groove lost 0.07 DSC on one seed).
    one_aligned_cylinder : bool
        A cluster the normals could not place gets one cylinder about a
        neighbour's axis, fitted to all its points (:mod:`houghcad.aligned`),
        not features in turn drawn from circles through three points and
        levels: a band ±τ (3 σ) holds most of a small noisy cluster whatever
        its shape, so the best of many draws is a chance fit (a generalised
        cone's pieces came out as planes and cylinders of a dozen points).
    complex_dominates : bool
        Selection: a more complex family's candidate that explains more
        points than a simpler one's, at a lower error in excess of the
        noise and a mean distance lower by ``recognition.dominance_se``
        standard errors, wins (the simpler one does nothing better). Within a band of
        ±6 σ a sphere through a bead, a groove and a wall holds thousands
        of points at an error near the noise's own, and against the rule of
        clear wins a torus explaining more of them lost to it. On exact
        samples the true face fits exactly, and no larger candidate fits
        better.
    larger_segments : bool
        The smallest segment is ``scale.noisy_min_points_floor`` points, not
        ``scale.min_points_floor``: a handful of noisy points fits some
        primitive of its own within the noise (a noisy groove's walls came
        out as scraps of 6-16 points with the clean floor).
    absorb_inwards : bool
        Leftover points are absorbed in rounds from a freed region's rim
        inwards, each by the segment among its nearest assigned points' whose
        surface is nearest (:func:`houghcad.growth.absorb`). On exact samples
        the leftovers are boundary rows and small faces the splitting phase
        must see (Fit4CAD: -0.0004 mean DSC, folds 0-2 down, with it on).
    one_link : bool
        Every point links at the cloud's link, not at its own sampling's
        (:meth:`houghcad.context.Context.link_scales`): under noise the
        neighbour distances read the noise's spread across the surface, not
        the sampling along it (an evenly sampled block at σ = 1.4 spacings:
        8-23 % of its points read 1.3 times sparser or more, against 0.7 %
        clean; the paper's noise block at σ = 0.2 lost 0.013 DSC).
    """

    name: str
    trim_to_noise: bool
    compete_above_noise: bool
    floor_selection: bool
    cluster_families_first: bool
    absorb_after_recognition: bool
    wide_removal: bool
    absorb_within_tau: bool
    strict_cover: bool
    group_planes: bool
    revote_creases: bool
    nearest_edges: bool
    torus_grid_from_points: bool
    one_aligned_cylinder: bool
    complex_dominates: bool
    larger_segments: bool
    absorb_inwards: bool
    one_link: bool

    @property
    def noisy(self) -> bool:
        return self.name == "noisy"


CLEAN = NoisePolicy("clean", *([False] * 17))
NOISY = NoisePolicy("noisy", *([True] * 17))


def choose(noise: str, sigma: float, spacing: float) -> NoisePolicy:
    """The policy for ``noise`` ("auto", "clean" or "noisy"), given the
    estimated σ and spacing (same units)."""
    if noise == "clean":
        return CLEAN
    if noise == "noisy":
        return NOISY
    if noise != "auto":
        raise ValueError(f"noise must be one of {', '.join(NOISE_CHOICES)}, got {noise!r}")
    return NOISY if sigma >= NOISY_SPACINGS * spacing else CLEAN
