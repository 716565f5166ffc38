"""Synthetic point clouds with exact ground truth: single primitives and mechanical parts.

This is the one generator behind the tests, the benchmarks and the examples. Modules:
:mod:`.primitives` (the cloud, single primitives, shared finishing), :mod:`.parts` (the parts
with simple surfaces, :data:`PARTS`, the Fit4CAD writer and the demo), :mod:`.complex` (the parts
with complex surfaces), :mod:`.small_faces` (a part with many small faces), :mod:`.paper` (the part of the paper's noise
experiment), :mod:`.perturb` (what scans do: noise, undersampling, holes, bumps, outliers), :mod:`._poses` and :mod:`._faces` (helpers). Each family samples itself:
its file declares a :class:`~houghcad.families.Sampler` (:data:`SAMPLERS` is the live table), and
the samplers are re-exported here under their usual names (:func:`sample_cylinder`...).

Conventions
-----------
Every primitive is described as ``{"type": str, "params": dict}`` (plus a human-readable
``"name"`` for the faces of composite parts) in world coordinates, with the parameter names of
:mod:`houghcad.result` (vectors are lists of 3 floats, angles in radians, lengths in the cloud's
units):

- plane: ``normal`` (unit, outward for parts), ``offset`` (``normal · x = offset``), ``point``
  (the centre of the sampled patch)
- cylinder: ``axis_point`` (centre of the sampled patch on the axis), ``axis`` (unit), ``radius``
- cone: ``apex``, ``axis`` (unit, from the apex into the opening), ``half_angle``
- sphere: ``center``, ``radius``
- torus: ``center``, ``axis`` (unit), ``major_radius``, ``minor_radius``

Surface samplers work in the primitive's *local standard frame*: axis = z, centre / apex at the
origin; they return points and unit normals with a uniform area density (area-correct sampling,
no rejection of points). Composite parts are assembled without a mesh library: every face is
sampled in its own frame as a generous, untrimmed patch of its primitive, placed in the part's
frame, and kept only where it really bounds the part's solid (a vectorised inside test evaluated
just in front of and just behind the surface). That trimming also orients the normals outwards.
All faces use the same density, so the part's density is uniform, and points of one primitive get
one label even when the trimming splits the surface into several pieces.

Randomness: every function takes a seed (or a :class:`numpy.random.Generator`) and never touches
global state; the same seed gives identical arrays. Each stage (shape, surface sampling, pose,
noise, outliers, shuffling) draws from its own child stream, so, for instance, the same seed with
and without noise gives the same underlying surface points.
"""

from __future__ import annotations

from ..families._sampling import TAU, Sampler  # noqa: F401  (TAU: as before the split)
from ..families.annulus import sample_annulus
from ..families.cone import sample_cone
from ..families.cylinder import sample_cylinder
from ..families.ellipsoid import sample_ellipsoid
from ..families.generalized_cone import sample_generalized_cone
from ..families.generalized_cylinder import sample_generalized_cylinder
from ..families.helical_strip import sample_helical_strip
from ..families.helical_surface import sample_helical_surface
from ..families.plane import sample_plane_patch
from ..families.revolution import sample_revolution
from ..families.sphere import sample_sphere
from ..families.torus import sample_torus
from ._poses import PARAM_KINDS, SAMPLERS, apply_transform, param_kinds, random_pose, random_rotation, transform_params
from .complex import ellipsoid_part, generalized_cone_part, screw_part
from .parts import (PARTS, block_with_hole_and_slot, filleted_block, filleted_disc, gear_like, mirrored_cones,
                    plate_with_holes, rounded_tube, shaft_with_groove, write_demo, write_fit4cad_segments)
from .primitives import FAMILIES, SynthCloud, _Streams, sample_family, sample_parametric, single  # noqa: F401
from .paper import PAPER_PARTS, table5_block
from .perturb import Perturbation, perturb
from .small_faces import SMALL_FACE_PARTS, bracket

__all__ = [
    "FAMILIES",
    "PARAM_KINDS",
    "PAPER_PARTS",
    "PARTS",
    "Perturbation",
    "SAMPLERS",
    "SMALL_FACE_PARTS",
    "Sampler",
    "SynthCloud",
    "apply_transform",
    "block_with_hole_and_slot",
    "bracket",
    "ellipsoid_part",
    "filleted_block",
    "filleted_disc",
    "gear_like",
    "generalized_cone_part",
    "mirrored_cones",
    "param_kinds",
    "perturb",
    "plate_with_holes",
    "random_pose",
    "random_rotation",
    "rounded_tube",
    "sample_annulus",
    "sample_cone",
    "sample_cylinder",
    "sample_ellipsoid",
    "sample_family",
    "sample_generalized_cone",
    "sample_generalized_cylinder",
    "sample_helical_strip",
    "sample_helical_surface",
    "sample_parametric",
    "sample_plane_patch",
    "sample_revolution",
    "sample_sphere",
    "sample_torus",
    "screw_part",
    "shaft_with_groove",
    "single",
    "table5_block",
    "transform_params",
    "write_demo",
    "write_fit4cad_segments",
]
