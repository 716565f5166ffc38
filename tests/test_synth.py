"""Tests of the synthetic generator: determinism, exact geometry, ground truth, files.

Distances and normals are recomputed here with independent closed forms from the *returned world
parameters*, so these tests validate the parameters as much as the points.
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

import numpy as np
import pytest
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from houghcad import synth as S

# ---------------------------------------------------------------- closed forms


def _v(x):
    return np.asarray(x, dtype=float)


def surface_distance(type_: str, params: dict, x: np.ndarray) -> np.ndarray:
    """Unsigned distance (N,) of points (N,3) to the primitive (unbounded surface)."""
    if type_ == "plane":
        return np.abs(x @ _v(params["normal"]) - params["offset"])
    if type_ == "sphere":
        return np.abs(np.linalg.norm(x - _v(params["center"]), axis=1) - params["radius"])
    if type_ == "cylinder":
        d = _v(params["axis"])
        v = x - _v(params["axis_point"])
        return np.abs(np.linalg.norm(v - np.outer(v @ d, d), axis=1) - params["radius"])
    if type_ == "cone":
        d, a = _v(params["axis"]), params["half_angle"]
        v = x - _v(params["apex"])
        h = v @ d
        rho = np.linalg.norm(v - np.outer(h, d), axis=1)
        return np.abs(rho * np.cos(a) - h * np.sin(a))
    if type_ == "torus":
        d = _v(params["axis"])
        v = x - _v(params["center"])
        h = v @ d
        rho = np.linalg.norm(v - np.outer(h, d), axis=1)
        return np.abs(np.hypot(rho - params["major_radius"], h) - params["minor_radius"])
    raise AssertionError(type_)


def surface_normal(type_: str, params: dict, x: np.ndarray) -> np.ndarray:
    """Unit normal direction (N,3) of the primitive at (or near) points x, up to sign."""
    if type_ == "plane":
        return np.tile(_v(params["normal"]), (len(x), 1))
    if type_ == "sphere":
        g = x - _v(params["center"])
    else:
        d = _v(params["axis"])
        base = _v(params.get("axis_point", params.get("apex", params.get("center"))))
        v = x - base
        h = v @ d
        radial = v - np.outer(h, d)
        e = radial / np.linalg.norm(radial, axis=1, keepdims=True)
        if type_ == "cylinder":
            g = e
        elif type_ == "cone":
            a = params["half_angle"]
            g = np.cos(a) * e - np.sin(a) * d
        elif type_ == "torus":
            g = v - params["major_radius"] * e
        else:
            raise AssertionError(type_)
    return g / np.linalg.norm(g, axis=1, keepdims=True)


def n_components(x: np.ndarray, radius: float, min_size: int = 5) -> int:
    """Connected components (of at least ``min_size`` points) of the radius graph of x."""
    pairs = cKDTree(x).query_pairs(radius, output_type="ndarray")
    g = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(len(x), len(x)))
    _, lab = connected_components(g, directed=False)
    return int(np.sum(np.bincount(lab) >= min_size))


def spacing(x: np.ndarray) -> float:
    """Typical point spacing ≈ 1/sqrt(density): twice the mean nearest-neighbour distance."""
    d, _ = cKDTree(x).query(x, k=2)
    return 2.0 * float(np.mean(d[:, 1]))


def by_name(cloud: S.SynthCloud, name: str) -> tuple[int, dict]:
    k = [p["name"] for p in cloud.primitives].index(name)
    return k, cloud.primitives[k]["params"]


# ---------------------------------------------------------------- single primitives

SEEDS = range(6)


@pytest.mark.parametrize("family", S.FAMILIES)
def test_single_deterministic(family):
    a = S.single(family, seed=3, noise=0.01, outliers=0.1, missing=0.2)
    b = S.single(family, seed=3, noise=0.01, outliers=0.1, missing=0.2)
    for f in ("points", "normals", "labels"):
        assert np.array_equal(getattr(a, f), getattr(b, f))
    assert a.primitives == b.primitives and a.sigma == b.sigma
    c = S.single(family, seed=4, noise=0.01, outliers=0.1, missing=0.2)
    assert not np.array_equal(a.points, c.points)


@pytest.mark.parametrize("family", S.FAMILIES)
@pytest.mark.parametrize("seed", SEEDS)
def test_single_on_surface(family, seed):
    c = S.single(family, seed=seed, n_points=3000)
    assert c.points.shape == (3000, 3) and c.points.dtype == np.float64
    assert c.normals.shape == (3000, 3) and c.labels.dtype == np.int64
    assert np.all(c.labels == 0) and len(c.primitives) == 1
    prim = c.primitives[0]
    assert prim["type"] == family
    p = prim["params"]
    dist = surface_distance(family, p, c.points)
    assert dist.max() < 1e-9 * c.diagonal()
    assert np.allclose(np.linalg.norm(c.normals, axis=1), 1.0, atol=1e-12)
    dots = np.abs(np.sum(c.normals * surface_normal(family, p, c.points), axis=1))
    assert dots.min() > 1 - 1e-9
    for key in ("normal", "axis"):
        if key in p:
            assert abs(np.linalg.norm(p[key]) - 1) < 1e-12
    if family == "plane":
        assert abs(np.dot(p["normal"], p["point"]) - p["offset"]) < 1e-9 * c.diagonal()
    if family == "cone":  # the patch lies on the opening side of the apex
        assert np.all((c.points - _v(p["apex"])) @ _v(p["axis"]) > 0)
        assert 0.26 < p["half_angle"] < 1.05


def test_single_unposed_is_standard_frame():
    c = S.single("torus", seed=1, pose=False)
    p = c.primitives[0]["params"]
    assert p["center"] == [0, 0, 0] and p["axis"] == [0, 0, 1]
    assert 0.2 <= p["minor_radius"] / p["major_radius"] <= 0.5
    c2 = S.single("cylinder", seed=1, pose=False, scale=3.0)
    c1 = S.single("cylinder", seed=1, pose=False)
    assert np.allclose(c2.points, 3.0 * c1.points)
    assert np.isclose(c2.primitives[0]["params"]["radius"], 3 * c1.primitives[0]["params"]["radius"])


def test_noise_level():
    clean = S.single("plane", seed=5, n_points=20000)
    noisy = S.single("plane", seed=5, n_points=20000, noise=0.01)
    sigma = 0.01 * clean.diagonal()
    assert np.isclose(noisy.sigma, sigma)
    # same underlying surface points: the displacement is the noise itself, isotropic
    disp = noisy.points - clean.points
    assert np.allclose(disp.std(axis=0), sigma, rtol=0.03)
    assert np.allclose(disp.mean(axis=0), 0, atol=0.05 * sigma)
    # and the distance to the plane (one component of the 3-D noise) has std sigma
    sd = noisy.points @ _v(noisy.primitives[0]["params"]["normal"]) - noisy.primitives[0]["params"]["offset"]
    assert np.isclose(sd.std(), sigma, rtol=0.03)


@pytest.mark.parametrize("family", S.FAMILIES)
def test_outliers_fraction(family):
    c = S.single(family, seed=2, n_points=4000, outliers=0.2)
    out = c.labels == -1
    assert abs(out.mean() - 0.2) < 0.005
    assert np.all(c.normals[out] == 0)
    surf = c.points[~out]
    assert surface_distance(family, c.primitives[0]["params"], surf).max() < 1e-9 * c.diagonal()
    lo, hi = surf.min(0), surf.max(0)
    pad = 0.1 * np.linalg.norm(hi - lo) + 1e-9
    assert np.all(c.points >= lo - pad) and np.all(c.points <= hi + pad)


@pytest.mark.parametrize("family", S.FAMILIES)
def test_missing_fraction(family):
    full = S.single(family, seed=4, n_points=4000)
    cut = S.single(family, seed=4, n_points=4000, missing=0.3)
    assert len(cut.points) == 4000 - 1200
    # a subset of the same surface sample ...
    d, _ = cKDTree(full.points).query(cut.points)
    assert d.max() < 1e-9 * full.diagonal()
    # ... whose removed part is one contiguous region cut off by a plane
    d2, _ = cKDTree(cut.points).query(full.points)
    removed = full.points[d2 > 0]
    assert len(removed) == 1200
    h = spacing(full.points)
    if family in ("plane", "cylinder", "sphere"):
        assert n_components(removed, 3 * h) == 1


def test_sampler_uniformity():
    rng = np.random.default_rng(0)
    n = 200000
    p, _ = S.sample_sphere(rng, n, 2.0)
    assert np.allclose(np.histogram(p[:, 2], bins=10)[0] / n, 0.1, atol=0.004)
    p, _ = S.sample_cone(rng, n, 0.5, (0.5, 2.0))
    assert np.allclose(np.histogram(p[:, 2] ** 2, bins=10)[0] / n, 0.1, atol=0.004)
    R, r = 1.0, 0.5
    p, nrm = S.sample_torus(rng, n, R, r)
    outer = np.mean(np.einsum("ij,ij->i", nrm[:, :2], p[:, :2]) > 0)  # cos v > 0
    assert np.isclose(outer, (np.pi * R + 2 * r) / (2 * np.pi * R), atol=0.004)
    assert np.isclose(S.SAMPLERS["torus"].area(major=R, minor=r), 4 * np.pi**2 * R * r)
    p, _ = S.sample_plane_patch(rng, n, (2.0, 1.0), shape="disc")
    assert np.all((p[:, 0] / 1.0) ** 2 + (p[:, 1] / 0.5) ** 2 <= 1 + 1e-12)
    assert np.isclose(np.mean(np.hypot(p[:, 0], 2 * p[:, 1]) < np.sqrt(0.5)), 0.5, atol=0.004)


def test_registry():
    assert set(S.FAMILIES) <= set(S.SAMPLERS)
    pts, nrm = S.sample_family("cylinder", np.random.default_rng(0), 10, radius=1.0, height=2.0)
    assert pts.shape == nrm.shape == (10, 3)
    with pytest.raises(ValueError):
        S.sample_family("nope", np.random.default_rng(0), 10)
    with pytest.raises(ValueError):
        S.single("nope")


def test_transform_params_roundtrip():
    rng = np.random.default_rng(1)
    R, t, s = S.random_pose(rng)
    assert np.allclose(R @ R.T, np.eye(3)) and np.isclose(np.linalg.det(R), 1)
    p = {"normal": [0, 0, 1.0], "offset": 2.0, "point": [1.0, 1.0, 2.0]}
    q = S.transform_params("plane", p, R, t, s)
    assert np.isclose(np.dot(q["normal"], q["point"]), q["offset"])
    with pytest.raises(ValueError):
        S.transform_params("x", {"weird": 1.0}, R, t, s)


# ---------------------------------------------------------------- composite parts

PART_CASES = [
    ("block_with_hole_and_slot", {}),
    ("plate_with_holes", {}),
    ("plate_with_holes", {"pattern": "grid", "n_holes": 9}),
    ("plate_with_holes", {"pattern": "grid", "n_holes": 2, "boss": False}),
    ("shaft_with_groove", {}),
    ("mirrored_cones", {}),
    ("gear_like", {}),
    ("filleted_block", {}),
    ("bracket", {}),
    ("table5_block", {}),
]

EXPECTED_TYPES = {
    "block_with_hole_and_slot": {"plane": 10, "cylinder": 1},
    "shaft_with_groove": {"plane": 4, "cylinder": 2},
    "mirrored_cones": {"plane": 2, "cylinder": 1, "cone": 2},
    "gear_like": {"plane": 2, "cylinder": 14},
    "filleted_block": {"plane": 7, "cylinder": 2, "sphere": 1, "torus": 1},
    "bracket": {"plane": 20, "cylinder": 24, "cone": 2},
    "table5_block": {"plane": 2, "cylinder": 1, "torus": 2},
}

MULTI_COMPONENT = {"block_with_hole_and_slot": {"hole": 2}, "shaft_with_groove": {"shaft": 2},
                   "table5_block": {"cylinder": 2}}


@pytest.fixture(scope="module", params=PART_CASES, ids=lambda c: c[0] + "-" + "-".join(f"{k}={v}" for k, v in c[1].items()))
def part(request):
    name, kw = request.param
    return name, kw, S.PARTS[name](seed=1, n_points=20000, **kw)


def test_part_structure(part):
    name, kw, c = part
    assert c.points.shape == (20000, 3)
    assert set(np.unique(c.labels)) == set(range(len(c.primitives)))
    types: dict[str, int] = {}
    for p in c.primitives:
        types[p["type"]] = types.get(p["type"], 0) + 1
    if name in EXPECTED_TYPES:
        assert types == EXPECTED_TYPES[name]
    if name == "plate_with_holes":
        n_holes = kw.get("n_holes", 6)
        boss = kw.get("boss", True)
        assert types == {"plane": 6 + boss, "cylinder": n_holes + boss}
        if boss:
            hole_r = by_name(c, "hole 0")[1]["radius"]
            assert abs(by_name(c, "boss wall")[1]["radius"] / hole_r - 1) >= 0.4
    segs = c.segments()
    assert sum(len(s) for s in segs) == len(c.points)


def test_part_labels_on_primitives(part):
    _, _, c = part
    diag = c.diagonal()
    assert np.allclose(np.linalg.norm(c.normals, axis=1), 1.0, atol=1e-12)
    for k, prim in enumerate(c.primitives):
        m = c.labels == k
        x = c.points[m]
        assert surface_distance(prim["type"], prim["params"], x).max() < 1e-9 * diag, prim["name"]
        dots = np.sum(c.normals[m] * surface_normal(prim["type"], prim["params"], x), axis=1)
        assert np.abs(dots).min() > 1 - 1e-9, prim["name"]
        if prim["type"] == "plane":  # plane normals in the params point out of the material
            assert dots.min() > 1 - 1e-9, prim["name"]


def test_part_components(part):
    name, _, c = part
    h = spacing(c.points)
    expected = MULTI_COMPONENT.get(name, {})
    for k, prim in enumerate(c.primitives):
        got = n_components(c.points[c.labels == k], 3 * h)
        assert got == expected.get(prim["name"], 1), (prim["name"], got)


def test_part_uniform_density():
    c = S.gear_like(seed=2, n_points=40000, pose=False)
    (_, top), (_, outer), (_, bore), (_, hole) = (by_name(c, n) for n in ("top", "outer", "bore", "hole 0"))
    T = top["offset"]
    n_holes = sum(p["name"].startswith("hole") for p in c.primitives)
    a_top = np.pi * (outer["radius"] ** 2 - bore["radius"] ** 2 - n_holes * hole["radius"] ** 2)
    a_out = 2 * np.pi * outer["radius"] * T
    a_bore = 2 * np.pi * bore["radius"] * T
    counts = np.bincount(c.labels)
    dens = np.array([counts[0] / a_top, counts[2] / a_out, counts[3] / a_bore])
    assert np.allclose(dens / dens.mean(), 1, atol=0.06)


def _inside_all(c, names, x, margin):
    """Points strictly on the inner side (normal · x − offset > margin) of all named planes."""
    ok = np.ones(len(x), bool)
    for n in names:
        p = by_name(c, n)[1]
        ok &= x @ _v(p["normal"]) - p["offset"] > margin
    return ok


def _axis_dist(p, x):
    d = _v(p["axis"])
    v = x - _v(p["axis_point"])
    return np.linalg.norm(v - np.outer(v @ d, d), axis=1)


@pytest.mark.parametrize("seed", range(3))
def test_block_no_points_in_removed_material(seed):
    c = S.block_with_hole_and_slot(seed=seed)
    x, tol = c.points, 1e-9 * c.diagonal()
    box = [f"box {s}{a}" for a in "xyz" for s in "-+"]
    # inside the block: on the inner side of the six outward box planes
    for n in box:
        p = by_name(c, n)[1]
        assert np.all(x @ _v(p["normal"]) - p["offset"] < tol)
    # nothing strictly inside the tunnel (its planes' normals point into it) or the hole
    tunnel = ["tunnel floor", "tunnel ceiling", "tunnel wall -x", "tunnel wall +x"]
    assert not np.any(_inside_all(c, tunnel, x, tol))
    hole = by_name(c, "hole")[1]
    assert np.all(_axis_dist(hole, x) > hole["radius"] - tol)
    # the tunnel is wider than the hole: no hole-wall points between floor and ceiling
    k = by_name(c, "hole")[0]
    xs = x[c.labels == k]
    assert not np.any(_inside_all(c, ["tunnel floor", "tunnel ceiling"], xs, tol))
    # both tunnel openings really are open: no +-y face points inside the tunnel's cross-section
    for n in ("box -y", "box +y"):
        xs = x[c.labels == by_name(c, n)[0]]
        assert not np.any(_inside_all(c, tunnel, xs, tol))


def test_holes_are_empty():
    for c in (S.plate_with_holes(seed=3), S.plate_with_holes(seed=3, pattern="grid"), S.gear_like(seed=3)):
        tol = 1e-9 * c.diagonal()
        for p in c.primitives:
            if p["name"].startswith("hole") or p["name"] == "bore":
                assert np.all(_axis_dist(p["params"], c.points) > p["params"]["radius"] - tol), (c.name, p["name"])


def test_shaft_groove_is_empty():
    c = S.shaft_with_groove(seed=2)
    tol = 1e-9 * c.diagonal()
    shaft, groove = by_name(c, "shaft")[1], by_name(c, "groove bottom")[1]
    r = _axis_dist(shaft, c.points)
    between = _inside_all(c, ["groove wall low", "groove wall high"], c.points, tol)
    assert not np.any(between & (r > groove["radius"] + tol))
    assert np.all(r < shaft["radius"] + tol)


def test_filleted_block_dimple_and_fillet():
    c = S.filleted_block(seed=2)
    tol = 1e-9 * c.diagonal()
    sph = by_name(c, "dimple")[1]
    assert np.all(np.linalg.norm(c.points - _v(sph["center"]), axis=1) > sph["radius"] - tol)
    # the torus fillet is concave: its points lie outside the tube, between the boss and the top
    k, tor = by_name(c, "boss fillet")
    top = by_name(c, "box +z")[1]
    h = c.points[c.labels == k] @ _v(top["normal"]) - top["offset"]
    assert np.all(h > -tol) and np.all(h < tor["minor_radius"] + tol)


@pytest.mark.parametrize("seed", range(3))
def test_bracket_has_many_small_faces(seed):
    c = S.bracket(seed=seed)
    sizes = np.bincount(c.labels, minlength=len(c.primitives))
    assert len(c.points) == 8000 and len(c.primitives) == 46
    assert np.sum((sizes >= 20) & (sizes <= 100)) >= 25  # chamfers, hole walls, steps, boss tops
    # The holes are empty: no point inside a hole's radius within the plate.
    tol = 1e-9 * c.diagonal()
    for p in c.primitives:
        if p["name"].startswith("hole"):
            assert np.all(_axis_dist(p["params"], c.points) > p["params"]["radius"] - tol), p["name"]


def test_table5_block_has_the_papers_parameters():
    c = S.table5_block(n_points=5000)
    p = {q["name"]: q["params"] for q in c.primitives}
    assert p["bottom plane"]["offset"] == pytest.approx(1.28) and p["bottom plane"]["normal"][2] == -1.0
    assert p["top plane"]["offset"] == pytest.approx(1.28) and p["top plane"]["normal"][2] == 1.0
    assert p["cylinder"]["radius"] == pytest.approx(1.80)
    assert (p["torus 1 (bead)"]["major_radius"], p["torus 1 (bead)"]["minor_radius"]) == pytest.approx((1.49, 0.72))
    assert (p["torus 2 (groove)"]["major_radius"], p["torus 2 (groove)"]["minor_radius"]) == pytest.approx((1.05, 0.79))
    # Unposed: the points are in the paper's frame (the part spans z = -1.28 .. 1.28 + 0.72).
    assert c.points[:, 2].min() == pytest.approx(-1.28) and c.points[:, 2].max() <= 1.28 + 0.72 + 1e-9


def test_parts_deterministic():
    for name, fn in S.PARTS.items():
        a, b = fn(seed=5, n_points=3000, noise=0.01), fn(seed=5, n_points=3000, noise=0.01)
        assert np.array_equal(a.points, b.points) and np.array_equal(a.labels, b.labels), name
        assert a.primitives == b.primitives


def test_part_noise_and_outliers():
    c = S.mirrored_cones(seed=0, noise=0.005, outliers=0.1)
    assert abs(np.mean(c.labels == -1) - 0.1) < 0.005
    clean = S.mirrored_cones(seed=0)
    assert np.isclose(c.sigma, 0.005 * clean.diagonal())


# ---------------------------------------------------------------- files


def _read_fit4cad(path):
    blocks = [b for b in path.read_text().split("\n\n") if b.strip()]
    out = []
    for b in blocks:
        head, body = b.strip().split(":=[")
        assert head.startswith("Primitive") and body.endswith("];")
        out.append(np.array(body[:-2].split(), dtype=np.int64) - 1)
    return out


def test_write_demo(tmp_path):
    from plyfile import PlyData

    path = tmp_path / "demo.ply"
    cloud = S.write_demo(path)
    ply = PlyData.read(str(path))
    assert ply.byte_order == "<" and not ply.text
    v = ply["vertex"]
    assert [p.name for p in v.properties] == ["x", "y", "z"]
    assert all(v.data.dtype[n] == np.dtype("<f4") for n in "xyz")
    xyz = np.column_stack([v["x"], v["y"], v["z"]])
    assert len(xyz) == 12000
    assert np.allclose(xyz, cloud.points, atol=1e-5 * cloud.diagonal())
    segs = _read_fit4cad(tmp_path / "demo_primitives.txt")
    assert len(segs) == len(cloud.primitives) == 11
    for k, s in enumerate(segs):
        assert np.array_equal(s, np.flatnonzero(cloud.labels == k))
    assert not list(tmp_path.glob("*.tmp"))


def test_bundled_demo_matches_generator():
    data = resources.files("houghcad") / "data"
    ply, txt = data / "demo_part.ply", data / "demo_part_primitives.txt"
    assert ply.is_file() and txt.is_file()
    raw = ply.read_bytes()
    assert len(raw) < 400_000
    from plyfile import PlyData
    import io

    v = PlyData.read(io.BytesIO(raw))["vertex"]
    cloud = S.block_with_hole_and_slot(seed=7, n_points=12000, noise=0.001)
    xyz = np.column_stack([v["x"], v["y"], v["z"]]).astype(float)
    assert np.allclose(xyz, cloud.points, atol=1e-4 * cloud.diagonal())


# --------------------------------------------------------------------------- python -m houghcad.synth


def _package_data() -> dict[str, bytes]:
    data = resources.files("houghcad") / "data"
    return {name: (data / name).read_bytes() for name in ("demo_part.ply", "demo_part_primitives.txt")}


def test_synth_main_help_and_no_arguments_write_nothing(tmp_path):
    # `python -m houghcad.synth --help` used to ignore its arguments and rewrite the package's data.
    import subprocess
    import sys

    before = _package_data()
    data = Path(str(resources.files("houghcad") / "data"))
    stamps = {p.name: p.stat().st_mtime_ns for p in data.iterdir()}
    for argv in (["--help"], []):
        proc = subprocess.run([sys.executable, "-m", "houghcad.synth", *argv], capture_output=True, text=True,
                              cwd=tmp_path, timeout=120)
        if argv:
            assert proc.returncode == 0 and "--package-data" in proc.stdout and "-o DIR" in proc.stdout
            assert "demo_part_primitives.txt" in " ".join(proc.stdout.split())
        else:  # where to write must be said
            assert proc.returncode == 2 and proc.stderr.count("\n") == 2 and "Traceback" not in proc.stderr
            assert "one of the arguments -o/--output --package-data is required" in proc.stderr
    assert _package_data() == before and {p.name: p.stat().st_mtime_ns for p in data.iterdir()} == stamps
    assert list(tmp_path.iterdir()) == []


def test_synth_main_writes_the_demo_where_it_is_told(tmp_path, monkeypatch, capsys):
    from plyfile import PlyData

    from houghcad.synth import __main__ as synth_main

    out = tmp_path / "new" / "folder"
    assert synth_main.main(["-o", str(out)]) == 0
    assert sorted(p.name for p in out.iterdir()) == ["demo_part.ply", "demo_part_primitives.txt"]
    assert capsys.readouterr().out == f"wrote {out / 'demo_part.ply'} and {out / 'demo_part_primitives.txt'}\n"
    assert len(PlyData.read(str(out / "demo_part.ply"))["vertex"]) == 12000
    assert len(_read_fit4cad(out / "demo_part_primitives.txt")) == 11
    # --package-data: into the package's data folder (here a stand-in), nowhere else.
    data = tmp_path / "data"
    data.mkdir()
    monkeypatch.setattr(synth_main, "DATA", data)
    assert synth_main.main(["--package-data"]) == 0
    for name in ("demo_part.ply", "demo_part_primitives.txt"):
        assert (data / name).read_bytes() == (out / name).read_bytes()
    # A file where the folder should be: one line, exit 2.
    capsys.readouterr()
    (tmp_path / "a_file").write_text("x")
    assert synth_main.main(["-o", str(tmp_path / "a_file")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "a_file: not a folder" in err
