"""Primitive families, one file each, behind the protocol of :mod:`.base`.

Adding a family is adding one file that subclasses :class:`Family`, decorates
it with :func:`register`, and is imported here.
"""

from __future__ import annotations

from ..errors import InputError
from .base import REGISTRY, Family, Frame, Placement, Primitive, register
from . import plane, cylinder, sphere, cone, torus  # noqa: F401  (registration)
from . import generalized_cylinder, generalized_cone  # noqa: F401  (registration)
from . import helical_surface, helical_strip, annulus  # noqa: F401  (registration)
from . import ellipsoid, revolution  # noqa: F401  (registration; complex families of issue 3)
from .parametric import ParametricFamily, define_family, unregister_family, user_families  # noqa: F401

SIMPLE = ("plane", "cylinder", "cone", "sphere", "torus")


def select(families) -> list[Family]:
    """Families named by ``"simple"``, ``"all"``, a comma-separated string or a list."""
    if families is None:
        families = "simple"
    if isinstance(families, str):
        names = [f.strip().lower() for f in families.split(",") if f.strip()]
    else:
        names = [str(f).strip().lower() for f in families]
    out: list[str] = []
    for n in names:
        if n == "simple":
            out += [f for f in SIMPLE]
        elif n == "all":
            out += list(REGISTRY)
        elif n in REGISTRY:
            out.append(n)
        else:
            raise InputError(f"unknown family {n!r} (known: simple, all, {', '.join(REGISTRY)})")
    if not out:
        raise InputError("no family selected")
    seen = dict.fromkeys(out)
    return [REGISTRY[n] for n in seen]


__all__ = ["REGISTRY", "SIMPLE", "Family", "Placement", "Primitive", "register", "select"]
