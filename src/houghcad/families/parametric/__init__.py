"""User-defined parametric families (paper §4–5.2: a family is any x(u, v; a)).

:func:`define_family` turns three coordinate functions of the surface
parameters ``u, v`` and at most three shape parameters ``a`` into a family
the pipeline recognises like the built-in ones::

    u, v, k, h = sympy.symbols("u v k h")
    define_family("paraboloid", x=u * sympy.cos(v), y=u * sympy.sin(v), z=k * u**2 + h,
                  params=[k, h], u_range=None, v_range=(0, 2 * sympy.pi),
                  lengths={"k": -1, "h": 1}, placement="axis")

The equations are sympy expressions (or strings sympy parses) in the symbols
``u``, ``v`` and the parameters, or numpy-vectorised callables
``f(u, v, **params)``.

How a family is recognised
--------------------------
- **Placement** (standard form): the cluster is put in a local frame by one
  of the normal-based estimators of the built-in families (see
  :data:`PLACEMENTS`); the user's equations are written in that frame.
- **Voting**: every parameter is a voted unknown (at most three). The ones
  that enter the equations linearly (found with sympy, or numerically for
  callables) are *solved*: for each point P, sweep u, v and the other
  parameters over their bins and solve ``A(u, v, a_N) a_L = P − b(u, v, a_N)``
  with the Moore–Penrose pseudo-inverse of A (one batched ``pinv`` per sweep
  sample, shared by all points). With three solved parameters the system is
  square and each (u, v) sample gives a point of Γ_P. With fewer, P pins
  (u, v) down (partly), and each sample is projected on Γ_P by a few
  minimum-norm Newton steps on (u, v, a_L). Samples whose surface normal
  disagrees with the point's normal do not vote.
- **Distance**: nearest of a dense (u, v) sample of the surface (cKDTree,
  cached per parameter vector), refined by vectorised Gauss–Newton steps on
  (u, v).
- **Fit**: damped Gauss–Newton (:func:`..base.gauss_newton`) on the parameters and the
  placement (rotation vector, translation), residuals the signed normal
  distances at the feet.

Units: the standard frame is the cloud's unit cube. ``lengths`` gives each
parameter's power of length (1 a length, −1 a curvature, 0 a number or an
angle); parameters are reported in world units accordingly. ``bounds`` are
multiples of the segment's size to that power, so they do not depend on the
cloud's scale. A coordinate range given as ``None`` makes u or v a free length
coordinate (e.g. ``z = v`` for an extrusion, ``x = u cos v`` for a profile of
revolution), swept over the segment's extent.

Errors: a definition that cannot work (a parameter in no equation, a callable
that raises or answers in the wrong shape when probed...) is refused by
:func:`define_family` with an :class:`~houghcad.errors.InputError`. During a
run, a function of the family (an equation, the placement, ``valid``) that
raises or returns something unusable stops it with a :class:`UserFamilyError`
naming the family and the function (:mod:`.guard`).

Modules: :mod:`.equations` (evaluation, linear parameters), :mod:`.placement`
(standard forms), :mod:`.vote` (Γ_P sampling), :mod:`.family`
(:class:`ParametricFamily`), :mod:`.guard` (calls into the user's code); this
one declares families (:func:`define_family`).
"""

from __future__ import annotations

import re
from typing import Callable, Mapping, Sequence

import numpy as np

from ...errors import InputError
from ..base import REGISTRY, SEARCHES, SELECTION_WORDS, add
from .equations import (CallableEquations, Equations, SympyEquations, linear_params_numeric, linear_params_sympy,
                        solvable_subset, unused_params)
from .family import LENGTH_SPAN, ParametricFamily
from .guard import UserFamilyError
from .placement import PLACEMENTS, place

__all__ = ["LENGTH_SPAN", "PLACEMENTS", "ParametricFamily", "UserFamilyError", "define_family",
           "linear_params_numeric", "linear_params_sympy", "place", "solvable_subset", "unregister_family",
           "user_families"]

_NAME = re.compile(r"^[a-z][a-z0-9_]*$")
_USER: set[str] = set()


# --------------------------------------------------------------------------- public API


def _range(r, what: str):
    if r is None:
        return None
    try:
        lo, hi = (float(x) for x in r)
    except (TypeError, ValueError):
        raise InputError(f"{what} must be (low, high) or None, got {r!r}") from None
    if not (np.isfinite(lo) and np.isfinite(hi) and hi > lo):
        raise InputError(f"{what} must be finite with high > low, got {r!r}")
    return lo, hi


def define_family(name: str, x, y, z, params: Sequence, u_range, v_range, *, linear: Sequence[str] | None = None,
                  bounds: Mapping[str, tuple[float, float]] | None = None,
                  lengths: Sequence[str] | Mapping[str, float] | None = None, placement: str | Callable = "axis",
                  samples: tuple[int, int] | None = None, valid: Callable[[dict], bool] | None = None,
                  search: str = "whole", precedence: int = 10, register: bool = True) -> ParametricFamily:
    """Declare a parametric family x(u, v; a), y(u, v; a), z(u, v; a).

    Parameters
    ----------
    name : str
        Lower-case identifier (``[a-z][a-z0-9_]*``) used in ``families=...``
        and as the segments' ``type``. Redefining a user family replaces it;
        built-in names are refused.
    x, y, z : sympy expressions, strings, or callables
        Expressions in the symbols ``u``, ``v`` and the parameters (strings
        are parsed by sympy), or numpy-vectorised callables
        ``f(u, v, **params)``. Written in the local frame of ``placement``.
    params : sequence of sympy Symbols or str
        The shape parameters, at most three (the voted unknowns).
    u_range, v_range : (low, high) or None
        Domain of u and v. A range of length 2π is periodic. ``None`` makes
        the coordinate a free length, swept over the segment's extent.
    linear : sequence of str, optional
        Parameters entering linearly (default: detected, symbolically for
        sympy expressions, numerically for callables; a declared one that is
        not linear is an error).
    bounds : {param: (low, high)}, optional
        Range voted over, in multiples of the segment's size (bounding-box
        diagonal in the local frame) to the parameter's power of length
        (default (−2, 2)).
    lengths : sequence of str or {param: power}, optional
        Power of length of each parameter: listed names are lengths (power 1)
        and the others dimensionless; a mapping gives the powers (−1 for a
        curvature). Default: every parameter is a length.
    placement : str or callable
        One of :data:`PLACEMENTS` (see :func:`place`), or
        ``f(P, N) -> (R, origin)`` (or a list of such pairs) in the cloud's
        standard frame, R's rows the local axes.
    samples : (n_u, n_v), optional
        (u, v) samples per point in the vote, whole numbers: the starting
        lattice refined adaptively when three parameters are solved (default
        16 × 16, at least 2 × 2), the Newton starts otherwise (default 10 × 10
        with two solved, 4 × 4 with one; at least 1 × 1).
    valid : callable, optional
        ``valid({param: value}) -> bool`` on standard-frame values; rejects
        degenerate shapes a simpler family covers.
    search : {"whole", "cluster"}
        ``"whole"``: also seek the family on the whole cloud in the first
        round (placed from all the normals), not only per cluster in the
        splitting phase (``"cluster"``; see :attr:`Family.search`).
        On a cloud that is mostly one such surface this keeps the simple
        families from taking it band by band first; on a multi-surface part
        it costs one vote (about a second) for nothing: use ``"cluster"`` there.
    precedence : int
        Rank for ties (built-in: plane 0 … torus 4). A family more complex
        than its competitor must halve its fitting error to replace it
        (``recognize._better``); the default 10 puts it above every built-in
        family, so a shallow paraboloid that a sphere fits about as well
        under noise comes out as the sphere.
    register : bool
        Add the family to the registry (selectable by name; also in ``"all"``).

    Returns
    -------
    ParametricFamily
    """
    # The checks run in this order (the first failing one is reported).
    names = _checked_names(name, params)
    ur, vr = _range(u_range, "u_range"), _range(v_range, "v_range")
    eq, solved = _compile(name, (x, y, z), names, ur, vr, linear)
    dims, bnds = _length_powers(name, lengths, names), _vote_bounds(name, bounds, names)
    samples = _checked_vote_setup(name, placement, samples, solved)
    if valid is not None and not callable(valid):
        raise InputError(f"{name}: valid must be a function of the parameters' values, got {valid!r}")
    fam = ParametricFamily(name, eq, names, dims, ur, vr, solved, bnds, placement, samples, valid)
    _set_search(fam, search, precedence)
    if register:
        add(fam)
        _USER.add(name)
    return fam


# --------------------------------------------------------------------------- define_family's steps


def _checked_names(name: str, params: Sequence) -> list[str]:
    """The parameters' names, after checking the family's name and theirs (1 to 3, distinct, not u, v)."""
    if not isinstance(name, str) or not _NAME.match(name):
        raise InputError(f"family name must match [a-z][a-z0-9_]*, got {name!r}")
    if name in SELECTION_WORDS or (name in REGISTRY and name not in _USER):
        raise InputError(f"family name {name!r} is taken by a built-in family")
    names = [str(p) for p in params]
    if not 1 <= len(names) <= 3:
        raise InputError(f"{name}: a family has one to three parameters (the voted unknowns), got {len(names)}")
    if len(set(names)) != len(names) or {"u", "v"} & set(names):
        raise InputError(f"{name}: parameter names must be distinct and not u or v, got {names}")
    return names


def _compile(name: str, funcs: tuple, names: list[str], ur: tuple[float, float] | None,
             vr: tuple[float, float] | None, linear: Sequence[str] | None) -> tuple[Equations, list[int]]:
    """The equations and the indices of the solved (linear, jointly solvable) parameters.

    ``funcs`` are the x, y, z equations as given, ``ur`` and ``vr`` the checked (u, v) ranges
    (None: a free length, probed over (-1, 1)), ``linear`` the declared linear parameters.
    """
    # One seeded generator for both numerical probes: the same family compiles the same way.
    rng = np.random.default_rng(0)
    spans = [(-1.0, 1.0) if r is None else r for r in (ur, vr)]
    eq, detected = _equations(name, funcs, names, spans, rng)
    # Its own generator: this check leaves the linear parameters' probes as they were.
    unused = unused_params(eq, *spans, np.random.default_rng(1))
    if unused:
        raise InputError(f"{name}: parameters {[names[i] for i in unused]} appear in no equation (the surface "
                         "does not change with them): they cannot be estimated")
    if linear is not None:
        detected = _declared_linear(name, linear, names, detected)
    solved = solvable_subset(eq, detected, *spans, rng) if detected else []
    return eq, solved


def _equations(name: str, funcs: tuple, names: list[str], spans: list[tuple[float, float]],
               rng: np.random.Generator) -> tuple[Equations, list[int]]:
    """Callable or sympy equations, and the indices of the parameters they are linear in.

    The callables run here first: one that raises or answers in the wrong shape is reported now
    (a :class:`UserFamilyError`), not in the middle of a run."""
    x, y, z = funcs
    if all(callable(f) for f in funcs) and not any(hasattr(f, "free_symbols") for f in funcs):
        eq: Equations = CallableEquations(x, y, z, names, family=name)
        return eq, linear_params_numeric(eq, *spans, rng)
    import sympy as sp

    syms = [sp.Symbol(n) for n in names]
    su, sv = sp.Symbol("u"), sp.Symbol("v")
    try:
        exprs = [sp.sympify(f) for f in funcs]
    except (sp.SympifyError, TypeError) as exc:
        raise InputError(f"{name}: cannot read the equations ({exc})") from None
    # Parameters may have been created with assumptions: match by name.
    exprs = [e.subs({s: sp.Symbol(s.name) for s in e.free_symbols}) for e in exprs]
    extra = set().union(*(e.free_symbols for e in exprs)) - {su, sv, *syms}
    if extra:
        raise InputError(f"{name}: unknown symbols {sorted(map(str, extra))} in the equations "
                         f"(coordinates are u and v; parameters {names})")
    try:
        eq = SympyEquations(exprs, su, sv, syms, family=name)
    except Exception as exc:  # lambdify: e.g. an undefined function, which numpy cannot evaluate
        raise InputError(f"{name}: cannot evaluate the equations with numpy ({type(exc).__name__}: "
                         f"{' '.join(str(exc).split())})") from None
    return eq, linear_params_sympy(exprs, syms)


def _declared_linear(name: str, linear: Sequence[str], names: list[str], detected: list[int]) -> list[int]:
    """The detected linear parameters restricted to the declared ones (each must be detected)."""
    declared = [names.index(str(p)) if str(p) in names else -1 for p in linear]
    if -1 in declared:
        raise InputError(f"{name}: linear names unknown parameters {list(linear)} (parameters {names})")
    wrong = [names[i] for i in declared if i not in detected]
    if wrong:
        raise InputError(f"{name}: parameters {wrong} are declared linear but the equations are not linear in them")
    return [i for i in detected if i in declared]


def _length_powers(name: str, lengths: Sequence[str] | Mapping[str, float] | None,
                   names: list[str]) -> list[float]:
    """Each parameter's power of length (see ``lengths`` in :func:`define_family`)."""
    if lengths is None:
        return [1.0] * len(names)
    if isinstance(lengths, Mapping):
        unknown = set(map(str, lengths)) - set(names)
        if unknown:
            raise InputError(f"{name}: lengths names unknown parameters {sorted(unknown)}")
        powers = {str(s): float(d) for s, d in lengths.items()}
        return [powers.get(n, 0.0) for n in names]
    listed = {str(s) for s in lengths}
    if listed - set(names):
        raise InputError(f"{name}: lengths names unknown parameters {sorted(listed - set(names))}")
    return [1.0 if n in listed else 0.0 for n in names]


def _vote_bounds(name: str, bounds: Mapping[str, tuple[float, float]] | None,
                 names: list[str]) -> list[tuple[float, float]]:
    """Each parameter's voted range, multiples of the segment's size to its power (default (-2, 2))."""
    bnds = []
    bounds = {str(k): v for k, v in (bounds or {}).items()}
    if set(bounds) - set(names):
        raise InputError(f"{name}: bounds name unknown parameters {sorted(set(bounds) - set(names))}")
    for n in names:
        bnds.append(_range(bounds.get(n, (-2.0, 2.0)), f"bounds[{n!r}]"))
    return bnds


def _checked_vote_setup(name: str, placement: str | Callable, samples: tuple[int, int] | None,
                        solved: list[int]) -> tuple[int, int] | None:
    """``samples`` as ints, after checking the placement, the samples and that some parameter is solved."""
    if not callable(placement) and placement not in PLACEMENTS:
        raise InputError(f"{name}: unknown placement {placement!r} (known: {', '.join(PLACEMENTS)}, or a callable)")
    if samples is not None:
        samples = _checked_samples(name, samples, solved)
    if not solved:
        raise InputError(f"{name}: no parameter enters the equations linearly (or none is solvable): the Hough "
                         "transform is sampled by solving for linear parameters")
    return samples


def _checked_samples(name: str, samples, solved: list[int]) -> tuple[int, int]:
    """``samples`` as two ints, each at least 1, or 2 with three solved parameters (the lattice's
    quads are split: one node along a coordinate makes none). Zero samples vote nothing, and a
    fraction would be truncated."""
    least = 2 if len(solved) == 3 else 1
    try:
        pair = tuple(samples)
    except TypeError:
        pair = ()
    whole = len(pair) == 2 and all(isinstance(n, (int, np.integer)) and not isinstance(n, bool) for n in pair)
    if not whole or min(pair) < least:
        why = " with three solved parameters" if least == 2 else ""
        raise InputError(f"{name}: samples must be two whole numbers (n_u, n_v), each at least {least}{why}, "
                         f"got {samples!r}")
    return int(pair[0]), int(pair[1])


def _set_search(fam: ParametricFamily, search: str, precedence: int) -> None:
    """Set the family's search mode (checked) and tie rank."""
    if search not in SEARCHES:
        raise InputError(f"{fam.name}: search must be one of {SEARCHES}, got {search!r}")
    if isinstance(precedence, bool) or not isinstance(precedence, (int, np.integer)):
        raise InputError(f"{fam.name}: precedence must be a whole number (lower wins ties), got {precedence!r}")
    fam.search = search
    fam.precedence = int(precedence)


def unregister_family(name: str) -> None:
    """Remove a user-defined family from the registry (built-in ones stay)."""
    if name in _USER:
        _USER.discard(name)
        REGISTRY.pop(name, None)


def user_families() -> list[str]:
    """Names of the registered user-defined families."""
    return sorted(_USER)
