"""Tests of the family protocol (houghcad.families.base, .__init__): the declared attributes of
every family, discovery and registry order, selection with Family objects, and a family added
in one file of its own (a temporary module) that segments a cloud its own sampler drew."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest

import houghcad
from houghcad import families, palette, synth
from houghcad.errors import InputError
from houghcad.families import REGISTRY, Family, add, select, simple_families, unregister
from houghcad.families.base import FamilyTable

#: (role, precedence, search, order, colour, type code) of the built-in families, in registry order.
EXPECTED = {
    "plane": ("simple", 0, "whole", 10, (228, 26, 28), 1),
    "cylinder": ("simple", 1, "whole", 20, (30, 160, 45), 2),
    "sphere": ("simple", 2, "whole", 30, (200, 40, 200), 4),
    "cone": ("simple", 3, "cluster", 40, (35, 70, 230), 3),
    "torus": ("simple", 4, "cluster", 50, (0, 0, 0), 5),
    "generalized_cylinder": ("complex", 6, "whole", 60, (0, 170, 170), 7),
    "generalized_cone": ("complex", 7, "whole", 70, (128, 128, 0), 8),
    "helical_surface": ("complex", 9, "whole", 80, (140, 80, 30), 10),
    "helical_strip": ("complex", 8, "whole", 90, (110, 60, 200), 11),
    "annulus": ("complex", 7, "cluster", 100, (128, 128, 128), 12),
    "ellipsoid": ("complex", 5, "whole", 110, (255, 140, 0), 6),
    "surface_of_revolution": ("complex", 7, "whole", 120, (255, 110, 180), 9),
}

# A plane-like family in a file of its own: new name, colour, type code and sampler (a square patch).
SLAB_MODULE = '''
import numpy as np

from houghcad.families import Sampler
from houghcad.families.plane import Plane


def sample_square(rng, n, side=1.0):
    """Uniform points (n, 3) on the square [-side/2, side/2]² of z = 0, normals +z."""
    xy = (rng.random((n, 2)) - 0.5) * side
    return np.column_stack([xy, np.zeros(n)]), np.tile([0.0, 0.0, 1.0], (n, 1))


def square_area(side=1.0):
    return float(side * side)


def square_local(**_):
    return {"normal": [0.0, 0.0, 1.0], "offset": 0.0, "point": [0.0, 0.0, 0.0]}


def square_random(rng):
    return {"side": float(rng.uniform(0.8, 1.2))}


class Slab(Plane):
    name = "test_slab"
    role = "complex"
    precedence = 10
    search = "whole"
    order = 500
    color = (12, 34, 56)
    type_code = 42
    sampler = Sampler(sample_square, square_area, square_local, square_random,
                      {"normal": "direction", "offset": "offset", "point": "point"})
'''


def _import_file(path: Path, name: str):
    spec = importlib.util.spec_from_file_location(name, path)
    mod = importlib.util.module_from_spec(spec)
    sys.modules[name] = mod
    spec.loader.exec_module(mod)
    return mod


@pytest.fixture
def slab_module(tmp_path):
    """The Slab family's module, imported from a temporary file; the registry is restored after."""
    path = tmp_path / "slab_family.py"
    path.write_text(SLAB_MODULE)
    mod = _import_file(path, "slab_family")
    try:
        yield mod
    finally:
        unregister("test_slab")
        sys.modules.pop("slab_family", None)


# ---------------------------------------------------------------------------- attributes


def test_registry_order_and_attributes_of_every_family():
    assert list(REGISTRY) == list(EXPECTED)
    for name, (role, prec, search, order, color, code) in EXPECTED.items():
        f = REGISTRY[name]
        assert (f.role, f.precedence, f.search, f.order, f.color, f.type_code) == (role, prec, search, order,
                                                                                   color, code), name


def test_the_old_flags_are_gone():
    for f in list(REGISTRY.values()) + [Family]:
        for old in ("simple", "complexity", "global_search"):
            assert not hasattr(f, old), (f, old)


def test_palette_tables_come_from_the_families_unchanged():
    assert dict(palette.TYPE_CODES) == {n: e[5] for n, e in EXPECTED.items()}
    assert dict(palette.TYPE_COLORS) == {n: e[4] for n, e in EXPECTED.items()}
    assert palette.type_code("no_such_family") == palette.OTHER_CODE == 0
    assert palette.type_color("no_such_family") == palette.OTHER_COLOR


def test_every_sampler_describes_its_parameters():
    """Each family's sampler gives the kind of every parameter it reports (synth's poses need them)."""
    assert list(synth.SAMPLERS) == list(EXPECTED)
    rng = np.random.default_rng(0)
    for name, s in synth.SAMPLERS.items():
        shape = s.random_shape(rng)
        P, N = s(rng, 50, **shape)
        assert P.shape == N.shape == (50, 3)
        assert set(s.local_params(**shape)) <= set(s.param_kinds), name
    # Where two families disagree on a name, the later one's kind is keyed by family.
    assert synth.PARAM_KINDS["a"] == "length" and synth.PARAM_KINDS["generalized_cone.a"] == "invariant"


# ---------------------------------------------------------------------------- discovery and selection


def test_discovery_imports_every_public_module_of_the_package():
    pkg = Path(families.__file__).parent
    public = sorted(p.stem for p in pkg.glob("*.py") if not p.stem.startswith("_"))
    assert list(families.MODULES) == [m for m in public if m not in ("base", "parametric")]
    assert {type(f).__module__.rsplit(".", 1)[1] for f in REGISTRY.values()} == set(families.MODULES)


def test_adding_a_file_to_the_package_adds_its_family(tmp_path, monkeypatch):
    """Discovery picks up any module on the package's path; the registry stays in `order`."""
    (tmp_path / "slab_in_package.py").write_text(
        SLAB_MODULE + "\nfrom houghcad.families import register\nregister(Slab)\n")
    monkeypatch.setattr(families, "__path__", [*families.__path__, str(tmp_path)])
    try:
        names = families._discover()
        assert "slab_in_package" in names
        assert list(REGISTRY)[:len(EXPECTED)] == list(EXPECTED) and list(REGISTRY)[-1] == "test_slab"
        assert palette.type_code("test_slab") == 42
    finally:
        unregister("test_slab")
        sys.modules.pop("houghcad.families.slab_in_package", None)
    assert list(REGISTRY) == list(EXPECTED)


def test_select_keywords_and_order():
    assert [f.name for f in select("simple")] == ["plane", "cylinder", "cone", "sphere", "torus"]
    assert simple_families() == families.SIMPLE == synth.FAMILIES
    assert [f.name for f in select("all")] == list(REGISTRY)
    assert [f.name for f in select(None)] == list(families.SIMPLE)
    assert [f.name for f in select(["sphere, plane", "sphere"])] == ["sphere", "plane"]


def test_select_takes_family_objects_and_classes():
    plane = REGISTRY["plane"]
    got = select([plane, type(REGISTRY["cylinder"]), "cone", type(plane)()])
    assert [f.name for f in got] == ["plane", "cylinder", "cone"]
    assert got[0] is plane and got[1] is REGISTRY["cylinder"]  # the registered objects stand for them
    with pytest.raises(InputError, match="no family"):
        select([])
    with pytest.raises(InputError, match="expected names or Family"):
        select([3])
    with pytest.raises(InputError, match="in a list"):
        select(plane)


def test_select_refuses_another_family_under_a_registered_name(slab_module):
    class Impostor(slab_module.Slab):
        name = "plane"
        type_code = None

    with pytest.raises(InputError, match="different family is registered as 'plane'"):
        select([Impostor()])
    with pytest.raises(InputError, match="different family"):
        select([Impostor])
    assert type(REGISTRY["plane"]).__name__ == "Plane"


@pytest.mark.parametrize("attr, value, match", [
    ("role", "medium", "role must be one of"),
    ("search", "everywhere", "search must be one of"),
    ("color", (300, 0, 0), "color must be"),
    ("color", [1, 2, 3], "color must be"),
    ("type_code", 0, "type_code must be"),
    ("type_code", 3, "taken by 'cone'"),
    ("name", "all", "selection of families"),
])
def test_add_checks_the_declared_attributes(slab_module, attr, value, match):
    fam = slab_module.Slab()
    setattr(fam, attr, value)
    with pytest.raises(InputError, match=match):
        add(fam)
    assert "test_slab" not in REGISTRY and "all" not in REGISTRY


def test_family_table_is_a_live_view(slab_module):
    codes = FamilyTable("type_code")
    assert "test_slab" not in codes and len(codes) == len(EXPECTED)
    add(slab_module.Slab())
    assert codes["test_slab"] == 42 and list(codes)[-1] == "test_slab" and len(codes) == len(EXPECTED) + 1
    unregister("test_slab")
    with pytest.raises(KeyError):
        codes["test_slab"]


# ---------------------------------------------------------------------------- a family in a file of its own


def test_a_family_from_its_own_file_segments_its_own_samples(slab_module):
    """Segmenter(families=[obj]) registers the object: the segments carry its type and the pictures
    its colour and type code; synth samples it by name afterwards."""
    fam = slab_module.Slab()
    assert "test_slab" not in REGISTRY and "test_slab" not in synth.SAMPLERS
    rng = np.random.default_rng(7)
    P, _ = fam.sampler(rng, 3000, **fam.sampler.random_shape(rng))
    R, t, s = synth.random_pose(rng)
    P, _ = synth.apply_transform(P, None, R, t, s)
    P = P + rng.normal(0.0, 0.003 * s, P.shape)  # exactly coplanar input is refused

    res = houghcad.segment(P, families=[fam], seed=0)
    assert REGISTRY["test_slab"] is fam
    assert [seg.type for seg in res.segments] == ["test_slab"]
    assert len(res.segments[0].indices) >= 0.95 * len(P)
    normal = np.asarray(res.segments[0].params["normal"])
    assert abs(abs(normal @ (R @ [0.0, 0.0, 1.0])) - 1.0) < 1e-4
    # The pictures: its colour and code, for every point of the segment.
    assert palette.type_color("test_slab") == (12, 34, 56)
    codes = palette.point_type_codes(res)
    assert set(np.unique(codes)) <= {42, -1} and (codes == 42).sum() == len(res.segments[0].indices)
    colors = palette.point_colors(res, by="type")
    assert (colors[res.segments[0].indices] == (12, 34, 56)).all()
    assert houghcad.Result.from_dict(res.to_dict()).options["families"] == ["test_slab"]

    # Registered now: selectable by name, and synth samples it like the built-in families.
    cloud = synth.single("test_slab", seed=1, n_points=2000, noise=0.003)
    assert cloud.primitives[0]["type"] == "test_slab"
    again = houghcad.Segmenter(families="test_slab", seed=0).fit(cloud.points).result_
    assert [seg.type for seg in again.segments] == ["test_slab"]


def test_a_family_class_is_registered_once(slab_module):
    a = select([slab_module.Slab])[0]
    b = select([slab_module.Slab, "test_slab"])
    assert b == [a] and REGISTRY["test_slab"] is a
