"""A self-contained HTML report of a segmentation: interactive 3-D view, tables, timings.

The report is ONE file that opens offline: plotly.js is inlined from the
``plotly`` package's bundled ``plotly.min.js``, the data are embedded, and a
Content-Security-Policy (``default-src 'none'``) forbids the page any network
request (no CDN, no font, no MathJax, no map tiles).

Size: plotly.js is about 4.8 MB; each drawn point adds 16 bytes (three
float32 coordinates, base64).  Clouds larger than :data:`MAX_REPORT_POINTS`
are subsampled deterministically for the 3-D view (the tables always describe
the whole result).

Layout of the embedded data (``<script type="application/json" id="houghcad-data">``):
the drawn points are sorted by segment (unsegmented last) so that each plotly
trace is one contiguous slice; ``xyz`` holds the x, then y, then z offsets
from ``centre`` as little-endian float32, base64-encoded.
"""

from __future__ import annotations

import base64
import functools
import html
import json
import math
import os
from pathlib import Path
from typing import Any

import numpy as np

from .palette import (UNSEGMENTED_COLOR, group_color, hex_color, segment_colors, type_color,
                      types_present)
from .render import draw_sample
from .result import GROUP_KINDS, Result

__all__ = ["write_html_report", "build_html_report", "plotly_js", "MAX_REPORT_POINTS"]

#: Points drawn in the 3-D view at most (about 3.2 MB of data on top of plotly.js).
MAX_REPORT_POINTS = 200_000

# No request can leave the page: scripts and styles are inline, images only data:/blob:
# (plotly's "download PNG" button).  'unsafe-eval': plotly's WebGL code generates functions.
_CSP = ("default-src 'none'; script-src 'unsafe-inline' 'unsafe-eval'; style-src 'unsafe-inline'; "
        "img-src data: blob:; worker-src blob:; connect-src 'none'; font-src 'none'; "
        "form-action 'none'; base-uri 'none'")

# Nothing that plotly could fetch: no MathJax typesetting, no Chart Studio links, no maps.
_PLOTLY_CONFIG = {"displaylogo": False, "showLink": False, "showSendToCloud": False,
                  "showEditInChartStudio": False, "typesetMath": False, "responsive": True,
                  "topojsonURL": "", "plotlyServerURL": "", "scrollZoom": True}


@functools.lru_cache(maxsize=1)
def plotly_js() -> str:
    """The text of plotly.min.js shipped inside the ``plotly`` PyPI package (no network).

    Raises
    ------
    RuntimeError
        The installed ``plotly`` package lacks the file (a broken install).
    """
    import plotly

    path = Path(plotly.__file__).parent / "package_data" / "plotly.min.js"
    try:
        return path.read_text(encoding="utf-8")
    except OSError as exc:  # not the output's fault: say what is missing
        raise RuntimeError(f"{path}: cannot read plotly.js ({exc.strerror or exc}); reinstall plotly") from None


def _fmt_num(x: Any) -> str:
    """A parameter value for the tables: 5 significant digits, vectors in parentheses."""
    if isinstance(x, (list, tuple, np.ndarray)):
        return "(" + ", ".join(_fmt_num(v) for v in x) + ")"
    if isinstance(x, (bool, np.bool_)):
        return str(bool(x))
    if isinstance(x, (int, np.integer)):
        return str(int(x))
    if isinstance(x, (float, np.floating)):
        return f"{float(x):.5g}" if math.isfinite(x) else str(float(x))
    if isinstance(x, dict):
        return ", ".join(f"{k} {_fmt_num(v)}" for k, v in x.items())
    return str(x)


def _fmt_params(params: dict[str, Any]) -> str:
    """``name = value`` lines, HTML-escaped."""
    return "<br>".join(f"{html.escape(str(k))} = {html.escape(_fmt_num(v))}" for k, v in params.items())


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


def _payload(points: np.ndarray, result: Result, max_points: int) -> dict[str, Any]:
    """The JSON object the page's script reads (see the module docstring)."""
    sel = draw_sample(len(points), max_points)
    lab = result.labels()[sel]
    n_seg = len(result.segments)
    key = np.where(lab < 0, n_seg, lab)  # unsegmented last
    order = np.argsort(key, kind="stable")
    P = points[sel][order]
    counts = np.bincount(key, minlength=n_seg + 1)
    lo, hi = points.min(axis=0), points.max(axis=0)
    centre = (lo + hi) / 2.0
    # float32 offsets from the centre keep ~7 significant digits of the extent even
    # when the coordinates carry a large common offset.
    planar = np.ascontiguousarray((P - centre).T, dtype="<f4")
    colour_group, member_of = _segment_groups(result)
    seg_rgb = segment_colors([s.type for s in result.segments])
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
        "n_points": int(result.n_points), "n_drawn": int(len(sel)),
        "centre": [float(c) for c in centre],
        "xyz": base64.b64encode(planar.tobytes()).decode("ascii"),
        "traces": traces,
        "types": [{"name": t, "color": hex_color(type_color(t)),
                   "segments": [s.id for s in result.segments if s.type == t]} for t in types_present(result)],
        "groups": [{"id": g_id, "kind": g.kind, "members": [int(m) for m in g.members],
                    "color": hex_color(group_color(g_id))} for g_id, g in enumerate(result.groups)],
        "config": _PLOTLY_CONFIG,
    }


def _segments_table(result: Result, member_of: list[list[int]]) -> str:
    seg_rgb = segment_colors([s.type for s in result.segments])
    rows = []
    for s in result.segments:
        mfe = f"{s.mfe:.3e}" if math.isfinite(s.mfe) else "-"
        groups = ", ".join(str(g) for g in member_of[s.id]) or ""
        rows.append(
            f'<tr data-segment-id="{s.id}"><td class="num">{s.id}</td>'
            f'<td><span class="sw" style="background:{hex_color(seg_rgb[s.id])}"></span>{html.escape(s.type)}</td>'
            f'<td class="num">{len(s.indices)}</td><td class="num">{mfe}</td>'
            f'<td class="num">{len(s.parts) if s.parts else 1}</td>'
            f'<td class="params">{_fmt_params(s.params)}</td>'
            f'<td class="params">{_fmt_params(s.descriptors)}</td><td>{groups}</td></tr>')
    return ('<table id="segments"><thead><tr><th>id</th><th>type</th><th>points</th><th>MFE</th>'
            '<th>parts</th><th>parameters</th><th>descriptors</th><th>groups</th></tr></thead>'
            f'<tbody>{"".join(rows)}</tbody></table>')


def _groups_table(result: Result) -> str:
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
                    f'<td class="params">{_fmt_params(g.descriptors)}</td></tr>')
    return ('<table id="groups"><thead><tr><th>id</th><th>kind</th><th>members</th><th>shared descriptors</th>'
            f'</tr></thead><tbody>{"".join(rows)}</tbody></table>')


def _timing_table(result: Result) -> str:
    rows = "".join(f'<tr><td>{html.escape(str(k))}</td><td class="num">{float(v):.3f}</td></tr>'
                   for k, v in result.timing.items())
    return f'<table id="timing"><thead><tr><th>stage</th><th>seconds</th></tr></thead><tbody>{rows}</tbody></table>'


def _summary(result: Result, n_drawn: int) -> str:
    src = html.escape(str(result.source)) if result.source else "(no file)"
    share = 100.0 * len(result.unsegmented) / result.n_points if result.n_points else 0.0
    drawn = "" if n_drawn == result.n_points else f" ({n_drawn} drawn, a deterministic sample)"
    opts = html.escape(", ".join(f"{k}={_fmt_num(v)}" for k, v in result.options.items()))
    return (f'<p id="summary">Source: <code>{src}</code><br>{result.n_points} points{drawn}, '
            f'<span id="n-segments">{len(result.segments)}</span> segments, {len(result.groups)} groups, '
            f'{len(result.unsegmented)} unsegmented points ({share:.1f}%).<br>Options: {opts}</p>')


_STYLE = """
body{font-family:system-ui,-apple-system,"Segoe UI",Roboto,sans-serif;margin:0;color:#222;font-size:14px}
header{padding:8px 16px;background:#f4f4f4;border-bottom:1px solid #ddd}
h1{font-size:18px;margin:4px 0} h2{font-size:16px;margin:18px 0 6px}
#main{display:flex;height:72vh;min-height:420px}
#controls{width:270px;overflow-y:auto;padding:8px 12px;border-right:1px solid #ddd;font-size:13px}
#controls fieldset{border:1px solid #ddd;margin:0 0 8px;padding:4px 8px}
#controls label{display:block;white-space:nowrap;overflow:hidden;text-overflow:ellipsis}
#plot{flex:1;min-width:0}
.sw{display:inline-block;width:11px;height:11px;margin:0 5px 0 2px;border:1px solid #888;vertical-align:-1px}
section{padding:0 16px 12px}
table{border-collapse:collapse;font-size:13px} th,td{border:1px solid #ccc;padding:3px 6px;vertical-align:top}
th{background:#f0f0f0} td.num{text-align:right;font-variant-numeric:tabular-nums}
td.params{font-family:ui-monospace,Menlo,Consolas,monospace;font-size:12px}
button{font-size:12px;margin:0 4px 4px 0}
"""

# Reads the embedded data, builds one scatter3d trace per segment (unsegmented last)
# and wires the checkboxes: segment boxes decide visibility; a type or group box
# sets the boxes of its segments.
_SCRIPT = r"""
(function () {
  "use strict";
  var D = JSON.parse(document.getElementById("houghcad-data").textContent);
  var raw = atob(D.xyz), bytes = new Uint8Array(raw.length);
  for (var i = 0; i < raw.length; i++) bytes[i] = raw.charCodeAt(i);
  var off = new Float32Array(bytes.buffer), n = D.n_drawn;
  var traces = [], start = 0;
  D.traces.forEach(function (t) {
    var cols = [0, 1, 2].map(function (a) {
      var c = new Float64Array(t.drawn), base = a * n + start, o = D.centre[a];
      for (var k = 0; k < t.drawn; k++) c[k] = o + off[base + k];
      return c;
    });
    start += t.drawn;
    var name = t.id < 0 ? "unsegmented" : "segment " + t.id + " (" + t.type + ")";
    traces.push({type: "scatter3d", mode: "markers", name: name, x: cols[0], y: cols[1], z: cols[2],
      marker: {size: 2, color: t.color_segment, line: {width: 0}}, showlegend: false,
      hovertemplate: name + "<br>x %{x:.5g}<br>y %{y:.5g}<br>z %{z:.5g}<extra></extra>"});
  });
  var layout = {margin: {l: 0, r: 0, t: 0, b: 0}, paper_bgcolor: "#ffffff",
    font: {family: "system-ui, sans-serif"},
    scene: {aspectmode: "data", xaxis: {title: {text: "x"}}, yaxis: {title: {text: "y"}},
            zaxis: {title: {text: "z"}}}};
  var gd = document.getElementById("plot");
  var segBoxes = {};
  function box(id) { return segBoxes[id]; }
  function updateVisibility() {
    var vis = D.traces.map(function (t) { return box(t.id).checked; });
    Plotly.restyle(gd, {visible: vis}, D.traces.map(function (_, i) { return i; }));
    syncSets("type", D.types, "segments");
    syncSets("group", D.groups, "members");
  }
  function syncSets(prefix, sets, key) {
    sets.forEach(function (s, i) {
      var el = document.getElementById(prefix + "-" + i), on = 0;
      s[key].forEach(function (m) { if (box(m) && box(m).checked) on++; });
      el.checked = on > 0; el.indeterminate = on > 0 && on < s[key].length;
    });
  }
  function addBox(parent, id, color, text, handler) {
    var label = document.createElement("label"), cb = document.createElement("input");
    cb.type = "checkbox"; cb.checked = true; cb.id = id; cb.addEventListener("change", handler);
    var sw = document.createElement("span"); sw.className = "sw"; sw.style.background = color;
    label.appendChild(cb); label.appendChild(sw); label.appendChild(document.createTextNode(text));
    parent.appendChild(label); return cb;
  }
  var fsType = document.getElementById("types"), fsGroup = document.getElementById("groupboxes"),
      fsSeg = document.getElementById("segboxes");
  D.types.forEach(function (t, i) {
    addBox(fsType, "type-" + i, t.color, t.name + " (" + t.segments.length + ")", function (e) {
      t.segments.forEach(function (m) { box(m).checked = e.target.checked; }); updateVisibility(); });
  });
  if (!D.groups.length) fsGroup.appendChild(document.createTextNode("none"));
  D.groups.forEach(function (g, i) {
    addBox(fsGroup, "group-" + i, g.color, g.id + ": " + g.kind + " [" + g.members.join(", ") + "]", function (e) {
      g.members.forEach(function (m) { if (box(m)) box(m).checked = e.target.checked; }); updateVisibility(); });
  });
  D.traces.forEach(function (t) {
    var text = t.id < 0 ? "unsegmented (" + t.n + ")" : t.id + ": " + t.type + " (" + t.n + ")";
    segBoxes[t.id] = addBox(fsSeg, "segment-" + t.id, t.color_segment, text, updateVisibility);
  });
  function setAll(on) { D.traces.forEach(function (t) { box(t.id).checked = on; }); updateVisibility(); }
  document.getElementById("all").addEventListener("click", function () { setAll(true); });
  document.getElementById("none").addEventListener("click", function () { setAll(false); });
  document.querySelectorAll("input[name=colorby]").forEach(function (r) {
    r.addEventListener("change", function () {
      var key = "color_" + r.value;
      Plotly.restyle(gd, {"marker.color": D.traces.map(function (t) { return t[key]; })},
                     D.traces.map(function (_, i) { return i; }));
    });
  });
  Plotly.newPlot(gd, traces, layout, D.config).then(function () {
    // For tests and scripted screenshots: rendered, and when (ms since navigation start).
    document.body.setAttribute("data-render-ms", String(Math.round(performance.now())));
    document.body.setAttribute("data-rendered", "1");
  });
})();
"""


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
    data = _payload(pts, result, max_points)
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
<style>{_STYLE}</style>
<script>{plotly_js()}</script>
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
<div id="plot"></div>
</div>
<section><h2>Segments</h2>{_segments_table(result, member_of)}</section>
<section><h2>Groups</h2>{_groups_table(result)}</section>
<section><h2>Timing</h2>{_timing_table(result)}</section>
<script type="application/json" id="houghcad-data">{data_json}</script>
<script>{_SCRIPT}</script>
</body></html>
"""


def write_html_report(path: str | os.PathLike[str], points: np.ndarray, result: Result, *,
                      title: str | None = None, max_points: int = MAX_REPORT_POINTS) -> None:
    """Write :func:`build_html_report` to ``path`` (UTF-8), atomically; its directory must exist."""
    from .io.writers import atomic_write

    text = build_html_report(points, result, title=title, max_points=max_points)
    with atomic_write(path, "w") as f:
        f.write(text)
