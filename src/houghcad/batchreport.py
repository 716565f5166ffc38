"""The batch's summary: ``summary.csv`` and a self-contained ``index.html`` (both written atomically).

``summary.csv`` has one row per input with the columns :data:`COLUMNS`, in the inputs' order;
when some clouds have a Fit4CAD ground truth, two closing lines ``# mean over N clouds`` and
``# median over N clouds`` give the measures' means and medians over those N clouds (``error``
rows count 0; ``skipped`` rows are scored from their saved results), so
``pandas.read_csv(path, comment="#")`` reads the clouds alone. ``index.html`` shows the same rows
in a table sorted by clicking a column's header (a few lines of inline JavaScript, no network),
each row linking to its files in the same folder.
"""

from __future__ import annotations

import csv
import html
import io
import math
import os
import statistics
from collections.abc import Sequence
from pathlib import Path
from urllib.parse import quote

from .batch import MEASURES, OUTPUT_NAMES, SUMMARY_NAME, BatchRow
from .errors import InputError
from .io import atomic_write

__all__ = ["COLUMNS", "make_out_dir", "read_summary", "write_summary", "summary_csv", "index_html"]

COLUMNS = ("input", "status", "n_points", "n_segments", "unsegmented", "seconds", "error", *MEASURES)
SUMMARY = SUMMARY_NAME
INDEX = "index.html"
_INTS = ("n_points", "n_segments", "unsegmented")
_FLOATS = ("seconds", *MEASURES)
#: Link labels of a row's files in index.html, in column order.
_LINKS = {"report": "report", "png": "picture", "json": "JSON", "ply": "PLY", "fit4cad": "Fit4CAD"}


def make_out_dir(out: Path) -> None:
    """Create the output folder; a path that is not a usable folder is an InputError."""
    if out.exists() and not out.is_dir():
        raise InputError(f"{out}: cannot write outputs (not a folder)")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"{out}: cannot create the output folder ({exc.strerror or exc})") from None
    if not os.access(out, os.W_OK | os.X_OK):
        raise InputError(f"{out}: cannot write outputs (permission denied)")


# --------------------------------------------------------------------------- summary.csv


def _cell(value: object) -> str:
    if value is None:
        return ""
    if isinstance(value, float):
        return f"{value:.6g}" if math.isfinite(value) else ""
    return str(value)


def _stats(rows: Sequence[BatchRow]) -> dict[str, dict[str, float]]:
    """``{"mean over N clouds": {...}, "median over N clouds": {...}}``: each measure over the N
    rows that have measures ({} for both when none has)."""
    scored = [r for r in rows if r.measures()]
    over = f"over {len(scored)} cloud{'s' if len(scored) != 1 else ''}"
    out: dict[str, dict[str, float]] = {f"mean {over}": {}, f"median {over}": {}}
    mean, median = out.values()
    for m in MEASURES:
        values = [getattr(r, m) for r in scored if getattr(r, m) is not None]
        if values:
            mean[m] = statistics.fmean(values)
            median[m] = statistics.median(values)
    return out


def summary_csv(rows: Sequence[BatchRow]) -> str:
    """The text of ``summary.csv``."""
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(COLUMNS)
    for r in rows:
        writer.writerow([_cell(getattr(r, c)) for c in COLUMNS])
    for name, values in _stats(rows).items():
        if values:
            writer.writerow([f"# {name}"] + [_cell(values.get(c)) for c in COLUMNS[1:]])
    return buf.getvalue()


def read_summary(out: Path) -> dict[str, BatchRow]:
    """The ``ok`` and ``skipped`` rows of an earlier ``out/summary.csv`` by input ({} if none):
    a re-run's skipped rows keep their figures."""
    try:
        with open(out / SUMMARY, newline="", encoding="utf-8") as fh:
            records = list(csv.DictReader(fh))
    except (OSError, UnicodeDecodeError, csv.Error):
        return {}
    rows = {}
    for rec in records:
        if rec.get("status") not in ("ok", "skipped") or (rec.get("input") or "").startswith("#"):
            continue
        try:
            values = {c: int(rec[c]) if rec.get(c) else None for c in _INTS}
            values |= {c: float(rec[c]) if rec.get(c) else None for c in _FLOATS}
        except ValueError:
            continue  # a hand-edited line: run that cloud's figures anew next time
        rows[rec["input"]] = BatchRow(rec["input"], rec["status"], **values)
    return rows


# --------------------------------------------------------------------------- index.html


_PAGE = """<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>houghcad batch</title>
<style>
body {{ font: 14px system-ui, sans-serif; margin: 1.5em; }}
table {{ border-collapse: collapse; }}
th, td {{ padding: .25em .6em; border-bottom: 1px solid #ddd; text-align: right; }}
th {{ cursor: pointer; background: #f3f3f3; position: sticky; top: 0; user-select: none; }}
td.t, th.t {{ text-align: left; }}
tr.error td {{ background: #fdecea; }} tr.skipped td {{ color: #666; }}
th[aria-sort=ascending]::after {{ content: " \\25B2"; }} th[aria-sort=descending]::after {{ content: " \\25BC"; }}
</style></head><body>
<h1>houghcad batch</h1>
<p>{counts}</p>
{stats}
<table id="rows"><thead><tr>{head}</tr></thead><tbody>
{body}
</tbody></table>
<script>
// Click a header to sort by it; click again to reverse. Numbers sort as numbers, blanks last.
document.querySelectorAll("#rows th").forEach((th, col) => th.addEventListener("click", () => {{
  const body = document.querySelector("#rows tbody");
  const up = th.getAttribute("aria-sort") !== "ascending";
  document.querySelectorAll("#rows th").forEach(h => h.removeAttribute("aria-sort"));
  th.setAttribute("aria-sort", up ? "ascending" : "descending");
  const key = tr => tr.children[col].dataset.v ?? tr.children[col].textContent;
  const rows = [...body.rows].sort((a, b) => {{
    const x = key(a), y = key(b);
    if (x === "" || y === "") return (x === "") - (y === "");
    const nx = Number(x), ny = Number(y);
    const c = isNaN(nx) || isNaN(ny) ? x.localeCompare(y, undefined, {{numeric: true}}) : nx - ny;
    return up ? c : -c;
  }});
  rows.forEach(r => body.appendChild(r));
}}));
</script>
</body></html>
"""


def _td(value: object, text: bool = False) -> str:
    shown = _cell(value)
    if isinstance(value, float) and shown:
        shown = f"{value:.3f}" if abs(value) < 1000 else f"{value:.0f}"
    cls = ' class="t"' if text else ""
    sort = f' data-v="{html.escape(_cell(value))}"' if not text else ""
    return f"<td{cls}{sort}>{html.escape(shown)}</td>"


def _links(row: BatchRow, kinds: Sequence[str]) -> str:
    names = set(row.outputs)
    cells = []
    for kind in kinds:
        name = next((n for n in names if n.endswith(OUTPUT_NAMES[kind])), None)
        link = f'<a href="{html.escape(quote(name))}">{_LINKS[kind]}</a>' if name else ""
        cells.append(f'<td class="t">{link}</td>')
    return "".join(cells)


def index_html(rows: Sequence[BatchRow], outputs: Sequence[str] = ()) -> str:
    """The text of ``index.html``: counts, the measures' means and medians, the sortable table."""
    kinds = [k for k in _LINKS if k == "json" or k in outputs]
    shown = [c for c in COLUMNS if c not in MEASURES or any(getattr(r, c) is not None for r in rows)]
    head = "".join(f'<th class="t">{c}</th>' if c in ("input", "status", "error") else f"<th>{c}</th>"
                   for c in shown) + "".join(f'<th class="t">{_LINKS[k]}</th>' for k in kinds)
    body = "\n".join(
        f'<tr class="{html.escape(r.status)}">'
        + "".join(_td(getattr(r, c), text=c in ("input", "status", "error")) for c in shown)
        + _links(r, kinds) + "</tr>" for r in rows)
    counts = ", ".join(f"{sum(r.status == s for r in rows)} {s}" for s in ("ok", "skipped", "error"))
    stats = _stats(rows)
    table = ""
    means = next(iter(stats.values()))
    if means:
        names = list(means)
        table = ("<table><tr><th></th>" + "".join(f"<th>{m}</th>" for m in names) + "</tr>"
                 + "".join(f'<tr><td class="t">{k}</td>' + "".join(f"<td>{v[m]:.3f}</td>" for m in names) + "</tr>"
                           for k, v in stats.items()) + "</table>\n<p></p>")
    return _PAGE.format(counts=f"{len(rows)} clouds: {counts}.", stats=table, head=head, body=body)


def write_summary(out: Path, rows: Sequence[BatchRow], outputs: Sequence[str] = ()) -> tuple[Path, Path]:
    """Write ``out/summary.csv`` and ``out/index.html`` (atomically); returns their paths."""
    written = []
    for name, text in ((SUMMARY, summary_csv(rows)), (INDEX, index_html(rows, outputs))):
        try:
            with atomic_write(out / name) as fh:
                fh.write(text)
        except OSError as exc:
            raise InputError(f"{out / name}: cannot write output ({exc.strerror or exc})") from None
        written.append(out / name)
    return written[0], written[1]
