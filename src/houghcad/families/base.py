"""The family protocol.

A family is one file: a subclass of :class:`Family` registered with
:func:`register`. It states its parameters and provides

- ``placements``: the standard-form estimation (rigid frames in which the
  family has at most three unknowns), from the points' normals;
- ``region``: the box T of its standard-form unknowns, from the geometry;
- ``gamma``: samples of the Hough transform Γ_P of every point;
- ``primitive``: the primitive of a cell, back in the cloud's frame;
- ``distance`` / ``surface_normals``: point-to-surface geometry;
- ``fit``: least-squares refinement on inliers;
- ``refines`` / ``refine`` (optional): the family specialises another one
  (same surface, a particular boundary) and takes over its segments that
  have that shape;
- ``to_world`` and ``descriptors``.

and declares, as class attributes, how the rest of houghcad treats it: its
``role`` ("simple" or "complex"), ``precedence`` (ties), ``search`` (whole
cloud or per cluster), ``order`` (place in the registry, which is the voting
order), its ``color`` and PLY ``type_code`` in the pictures, and its
synthetic ``sampler`` (:class:`Sampler`, for :mod:`houghcad.synth`).

Everything a family computes before ``to_world`` is in the cloud's
*standard* frame (see :mod:`houghcad.preprocess`).
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar, TypeVar

import numpy as np

from ..errors import InputError
from ..hough import Grid
from ..preprocess import Similarity
from ._geometry import (  # noqa: F401
    axial,
    axial_row,
    axis_from_normal_lines,
    damped_step,
    frame_turn_rows,
    gauss_newton,
    lines_intersection,
    normal_equations,
    on_one_line,
    planes_intersection,
    radial,
    regular_indices,
    tangent_basis,
    turned_axis,
    unit,
    unit_derivatives,
)
from ._sampling import Sampler

#: Values of :attr:`Family.role`.
ROLES = ("simple", "complex")
#: Values of :attr:`Family.search`.
SEARCHES = ("whole", "cluster")
#: Words of ``families=...`` that are not family names.
SELECTION_WORDS = ("simple", "all")


@dataclass
class Placement:
    """A rigid frame putting a point set in a family's standard form.

    ``x_local = (x - origin) @ R.T``; the standard form's axis is local z.
    """

    R: np.ndarray
    origin: np.ndarray
    info: dict[str, Any] = field(default_factory=dict)

    def local(self, P: np.ndarray, N: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Points and normals (n, 3) in the local frame."""
        return (P - self.origin) @ self.R.T, N @ self.R.T

    @property
    def axis(self) -> np.ndarray:
        return self.R[2]


@dataclass
class Primitive:
    """A primitive of some family, with named parameters in the standard frame."""

    family: str
    params: dict[str, Any]

    def copy(self) -> "Primitive":
        return Primitive(self.family, {k: (np.array(v) if isinstance(v, np.ndarray) else v)
                                       for k, v in self.params.items()})


@dataclass
class Frame:
    """Where a primitive sits, for the association step (paper §5.4).

    ``kind`` says what ``anchor`` pins down: ``"plane"`` (a point of the
    plane, ``direction`` its normal), ``"line"`` (a point of the axis line,
    ``direction`` the axis) or ``"point"`` (a distinguished point: centre,
    apex; ``direction`` the axis when there is one). ``oriented`` tells
    whether the sign of ``direction`` is significant (a cone's opening).
    """

    kind: str
    anchor: np.ndarray
    direction: np.ndarray | None = None
    oriented: bool = False


class Family:
    """Base class of primitive families (see module docstring)."""

    name: ClassVar[str] = ""
    #: Names of the parameters reported in world coordinates.
    param_names: ClassVar[tuple[str, ...]] = ()
    #: Number of unknowns voted in standard form.
    n_unknowns: ClassVar[int] = 1
    #: ``"simple"``: one of the paper's five families (plane, cylinder, cone,
    #: sphere, torus), selected by ``families="simple"`` (the default). Their
    #: ties are settled by fitting error alone, and on noisy clouds the
    #: per-cluster ones also join the whole-cloud round. ``"complex"``: voted
    #: only when selected by name or ``"all"``; it evaluates fewer peaks per
    #: placement (they cost nonlinear fits), must clearly beat a simple
    #: candidate to replace it, and re-votes the groups of simple segments
    #: that may be slices of its surface (consolidation).
    role: ClassVar[str] = "complex"
    #: Rank for ties between families (the paper's "simpler family wins"):
    #: the lower wins equal fits, and a family of higher precedence must
    #: halve the other's fitting error to replace it. Built-in: plane 0,
    #: cylinder 1, sphere 2, cone 3, torus 4, ellipsoid 5, generalised
    #: cylinder 6, generalised cone, annulus and surface of revolution 7,
    #: helical strip 8, helical surface 9; user families 10.
    precedence: ClassVar[int] = 10
    #: Where the family is voted. ``"whole"``: on the whole cloud in the first
    #: round, then per cluster in the splitting phase. ``"cluster"``: only per
    #: cluster: a family whose standard-form placement needs the normals of
    #: one surface (a cone's apex where its tangent planes meet, a torus's
    #: centre where its normal lines meet in the meridian plane) cannot be
    #: placed from the normals of a whole part, which belong to many surfaces.
    #: (On noisy clouds simple ``"cluster"`` families join the first round
    #: too: a simpler family's slice of their surface fits within the noise,
    #: and only the whole surface's candidate can beat it.)
    search: ClassVar[str] = "whole"
    #: Place in the registry, which is the order families are voted and
    #: candidates listed (it settles exact ties): lower first. The built-in
    #: families use multiples of 10 (plane 10 … surface of revolution 120);
    #: families registered later with the same order follow them.
    order: ClassVar[int] = 1000
    #: Base colour (uint8 RGB) of the family's segments in every picture:
    #: the first shade of the type (:mod:`houghcad.palette`). None: the
    #: palette's ``OTHER_COLOR``.
    color: ClassVar[tuple[int, int, int] | None] = None
    #: Code of the family in the ``type`` field of the coloured PLY: a
    #: positive integer unique among the registered families (-1 is
    #: "unsegmented", 0 "unknown family"). None: 0.
    type_code: ClassVar[int | None] = None
    #: How :mod:`houghcad.synth` samples the family (area-uniform points of a
    #: patch in the standard frame, its area, its parameters, random shapes);
    #: None: the family has no synthetic sampler.
    sampler: ClassVar[Sampler | None] = None
    #: Whether surfaces of the family often share one placement at several
    #: sizes (the sections of a stepped shaft on one axis and directrix):
    #: the whole-cloud vote then also seeks peaks beside the top one.
    stacked: ClassVar[bool] = False
    #: Whether Γ_P of a point depends on that point (and the grid) alone, not on the
    #: other points: then the votes are taken over blocks of points, and the samples
    #: held at once stay bounded however big the cloud (a cone's or torus's Γ_P has a
    #: sample per bin of a swept parameter: hundreds per point).
    pointwise: ClassVar[bool] = False
    #: Name of the family this one specialises (same surface, plus a boundary
    #: shape: an annulus is a plane bounded by two circles). The two explain
    #: the points equally well and ties go to the simpler one, so when both
    #: are selected this one is not voted: after recognition, the base
    #: family's segments are offered to :meth:`refine`.
    refines: ClassVar[str | None] = None

    # --- standard form and voting -------------------------------------------
    def placements(self, P: np.ndarray, N: np.ndarray, ctx) -> list[Placement]:
        raise NotImplementedError

    def region(self, Pl: np.ndarray, Nl: np.ndarray, ctx) -> Grid:
        raise NotImplementedError

    def gamma(self, Pl: np.ndarray, Nl: np.ndarray, grid: Grid, ctx) -> tuple[np.ndarray, np.ndarray]:
        """Samples of Γ_P: (voter index (k,), parameter vectors (k, d))."""
        raise NotImplementedError

    def votes(self, Pl: np.ndarray, Nl: np.ndarray, grid: Grid, ctx) -> np.ndarray | None:
        """The accumulator (``grid.bins``) of the points' votes computed directly, for a pointwise
        family whose Γ_P has a closed form per bin of a swept parameter: sampling and voting in
        one pass, without holding the samples. None (the default): :meth:`gamma` is sampled and
        accumulated over blocks of points."""
        return None

    def primitive(self, values: np.ndarray, placement: Placement) -> Primitive | None:
        raise NotImplementedError

    def coarse_tolerance(self, grid: Grid, Pl: np.ndarray, ctx) -> float:
        """Inlier distance (standard units) of a peak's first evaluation: what
        a cell of the accumulator leaves uncertain. The default reads the first
        axis of the grid as a length."""
        return max(2.0 * ctx.cell, 1.5 * float(grid.width[0]))

    # --- geometry -----------------------------------------------------------
    def distance(self, prim: Primitive, P: np.ndarray) -> np.ndarray:
        """Euclidean distance of points (n, 3) to the surface, shape (n,)."""
        raise NotImplementedError

    def surface_normals(self, prim: Primitive, P: np.ndarray) -> np.ndarray:
        """Unit surface normal at the foot of each point (n, 3)."""
        raise NotImplementedError

    def signed_distance(self, prim: Primitive, P: np.ndarray, normals: np.ndarray | None = None) -> np.ndarray:
        """Distance (n,) signed by the side of the surface the points lie on:
        positive along :meth:`surface_normals` (pass them as ``normals``
        (n, 3) when the caller has them). Generic: the foot is the point
        moved back along its normal by its distance; a family with a closed
        form may override it."""
        d = self.distance(prim, P)
        n = self.surface_normals(prim, P) if normals is None else normals
        back = self.distance(prim, P - d[:, None] * n)
        ahead = self.distance(prim, P + d[:, None] * n)
        return np.where(back <= ahead, d, -d)

    def fit(self, prim: Primitive, P: np.ndarray, N: np.ndarray) -> Primitive | None:
        """Least-squares refinement on inliers; None when degenerate."""
        return prim

    def final_fit(self, prim: Primitive, P: np.ndarray, N: np.ndarray) -> Primitive | None:
        """The fit whose parameters a segment reports (the output's refit on its own points): the
        least-squares :meth:`fit` unless a family's least squares is biased under noise."""
        return self.fit(prim, P, N)

    def well_determined(self, prim: Primitive, P: np.ndarray, ctx) -> bool:
        """Whether a segment (points P) pins the primitive down well enough to
        be accepted in the global round, before other families compete."""
        return True

    def valid(self, prim: Primitive, ctx) -> bool:
        """Reject degenerate shapes (radii beyond the model's size...)."""
        return True

    def refine(self, base: Primitive, P: np.ndarray, N: np.ndarray, ctx) -> Primitive | None:
        """This family's primitive for a segment (points P, normals N) of the
        family it ``refines`` (primitive ``base``), or None when the points do
        not have this family's shape. The primitive must explain P as well as
        ``base`` does: the segment keeps its points."""
        return None

    # --- output -------------------------------------------------------------
    def to_world(self, prim: Primitive, T: Similarity) -> dict[str, Any]:
        raise NotImplementedError

    def descriptors(self, prim: Primitive) -> dict[str, float]:
        """Position-independent descriptors (standard units)."""
        return {}

    #: Descriptors that are lengths (scaled to world units on output); the
    #: others are angles (radians) unless listed as integers.
    length_descriptors: ClassVar[tuple[str, ...]] = ()
    #: Descriptors that are integers (equal or not at all).
    integer_descriptors: ClassVar[tuple[str, ...]] = ()

    def frame(self, prim: Primitive) -> Frame | None:
        """Placement descriptors: axis line, centre, normal, apex (standard frame)."""
        return None

    def __repr__(self) -> str:
        # Deterministic (no address): reports and options print families.
        return f"{type(self).__name__}({self.name!r})"


#: Registered families by name, in :attr:`Family.order` (stable: equal orders
#: keep the order of registration). The families of this package register
#: when it is imported; the others when their module is imported, when
#: :func:`houghcad.families.select` meets them, or through
#: :func:`houghcad.families.define_family`.
REGISTRY: dict[str, Family] = {}


def check(fam: Family) -> None:
    """Raise :class:`InputError` when a family's declared attributes are not
    valid (name, role, search, colour, type code, sampler, stacked with pointwise)."""
    if not isinstance(fam.name, str) or not fam.name:
        raise InputError(f"{type(fam).__name__}: a family needs a non-empty name")
    if fam.name in SELECTION_WORDS:
        raise InputError(f"{fam.name!r} names a selection of families, not a family")
    if fam.role not in ROLES:
        raise InputError(f"family {fam.name!r}: role must be one of {ROLES}, got {fam.role!r}")
    if fam.search not in SEARCHES:
        raise InputError(f"family {fam.name!r}: search must be one of {SEARCHES}, got {fam.search!r}")
    c = fam.color
    if c is not None and not (isinstance(c, tuple) and len(c) == 3
                              and all(isinstance(x, int) and 0 <= x <= 255 for x in c)):
        raise InputError(f"family {fam.name!r}: color must be None or three ints in 0..255, got {c!r}")
    code = fam.type_code
    if code is not None and not (isinstance(code, int) and code >= 1):
        raise InputError(f"family {fam.name!r}: type_code must be None or an int >= 1, got {code!r}")
    if fam.stacked and fam.pointwise:
        # The search beside the top peak withdraws votes sample by sample, which block votes
        # do not keep.
        raise InputError(f"family {fam.name!r}: a stacked family cannot be pointwise")
    if fam.sampler is not None and not isinstance(fam.sampler, Sampler):
        raise InputError(f"family {fam.name!r}: sampler must be None or a Sampler, got {fam.sampler!r}")


def add(fam: Family) -> Family:
    """Put a family (an instance) in :data:`REGISTRY` under its name, replacing
    one of that name, and keep the registry in :attr:`Family.order`.

    Raises :class:`InputError` when its attributes are invalid (:func:`check`)
    or its type code belongs to another registered family (the PLY ``type``
    field must name one family).
    """
    check(fam)
    if fam.type_code is not None:
        taken = [n for n, f in REGISTRY.items() if f.type_code == fam.type_code and n != fam.name]
        if taken:
            raise InputError(f"family {fam.name!r}: type_code {fam.type_code} is taken by {taken[0]!r}")
    REGISTRY[fam.name] = fam
    ordered = sorted(REGISTRY.items(), key=lambda kv: kv[1].order)  # stable
    REGISTRY.clear()
    REGISTRY.update(ordered)
    return fam


def register(cls: type[Family]) -> type[Family]:
    """Class decorator adding a family (an instance of ``cls``) to the registry."""
    add(cls())
    return cls


def unregister(name: str) -> Family | None:
    """Remove the family ``name`` from the registry; returns it (None when absent)."""
    return REGISTRY.pop(name, None)


V = TypeVar("V")


class FamilyTable(Mapping[str, V]):
    """A read-only, live view of one attribute of the registered families:
    name → value in registry order, leaving out the families where it is None.

    Tables built from it (the palette's colours and type codes, synth's
    samplers) follow the registry as families are added or removed.
    """

    def __init__(self, attribute: str):
        self.attribute = attribute

    def __getitem__(self, name: str) -> V:
        value = getattr(REGISTRY[name], self.attribute)
        if value is None:
            raise KeyError(name)
        return value

    def __iter__(self) -> Iterator[str]:
        return iter([n for n, f in REGISTRY.items() if getattr(f, self.attribute) is not None])

    def __len__(self) -> int:
        return sum(getattr(f, self.attribute) is not None for f in REGISTRY.values())

    def __repr__(self) -> str:
        return f"FamilyTable({self.attribute!r}, {dict(self)!r})"


# --- small geometric helpers shared by the families ---------------------------

def swept_votes(kernel, Pl: np.ndarray, grid: Grid) -> np.ndarray:
    """The accumulator (``grid.bins``, 2-D) of a Γ_P swept over the bins of its first parameter
    about the z axis: ``kernel(z, rho, centres, lo, w, H)`` (numba) adds each point's vote for
    every centre of the first parameter to H, in the second parameter's bins (from ``lo``,
    ``w`` wide). A point's samples fall in distinct bins of the first parameter, so each is a
    vote of its own (one per point and cell)."""
    H = np.zeros(grid.bins)
    kernel(Pl[:, 2].astype(float), np.hypot(Pl[:, 0], Pl[:, 1]), grid.centers(0), float(grid.lower[1]),
           float(grid.width[1]), H)
    return H
