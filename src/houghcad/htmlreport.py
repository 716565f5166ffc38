"""A self-contained HTML report of a segmentation: interactive 3-D view, tables, timings.

The report is ONE file that opens offline: the data and a small WebGL point
viewer (plain JavaScript, about 10 kB, written for this report) are embedded,
and a Content-Security-Policy (``default-src 'none'``) forbids the page any
network request (no CDN, no font, no script or image from elsewhere).

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
ranges in order with their colours per colouring mode.
"""

from __future__ import annotations

import base64
import html
import json
import math
import os
from typing import Any

import numpy as np

from .palette import (UNSEGMENTED_COLOR, group_color, hex_color, segment_colors, type_color,
                      types_present)
from .render import draw_sample
from .result import GROUP_KINDS, Result

__all__ = ["write_html_report", "build_html_report", "MAX_REPORT_POINTS"]

#: Points drawn in the 3-D view at most (about 3.2 MB of data).
MAX_REPORT_POINTS = 200_000

# No request can leave the page: script and styles are inline, images only data:
# (the viewer's "save PNG" link).
_CSP = ("default-src 'none'; script-src 'unsafe-inline'; style-src 'unsafe-inline'; img-src data:; "
        "connect-src 'none'; font-src 'none'; form-action 'none'; base-uri 'none'")


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
        return "{" + ", ".join(f"{k} {_fmt_num(v)}" for k, v in x.items()) + "}"
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
        "radius": float(max(np.linalg.norm(hi - lo) / 2.0, 1e-12)),
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
#plot{flex:1;min-width:0;position:relative;background:#fff}
#view{width:100%;height:100%;display:block;cursor:grab;touch-action:none}
#triad{position:absolute;left:8px;bottom:8px;pointer-events:none}
#toolbar{position:absolute;right:8px;top:6px;font-size:12px}
#pick{position:absolute;left:8px;top:6px;font-size:12px;background:rgba(255,255,255,.85);padding:2px 6px;
  font-family:ui-monospace,Menlo,Consolas,monospace;white-space:pre}
#help{position:absolute;right:8px;bottom:6px;font-size:11px;color:#777}
.sw{display:inline-block;width:11px;height:11px;margin:0 5px 0 2px;border:1px solid #888;vertical-align:-1px}
section{padding:0 16px 12px}
table{border-collapse:collapse;font-size:13px} th,td{border:1px solid #ccc;padding:3px 6px;vertical-align:top}
th{background:#f0f0f0} td.num{text-align:right;font-variant-numeric:tabular-nums}
td.params{font-family:ui-monospace,Menlo,Consolas,monospace;font-size:12px}
button{font-size:12px;margin:0 4px 4px 0}
"""

# The viewer: one WebGL program, one buffer holding the planar float32 offsets
# (x block, y block, z block: three attributes on one buffer, no copy), one
# drawArrays per visible segment with its colour as a uniform.  Segment boxes
# decide visibility; a type or group box sets the boxes of its segments.
_SCRIPT = r"""
(function () {
  "use strict";
  var D = JSON.parse(document.getElementById("houghcad-data").textContent);
  var raw = atob(D.xyz), bytes = new Uint8Array(raw.length);
  for (var i = 0; i < raw.length; i++) bytes[i] = raw.charCodeAt(i);
  var xyz = new Float32Array(bytes.buffer), n = D.n_drawn;  // little-endian, as every browser platform
  var start = 0;
  D.traces.forEach(function (t) { t.start = start; start += t.drawn; t.visible = true; });
  var mode = "segment";

  // ---------------------------------------------------------------- WebGL
  var canvas = document.getElementById("view");
  var gl = canvas.getContext("webgl", {preserveDrawingBuffer: true, antialias: true});
  if (!gl) {
    document.getElementById("pick").textContent = "WebGL is not available: the tables below hold the result.";
    document.body.setAttribute("data-rendered", "0");
    return;
  }
  function shader(type, src) {
    var s = gl.createShader(type); gl.shaderSource(s, src); gl.compileShader(s); return s;
  }
  var prog = gl.createProgram();
  gl.attachShader(prog, shader(gl.VERTEX_SHADER,
    "attribute float ax; attribute float ay; attribute float az; uniform mat4 mvp; uniform float size;" +
    "void main() { gl_Position = mvp * vec4(ax, ay, az, 1.0); gl_PointSize = size; }"));
  gl.attachShader(prog, shader(gl.FRAGMENT_SHADER,
    "precision mediump float; uniform vec3 color;" +
    "void main() { vec2 d = gl_PointCoord - 0.5; if (dot(d, d) > 0.25) discard; gl_FragColor = vec4(color, 1.0); }"));
  gl.linkProgram(prog);
  gl.useProgram(prog);
  var buf = gl.createBuffer();
  gl.bindBuffer(gl.ARRAY_BUFFER, buf);
  gl.bufferData(gl.ARRAY_BUFFER, xyz, gl.STATIC_DRAW);
  ["ax", "ay", "az"].forEach(function (name, a) {
    var loc = gl.getAttribLocation(prog, name);
    gl.enableVertexAttribArray(loc);
    gl.vertexAttribPointer(loc, 1, gl.FLOAT, false, 0, a * n * 4);
  });
  var uMvp = gl.getUniformLocation(prog, "mvp"), uSize = gl.getUniformLocation(prog, "size"),
      uColor = gl.getUniformLocation(prog, "color");
  gl.enable(gl.DEPTH_TEST);
  gl.clearColor(1, 1, 1, 1);

  // ---------------------------------------------------------------- camera (z up, orbit about the centre)
  var R = D.radius, FOV = 30 * Math.PI / 180;
  var cam = {};
  function home(az, el) { cam.az = az; cam.el = el; cam.zoom = 1; cam.target = [0, 0, 0]; }
  home(-Math.PI / 4, 0.6);
  function sub(a, b) { return [a[0] - b[0], a[1] - b[1], a[2] - b[2]]; }
  function cross(a, b) { return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]; }
  function norm(a) { var l = Math.hypot(a[0], a[1], a[2]) || 1; return [a[0] / l, a[1] / l, a[2] / l]; }
  function dot(a, b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
  function frame() {  // eye, right, up, forward (world, offsets from the centre)
    var dist = R / Math.sin(FOV / 2) * 0.9 / cam.zoom;  // the part fills the view; zoom out with the wheel
    var f = [-Math.cos(cam.el) * Math.cos(cam.az), -Math.cos(cam.el) * Math.sin(cam.az), -Math.sin(cam.el)];
    var r = norm(cross(f, [0, 0, 1])), u = cross(r, f);
    var eye = [cam.target[0] - dist * f[0], cam.target[1] - dist * f[1], cam.target[2] - dist * f[2]];
    return {eye: eye, r: r, u: u, f: f, dist: dist};
  }
  function mvpMatrix() {  // column-major projection * view
    var c = frame(), w = canvas.width, h = canvas.height;
    var near = Math.max(c.dist - 2 * R, c.dist * 0.01), far = c.dist + 2 * R;
    // The bounding sphere fits the narrower side of the view.
    var t = 1 / Math.tan(FOV / 2), aspect = w / Math.max(h, 1);
    var sx = t / Math.max(aspect, 1), sy = t * Math.min(aspect, 1);
    var A = (far + near) / (near - far), B = 2 * far * near / (near - far);
    var V = [c.r, c.u, [-c.f[0], -c.f[1], -c.f[2]]];
    var tr = [-dot(c.r, c.eye), -dot(c.u, c.eye), dot(c.f, c.eye)];
    var m = new Float32Array(16);
    for (var j = 0; j < 3; j++) {  // column j of the view's rotation, then the projection
      m[4 * j] = sx * V[0][j]; m[4 * j + 1] = sy * V[1][j];
      m[4 * j + 2] = A * V[2][j]; m[4 * j + 3] = -V[2][j];
    }
    m[12] = sx * tr[0]; m[13] = sy * tr[1]; m[14] = A * tr[2] + B; m[15] = -tr[2];
    return m;
  }
  var colors = {};
  function rgb(hex) { return [1, 3, 5].map(function (k) { return parseInt(hex.substr(k, 2), 16) / 255; }); }
  var pointSize = 3, pending = false, mvp = null;
  function draw() {
    pending = false;
    var dpr = window.devicePixelRatio || 1, w = Math.round(canvas.clientWidth * dpr),
        h = Math.round(canvas.clientHeight * dpr);
    if (canvas.width !== w || canvas.height !== h) { canvas.width = w; canvas.height = h; }
    gl.viewport(0, 0, canvas.width, canvas.height);
    gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
    mvp = mvpMatrix();
    gl.uniformMatrix4fv(uMvp, false, mvp);
    gl.uniform1f(uSize, pointSize * dpr);
    D.traces.forEach(function (t) {
      if (!t.visible || !t.drawn) return;
      gl.uniform3fv(uColor, rgb(t["color_" + mode]));
      gl.drawArrays(gl.POINTS, t.start, t.drawn);
    });
    drawTriad();
  }
  function redraw() { if (!pending) { pending = true; requestAnimationFrame(draw); } }
  var triad = document.getElementById("triad").getContext("2d");
  function drawTriad() {  // the world axes as the camera sees them
    var c = frame(), s = 26, o = 36;
    triad.clearRect(0, 0, 72, 72);
    triad.strokeStyle = "#555"; triad.fillStyle = "#333"; triad.font = "11px sans-serif";
    [[1, 0, 0, "x"], [0, 1, 0, "y"], [0, 0, 1, "z"]].forEach(function (a) {
      var px = o + s * dot(a, c.r), py = o - s * dot(a, c.u);
      triad.beginPath(); triad.moveTo(o, o); triad.lineTo(px, py); triad.stroke();
      triad.fillText(a[3], px + 2, py + 4);
    });
  }

  // ---------------------------------------------------------------- mouse: orbit, pan, zoom, pick
  var drag = null;
  canvas.addEventListener("contextmenu", function (e) { e.preventDefault(); });
  canvas.addEventListener("pointerdown", function (e) {
    drag = {x: e.clientX, y: e.clientY, moved: false, pan: e.button === 2 || e.shiftKey};
    canvas.setPointerCapture(e.pointerId);
  });
  canvas.addEventListener("pointermove", function (e) {
    if (!drag) return;
    var dx = e.clientX - drag.x, dy = e.clientY - drag.y;
    if (Math.abs(dx) + Math.abs(dy) > 2) drag.moved = true;
    drag.x = e.clientX; drag.y = e.clientY;
    if (drag.pan) {
      var c = frame(), k = 2 * c.dist * Math.tan(FOV / 2) / canvas.clientHeight;
      for (var a = 0; a < 3; a++) cam.target[a] -= k * (dx * c.r[a] - dy * c.u[a]);
    } else {
      cam.az -= dx * 0.01;
      cam.el = Math.max(-1.55, Math.min(1.55, cam.el + dy * 0.01));
    }
    redraw();
  });
  canvas.addEventListener("pointerup", function (e) {
    if (drag && !drag.moved) pick(e);
    drag = null;
  });
  canvas.addEventListener("wheel", function (e) {
    e.preventDefault();
    cam.zoom = Math.max(0.2, Math.min(200, cam.zoom * Math.exp(-e.deltaY * 0.0015)));
    redraw();
  }, {passive: false});
  canvas.addEventListener("dblclick", function () { home(-Math.PI / 4, 0.6); redraw(); });
  function pick(e) {  // the nearest visible point within 8 px of the click, front-most first
    var rect = canvas.getBoundingClientRect(), mx = e.clientX - rect.left, my = e.clientY - rect.top;
    var W = rect.width, H = rect.height, best = null, bestD = 64, bestZ = Infinity;
    D.traces.forEach(function (t) {
      if (!t.visible) return;
      for (var k = t.start; k < t.start + t.drawn; k++) {
        var x = xyz[k], y = xyz[n + k], z = xyz[2 * n + k];
        var cw = mvp[3] * x + mvp[7] * y + mvp[11] * z + mvp[15];
        if (cw <= 0) continue;
        var sx = (mvp[0] * x + mvp[4] * y + mvp[8] * z + mvp[12]) / cw,
            sy = (mvp[1] * x + mvp[5] * y + mvp[9] * z + mvp[13]) / cw,
            sz = (mvp[2] * x + mvp[6] * y + mvp[10] * z + mvp[14]) / cw;
        var px = (sx + 1) / 2 * W - mx, py = (1 - sy) / 2 * H - my, d2 = px * px + py * py;
        if (d2 < bestD || (d2 <= bestD + 4 && sz < bestZ)) { bestD = d2; bestZ = sz; best = [t, k]; }
      }
    });
    var out = document.getElementById("pick");
    if (!best) { out.textContent = ""; return; }
    var t = best[0], k = best[1], c = D.centre;
    out.textContent = (t.id < 0 ? "unsegmented" : "segment " + t.id + " (" + t.type + ")") + "\n" +
      [0, 1, 2].map(function (a) { return "xyz"[a] + " " + (c[a] + xyz[a * n + k]).toPrecision(6); }).join("  ");
  }

  // ---------------------------------------------------------------- controls
  var segBoxes = {};
  function box(id) { return segBoxes[id]; }
  function updateVisibility() {
    D.traces.forEach(function (t) { t.visible = box(t.id).checked; });
    syncSets("type", D.types, "segments");
    syncSets("group", D.groups, "members");
    redraw();
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
  var swatches = [];
  D.traces.forEach(function (t) {
    var text = t.id < 0 ? "unsegmented (" + t.n + ")" : t.id + ": " + t.type + " (" + t.n + ")";
    segBoxes[t.id] = addBox(fsSeg, "segment-" + t.id, t.color_segment, text, updateVisibility);
    swatches.push(segBoxes[t.id].nextSibling);
  });
  function setAll(on) { D.traces.forEach(function (t) { box(t.id).checked = on; }); updateVisibility(); }
  document.getElementById("all").addEventListener("click", function () { setAll(true); });
  document.getElementById("none").addEventListener("click", function () { setAll(false); });
  document.querySelectorAll("input[name=colorby]").forEach(function (r) {
    r.addEventListener("change", function () {
      mode = r.value;
      D.traces.forEach(function (t, i) { swatches[i].style.background = t["color_" + mode]; });
      redraw();
    });
  });
  document.getElementById("size").addEventListener("input", function (e) { pointSize = +e.target.value; redraw(); });
  var views = {iso: [-Math.PI / 4, 0.6], top: [-Math.PI / 2, 1.55], front: [-Math.PI / 2, 0], side: [0, 0]};
  Object.keys(views).forEach(function (k) {
    document.getElementById("view-" + k).addEventListener("click", function () {
      home(views[k][0], views[k][1]); redraw(); });
  });
  document.getElementById("save").addEventListener("click", function () {
    draw();
    var a = document.createElement("a");
    a.href = canvas.toDataURL("image/png"); a.download = "houghcad-view.png"; a.click();
  });
  window.addEventListener("resize", redraw);
  // For tests and scripted screenshots: what is shown, and the first frame's time.
  window.houghcadView = {
    visible: function () { return D.traces.map(function (t) { return t.visible; }); },
    traces: D.traces.length, mode: function () { return mode; }
  };
  draw();
  gl.finish();
  document.body.setAttribute("data-render-ms", String(Math.round(performance.now())));
  document.body.setAttribute("data-rendered", "1");
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
<label>point size <input id="size" type="range" min="1" max="8" step="0.5" value="3"></label></div>
<div id="help">drag: rotate, shift/right drag: pan, wheel: zoom, click: identify, double click: reset</div></div>
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
