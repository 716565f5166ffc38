"""Tests of houghcad.batchreport: summary.csv and index.html (no cluster needed)."""

from __future__ import annotations

import csv
import io
import os
from pathlib import Path

import pytest

from houghcad.batch import BatchRow
from houghcad.batchreport import index_html, read_summary, summary_csv, write_summary
from houghcad.errors import InputError

ROWS = [
    BatchRow("a/p1.txt", "ok", 1000, 5, 10, 1.25, None, DSC=0.9, PPV=1.0, TPR=0.8, TNR=1.0, NPV=0.9, ACC=0.95,
             outputs=("p1_segments.json", "p1_report.html")),
    BatchRow("a/p2.txt", "error", error="a/p2.txt: file is empty", DSC=0.0, PPV=0.0, TPR=0.0, TNR=0.0, NPV=0.0,
             ACC=0.0),
    BatchRow("b/x <&> y.ply", "skipped", 2000, 7, 0, 3.5, outputs=("x <&> y_segments.json",)),
    BatchRow("a/p3.txt", "ok", 500, 2, 1, 0.5, DSC=0.6, PPV=0.5, TPR=0.7, TNR=0.9, NPV=0.8, ACC=0.85),
]


def test_summary_csv_has_the_columns_and_closing_means_and_medians():
    text = summary_csv(ROWS)
    lines = text.splitlines()
    assert lines[0] == "input,status,n_points,n_segments,unsegmented,seconds,error,DSC,PPV,TPR,TNR,NPV,ACC"
    rows = list(csv.DictReader(io.StringIO(text)))
    assert [r["input"] for r in rows] == ["a/p1.txt", "a/p2.txt", "b/x <&> y.ply", "a/p3.txt",
                                          "# mean over 3 clouds", "# median over 3 clouds"]
    assert rows[1]["error"] == "a/p2.txt: file is empty" and rows[2]["DSC"] == "" and rows[0]["seconds"] == "1.25"
    assert float(rows[4]["DSC"]) == pytest.approx(0.5) and float(rows[5]["DSC"]) == pytest.approx(0.6)
    assert rows[4]["status"] == "" and rows[4]["n_points"] == ""
    assert "# mean" not in summary_csv([ROWS[2]])  # no ground truth: no closing lines


def test_the_closing_lines_say_how_many_clouds_they_cover():
    # A mean over fewer clouds than the batch scored would pass unnoticed: the line names its count.
    skipped = BatchRow("a/p4.txt", "skipped", 800, 3, 0, None, DSC=0.7, PPV=0.7, TPR=0.7, TNR=0.7, NPV=0.7, ACC=0.7)
    closing = [line.split(",")[0] for line in summary_csv([*ROWS, skipped]).splitlines() if line.startswith("#")]
    assert closing == ["# mean over 4 clouds", "# median over 4 clouds"]
    one = [line.split(",")[:8] for line in summary_csv([ROWS[2], skipped]).splitlines() if line.startswith("#")]
    assert one == [["# mean over 1 cloud", *[""] * 6, "0.7"], ["# median over 1 cloud", *[""] * 6, "0.7"]]
    page = index_html([*ROWS, skipped])
    assert ">mean over 4 clouds</td>" in page and ">median over 4 clouds</td>" in page


def test_write_and_read_back_keeps_ok_and_skipped_rows(tmp_path: Path):
    csv_path, html_path = write_summary(tmp_path, ROWS, ["report"])
    assert csv_path.name == "summary.csv" and html_path.name == "index.html"
    assert not [p for p in os.listdir(tmp_path) if p.endswith(".tmp")]
    back = read_summary(tmp_path)
    assert sorted(back) == ["a/p1.txt", "a/p3.txt", "b/x <&> y.ply"]
    assert back["a/p1.txt"].DSC == pytest.approx(0.9) and back["b/x <&> y.ply"].n_segments == 7
    assert read_summary(tmp_path / "missing") == {}
    with pytest.raises(InputError, match="cannot write"):
        write_summary(tmp_path / "no" / "such", ROWS)


def test_index_escapes_links_relative_and_shows_only_known_measures():
    page = index_html(ROWS, ["report"])
    assert "x &lt;&amp;&gt; y.ply" in page and "<&>" not in page.split("<script>")[0]
    assert 'href="p1_report.html"' in page and 'href="x%20%3C%26%3E%20y_segments.json"' in page
    assert page.count("<tr class=") == 4 and "4 clouds: 2 ok, 1 skipped, 1 error." in page
    assert "<th>DSC</th>" in page and 'data-v="0.9"' in page
    plain = index_html([ROWS[2]])
    assert "DSC" not in plain and "report" not in plain.split("<tbody>")[0].split("<table id")[1]


def test_clicking_a_header_sorts_the_rows_in_headless_chromium(tmp_path: Path):
    import shutil
    import tempfile

    for exe in ("/usr/bin/chromium", "/usr/bin/chromedriver"):
        if not os.access(exe, os.X_OK):
            pytest.skip(f"{exe} not installed (Debian packages chromium and chromium-driver; .ci/run installs them)")
    webdriver = pytest.importorskip("selenium.webdriver", reason="selenium not installed (pip install '.[test]')")
    from selenium.webdriver.chrome.service import Service
    from selenium.webdriver.common.by import By

    write_summary(tmp_path, ROWS, ["report"])
    profile = tempfile.mkdtemp(prefix="houghcad-chromium-")
    opts = webdriver.ChromeOptions()
    opts.binary_location = "/usr/bin/chromium"  # never let selenium look for (or download) a browser
    for arg in ("--headless=new", "--no-sandbox", "--disable-gpu", "--no-first-run", f"--user-data-dir={profile}",
                "--disable-background-networking", "--disable-component-update", "--disable-extensions"):
        opts.add_argument(arg)
    driver = webdriver.Chrome(service=Service("/usr/bin/chromedriver"), options=opts)
    try:
        driver.get((tmp_path / "index.html").as_uri())
        first_column = lambda: [td.text for td in driver.find_elements(By.CSS_SELECTOR, "#rows tbody td:first-child")]
        header = {th.text: th for th in driver.find_elements(By.CSS_SELECTOR, "#rows th")}
        header["DSC"].click()  # ascending, blanks last
        assert first_column() == ["a/p2.txt", "a/p3.txt", "a/p1.txt", "b/x <&> y.ply"]
        header["DSC"].click()  # descending
        assert first_column()[:3] == ["a/p1.txt", "a/p3.txt", "a/p2.txt"]
        header["n_points"].click()  # numbers as numbers: 500 before 1000
        assert first_column()[:3] == ["a/p3.txt", "a/p1.txt", "b/x <&> y.ply"]
        assert driver.get_log("browser") == []  # no script error
    finally:
        driver.quit()
        shutil.rmtree(profile, ignore_errors=True)
