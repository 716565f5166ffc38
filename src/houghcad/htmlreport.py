"""A self-contained HTML report of a segmentation: interactive 3-D view, tables, timings.

The report is ONE file that opens offline: the data and a small WebGL point
viewer (plain JavaScript, about 10 kB, written for this report; its source is the
package data file ``data/report/viewer.js``, its style ``data/report/report.css``)
are embedded, and a Content-Security-Policy (``default-src 'none'``) forbids the
page any network request (no CDN, no font, no script or image from elsewhere).

Why not plotly.js: its bundle is 4.8 MB and its 3-D scene compiles dozens of
shaders and vectorises its tick labels before the first frame; in headless
Chromium with software WebGL that took 2-4 s on an idle 2-core machine and
8 s on a busy one, over the 3 s budget.  This viewer compiles one shader and
draws each segment with one ``drawArrays`` call.

Size: each drawn point takes 16 bytes (three float32 coordinates, base64), so
a 50,000-point cloud makes a report of about 0.85 MB.  Clouds larger than
:data:`MAX_REPORT_POINTS` are subsampled deterministically for the 3-D view
(the tables always describe the whole result).

Layout of the embedded data (``<script type="application/json" id="houghcad-data">``):
the drawn points are sorted by segment (unsegmented last) so that each segment
is one contiguous range; ``xyz`` holds the x, then y, then z offsets from
``centre`` as little-endian float32, base64-encoded; ``traces`` lists the
ranges in order with their colours per colouring mode.  The view frames the
first ``framed`` points, the part (:func:`houghcad.render.framed_points`), with
``centre`` and ``radius`` from their bounding box: stray unsegmented points far
from the part come last and may lie outside the view.
"""

from __future__ import annotations

import base64
import functools
import html
import importlib.resources
import json
import math
import os
from typing import Any

import numpy as np

from .palette import (UNSEGMENTED_COLOR, group_color, hex_color, segment_colors, segment_edges, type_color,
                      types_present)
from .render import AMBIENT, LIGHT, draw_sample, framed_points, local_surface
from .report import group_sentence
from .result import GROUP_KINDS, Result

__all__ = ["write_html_report", "build_html_report", "MAX_REPORT_POINTS"]

#: Points drawn in the 3-D view at most (about 3.2 MB of data).
MAX_REPORT_POINTS = 200_000

# No request can leave the page: script and styles are inline, images only data:
# (the viewer's "save PNG" link).
_CSP = ("default-src 'none'; script-src 'unsafe-inline'; style-src 'unsafe-inline'; img-src data:; "
        "connect-src 'none'; font-src 'none'; form-action 'none'; base-uri 'none'")


#: A value within this share of its scale (the part's diagonal, or a vector's largest
#: component) is shown as 0: a plane's normal (8.4e-19, -6.5e-19, 1) is rounding, not a tilt.
ROUNDING_SHARE = 1e-9


def _fmt_num(x: Any, scale: float = 0.0, zero: float | None = None) -> str:
    """A parameter value for the tables, vectors in parentheses: enough significant digits to
    show it to 1e-5 of ``scale`` (the part's diagonal), at least 5; values within
    :data:`ROUNDING_SHARE` of ``scale`` (or of a vector's largest component) read 0."""
    zero = ROUNDING_SHARE * scale if zero is None else zero
    if isinstance(x, (list, tuple, np.ndarray)):
        flat = [abs(float(v)) for v in x if isinstance(v, (int, float, np.integer, np.floating))
                and not isinstance(v, (bool, np.bool_)) and math.isfinite(v)]
        return "(" + ", ".join(_fmt_num(v, scale, max([zero] + [ROUNDING_SHARE * v for v in flat])) for v in x) + ")"
    if isinstance(x, (bool, np.bool_)):
        return str(bool(x))
    if isinstance(x, (int, np.integer)):
        return str(int(x))
    if isinstance(x, (float, np.floating)):
        if not math.isfinite(x):
            return str(float(x))
        if abs(float(x)) <= zero:
            return "0"
        return f"{float(x):.{_digits(float(x), scale)}g}"
    if isinstance(x, dict):
        return "{" + ", ".join(f"{k} {_fmt_num(v, scale)}" for k, v in x.items()) + "}"
    return str(x)


def _digits(x: float, scale: float) -> int:
    """Significant digits that show ``x`` to 1e-5 of ``scale`` (the part's diagonal), at least 5:
    a georeferenced axis point at y = 3999966.67 read 4e+06 at 5 digits, 33 units off."""
    if scale <= 0 or x == 0:
        return 5
    return int(min(15, max(5, math.ceil(math.log10(abs(x) / (1e-5 * scale))))))


def _fmt_params(params: dict[str, Any], scale: float = 0.0) -> str:
    """``name = value`` lines, HTML-escaped; ``scale`` as in :func:`_fmt_num`."""
    return "<br>".join(f"{html.escape(str(k))} = {html.escape(_fmt_num(v, scale))}" for k, v in params.items())


def _jsonable(x: Any) -> Any:
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple, np.ndarray)):
        return [_jsonable(v) for v in x]
    if isinstance(x, (np.integer, int)) and not isinstance(x, bool):
        return int(x)
    if isinstance(x, (np.floating, float)):
        return float(x) if math.isfinite(x) else None  # strict JSON for the browser
    return x


def _segment_groups(result: Result) -> tuple[np.ndarray, list[list[int]]]:
    """(colour group per segment as in :meth:`Result.group_labels`, -1 none; all group ids per segment)."""
    n = len(result.segments)
    gl = result.group_labels()
    colour_group = np.array([int(gl[s.indices[0]]) if len(s.indices) else -1 for s in result.segments],
                            dtype=np.int64).reshape(n)
    member_of: list[list[int]] = [[] for _ in range(n)]
    for g_id, g in enumerate(result.groups):
        for m in g.members:
            if 0 <= m < n:
                member_of[m].append(g_id)
    return colour_group, member_of


def _payload(points: np.ndarray, result: Result, max_points: int, seg_rgb: np.ndarray) -> dict[str, Any]:
    """The JSON object the page's script reads (see the module docstring)."""
    sel = draw_sample(len(points), max_points)
    lab = result.labels()[sel]
    # Framed on the part, as the PNG views: a few strays far off shrank it to a dot.
    keep = framed_points(points[sel], lab)
    n_seg = len(result.segments)
    key = np.where(lab < 0, n_seg, lab)  # unsegmented last, and the strays after the framed ones
    order = np.lexsort((~keep, key))
    P = points[sel][order]
    counts = np.bincount(key, minlength=n_seg + 1)
    lo, hi = points[sel][keep].min(axis=0), points[sel][keep].max(axis=0)
    centre = (lo + hi) / 2.0
    # float32 offsets from the centre keep ~7 significant digits of the extent even
    # when the coordinates carry a large common offset.
    planar = np.ascontiguousarray((P - centre).T, dtype="<f4")
    spacing, normals = local_surface(P - centre)
    colour_group, member_of = _segment_groups(result)
    traces = []
    for s in result.segments:
        traces.append({"id": s.id, "type": s.type, "n": int(len(s.indices)), "drawn": int(counts[s.id]),
                       "color_segment": hex_color(seg_rgb[s.id]), "color_type": hex_color(type_color(s.type)),
                       "color_group": hex_color(group_color(int(colour_group[s.id]))),
                       "groups": member_of[s.id]})
    traces.append({"id": -1, "type": "unsegmented", "n": int(len(result.unsegmented)), "drawn": int(counts[n_seg]),
                   "color_segment": hex_color(UNSEGMENTED_COLOR), "color_type": hex_color(UNSEGMENTED_COLOR),
                   "color_group": hex_color(UNSEGMENTED_COLOR), "groups": []})
    return {
        "n_points": int(result.n_points), "n_drawn": int(len(sel)), "framed": int(keep.sum()),
        "centre": [float(c) for c in centre],
        "xyz": base64.b64encode(planar.tobytes()).decode("ascii"),
        "traces": traces,
        "types": [{"name": t, "color": hex_color(type_color(t)),
                   "segments": [s.id for s in result.segments if s.type == t]} for t in types_present(result)],
        "groups": [{"id": g_id, "kind": g.kind, "members": [int(m) for m in g.members],
                    "color": hex_color(group_color(g_id))} for g_id, g in enumerate(result.groups)],
        "radius": float(max(np.linalg.norm(hi - lo) / 2.0, 1e-12)),
        # A drawn point's width in the cloud's units: neighbouring points then meet, and the
        # near side of the part hides the far one (at a fixed 3 pixels it showed through).
        "spacing": spacing,
        # Unoriented normals, int8 per component (planar, as xyz): the view shades each point
        # by its surface's turn from the light, so faces at different angles read apart.
        "normals": base64.b64encode(np.ascontiguousarray(
            np.rint(normals.T * 127.0), dtype=np.int8).tobytes()).decode("ascii"),
        "light": [float(c) for c in LIGHT], "ambient": AMBIENT,
    }


def _segments_table(result: Result, member_of: list[list[int]], seg_rgb: np.ndarray, scale: float) -> str:
    rows = []
    for s in result.segments:
        mfe = f"{s.mfe:.3e}" if math.isfinite(s.mfe) else "-"
        groups = ", ".join(str(g) for g in member_of[s.id]) or ""
        rows.append(
            f'<tr data-segment-id="{s.id}"><td class="num">{s.id}</td>'
            f'<td><span class="sw" style="background:{hex_color(seg_rgb[s.id])}"></span>{html.escape(s.type)}</td>'
            f'<td class="num">{len(s.indices)}</td><td class="num">{mfe}</td>'
            f'<td class="num">{len(s.parts) if s.parts else 1}</td>'
            f'<td class="params">{_fmt_params(s.params, scale)}</td>'
            f'<td class="params">{_fmt_params(s.descriptors, scale)}</td><td>{groups}</td></tr>')
    return ('<table id="segments"><thead><tr><th>id</th><th>type</th><th>points</th><th>MFE</th>'
            '<th>parts</th><th>parameters</th><th>descriptors</th><th>groups</th></tr></thead>'
            f'<tbody>{"".join(rows)}</tbody></table>')


def _groups_table(result: Result, scale: float) -> str:
    if not result.groups:
        return '<p id="no-groups">No groups: the association step found no relation between segments, or was off.</p>'
    order = sorted(range(len(result.groups)),
                   key=lambda i: (GROUP_KINDS.index(result.groups[i].kind)
                                  if result.groups[i].kind in GROUP_KINDS else len(GROUP_KINDS), i))
    rows = []
    for g_id in order:
        g = result.groups[g_id]
        rows.append(f'<tr data-group-id="{g_id}"><td class="num">{g_id}</td>'
                    f'<td><span class="sw" style="background:{hex_color(group_color(g_id))}"></span>'
                    f'{html.escape(g.kind)}</td><td>{", ".join(str(int(m)) for m in g.members)}</td>'
                    f'<td>{html.escape(group_sentence(g, result))}</td>'
                    f'<td class="params">{_fmt_params(g.descriptors, scale)}</td></tr>')
    return ('<table id="groups"><thead><tr><th>id</th><th>kind</th><th>members</th><th>what</th>'
            f'<th>shared descriptors</th></tr></thead><tbody>{"".join(rows)}</tbody></table>')


def _timing_table(result: Result) -> str:
    rows = "".join(f'<tr><td>{html.escape(str(k))}</td><td class="num">{float(v):.3f}</td></tr>'
                   for k, v in result.timing.items())
    return f'<table id="timing"><thead><tr><th>stage</th><th>seconds</th></tr></thead><tbody>{rows}</tbody></table>'


def _options_line(options: dict[str, Any]) -> str:
    """The options in one line: the tolerances that differ from their defaults, not all of them,
    and the derived scales."""
    from .tolerances import Tolerances

    shown = {k: v for k, v in options.items() if k not in ("tolerances", "derived", "input")}
    inp = options.get("input")
    if isinstance(inp, dict):  # the file's rows, not their ranges (a scan may list thousands)
        left = sum(int(b) - int(a) for a, b in inp.get("dropped_rows") or [])
        shown["input"] = f"{inp.get('rows')} rows" + (f" of scan {inp['scan']}" if inp.get("scan") is not None
                                                      else "") + (f", {left} left out" if left else "")
    if isinstance(options.get("tolerances"), dict):
        try:
            shown["tolerances"] = Tolerances.from_dict(options["tolerances"]).changed() or "defaults"
        except ValueError:  # a result from another version
            shown["tolerances"] = "(unreadable)"
    if isinstance(options.get("derived"), dict):
        shown.update({f"derived {k}": v for k, v in options["derived"].items()})
    return ", ".join(f"{k}={_fmt_num(v) if not isinstance(v, (dict, str)) else v}" for k, v in shown.items())


def _summary(result: Result, n_drawn: int) -> str:
    src = html.escape(str(result.source)) if result.source else "(no file)"
    share = 100.0 * len(result.unsegmented) / result.n_points if result.n_points else 0.0
    drawn = "" if n_drawn == result.n_points else f" ({n_drawn} drawn, a deterministic sample)"
    opts = html.escape(_options_line(result.options))
    return (f'<p id="summary">Source: <code>{src}</code><br>{result.n_points} points{drawn}, '
            f'<span id="n-segments">{len(result.segments)}</span> segments, {len(result.groups)} groups, '
            f'{len(result.unsegmented)} unsegmented points ({share:.1f}%).<br>Options: {opts}</p>')


# The viewer: one WebGL program, one buffer holding the planar float32 offsets
# (x block, y block, z block: three attributes on one buffer, no copy), one
# drawArrays per visible segment with its colour as a uniform.  Segment boxes
# decide visibility; a type or group box sets the boxes of its segments.
# Script and style are package data (data/report/) so that linters and editors
# see real JavaScript and CSS; they are pure: the page's data comes from the
# JSON block that build_html_report writes.
_VIEWER_JS = "viewer.js"
_REPORT_CSS = "report.css"


@functools.cache
def _asset(name: str) -> str:
    """The text of ``houghcad/data/report/<name>``, read once per process."""
    resource = importlib.resources.files("houghcad") / "data" / "report" / name
    # Text mode: a CRLF checkout still gives "\n" line ends, so the report's bytes do not depend on it.
    return resource.read_text(encoding="utf-8")


def build_html_report(points: np.ndarray, result: Result, *, title: str | None = None,
                      max_points: int = MAX_REPORT_POINTS) -> str:
    """The report's HTML text.

    Parameters
    ----------
    points : array_like, shape (N, 3)
        The cloud in world coordinates, ``N == result.n_points``.
    result : Result
    title : str, optional
        Page title (default: from the result's source).
    max_points : int
        Points drawn in the 3-D view at most (deterministic sample beyond).
    """
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape != (result.n_points, 3):
        raise ValueError(f"points must have shape ({result.n_points}, 3), got {pts.shape}")
    # Adjacent segments clearly apart in the "by segment" colours.
    seg_rgb = segment_colors([s.type for s in result.segments], segment_edges(result, pts),
                             np.array([len(s.indices) for s in result.segments]))
    data = _payload(pts, result, max_points, seg_rgb)
    _, member_of = _segment_groups(result)
    if title is None:
        title = f"houghcad: {os.path.basename(result.source)}" if result.source else "houghcad segmentation"
    # "</" cannot end the data's <script> element early once escaped.
    data_json = json.dumps(_jsonable(data), separators=(",", ":"), allow_nan=False).replace("</", "<\\/")
    esc_title = html.escape(title)
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8">
<meta http-equiv="Content-Security-Policy" content="{_CSP}">
<meta name="viewport" content="width=device-width, initial-scale=1">
<title>{esc_title}</title>
<style>
{_asset(_REPORT_CSS)}</style>
</head><body>
<header><h1>{esc_title}</h1>{_summary(result, data['n_drawn'])}</header>
<div id="main">
<div id="controls">
<fieldset><legend>Colour by</legend>
<label><input type="radio" name="colorby" value="segment" checked> segment</label>
<label><input type="radio" name="colorby" value="type"> type</label>
<label><input type="radio" name="colorby" value="group"> group</label></fieldset>
<fieldset id="types"><legend>Types</legend></fieldset>
<fieldset id="groupboxes"><legend>Groups</legend></fieldset>
<fieldset id="segboxes"><legend>Segments</legend><button id="all" type="button">all</button><button id="none" type="button">none</button><br></fieldset>
</div>
<div id="plot"><canvas id="view"></canvas><canvas id="triad" width="72" height="72"></canvas>
<div id="pick"></div>
<div id="toolbar"><button id="view-iso" type="button">iso</button><button id="view-top" type="button">top</button><button id="view-front" type="button">front</button><button id="view-side" type="button">side</button><button id="save" type="button">save PNG</button>
<label>point size <input id="size" type="range" min="0.25" max="3" step="0.25" value="1"></label></div>
<div id="help">drag: rotate, shift/right drag: pan, wheel: zoom, click: identify, double click: reset</div></div>
</div>
<section><h2>Segments</h2>{_segments_table(result, member_of, seg_rgb, 2.0 * data['radius'])}</section>
<section><h2>Groups</h2>{_groups_table(result, 2.0 * data['radius'])}</section>
<section><h2>Timing</h2>{_timing_table(result)}</section>
<script type="application/json" id="houghcad-data">{data_json}</script>
<script>
{_asset(_VIEWER_JS)}</script>
</body></html>
"""


def write_html_report(path: str | os.PathLike[str], points: np.ndarray, result: Result, *,
                      title: str | None = None, max_points: int = MAX_REPORT_POINTS) -> None:
    """Write :func:`build_html_report` to ``path`` (UTF-8), atomically; its directory must exist."""
    from .io.writers import atomic_write

    text = build_html_report(points, result, title=title, max_points=max_points)
    with atomic_write(path, "w") as f:
        f.write(text)
