"""Every threshold of the pipeline, named, with its unit, default and reason.

One frozen dataclass per stage, in the manner of CGAL's
``Efficient_RANSAC::Parameters``; :class:`Tolerances` holds them all. Units:

- ``spacings``: the median nearest-neighbour distance of the cloud;
- ``σ``: the estimated noise standard deviation;
- ``τ``: the run's inlier distance; ``links``: its neighbour distance;
- ``diagonals``: the bounding-box diagonal; ``standard units``: the unit cube
  the cloud is scaled into;
- ``degrees``; ``points``; ``min_points``: multiples of the smallest segment;
- ``share``: a fraction of a set; ``ratio``: a factor between two figures.

Set them from the API (``Segmenter(tolerances=...)``, a :class:`Tolerances` or
a dict ``{"stage": {"name": value}}``); the run records them in the JSON
``options["tolerances"]``; ``docs/tolerances.md`` lists them
(``python -m houghcad.tolerances`` writes that page).
"""

from __future__ import annotations

import sys
from dataclasses import MISSING, dataclass, field, fields, replace
from typing import Any


def tol(default: Any, unit: str, why: str, least: float | None = None, most: float | None = None) -> Any:
    """A tolerance field: its default, unit and one line saying why; ``least`` and ``most`` bound
    the values a user may set (beyond positive, which every tolerance is). A share or a quantile
    is at most 1 (``keep_share=7`` left every point unsegmented without a word)."""
    if most is None and (unit.startswith("share") or unit == "quantile"):
        most = 1.0
    return field(default=default, metadata={"unit": unit, "why": why, "least": least, "most": most})


@dataclass(frozen=True)
class ScaleTolerances:
    """The run's scales, derived from the point spacing and the noise (:mod:`houghcad.context`)."""

    tau_spacings: float = tol(0.1, "spacings", "inlier distance τ on exact samples: tight, so tangent-continuous "
                              "neighbours (a fillet beside a plane) stay apart")
    tau_sigmas: float = tol(3.0, "σ", "inlier distance τ on noisy clouds: three noise sigmas hold 99.7 % of a face")
    epsilon_taus: float = tol(1.0, "τ", "removal distance ε around accepted primitives on exact samples: their "
                              "points lie on their surface, and a wider band takes the boundary rows of small "
                              "neighbouring faces (ablation: 2 τ loses 0.005 mean DSC on Fit4CAD, on every fold)")
    noisy_epsilon_taus: float = tol(2.0, "τ", "removal distance ε on noisy clouds (the paper's 1-3 % of the "
                                    "diagonal on its clouds): the scatter about a face reaches past τ")
    angle_deg: float = tol(20.0, "degrees", "normal compatibility on exact samples: PCA normals of CAD samples are "
                           "within a few degrees except at creases")
    angle_deg_per_noise: float = tol(30.0, "degrees per (σ / spacing)", "normals scatter as the noise grows against "
                                     "the spacing")
    angle_max_deg: float = tol(45.0, "degrees", "beyond this a normal no longer tells the surface's orientation")
    link_spacings: float = tol(2.0, "spacings", "neighbour distance that keeps a surface's sample connected")
    link_reach: float = tol(1.5, "6th-neighbour distances", "the link spans uneven sampling too")
    link_sigmas: float = tol(2.0, "σ", "noise spreads the points across the surface, widening the gaps")
    link_scale_from: float = tol(1.3, "times the cloud's sampling", "a point links farther than the cloud's link "
                                 "only where the sampling around it is at least this much sparser "
                                 "(`Preprocessed.link_scale`): random sampling alone reads up to 1.26-1.31 at "
                                 "its 99th percentile (synthetic planes to tori, 3k-20k points), a scan's faces "
                                 "turned away read 2-3. Fit4CAD thinned 10:1 across each part: 0.9263 with one "
                                 "link, 0.9320 here, uncapped (at 1.5: 0.9311); full density and 35 % unchanged. At 1 "
                                 "(no threshold) 35 % gained 2.0 thousandths on every fold, but a disc with "
                                 "both rim edges rounded lost 0.037 on the synthetic parts")
    link_scale_max: float = tol(4.0, "links", "a point links at most this many times the cloud's link where the "
                                "sampling around it is clearly sparser: a scan's faces turned away read 2-3, "
                                "Fit4CAD thinned 10:1 across each part up to 3.2; the cap bounds the pair search, "
                                "whose neighbours grow as its square. 1 gives one link for the cloud. Fit4CAD "
                                "thinned 10:1: 0.9263 -> 0.9307 (folds +4.8 / +6.8 / -2.7 / +5.7 / +7.5 "
                                "thousandths), predicted / true faces at the 90th percentile 1.59 -> 1.46; full "
                                "density identical on every cloud")
    link_off_surface_max: float = tol(0.1, "neighbourhood radii", "a point whose 16 neighbours no local quadric fits "
                                      "within this RMS (`Preprocessed.off_surface`) links farther only to points "
                                      "that one fits: uniform outliers read as sparse sampling too (3.7-5) and "
                                      "read 0.08-0.13 here at their 1st percentile (synthetic parts, 5-30 % "
                                      "outliers), so they do not chain among themselves (linked, the splitting "
                                      "phase searched their clusters: 30 % outliers, 2-3 times the time); a sparse "
                                      "face's points read 0.02 at their median, more beside an edge, and still "
                                      "link to the face. As a cut of the scale alone (0.9299), a hole's rim came "
                                      "apart from its sparse hole")
    cell_spacings: float = tol(0.5, "spacings", "accumulator cell for lengths: finer than the sampling resolves "
                               "only splits the votes")
    min_points_floor: int = tol(6, "points", "smallest segment: the fewest points that still show a misfit of "
                                "a plane, sphere or cylinder (3, 4, 5 parameters); 8 lost faces of 6-7 points on "
                                "sparse clouds (Fit4CAD: every fold up at 6, at full density and at 35 %; 4 "
                                "over-segments the sparse clouds)", least=2)
    noisy_min_points_floor: int = tol(8, "points", "smallest segment on noisy clouds: a handful of noisy points "
                                      "fits some primitive of its own within the noise")
    min_face_diagonals: float = tol(0.015, "diagonals", "smallest face: a patch this wide, in points at the "
                                    "cloud's density (at least min_points_floor); a size on the part, whatever "
                                    "its sampling density")
    first_round_share: float = tol(0.01, "share of the cloud", "the whole-cloud round keeps only substantial "
                                   "segments; smaller ones are settled per cluster, where every family competes. "
                                   "A share of the points is one of the surface under even sampling. As 1 % of "
                                   "the surface's area (each point the disc through its 6th neighbour; counted "
                                   "first at the 90th percentile of a point's area) it gained 0.2 and 0.3 "
                                   "thousandths on Fit4CAD at full density and at 35 % but lost 1.4 on Fit4CAD "
                                   "thinned 10:1 across each part (`--uneven 0.9`, folds +0.1 / -1.7 / +0.7 / -5.9 "
                                   "/ -0.3), the case it is for, and 0.006 on the parts at noise 0.0005: the votes "
                                   "count points, and a sparse face's first-round candidate is the weaker one. As a "
                                   "face width (0.105 diagonals) it lost 0.0005; shares 0.005 and 0.02 lost 0.0004 "
                                   "and 0.0018")
    max_radius: float = tol(1.0, "standard units", "radii beyond the unit cube are planes read as curved")
    max_peaks: int = tol(24, "peaks", "peaks evaluated per accumulator: each costs a refit")
    max_directions: int = tol(12, "directions", "normal directions tried per family (planes, axes)")
    on_surface_spacings: float = tol(0.3, "spacings", "a point this close to a surface (or within τ) lies on it, for "
                                     "edge settling and dissolving")


@dataclass(frozen=True)
class RecognitionTolerances:
    """Candidate evaluation and selection (paper §5.2, :mod:`houghcad.recognize`)."""

    dense_min_samples: int = tol(3, "points", "DBSCAN core size of a dense subset X_i: a row of points is connected")
    refit_points: int = tol(600, "points", "least-squares refits on a random subset: beyond this the fit no "
                            "longer moves")
    coarse_taus: float = tol(4.0, "τ", "intermediate inlier distance between the cell's and τ, so each refit sees "
                             "cleaner inliers")
    clean_trim_rounds: int = tol(4, "rounds", "refits on the closer half of the inliers on exact samples")
    noisy_trim_rounds: int = tol(2, "rounds", "refits on the inliers within trim_sigmas on noisy clouds")
    trim_stop_taus: float = tol(0.05, "τ", "exact samples: stop trimming once the inliers fit to this")
    trim_sigmas: float = tol(2.0, "σ", "noisy clouds: 95 % of a face within 2 σ, while a neighbour's points within τ "
                             "sit further out on one side")
    trim_min_points: float = tol(2.0, "min_points", "trimming keeps enough points to refit")
    strip_width_spacings: float = tol(0.4, "spacings", "a dense subset narrower than this across is a one-row strip, "
                                      "not a surface patch")
    slice_sigmas: float = tol(2.0, "σ", "on the whole cloud a candidate fitting worse than this (and slice_taus) is a "
                              "tangent slice that another family explains exactly")
    slice_taus: float = tol(0.1, "τ", "the tangent-slice gate on exact samples")
    compete_taus: float = tol(0.25, "τ", "a point leaves a candidate only for one explaining it clearly better")
    compete_sigmas: float = tol(2.0, "σ", "noisy clouds: some candidate among dozens passes through any point; a "
                                "margin under the noise shreds the true surface")
    keep_share: float = tol(0.6, "share", "a selected candidate must still hold this much of its points free; "
                            "candidates sharing more than 1 - this compete")
    settle_share: float = tol(0.5, "share", "candidates mostly overlapping the winner are settled with it")
    complex_max_peaks: int = tol(6, "peaks", "a complex family's candidate costs tens of milliseconds of nonlinear "
                                 "fits; its surface is one of the most persistent peaks")
    beside_top_peaks: int = tol(2, "peaks", "peaks a stacked family adds from the votes off its top surface")
    beside_top_persistence: float = tol(0.5, "share of the persistence threshold", "a surface sharing a placement "
                                        "with a larger one votes a lower peak, at least this persistent")
    covers_size: float = tol(1.5, "ratio", "a complex candidate explaining this many times the points ...")
    covers_mfe: float = tol(1.25, "ratio", "... at most this much worse replaces another (same rank)")
    complex_wins_mfe: float = tol(0.5, "ratio", "a more complex family wins with at most this share of the simpler "
                                  "one's error ...")
    complex_wins_abs: float = tol(2e-5, "MFE (diagonals)", "... and a difference above this, not rounding")
    noise_mean_sigmas: float = tol(0.8, "σ", "mean |d| of Gaussian noise (0.798 σ): the error no surface beats")
    noise_floor_size: float = tol(0.9, "share of the largest", "candidates about as large as the largest show the "
                                  "noise's own error where σ is overestimated")
    noise_floor_se: float = tol(1.5, "standard errors", "an excess below two standard errors of the mean |d| "
                                "(0.755 m / √n) is the floor itself")
    noise_floor_least: float = tol(0.05, "share of the floor", "the least excess selection resolves")
    dominance_se: float = tol(2.0, "standard errors", "noisy clouds: a more complex candidate explaining more "
                              "points wins when its mean distance is lower by this many standard errors of the "
                              "difference, more than a nesting family's extra freedom gives")
    neighbours: int = tol(10, "neighbours", "neighbour table handed to the families' placements", least=2)
    tube_centre_share: float = tol(0.5, "share of the normal lines", "a torus placement's tube centre, where the "
                                   "normal lines meet in the meridian plane, that fewer lines pass near is no "
                                   "meeting point: the lines of several tubes (or none) meet at their average")
    tube_centres: int = tol(3, "centres", "tube centres tried per torus placement when the lines meet in several "
                            "places: each costs a vote over (R, r)")
    meridian_bins: int = tol(64, "bins", "cells across the meridian plane's larger side in the vote of the normal "
                             "lines for tube centres (at least τ wide)")
    meet_cells: float = tol(2.0, "meridian cells", "a normal line this near a point or the axis meets it: at σ = "
                            "1.4 % of the diagonal 71 % of a turned part's lines pass within two cells of its axis, "
                            "46 % within one")
    axis_cells: int = tol(3, "meridian cells", "normal lines meeting this near the axis meet at a sphere's centre "
                          "or a cone's apex, not a tube's")
    turned_share: float = tol(0.6, "share of the normal lines", "tube centres beyond the first are sought when "
                              "this much of the normal lines not parallel to the axis meet it: the part is turned "
                              "about it, and its lines are true enough to meet where they should (at σ = 1.4 % of "
                              "the diagonal 71 % of a turned part's lines do, at 2.8 % 54 %, where the extra tubes "
                              "lost 47 thousandths over 10 seeds; parts not turned: at most 47 %)")
    parallel_deg: float = tol(10.0, "degrees", "a normal line this close to the axis's direction is parallel to it "
                              "(a disc about the axis)")


@dataclass(frozen=True)
class SplittingTolerances:
    """The splitting phase (paper §5.3, :mod:`houghcad.splitting`, :mod:`houghcad.ransac`)."""

    max_rounds: int = tol(6, "rounds", "clustering rounds; each finds what the last freed")
    cluster_min_samples: int = tol(4, "points", "DBSCAN core size of a cluster")
    fragment_share: float = tol(0.25, "share of the cluster", "a cluster whose largest recognised piece is smaller "
                                "is also split by RANSAC; the larger pieces win")
    ransac_min_size: float = tol(3.0, "min_points", "clusters this large where the vote finds nothing are "
                                 "over-segmented with RANSAC")
    ransac_min_points: int = tol(10, "points", "RANSAC's smallest shape")
    ransac_probability: float = tol(0.01, "probability", "RANSAC's chance of missing the largest shape")
    aligned_neighbours: int = tol(12, "neighbours", "points around a cluster read for its adjacent segments")
    aligned_axis_deg: float = tol(2.0, "degrees", "adjacent axes closer than this are one")
    aligned_samples: int = tol(256, "circles", "circles through three points drawn per direction: a feature with a "
                               "third of a cluster's points is drawn about ten times")
    aligned_band_taus: float = tol(2.0, "τ", "boundary points this close to a cylinder join its refit")
    aligned_refits: int = tol(2, "refits", "refits of an aligned cylinder (on its points and the boundary rows) or cone")
    aligned_pieces: int = tol(4, "features", "features aligned with the neighbours taken per cluster: a counterbore "
                              "is three (bore, step, hole); a surface the normals missed, sliced into rings, is many")
    aligned_cone_taus: float = tol(0.02, "τ", "a cone about a hole's axis, refitted axis free, must fit its points "
                                   "to the rounding of an exact fit: a torus fillet's arc or a crease fits a cone "
                                   "to 0.04-0.6 τ")
    aligned_cover: float = tol(0.8, "share", "the aligned features must explain this much of the cluster together")
    aligned_exact_taus: float = tol(0.02, "τ", "short of that cover, an aligned cylinder stays if it fits its points "
                                    "to the rounding of an exact fit ...")
    aligned_rings_spacings: float = tol(0.5, "spacings", "... over more than one ring: its points this far apart "
                                        "along its axis. Two rings of one radius lie on one cylinder only where "
                                        "the part has one, while one ring lies on every cylinder and cone through it")
    crease_neighbours: int = tol(6, "points", "a cluster's crease point takes the PCA normal of this many of the "
                                 "cluster's points: on a hole a few spacings wide, more reach across it", least=2)
    crease_row_ratio: float = tol(0.05, "eigenvalue ratio", "a neighbourhood whose middle spread is under this share "
                                  "of the largest is one row of points, which no plane fits")


@dataclass(frozen=True)
class BoundaryTolerances:
    """Edge settling and dissolving (extensions, :mod:`houghcad.boundaries`)."""

    neighbours: int = tol(12, "neighbours", "points read around each point for adjacent segments")
    settle_slack: float = tol(0.1, "τ", "a point lies on every surface no farther from it than the nearest plus this "
                              "(or settle_fits): a face continuing another tangentially passes nearer than τ "
                              "to the other's rows beside the tangent line, which are not on it; 0.5 lost "
                              "0.0004 mean DSC on Fit4CAD (without settle_fits)")
    settle_rounds: int = tol(8, "rounds", "a round settles the points next to a boundary; a tangent band a segment "
                             "took is deeper than one ring (one round gave 0.0011 less mean DSC on Fit4CAD, "
                             "0.0041 less at 35 % of the points)")
    settle_fits: float = tol(4.0, "median distances", "a surface's distances are only as sure as its fit: a small "
                             "face's boundary rows lie up to this many times its points' median distance off it; "
                             "2 and 8 gave 0.0004 and 0.0001 less mean DSC on Fit4CAD")
    edge_taus: float = tol(0.1, "τ", "a point on a boundary curve lies within this of both faces' surfaces: a CAD "
                           "sample's edge rows lie on both to the fits' accuracy, while random samples beside an "
                           "edge lie this near both only in a band a tenth as wide as at τ (synthetic parts, "
                           "whose truth gives each point one face: −0.003 DSC at τ, none at 0.1 τ; Fit4CAD, every "
                           "2nd cloud: 0.977 at 0.1 τ and at 0.2 τ, 0.9745 at τ on creases only)")
    noisy_rounds: int = tol(8, "rounds", "each round moves the points next to the boundary; it walks to where the "
                            "surfaces cross")
    side_links: float = tol(3.0, "links", "a face's points this near the other face tell its side")
    side_majority: float = tol(0.8, "share", "the side is clear when this many points agree")
    sound_fit: float = tol(1.5, "ratio to the median fit", "a primitive fitting worse than this is wrong, and keeps "
                           "the nearest-surface rule")
    dissolve_size: float = tol(3.0, "min_points", "segments smaller than this may be slivers")
    dissolve_exact_taus: float = tol(0.02, "τ", "exact samples: a segment of any size whose every point lies this "
                                     "near a larger neighbour's surface (the rounding of an exact fit), which its own "
                                     "primitive does not fit as closely, is a piece of that surface")
    absorb_neighbours: int = tol(6, "points", "noisy clouds: a leftover point may join the segment of any of this many "
                                 "nearest assigned points (its single nearest may lie across the edge)")
    absorb_rounds: int = tol(50, "rounds", "noisy clouds: absorption walks into a freed region two links a round; it "
                             "stops at the first round that takes nothing, this bounds the work")


@dataclass(frozen=True)
class AdjacencyTolerances:
    """Which segments touch, and smoothly (:mod:`houghcad.adjacency`)."""

    neighbours: int = tol(8, "neighbours", "points read around each point for smooth contacts: the nearest across a "
                          "boundary tell its smoothness")
    crease_angles: float = tol(0.5, "angle tolerances", "fitted normals agreeing within this are tangent-continuous; "
                               "a crease of a few degrees is still a crease")
    smooth_share: float = tol(0.5, "share", "most contacts must agree for a smooth boundary")
    contact_divisor: float = tol(3.0, "1 / √(points of the smaller)", "a boundary, not a corner, has about √n "
                                 "contacts; a pair needs √n / this")
    contact_min: int = tol(3, "points", "a contact of fewer points is a corner")


@dataclass(frozen=True)
class ConsolidationTolerances:
    """Consolidation (extension, :mod:`houghcad.consolidation`)."""

    dominant: float = tol(0.6, "share", "a candidate must explain this much of a poorly fitted segment to replace it")
    excess: float = tol(1.3, "ratio to the noise's cost", "segments fitted within this are left alone")
    least_excess: float = tol(0.05, "share of the noise's cost", "excesses below this are the noise's own")
    revisit_min_size: float = tol(3.0, "min_points", "smaller segments are not revisited")
    exact_taus: float = tol(0.05, "τ", "a segment whose median distance is below this lies on its primitive (the "
                            "clean refits stop there): what fits it worse is rows of its neighbours")
    complex_halving: float = tol(0.5, "ratio", "a more complex family must halve the excess to displace a simpler one")
    peel_share: float = tol(2 / 3, "share of the group", "a face this dominant is not a piece of a carved surface")
    peel_retries: int = tol(2, "faces", "where the vote takes nothing, the largest faces set aside in turn")
    merge_rounds: int = tol(10, "rounds", "rounds of segments taking their adjacent pieces")
    suffices_points: int = tol(600, "points", "refit of one simple primitive over several pieces")
    cover_share: float = tol(0.8, "share", "a primitive covers a piece holding this much of it within τ")
    cover_ratio: float = tol(1.1, "ratio", "... fitting it no worse than this times the piece's own fit")
    cover_taus: float = tol(0.02, "τ", "... plus this, the rounding of exact fits")
    own_fit_ratio: float = tol(1.5, "ratio", "or no worse than this times the covering segment's fit to its own points")
    strict_se: float = tol(1.5, "standard errors", "noisy clouds: over all the piece's points, within this of the "
                           "piece's own fit")
    plane_min_points: int = tol(10, "points", "curved segments smaller than this are not offered one plane")
    plane_se: float = tol(2.0, "standard errors", "a plane takes a curved segment unless it fits clearly worse")
    facet_exact_ratio: float = tol(2.0, "cover_taus", "a curved segment fitted worse than this many roundings of "
                                   "exact fits is loose: planes may take it in strips")
    facet_cover: float = tol(0.9, "share", "the planes must hold this much of a loose segment to the rounding of exact "
                             "fits to take it")
    facet_max_planes: int = tol(4, "planes", "a group goes to at most this many planes (a chamfered edge: the two "
                                "faces' rows and the chamfer)")
    facet_samples: int = tol(256, "planes", "planes through three points drawn per plane found")
    facet_score_points: int = tol(2000, "points", "planes are scored on at most this many points")


@dataclass(frozen=True)
class FilletTolerances:
    """Rolling-ball fillets between adjacent segments (extension, :mod:`houghcad.blend`)."""

    lr_min: float = tol(25.0, "σ²", "likelihood ratio a fillet must reach over the sharp corner (sharp edges of the "
                        "synthetic parts reached 11-16, 28 with a tilted neighbour)")
    passes: int = tol(3, "passes", "a segment gives points to one fillet per pass")
    radii: int = tol(48, "radii", "radii tried per corner before a local refinement")
    fine_radii: int = tol(9, "radii", "radii of the local refinement")
    corner_min_deg: float = tol(25.0, "degrees", "narrower corners are not filleted by a circle in the data")
    corner_max_deg: float = tol(155.0, "degrees", "wider corners are nearly flat: no fillet to tell")
    parallel_deg: float = tol(15.0, "degrees", "lines or planes closer to parallel make no corner")
    coaxial_deg: float = tol(2.0, "degrees", "axes closer than this are one")
    coaxial_taus: float = tol(2.0, "τ", "axis lines this close are one ...")
    coaxial_diagonals: float = tol(0.01, "diagonals", "... or this close")
    extent_quantile: float = tol(0.9, "quantile", "a face's extent along its ray, robust to strays", most=1.0)
    band_share: float = tol(0.5, "share of the shorter extent", "the corner's band along each ray; a radius "
                              "at its end (the band bounds it) is sought again to the shorter face's far end")
    band_before_sigmas: float = tol(3.0, "σ", "points this far before the corner still belong to its band")
    band_min_points: int = tol(10, "points", "a band needs points to fit a radius")
    trim_sigmas: float = tol(2.5, "σ", "the neighbours' lines refitted on their points within this")
    trim_rounds: int = tol(3, "rounds", "trimmed refits of the neighbours' lines")
    trim_min_points: int = tol(20, "points", "a line refit needs this many points")
    min_radius_sigmas: float = tol(2.0, "σ", "a fillet narrower than the noise cannot be told from a sharp edge")
    taken_share: float = tol(0.8, "share", "a segment with this much of it in the corner's band is a piece of the "
                             "fillet")
    max_radius_diagonals: float = tol(0.2, "diagonals", "largest fillet radius tried")
    reach_diagonals: float = tol(0.25, "diagonals", "each face's points this near the other make its corner")
    aligned_min_deg: float = tol(0.5, "degrees", "a cylinder this close to a plane's normal stands on it already")
    aligned_max_deg: float = tol(6.0, "degrees", "a short cylinder's axis this close to a plane's normal is snapped "
                                 "to it")
    aligned_rounds: int = tol(3, "rounds", "trimmed circle fits of the snapped cylinder")


@dataclass(frozen=True)
class AssociationTolerances:
    """Maximal primitives and relations (paper §5.4, :mod:`houghcad.associate`)."""

    angle_tol: float = tol(2.0, "degrees", "largest angle between parallel axes or normals, and between equal "
                           "half-angles")
    length_tol: float | None = tol(None, "diagonals", "largest difference between equal lengths and positions; "
                                   "None: positions from τ, at least length_floor, and shapes from fit_residuals")
    length_floor: float = tol(0.002, "diagonals", "the least tolerance on positions (axis lines, pivots), which "
                              "depend on how the points are spread over a face, and on same-surface proposals")
    length_taus: float = tol(0.5, "τ", "the position tolerance follows the inlier distance")
    fit_residuals: float = tol(2.0, "mean residuals", "lengths of congruent shapes (radii ...) differ by at most "
                               "this many of the looser fit's mean point distance: a fit knows its radius about as "
                               "well as its points lie on it, so exact fits agree closely and noisy ones within "
                               "their noise (2 × 0.8 σ ≈ τ/2)")
    relative_tol: float = tol(0.02, "share of the value", "lengths may also differ by this")
    extent_tol: float = tol(0.1, "share of the value", "extents are equal within this: they come from the points, "
                            "not a fit")
    extent_floor: float = tol(0.02, "diagonals", "the least extent tolerance")
    contact: float = tol(0.3, "√(points of the smaller)", "pieces of one surface are one part when each side has "
                         "this many points touching the other: a shared boundary, not a corner")
    bridge_links: float = tol(0.5, "links", "a gap joining two pieces of a narrow face lies this close to their "
                              "surface")
    bridge_angle: float = tol(25.0, "degrees", "a gap in a narrow face's sampling continues its row of points: "
                              "the pieces' axes are within this of the gap's direction")
    gap_links: float = tol(1.5, "links", "pieces of one surface this close, with no third segment between them, are "
                           "one part apart by a gap of the sampling")
    gap_front: float = tol(1.0, "√(points of the smaller)", "... along a front of at most this many points beyond "
                           "the link: a hole in the sampling, not a boundary all along")
    bridge_reach: float = tol(3.0, "links", "a row's direction at a gap is read from its points this close to "
                              "it: rings and arcs of narrow faces turn along their length")
    propose_lengths: float = tol(4.0, "length tolerances", "same-surface proposals are generous; the union refit "
                                 "decides")
    propose_angles: float = tol(3.0, "angle tolerances", "same-surface proposals are generous")
    verify_taus: float = tol(0.5, "τ", "a union refit keeps every member within its own fit plus this")
    refit_points: int = tol(4000, "points", "refits on a regular subsample: beyond this the parameters no longer move")
    axis_lengths: float = tol(2.0, "length tolerances", "an axis fitted on a piece of length h is known to about "
                              "this / h radians")
    coaxial_lengths: float = tol(2.0, "length tolerances", "axis lines this close are one")
    mirror_lengths: float = tol(2.0, "length tolerances", "mirror images of pivots this close match")


@dataclass(frozen=True)
class ResolutionTolerances:
    """Multi-resolution segmentation of big clouds (our extension, :mod:`houghcad.multires`)."""

    neighbours: int = tol(8, "points", "subsample neighbours whose segments an input point may join: one subsample "
                          "spacing around it, both sides of a crease")
    inlier_epsilons: float = tol(1.0, "ε", "an input point joins a segment within the subsample's removal distance, "
                                 "the band the pipeline itself gave it")
    angle_deg: float = tol(30.0, "degrees", "the point's normal must agree with the surface's: full-resolution "
                           "normals of scans scatter more than the subsample's")
    normals_neighbours: int = tol(10, "points", "PCA neighbourhood of the full-resolution normals when the file "
                                  "has none")
    flat_variation: float = tol(0.02, "share of the variance", "a PCA normal is trusted where the neighbourhood is "
                                "flat (smallest eigenvalue at most this share): across a crease it averages the "
                                "two faces")


@dataclass(frozen=True)
class Tolerances:
    """All the stages' tolerances (see the module docstring)."""

    scale: ScaleTolerances = field(default_factory=ScaleTolerances)
    recognition: RecognitionTolerances = field(default_factory=RecognitionTolerances)
    splitting: SplittingTolerances = field(default_factory=SplittingTolerances)
    boundaries: BoundaryTolerances = field(default_factory=BoundaryTolerances)
    adjacency: AdjacencyTolerances = field(default_factory=AdjacencyTolerances)
    consolidation: ConsolidationTolerances = field(default_factory=ConsolidationTolerances)
    fillets: FilletTolerances = field(default_factory=FilletTolerances)
    association: AssociationTolerances = field(default_factory=AssociationTolerances)
    resolution: ResolutionTolerances = field(default_factory=ResolutionTolerances)

    def to_dict(self) -> dict[str, dict[str, Any]]:
        """``{stage: {name: value}}``, every field."""
        return {f.name: {g.name: getattr(getattr(self, f.name), g.name) for g in fields(getattr(self, f.name))}
                for f in fields(self)}

    @classmethod
    def from_dict(cls, d: dict[str, dict[str, Any]] | None) -> "Tolerances":
        """Tolerances from ``{stage: {name: value}}``; missing ones keep their default.
        Raises ValueError naming an unknown stage or tolerance."""
        return cls().updated(d or {})

    def updated(self, d: dict[str, dict[str, Any]]) -> "Tolerances":
        """A copy with the values of ``{stage: {name: value}}`` (or ``{"stage.name": value}``) set."""
        nested: dict[str, dict[str, Any]] = {}
        for k, v in d.items():
            if "." in k:
                stage, name = k.split(".", 1)
                nested.setdefault(stage, {})[name] = v
            elif isinstance(v, dict):
                nested.setdefault(k, {}).update(v)
            else:
                raise ValueError(f"tolerance {k!r}: give a stage's dict or 'stage.name'")
        out = self
        stages = {f.name for f in fields(self)}
        for stage, values in nested.items():
            if stage not in stages:
                raise ValueError(f"unknown tolerance stage {stage!r} (known: {', '.join(sorted(stages))})")
            group = getattr(out, stage)
            known = {f.name: f for f in fields(group)}
            for name, value in values.items():
                if name not in known:
                    raise ValueError(f"unknown tolerance {stage}.{name}")
                values[name] = _checked(f"{stage}.{name}", known[name], value)
            out = replace(out, **{stage: replace(group, **values)})
        return out

    def changed(self) -> dict[str, Any]:
        """``{"stage.name": value}`` of the tolerances that differ from their defaults."""
        base = Tolerances().to_dict()
        return {f"{s}.{n}": v for s, g in self.to_dict().items() for n, v in g.items() if base[s][n] != v}


def _checked(name: str, f: Any, value: Any) -> Any:
    """``value`` as the field's type (int or float, or None where allowed), positive: every
    tolerance is a distance, an angle, a count, a share or a ratio (0 or less broke the run)."""
    default = f.default if f.default is not MISSING else None
    if value is None:
        if default is None:
            return None
        raise ValueError(f"tolerance {name} cannot be None")
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ValueError(f"tolerance {name} must be a number, got {value!r}")
    if not value == value or value in (float("inf"), float("-inf")):
        raise ValueError(f"tolerance {name} must be finite, got {value!r}")
    if value <= 0:
        raise ValueError(f"tolerance {name} must be positive, got {value!r}")
    least, most = f.metadata.get("least"), f.metadata.get("most")
    if least is not None and value < least:
        raise ValueError(f"tolerance {name} must be at least {least:g}, got {value!r}")
    if most is not None and value > most:
        raise ValueError(f"tolerance {name} must be at most {most:g}, got {value!r}")
    if isinstance(default, int) and not isinstance(default, bool):
        if float(value) != int(value):
            raise ValueError(f"tolerance {name} must be a whole number, got {value!r}")
        return int(value)
    return float(value)


def markdown() -> str:
    """The tolerances as the Markdown page docs/tolerances.md."""
    lines = ["# Tolerances", "",
             "Every threshold of the pipeline, by stage: its name, unit, default and why. Generated by",
             "`python -m houghcad.tolerances > docs/tolerances.md` from `src/houghcad/tolerances.py`; set them with",
             "`Segmenter(tolerances={\"stage\": {\"name\": value}})` (or `{\"stage.name\": value}`). A run records",
             "all of them in its JSON `options[\"tolerances\"]`. Every value must be positive; a few have bounds",
             "besides, given after their default.", ""]
    for f in fields(Tolerances):
        group = f.default_factory()
        lines += [f"## `{f.name}`", "", (type(group).__doc__ or "").strip(), "",
                  "| name | unit | default | why |", "|---|---|---|---|"]
        for g in fields(group):
            v = getattr(group, g.name)
            v = f"{v:.6g}" if isinstance(v, float) else str(v)
            bounds = [f"≥ {g.metadata['least']:g}"] if g.metadata.get("least") is not None else []
            bounds += [f"≤ {g.metadata['most']:g}"] if g.metadata.get("most") is not None else []
            v += f" ({', '.join(bounds)})" if bounds else ""
            lines.append(f"| `{g.name}` | {g.metadata['unit']} | {v} | {g.metadata['why']} |")
        lines.append("")
    return "\n".join(lines)


if __name__ == "__main__":
    sys.stdout.write(markdown())
