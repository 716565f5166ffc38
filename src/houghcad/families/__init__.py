"""Primitive families, one file each, behind the protocol of :mod:`.base`.

Adding a family is adding one file to this package: a subclass of
:class:`Family` decorated with :func:`register`, declaring its role,
precedence, search, order, colour, type code and synthetic sampler. The
package imports every public module in it (discovery, below); a family kept
elsewhere registers when its module is imported, or when a :class:`Family`
object is passed to :func:`select` (``Segmenter(families=[...])``).
"""

from __future__ import annotations

import importlib
import pkgutil
from collections.abc import Sequence

from ..errors import InputError
from .base import REGISTRY, Family, FamilyTable, Frame, Placement, Primitive, Sampler, add, register, unregister
from .parametric import ParametricFamily, define_family, unregister_family, user_families

#: Modules of the package that declare no family: the protocol, and the
#: machinery of user-defined families (imported below for its API). Private
#: helper modules (``_helix``, ``_sampling``...) start with an underscore.
_NOT_FAMILIES = ("base", "parametric")


def _discover() -> tuple[str, ...]:
    """Import every family module of this package, in name order; returns their names.

    The registry does not depend on that order: it is kept in
    :attr:`Family.order` (:func:`.base.add`).
    """
    names = sorted(m.name for m in pkgutil.iter_modules(__path__)
                   if not m.name.startswith("_") and m.name not in _NOT_FAMILIES)
    for name in names:
        importlib.import_module(f"{__name__}.{name}")
    return tuple(names)


MODULES = _discover()


def simple_families() -> tuple[str, ...]:
    """Names of the registered families of role ``"simple"``, by type code:
    the paper's order (plane, cylinder, cone, sphere, torus), which is the
    order ``families="simple"`` votes them in."""
    fams = [f for f in REGISTRY.values() if f.role == "simple"]
    fams.sort(key=lambda f: float("inf") if f.type_code is None else f.type_code)  # stable
    return tuple(f.name for f in fams)


#: The simple families as this package defines them (:func:`simple_families`
#: when the package was imported; the function follows later registrations).
SIMPLE = simple_families()


def _resolve(item: Family | type[Family]) -> Family:
    """The registered family for a :class:`Family` object or subclass,
    registering it when its name is free."""
    cls = item if isinstance(item, type) else type(item)
    name = item.name
    known = REGISTRY.get(name)
    if known is None:
        return add(item() if isinstance(item, type) else item)
    # The same family: the registered object itself, or another instance of
    # its class carrying no state of its own (class attributes define it).
    if known is item or (type(known) is cls and not vars(known)
                         and (isinstance(item, type) or not vars(item))):
        return known
    raise InputError(f"a different family is registered as {name!r} ({known!r}); give this one another name")


def select(families: str | Sequence[str | Family | type[Family]] | None) -> list[Family]:
    """The families to vote, in voting order.

    ``families`` is ``"simple"`` (the families of role simple,
    :func:`simple_families`), ``"all"`` (every registered family, in
    registry order), a comma-separated string of those and family names, or
    a sequence mixing such strings, :class:`Family` objects and Family
    subclasses. Duplicates are dropped (first kept); None means ``"simple"``.

    A :class:`Family` object (or subclass) that is not registered joins the
    registry under its name, as if its module had been imported: its colour
    and type code then reach the pictures, and it can be selected by name
    afterwards (:func:`unregister` removes it). A different family under an
    already registered name is refused with :class:`InputError`; another
    instance of a registered family's class that carries no state of its own
    stands for the registered one.
    """
    if families is None:
        families = "simple"
    if isinstance(families, str):
        families = [families]
    elif isinstance(families, (Family, type)):
        # Segmenter keeps the selection as given and records it as a list.
        raise InputError(f"families: give Family objects in a list, e.g. families=[{families!r}]")
    out: list[str] = []
    for item in families:
        if isinstance(item, Family) or (isinstance(item, type) and issubclass(item, Family)):
            out.append(_resolve(item).name)
            continue
        if not isinstance(item, str):
            raise InputError(f"families: expected names or Family objects, got {item!r}")
        for n in (f.strip().lower() for f in item.split(",")):
            if not n:
                continue
            if n == "simple":
                out += simple_families()
            elif n == "all":
                out += list(REGISTRY)
            elif n in REGISTRY:
                out.append(n)
            else:
                raise InputError(f"unknown family {n!r} (known: simple, all, {', '.join(REGISTRY)})")
    if not out:
        raise InputError("no family selected")
    return [REGISTRY[n] for n in dict.fromkeys(out)]


__all__ = ["MODULES", "REGISTRY", "SIMPLE", "Family", "FamilyTable", "Frame", "ParametricFamily", "Placement",
           "Primitive", "Sampler", "add", "define_family", "register", "select", "simple_families", "unregister",
           "unregister_family", "user_families"]
