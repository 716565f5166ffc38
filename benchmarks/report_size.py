#!/usr/bin/env python3
"""Size of the HTML report for a 50,000-point cloud, and its load time in headless Chromium.

Builds a synthetic part (``houghcad.synth.plate_with_holes``) and a result from its
ground truth (or, with ``--pipeline``, from ``houghcad.segment``), writes the report,
then opens it ``--trials`` times, each in a fresh headless Chromium (new profile, no
caches: a cold open), and prints

- the report's size;
- the time to write it;
- per trial, the time from navigation start to the finished plot (the page stamps
  ``performance.now()`` on ``<body data-render-ms>`` once the first frame is drawn)
  and the wall time of the whole load seen by the driver;
- the machine's load average, as the figures depend on a free CPU.

Needs /usr/bin/chromium, /usr/bin/chromedriver (Debian packages chromium and
chromium-driver) and selenium (``pip install '.[test]'``).  Example::

    python3 benchmarks/report_size.py --points 50000 --trials 5
"""

from __future__ import annotations

import argparse
import os
import platform
import shutil
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

CHROMIUM, CHROMEDRIVER = "/usr/bin/chromium", "/usr/bin/chromedriver"


def build_result(n_points: int, pipeline: bool, seed: int):
    """(points (N, 3), Result) of a plate with a circle of holes, N = n_points."""
    from houghcad.result import Group, Result, Segment
    from houghcad.synth import plate_with_holes

    cloud = plate_with_holes(seed=seed, n_points=n_points, n_holes=8)
    if pipeline:
        from houghcad import segment

        return cloud.points, segment(cloud.points, cloud.normals, source=cloud.name)
    segs = [Segment(k, prim["type"], idx, prim["params"], 0.0)
            for k, (prim, idx) in enumerate(zip(cloud.primitives, cloud.segments()))]
    holes = [s.id for s in segs if s.type == "cylinder"]
    groups = [Group("rotation", holes, {"radius": segs[holes[0]].params.get("radius", 0.0)})] if holes else []
    return cloud.points, Result(n_points=len(cloud.points), segments=segs,
                                unsegmented=np.flatnonzero(cloud.labels < 0).astype(np.int64),
                                timing={"total": 0.0}, source=f"{cloud.name} (ground truth)", groups=groups)


def open_once(path: Path, timeout: float) -> tuple[float, float]:
    """(in-page ms to the finished plot, wall seconds of the load) in a fresh headless Chromium."""
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import WebDriverWait

    profile = tempfile.mkdtemp(prefix="houghcad-bench-")
    opts = webdriver.ChromeOptions()
    opts.binary_location = CHROMIUM
    for arg in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                "--disable-background-networking", "--disable-component-update", "--disable-sync",
                "--disable-extensions", "--window-size=1400,1000", f"--user-data-dir={profile}"):
        opts.add_argument(arg)
    driver = webdriver.Chrome(service=Service(CHROMEDRIVER), options=opts)
    try:
        driver.get("about:blank")  # browser and GPU process up before the clock starts
        t = time.perf_counter()
        driver.get(path.resolve().as_uri())
        WebDriverWait(driver, timeout, poll_frequency=0.02).until(
            lambda d: d.find_element(By.TAG_NAME, "body").get_attribute("data-rendered") == "1")
        wall = time.perf_counter() - t
        ms = float(driver.find_element(By.TAG_NAME, "body").get_attribute("data-render-ms"))
        return ms, wall
    finally:
        driver.quit()
        shutil.rmtree(profile, ignore_errors=True)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--points", type=int, default=50_000, help="cloud size (default 50000)")
    ap.add_argument("--trials", type=int, default=3, help="cold opens in Chromium (default 3)")
    ap.add_argument("--pipeline", action="store_true", help="segment with houghcad instead of using the ground truth")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--keep", metavar="OUT.html", help="keep the report here")
    args = ap.parse_args(argv)

    from houghcad.htmlreport import write_html_report

    points, result = build_result(args.points, args.pipeline, args.seed)
    out_dir = Path(tempfile.mkdtemp(prefix="houghcad-report-"))
    path = Path(args.keep) if args.keep else out_dir / "report.html"
    t = time.perf_counter()
    write_html_report(path, points, result)
    write_s = time.perf_counter() - t
    size = path.stat().st_size

    print(f"machine: {platform.platform()}, {os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.2f}")
    print(f"cloud: {result.n_points} points, {len(result.segments)} segments, {len(result.groups)} groups")
    print(f"report: {size / 1e6:.2f} MB ({size / result.n_points:.1f} bytes per point), written in {write_s:.2f} s")
    if not (os.access(CHROMIUM, os.X_OK) and os.access(CHROMEDRIVER, os.X_OK)):
        print(f"load time: skipped ({CHROMIUM} or {CHROMEDRIVER} missing)")
        return 0
    renders, walls = [], []
    for i in range(args.trials):
        ms, wall = open_once(path, timeout=60.0)
        renders.append(ms / 1000.0)
        walls.append(wall)
        print(f"  open {i + 1}: plot ready {ms / 1000:.2f} s after navigation start, load seen by the driver {wall:.2f} s")
    print(f"load time (cold headless Chromium, software WebGL): median {statistics.median(renders):.2f} s "
          f"to the finished plot (max {max(renders):.2f} s), median {statistics.median(walls):.2f} s wall")
    print(f"load average after: {os.getloadavg()[0]:.2f}")
    if not args.keep:
        shutil.rmtree(out_dir, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
