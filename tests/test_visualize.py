"""Outputs a person looks at: palette, coloured PLY, PNG views, HTML report (and in headless Chromium)."""

from __future__ import annotations

import base64
import importlib.resources
import json
import os
import re
import shutil
import subprocess
import tempfile
from pathlib import Path

import numpy as np
import pytest

from houghcad import palette
from houghcad.htmlreport import build_html_report, write_html_report
from houghcad.io.writers import write_result_ply
from houghcad.render import draw_sample, render_png
from houghcad.result import Group, Result, Segment

# --------------------------------------------------------------------------- fixtures


def _hand_result(seed: int = 0) -> tuple[np.ndarray, Result]:
    """600 points in 6 hand-made segments (3 planes, 2 cylinders, 1 sphere), 20 unsegmented, 2 groups."""
    rng = np.random.default_rng(seed)
    pts = rng.uniform(-1.0, 1.0, size=(620, 3)) * [10.0, 5.0, 2.0] + [1000.0, -20.0, 3.0]
    perm = rng.permutation(620)
    types = ["plane", "cylinder", "plane", "sphere", "plane", "cylinder"]
    segs = [Segment(i, t, np.sort(perm[100 * i:100 * (i + 1)]).astype(np.int64),
                    {"radius": 1.5 + i, "axis": [0.0, 0.0, 1.0]} if t != "plane" else
                    {"normal": [0.0, 0.0, 1.0], "offset": float(i), "point": [0.0, 0.0, float(i)]},
                    1e-3 * (i + 1), descriptors={"radius": 1.5 + i} if t != "plane" else {})
            for i, t in enumerate(types)]
    groups = [Group("translation", [1, 5], {"radius": 2.5}), Group("parallel", [0, 2, 4], {"normal": [0, 0, 1]})]
    res = Result(n_points=620, segments=segs, unsegmented=np.sort(perm[600:]).astype(np.int64),
                 timing={"preprocess": 0.25, "recognition": 1.5, "total": 1.8}, options={"seed": 0},
                 source="hand.xyz", groups=groups)
    return pts, res


# --------------------------------------------------------------------------- palette


def test_palette_base_colours_follow_the_paper():
    r, g, b = (np.array(palette.type_color(t)) for t in ("plane", "cylinder", "cone"))
    assert r.argmax() == 0 and g.argmax() == 1 and b.argmax() == 2  # red, green, blue
    assert max(palette.type_color("torus")) < 40  # black
    sph = np.array(palette.type_color("sphere"))
    assert sph[0] > 150 and sph[2] > 150 and sph[1] < 100  # magenta
    assert palette.UNSEGMENTED_COLOR[0] > 200 and palette.UNSEGMENTED_COLOR[1] > 180 and palette.UNSEGMENTED_COLOR[2] < 60
    complex_types = ["ellipsoid", "generalized_cylinder", "generalized_cone", "surface_of_revolution",
                     "helical_surface", "helical_strip", "annulus"]
    everything = [palette.type_color(t) for t in palette.TYPE_CODES] + [palette.UNSEGMENTED_COLOR]
    assert len(set(everything)) == len(everything)  # one colour per family
    assert set(complex_types) <= set(palette.TYPE_CODES)
    codes = list(palette.TYPE_CODES.values())
    assert len(set(codes)) == len(codes) and min(codes) == 1
    assert palette.type_code("no_such_family") == 0 and palette.type_color("no_such_family") == palette.OTHER_COLOR


def _delta_e(a, b) -> np.ndarray:
    return np.linalg.norm(palette.srgb_to_lab(np.asarray(a)) - palette.srgb_to_lab(np.asarray(b)), axis=-1)


def test_srgb_to_lab_matches_reference_values():
    np.testing.assert_allclose(palette.srgb_to_lab(np.array([255, 255, 255])), [100, 0, 0], atol=1e-3)
    np.testing.assert_allclose(palette.srgb_to_lab(np.array([255, 0, 0])), [53.24, 80.09, 67.20], atol=0.02)
    np.testing.assert_allclose(palette.srgb_to_lab(np.array([0, 0, 0])), [0, 0, 0], atol=1e-9)


def test_segment_palette_colours_are_far_apart_and_off_the_unsegmented_yellow():
    pal = palette.segment_palette()
    d = _delta_e(pal[:, None], pal[None])
    assert d[np.triu_indices(len(pal), 1)].min() >= 30
    assert _delta_e(pal, palette.UNSEGMENTED_COLOR).min() >= 35


def test_adjacent_segments_differ_in_cielab():
    # Ten planes, as a chain and as a star: neighbours differ by at least 30 ΔE, however
    # many segments share the type; colours repeat only between segments far apart.
    types = ["plane"] * 10
    chain = np.array([[i, i + 1] for i in range(9)])
    star = np.array([[0, i] for i in range(1, 10)])
    for edges in (chain, star):
        cols = palette.segment_colors(types, edges, np.arange(10, 0, -1))
        assert cols.shape == (10, 3) and cols.dtype == np.uint8
        np.testing.assert_array_equal(cols, palette.segment_colors(types, edges, np.arange(10, 0, -1)))
        assert _delta_e(cols[edges[:, 0]], cols[edges[:, 1]]).min() >= 30
    assert len({tuple(c) for c in palette.segment_colors(types, chain)}) == 10  # varied while the palette lasts
    assert len({tuple(c) for c in palette.segment_colors(types)}) == 10  # no edges: all differ
    many = palette.segment_colors(["plane"] * 60, np.array([[i, i + 1] for i in range(59)]))
    assert len({tuple(c) for c in many}) == len(palette.segment_palette())  # then colours repeat


def test_adjacent_segments_of_a_real_part_differ_in_cielab():
    import houghcad
    from houghcad import synth

    cloud = synth.block_with_hole_and_slot(seed=1, n_points=3000)
    res = houghcad.segment(cloud.points)
    edges = palette.segment_edges(res, cloud.points)
    assert len(edges) >= len(res.segments) - 1  # a connected part
    by_seg = palette.point_colors(res, "segment", cloud.points)
    first = {s.id: by_seg[s.indices[0]] for s in res.segments}
    assert min(_delta_e(first[a], first[b]) for a, b in edges.tolist()) >= 30


def test_which_segments_touch_is_read_on_a_bounded_sample(monkeypatch):
    # All 3 M points of a scan took 6.8 s, once for each of the PNG, the PLY and the report.
    from houghcad import synth

    cloud = synth.block_with_hole_and_slot(seed=1, n_points=40_000)
    lab = np.asarray(cloud.labels)
    res = Result(len(lab), [Segment(k, p["type"], np.flatnonzero(lab == k), {}, 0.0)
                            for k, p in enumerate(cloud.primitives)], np.flatnonzero(lab < 0))
    every = palette.segment_edges(res, cloud.points)
    monkeypatch.setattr(palette, "EDGE_SAMPLE", 8_000)
    assert {tuple(e) for e in palette.segment_edges(res, cloud.points).tolist()} == {tuple(e) for e in every.tolist()}


def test_point_colours_and_codes():
    pts, res = _hand_result()
    by_seg, by_type = palette.point_colors(res, "segment"), palette.point_colors(res, "type")
    lab = res.labels()
    assert by_seg.shape == (620, 3) and by_seg.dtype == np.uint8
    assert (by_seg[lab < 0] == palette.UNSEGMENTED_COLOR).all()
    assert (by_type[res.segments[2].indices] == palette.type_color("plane")).all()
    assert len({tuple(c) for c in by_seg[lab >= 0]}) == 6  # every segment its own colour
    assert len({tuple(c) for c in by_type[lab >= 0]}) == 3
    codes = palette.point_type_codes(res)
    assert codes[lab < 0].tolist() == [-1] * 20
    assert set(codes[res.segments[3].indices]) == {palette.TYPE_CODES["sphere"]}


# --------------------------------------------------------------------------- PLY


def test_result_ply_round_trip(tmp_path):
    from plyfile import PlyData

    pts, res = _hand_result()
    path = tmp_path / "out.ply"
    write_result_ply(path, pts, res)
    ply = PlyData.read(str(path))
    assert ply.byte_order == "<" and not ply.text  # binary little-endian
    v = ply["vertex"].data
    assert {"x", "y", "z", "segment", "type", "group", "red", "green", "blue"} <= set(v.dtype.names)
    np.testing.assert_array_equal(np.column_stack([v["x"], v["y"], v["z"]]), pts)  # float64, exact
    np.testing.assert_array_equal(v["segment"], res.labels())
    np.testing.assert_array_equal(v["type"], palette.point_type_codes(res))
    np.testing.assert_array_equal(v["group"], res.group_labels())
    assert set(v["group"][res.segments[1].indices]) == {0} and set(v["group"][res.segments[0].indices]) == {-1}
    rgb = np.column_stack([v["red"], v["green"], v["blue"]])
    np.testing.assert_array_equal(rgb, palette.point_colors(res, "segment", pts))
    assert v["red"].dtype == np.uint8
    assert [p.name for p in tmp_path.iterdir()] == ["out.ply"]  # no temporary file left


def test_result_ply_rejects_wrong_point_count(tmp_path):
    pts, res = _hand_result()
    with pytest.raises(ValueError, match="620"):
        write_result_ply(tmp_path / "out.ply", pts[:10], res)
    assert not any(tmp_path.iterdir())


# --------------------------------------------------------------------------- PNG


def _png_pixels(path: Path) -> np.ndarray:
    from PIL import Image

    with Image.open(path) as im:
        assert im.format == "PNG"
        return np.asarray(im.convert("RGB"))


def test_png_views(tmp_path):
    pts, res = _hand_result()
    path = tmp_path / "views.png"
    render_png(path, pts, res)
    img = _png_pixels(path)
    assert img.shape == (850, 1600, 3)
    colours = {tuple(c) for c in img.reshape(-1, 3)[::7]}
    assert len(colours) > 20
    flat = img.reshape(-1, 3).astype(int)
    for rgb in (palette.type_color("plane"), palette.type_color("cylinder"), palette.type_color("sphere"),
                palette.UNSEGMENTED_COLOR, tuple(palette.segment_palette()[1])):
        near = np.abs(flat - np.array(rgb)).sum(axis=1) <= 12
        assert near.sum() > 20, rgb  # each type, a second segment colour, and the unsegmented points are drawn
    assert [p.name for p in tmp_path.iterdir()] == ["views.png"]


def _part_with_strays(strays: int, far: float = 5000.0) -> tuple[np.ndarray, Result]:
    """A block about 16 units across segmented by its ground truth, its top face left unsegmented
    (it still belongs to the part), then ``strays`` unsegmented points ``far`` units off (a
    scanner's outliers)."""
    from houghcad import synth

    cloud = synth.block_with_hole_and_slot(seed=0, n_points=4000)
    lab = np.asarray(cloud.labels).copy()
    top = max(range(lab.max() + 1), key=lambda k: cloud.points[lab == k, 2].mean())
    lab[lab == top] = -1
    d = np.random.default_rng(3).normal(size=(strays, 3))
    pts = np.r_[cloud.points, cloud.points.mean(axis=0) + far * d / np.linalg.norm(d, axis=1)[:, None]]
    lab = np.r_[lab, np.full(strays, -1)]
    segs = [Segment(k, p["type"], np.flatnonzero(lab == k), {}, 0.0) for k, p in enumerate(cloud.primitives)
            if k != top]
    segs = [Segment(i, s.type, s.indices, {}, 0.0) for i, s in enumerate(segs)]  # ids 0, 1, ...
    return pts, Result(len(lab), segs, np.flatnonzero(lab < 0))


def test_views_frame_the_part_not_far_strays(monkeypatch):
    from houghcad import render
    from houghcad.render import framed_points

    clean, clean_res = _part_with_strays(0)
    pts, res = _part_with_strays(5)
    n = len(clean)
    # The unsegmented top face is part of the part; the strays are not.
    np.testing.assert_array_equal(framed_points(pts, res.labels()), np.arange(n + 5) < n)
    assert framed_points(clean, clean_res.labels()).all()
    assert framed_points(pts, np.full(n + 5, -1)).all()  # nothing segmented: frame every point
    edge = clean[:, 2] >= clean[:, 2].max() - 1e-9
    assert (clean_res.labels()[edge] < 0).all()  # the extreme points are unsegmented ones
    # Read on a sample (a big cloud's), the others going with their nearest: the same.
    monkeypatch.setattr(render, "FRAME_SAMPLE", 500)
    np.testing.assert_array_equal(framed_points(pts, res.labels()), np.arange(n + 5) < n)


def test_png_frames_the_part_not_far_strays(tmp_path):
    """The part with 5 points 5000 units off draws as the part alone (it was a dot)."""
    clean, clean_res = _part_with_strays(0)
    pts, res = _part_with_strays(5)
    render_png(tmp_path / "clean.png", clean, clean_res, title="t")
    render_png(tmp_path / "strays.png", pts, res, title="t")
    # The panels, without the title and the legend (the unsegmented count differs).
    a, b = (_png_pixels(tmp_path / f)[80:760] for f in ("clean.png", "strays.png"))
    # Coloured pixels: drawn points (the background, axes and labels are grey).
    drawn_a, drawn_b = (~(x == x[..., :1]).all(axis=2) for x in (a, b))
    assert drawn_a.mean() > 0.05  # the part covers the panels
    assert abs(drawn_b.mean() - drawn_a.mean()) < 0.01 * drawn_a.mean()
    assert (a != b).any(axis=2).mean() < 0.01  # same frame, same axes: the same picture


def test_png_failure_leaves_nothing(tmp_path, monkeypatch):
    from matplotlib.figure import Figure

    pts, res = _hand_result()

    def boom(self, *a, **k):
        raise RuntimeError("disk on fire")

    monkeypatch.setattr(Figure, "savefig", boom)
    with pytest.raises(RuntimeError):
        render_png(tmp_path / "views.png", pts, res)
    assert not any(tmp_path.iterdir())


def test_draw_sample_is_deterministic_and_bounded():
    np.testing.assert_array_equal(draw_sample(100, 1000), np.arange(100))
    a, b = draw_sample(100_000, 5000), draw_sample(100_000, 5000)
    np.testing.assert_array_equal(a, b)
    assert len(np.unique(a)) == 5000 and (np.diff(a) > 0).all() and a[-1] < 100_000


# --------------------------------------------------------------------------- HTML (static checks)


def _embedded(html_text: str) -> dict:
    m = re.search(r'<script type="application/json" id="houghcad-data">(.*?)</script>', html_text, re.S)
    assert m
    return json.loads(m.group(1))


def test_html_report_is_self_contained(tmp_path):
    pts, res = _hand_result()
    path = tmp_path / "report.html"
    write_html_report(path, pts, res)
    text = path.read_text(encoding="utf-8")
    # No URL at all, no element that loads anything, and a policy that forbids it anyway.
    assert not re.search(r"(?i)(https?:|wss?:|ftp:)?//[a-z0-9.-]+\.[a-z]{2,}", text)
    assert not re.search(r"(?i)<script[^>]*\bsrc\s*=|<link\b|<img\b|<iframe\b|@import|@font-face", text)
    assert not re.search(r"\burl\(", text)  # CSS url(...) (toDataURL( is not one)
    csp = re.search(r'http-equiv="Content-Security-Policy" content="([^"]*)"', text).group(1)
    assert "default-src 'none'" in csp and "connect-src 'none'" in csp and "font-src 'none'" in csp
    assert "unsafe-eval" not in csp
    data = _embedded(text)
    assert [t["id"] for t in data["traces"]] == [0, 1, 2, 3, 4, 5, -1]
    assert [t["drawn"] for t in data["traces"]] == [100] * 6 + [20]


def test_html_report_points_and_tables():
    pts, res = _hand_result()
    text = build_html_report(pts, res)
    data = _embedded(text)
    xyz = np.frombuffer(base64.b64decode(data["xyz"]), dtype="<f4").reshape(3, -1).T + data["centre"]
    lab = res.labels()
    order = np.argsort(np.where(lab < 0, 99, lab), kind="stable")
    np.testing.assert_allclose(xyz, pts[order], rtol=0, atol=1e-5 * 20)  # float32 offsets: ~7 digits
    rows = re.findall(r'<tr data-segment-id="(\d+)"><td class="num">\d+</td><td>.*?</span>(\w+)</td>'
                      r'<td class="num">(\d+)</td>', text)
    assert [(int(i), t, int(n)) for i, t, n in rows] == [(s.id, s.type, len(s.indices)) for s in res.segments]
    assert len(re.findall(r"<tr data-group-id=", text)) == 2
    assert "translation" in text and "radius = 2.5" in text
    assert re.search(r"<td>recognition</td><td class=\"num\">1.500</td>", text)


def test_html_report_size_for_50k_points():
    rng = np.random.default_rng(1)
    n = 50_000
    pts = rng.normal(size=(n, 3)) * 100.0
    bounds = np.linspace(0, n - 500, 41).astype(int)
    segs = [Segment(i, ["plane", "cylinder", "cone", "sphere", "torus"][i % 5], np.arange(a, b, dtype=np.int64), {}, 1e-3)
            for i, (a, b) in enumerate(zip(bounds[:-1], bounds[1:]))]
    res = Result(n, segs, np.arange(n - 500, n, dtype=np.int64))
    text = build_html_report(pts, res)
    assert _embedded(text)["n_drawn"] == n
    size = len(text.encode("utf-8"))
    # 12 bytes of float32 and 3 of int8 normals per point, base64: ~1.05 MB, far below 15 MB
    assert size < 20 * n + 200_000


def test_html_report_frames_the_part_not_far_strays():
    """The view's centre and radius are the part's, as without the 5 points 5000 units off, and
    the viewer frames the first ``framed`` points: the part's, the strays last."""
    clean, clean_res = _part_with_strays(0)
    pts, res = _part_with_strays(5)
    a, b = (_embedded(build_html_report(p, r)) for p, r in ((clean, clean_res), (pts, res)))
    np.testing.assert_allclose(b["radius"], a["radius"], rtol=1e-12)
    np.testing.assert_allclose(b["centre"], a["centre"], rtol=0, atol=1e-9)
    assert a["radius"] < 20 and a["framed"] == a["n_drawn"] == len(clean)
    assert b["framed"] == len(clean) and b["n_drawn"] == len(pts)
    xyz = np.frombuffer(base64.b64decode(b["xyz"]), dtype="<f4").reshape(3, -1).T
    assert (np.linalg.norm(xyz[:b["framed"]], axis=1) <= b["radius"] * (1 + 1e-6)).all()
    assert (np.linalg.norm(xyz[b["framed"]:], axis=1) > 4000).all()


def test_html_report_subsamples_huge_clouds():
    pts, res = _hand_result()
    data = _embedded(build_html_report(pts, res, max_points=100))
    assert data["n_drawn"] == 100 and sum(t["drawn"] for t in data["traces"]) == 100
    assert len(base64.b64decode(data["xyz"])) == 100 * 12


def _report_asset(name: str) -> str:
    """A report asset as the package ships it (read here, not through htmlreport)."""
    return (importlib.resources.files("houghcad") / "data" / "report" / name).read_text(encoding="utf-8")


def test_html_report_viewer_script_passes_node_check(tmp_path):
    node = shutil.which("node")
    if node is None:
        pytest.skip("node (Node.js) not on PATH: cannot syntax-check data/report/viewer.js")
    script = importlib.resources.files("houghcad") / "data" / "report" / "viewer.js"
    with importlib.resources.as_file(script) as path:
        proc = subprocess.run([node, "--check", str(path)], check=False, capture_output=True, text=True,
                              timeout=120)
    assert proc.returncode == 0, proc.stderr
    # The check can fail: the same script cut short is rejected.
    broken = tmp_path / "broken.js"
    broken.write_text(_report_asset("viewer.js").rsplit("})();", 1)[0], encoding="utf-8")
    rejected = subprocess.run([node, "--check", str(broken)], check=False, capture_output=True, timeout=120)
    assert rejected.returncode != 0


def test_html_report_inlines_viewer_and_style():
    js, css = _report_asset("viewer.js"), _report_asset("report.css")
    # Either would end its element early once inlined.
    assert "</script" not in js.lower() and "</style" not in css.lower()
    assert 'getElementById("houghcad-data")' in js  # the data come from the JSON block, not the asset
    text = build_html_report(*_hand_result())
    assert re.findall(r"<script>\n(.*?)</script>", text, re.DOTALL) == [js]
    assert re.findall(r"<style>\n(.*?)</style>", text, re.DOTALL) == [css]


# --------------------------------------------------------------------------- HTML in headless Chromium

CHROMIUM, CHROMEDRIVER = "/usr/bin/chromium", "/usr/bin/chromedriver"


def _browser_missing() -> str | None:
    for exe in (CHROMIUM, CHROMEDRIVER):
        if not os.access(exe, os.X_OK):
            return f"{exe} not installed (Debian packages chromium and chromium-driver; .ci/run installs them)"
    try:
        import selenium  # noqa: F401
    except ImportError:
        return "selenium not installed (pip install '.[test]')"
    return None


@pytest.fixture(scope="module")
def browser():
    reason = _browser_missing()
    if reason:
        pytest.skip(reason)
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    profile = tempfile.mkdtemp(prefix="houghcad-chromium-")
    opts = webdriver.ChromeOptions()
    opts.binary_location = CHROMIUM  # never let selenium look for (or download) a browser
    for arg in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                "--disable-background-networking", "--disable-component-update", "--disable-sync",
                "--disable-extensions", "--window-size=1400,1000", f"--user-data-dir={profile}"):
        opts.add_argument(arg)
    opts.set_capability("goog:loggingPrefs", {"performance": "ALL"})
    driver = webdriver.Chrome(service=Service(CHROMEDRIVER), options=opts)
    try:
        yield driver
    finally:
        driver.quit()
        shutil.rmtree(profile, ignore_errors=True)


@pytest.fixture(scope="module")
def cli_outputs(tmp_path_factory):
    """A real run: `houghcad segment` of a synthetic block with every output."""
    from houghcad.cli import main
    from houghcad.synth import block_with_hole_and_slot

    d = tmp_path_factory.mktemp("cli")
    cloud = block_with_hole_and_slot(seed=0, n_points=4000)
    np.savetxt(d / "block.xyz", cloud.points, fmt="%.9f")
    argv = ["segment", str(d / "block.xyz"), "-o", str(d / "block.json"), "--ply", str(d / "block.ply"),
            "--png", str(d / "block.png"), "--report", str(d / "block.html"), "--quiet"]
    assert main(argv) == 0
    return d, cloud


def _load(driver, path: Path, timeout: float = 60.0):
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import WebDriverWait

    driver.get_log("performance")  # drop what earlier pages logged
    driver.get(path.resolve().as_uri())
    WebDriverWait(driver, timeout).until(
        lambda d: d.find_element(By.TAG_NAME, "body").get_attribute("data-rendered") == "1")


def _requested_urls(driver) -> set[str]:
    urls = set()
    for entry in driver.get_log("performance"):
        msg = json.loads(entry["message"])["message"]
        if msg["method"] == "Network.requestWillBeSent":
            urls.add(msg["params"]["request"]["url"])
    return urls


def test_cli_outputs_match_the_json(cli_outputs):
    from plyfile import PlyData

    d, cloud = cli_outputs
    res = Result.from_dict(json.loads((d / "block.json").read_text()))
    v = PlyData.read(str(d / "block.ply"))["vertex"].data
    np.testing.assert_array_equal(v["segment"], res.labels())
    np.testing.assert_array_equal(v["type"], palette.point_type_codes(res))
    np.testing.assert_array_equal(v["group"], res.group_labels())
    np.testing.assert_allclose(np.column_stack([v["x"], v["y"], v["z"]]), cloud.points, atol=1e-8)
    assert _png_pixels(d / "block.png").shape == (850, 1600, 3)


def _element_pixels(element) -> np.ndarray:
    """Screenshot of one element as an (H, W, 3) int array."""
    import io

    from PIL import Image

    return np.asarray(Image.open(io.BytesIO(element.screenshot_as_png)).convert("RGB")).astype(int)


def test_report_renders_in_headless_chromium(browser, cli_outputs):
    from selenium.webdriver.common.by import By

    d, _ = cli_outputs
    res = Result.from_dict(json.loads((d / "block.json").read_text()))
    _load(browser, d / "block.html")

    # Nothing but the file itself was requested: no CDN, font, MathJax or tile.
    urls = _requested_urls(browser)
    assert d.joinpath("block.html").resolve().as_uri() in urls
    assert not [u for u in urls if not u.startswith(("file:", "data:", "blob:", "chrome:", "about:"))], urls

    # The table: one row per segment, with the JSON's ids, types and point counts.
    rows = browser.find_elements(By.CSS_SELECTOR, "#segments tbody tr")
    cells = [[c.text for c in r.find_elements(By.TAG_NAME, "td")[:3]] for r in rows]
    assert cells == [[str(s.id), s.type, str(len(s.indices))] for s in res.segments]
    assert browser.find_element(By.ID, "n-segments").text == str(len(res.segments))

    # The 3-D view drew the points: many non-background pixels, in the palette's colours.
    plot = browser.find_element(By.ID, "view")
    img = _element_pixels(plot)
    plane_red = np.array(palette.type_color("plane"))
    coloured = (np.abs(img - img[2, 2]).sum(axis=2) > 60)  # differs from the background corner
    assert coloured.mean() > 0.02
    # The part, not its bounding sphere, fills the view: it spans most of the narrower side.
    ys, xs = np.nonzero(coloured)
    span = max((xs.max() - xs.min()) / img.shape[1], (ys.max() - ys.min()) / img.shape[0])
    assert span > 0.8, span
    assert (np.abs(img - plane_red).sum(axis=2) < 30).sum() > 50
    assert browser.execute_script("return window.houghcadView.traces") == len(res.segments) + 1

    # Toggles: unticking the plane type hides every plane trace, and only those.
    browser.find_element(By.ID, "type-0").click()
    assert browser.execute_script("return window.houghcadView.visible()") == \
        [s.type != "plane" for s in res.segments] + [True]
    assert not browser.find_element(By.ID, "type-0").is_selected()
    img2 = _element_pixels(plot)
    assert (np.abs(img2 - plane_red).sum(axis=2) < 30).sum() == 0  # the planes are gone from the picture
    browser.find_element(By.ID, "all").click()
    assert browser.execute_script("return window.houghcadView.visible()") == [True] * (len(res.segments) + 1)

    # Colour by type: every plane point in the one base red.
    browser.find_element(By.CSS_SELECTOR, "input[name=colorby][value=type]").click()
    assert browser.execute_script("return window.houghcadView.mode()") == "type"
    img3 = _element_pixels(plot)
    assert (np.abs(img3 - plane_red).sum(axis=2) < 30).sum() > (np.abs(img - plane_red).sum(axis=2) < 30).sum()

    # A click on a drawn point names its segment.
    ys, xs = np.nonzero(np.abs(img3 - plane_red).sum(axis=2) < 30)
    from selenium.webdriver.common.action_chains import ActionChains

    k = len(xs) // 2
    w, h = plot.size["width"], plot.size["height"]
    scale = img3.shape[1] / w
    ActionChains(browser).move_to_element_with_offset(plot, int(xs[k] / scale - w / 2),
                                                      int(ys[k] / scale - h / 2)).click().perform()
    assert re.match(r"segment \d+ \(plane\)", browser.find_element(By.ID, "pick").text)


def test_splat_nearest_point_wins():
    from houghcad.render import splat

    u = np.array([0.0, 0.0, 0.9])
    v = np.array([0.0, 0.0, -0.9])
    depth = np.array([1.0, 2.0, 0.0])
    colours = np.array([[255, 0, 0], [0, 255, 0], [0, 0, 255]], dtype=np.uint8)
    img = splat(u, v, depth, colours, half=1.0, size=21, radius=1)
    assert img.shape == (21, 21, 3) and img.dtype == np.uint8
    assert tuple(img[10, 10]) == (0, 255, 0)  # the nearer of the two centre points
    assert (img[9:12, 9:12] == [0, 255, 0]).all()  # a 3 x 3 square per point
    assert tuple(img[19, 19]) == (0, 0, 255)  # v = -0.9 is near the bottom row
    assert tuple(img[0, 0]) == (255, 255, 255)
    assert (img == [255, 255, 255]).all(axis=2).sum() == 21 * 21 - 18
    np.testing.assert_array_equal(img, splat(u, v, depth, colours, 1.0, 21, 1))


def test_views_close_the_near_surface():
    """A randomly sampled square in front of another: with the splat radius from the points'
    spacing the far one does not show through the near one's gaps (with 1 pixel it did)."""
    from houghcad.render import local_surface, splat, splat_radius

    rng = np.random.default_rng(0)
    n = 6000
    near = np.c_[rng.uniform(-1, 1, (n, 2)), np.full(n, 0.5)]
    far = np.c_[rng.uniform(-1, 1, (n, 2)), np.full(n, -0.5)]
    P = np.r_[near, far]
    colours = np.r_[np.tile([[255, 0, 0]], (n, 1)), np.tile([[0, 0, 255]], (n, 1))].astype(np.uint8)
    spacing, normals = local_surface(P)
    assert np.allclose(np.abs(normals[:, 2]), 1.0, atol=1e-6)
    size, half = 200, 1.2
    radius = splat_radius(spacing, half, size)
    inner = slice(int(size * 0.2), int(size * 0.8))  # well inside the squares' common area

    def blue(r: int) -> float:
        img = splat(P[:, 0], P[:, 1], P[:, 2], colours, half, size, r)[inner, inner]
        return float((img == [0, 0, 255]).all(axis=2).mean())

    assert blue(1) > 0.05
    assert radius > 1 and blue(radius) < min(0.01, blue(1) / 10)


def test_views_close_gaps_and_keep_holes():
    """With a depth slack the far side no longer shows through the near side's sampling gaps
    (without it some pixels do), while a real hole, wider than the gaps, still shows it."""
    from houghcad.render import GAP_SLACK, local_surface, splat, splat_radius

    rng = np.random.default_rng(1)
    near = np.c_[rng.uniform(-1, 1, (3000, 2)), np.full(3000, 0.5)]  # sparser than the far side
    near = near[np.hypot(near[:, 0], near[:, 1]) > 0.3]  # a round hole 0.6 across
    far = np.c_[rng.uniform(-1, 1, (8000, 2)), np.full(8000, -0.5)]
    P = np.r_[near, far]
    colours = np.r_[np.tile([[255, 0, 0]], (len(near), 1)), np.tile([[0, 0, 255]], (len(far), 1))].astype(np.uint8)
    spacing, _ = local_surface(P)
    size, half = 200, 1.2
    radius = splat_radius(spacing, half, size)
    yy, xx = np.mgrid[0:size, 0:size]
    r = np.hypot(xx - (size - 1) / 2, yy - (size - 1) / 2) * 2 * half / (size - 1)
    square = (np.abs(xx - (size - 1) / 2) < 0.8 * size / 2 / half) & (np.abs(yy - (size - 1) / 2) < 0.8 * size / 2 / half)

    def blue(slack: float | None) -> tuple[float, float]:
        img = splat(P[:, 0], P[:, 1], P[:, 2], colours, half, size, radius, slack=slack)
        b = (img == [0, 0, 255]).all(axis=2)
        return float(b[square & (r > 0.4)].mean()), float(b[r < 0.2].mean())

    (gaps_before, hole_before), (gaps_after, hole_after) = blue(None), blue(GAP_SLACK * spacing)
    assert gaps_before > 0.05 and gaps_after < gaps_before / 10
    assert hole_before > 0.99 and hole_after >= hole_before


def test_shading_tells_faces_apart_and_keeps_colours():
    from houghcad.render import LIGHT, shaded

    c = np.array([[200, 100, 50]] * 3, dtype=np.uint8)
    n = np.array([LIGHT, [0.0, 0.0, 1.0], np.cross(LIGHT, [0.0, 0.0, 1.0])])
    n /= np.linalg.norm(n, axis=1)[:, None]
    out = shaded(c, n).astype(int)
    assert (out[0] == c[0]).all()  # facing the light: the colour itself
    assert (out[0] > out[1]).all() and (out[1] > out[2]).all()
    assert (out[2] >= np.floor(0.55 * c[0])).all()  # edge-on: no darker than the ambient share
    assert (shaded(c, -n) == shaded(c, n)).all()  # normals are unoriented


def test_report_numbers_drop_rounding_noise():
    """A CAD plane's normal (8.4e-19, -6.5e-19, 1) reads (0, 0, 1); real small values stay."""
    from houghcad.htmlreport import _fmt_num

    assert _fmt_num([8.4291e-19, -6.5125e-19, 1.0]) == "(0, 0, 1)"
    assert _fmt_num(4.8e-17, scale=150.0) == "0"
    assert _fmt_num(0.0123, scale=150.0) == "0.0123"
    assert _fmt_num([1e-3, 0.0, 1.0]) == "(0.001, 0, 1)"
    assert _fmt_num(float("nan"), scale=1.0) == "nan"
    # Georeferenced coordinates keep the digits that place a feature on the part.
    assert _fmt_num([500009.41, 3999966.67, 99.963], scale=20.0) == "(500009.41, 3999966.67, 99.963)"
    assert _fmt_num(0.70710678, scale=150.0) == "0.70711"


def test_report_draws_points_as_wide_as_their_spacing_and_shaded():
    from houghcad.htmlreport import _payload
    from houghcad.render import local_surface

    rng = np.random.default_rng(1)
    P = np.c_[rng.uniform(0, 10, (4000, 2)), np.zeros(4000)]
    # The 6th neighbour of a random sample of density 40 per unit area: about sqrt(6 / (pi 40)).
    spacing, normals = local_surface(P)
    assert 0.8 * np.sqrt(6 / (np.pi * 40)) < spacing < 1.2 * np.sqrt(6 / (np.pi * 40))
    assert np.allclose(np.abs(normals[:, 2]), 1.0)
    assert local_surface(P[:2])[0] == 0.0
    pts, res = _hand_result()
    data = _payload(pts, res, 100_000, np.zeros((len(res.segments), 3), np.uint8))
    assert data["spacing"] > 0
    nrm = np.frombuffer(base64.b64decode(data["normals"]), dtype=np.int8).reshape(3, -1).T
    assert nrm.shape == (data["n_drawn"], 3)
    assert np.all(np.abs(np.linalg.norm(nrm / 127.0, axis=1) - 1.0) < 0.02)
