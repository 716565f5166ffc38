(function () {
  "use strict";
  var D = JSON.parse(document.getElementById("houghcad-data").textContent);
  var raw = atob(D.xyz), bytes = new Uint8Array(raw.length);
  for (var i = 0; i < raw.length; i++) bytes[i] = raw.charCodeAt(i);
  var xyz = new Float32Array(bytes.buffer), n = D.n_drawn;  // little-endian, as every browser platform
  var rawN = atob(D.normals), nrm = new Int8Array(rawN.length);  // planar int8 normals, 127 = 1
  for (var i = 0; i < rawN.length; i++) nrm[i] = rawN.charCodeAt(i);
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
    "attribute float bx; attribute float by; attribute float bz; uniform mat3 rot; uniform vec3 light;" +
    "uniform float ambient;" +
    "uniform float wsize; varying float shade;" +
    // A point is as wide as the points' spacing at its depth (wsize / w pixels), at least
    // `size` pixels: the surface closes and hides what lies behind it at any zoom. It is shaded
    // by its unoriented normal against a light from the viewer's upper left, never below the
    // ambient share of its colour (both from render.py, as the PNG views).
    "void main() { gl_Position = mvp * vec4(ax, ay, az, 1.0);" +
    " gl_PointSize = max(size, wsize / gl_Position.w);" +
    " vec3 m = rot * vec3(bx, by, bz); float l = length(m);" +
    " shade = l > 0.0 ? ambient + (1.0 - ambient) * abs(dot(m / l, light)) : 1.0; }"));
  gl.attachShader(prog, shader(gl.FRAGMENT_SHADER,
    "precision mediump float; uniform vec3 color; varying float shade;" +
    "void main() { vec2 d = gl_PointCoord - 0.5; if (dot(d, d) > 0.25) discard;" +
    " gl_FragColor = vec4(color * shade, 1.0); }"));
  gl.linkProgram(prog);
  gl.useProgram(prog);
  function attributes(data, names, type, normalized, bytes) {  // planar columns of one buffer
    gl.bindBuffer(gl.ARRAY_BUFFER, gl.createBuffer());
    gl.bufferData(gl.ARRAY_BUFFER, data, gl.STATIC_DRAW);
    names.forEach(function (name, a) {
      var loc = gl.getAttribLocation(prog, name);
      gl.enableVertexAttribArray(loc);
      gl.vertexAttribPointer(loc, 1, type, normalized, 0, a * n * bytes);
    });
  }
  attributes(xyz, ["ax", "ay", "az"], gl.FLOAT, false, 4);
  attributes(nrm, ["bx", "by", "bz"], gl.BYTE, true, 1);
  var uRot = gl.getUniformLocation(prog, "rot"), uLight = gl.getUniformLocation(prog, "light");
  gl.uniform3fv(uLight, D.light);
  gl.uniform1f(gl.getUniformLocation(prog, "ambient"), D.ambient);
  var uMvp = gl.getUniformLocation(prog, "mvp"), uSize = gl.getUniformLocation(prog, "size"),
      uWsize = gl.getUniformLocation(prog, "wsize"),
      uColor = gl.getUniformLocation(prog, "color");
  gl.enable(gl.DEPTH_TEST);
  gl.clearColor(1, 1, 1, 1);

  // ---------------------------------------------------------------- camera (z up, orbit about the centre)
  var R = D.radius, FOV = 30 * Math.PI / 180, nFramed = D.framed === undefined ? n : D.framed;
  var cam = {};
  // The view's share the part fills when it is framed (its farthest projected point).
  var FILL = 0.92;
  function home(az, el) { cam.az = az; cam.el = el; cam.zoom = 1; cam.target = [0, 0, 0]; cam.fit = null; }
  home(-Math.PI / 4, 0.6);
  function sub(a, b) { return [a[0] - b[0], a[1] - b[1], a[2] - b[2]]; }
  function cross(a, b) { return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]; }
  function norm(a) { var l = Math.hypot(a[0], a[1], a[2]) || 1; return [a[0] / l, a[1] / l, a[2] / l]; }
  function dot(a, b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
  function axes(az, el) {  // right, up, forward of a view direction
    var f = [-Math.cos(el) * Math.cos(az), -Math.cos(el) * Math.sin(az), -Math.sin(el)];
    var r = norm(cross(f, [0, 0, 1]));
    return {r: r, u: cross(r, f), f: f};
  }
  function scales() {  // the projection's x and y scales: the narrower side of the view holds the fov
    var t = 1 / Math.tan(FOV / 2), aspect = canvas.width / Math.max(canvas.height, 1);
    return [t / Math.max(aspect, 1), t * Math.min(aspect, 1)];
  }
  function fitDistance() {
    // The nearest camera distance at which every framed point (the first D.framed: the part,
    // not the strays far off) projects within FILL of the view: a point at (x, y) across the
    // view and z toward the camera needs dist >= z + max(sx |x|, sy |y|) / FILL. The part, not
    // its bounding sphere, fills the view.
    var a = axes(cam.az, cam.el), s = scales(), best = 1e-9 * R, front = -R;
    for (var i = 0; i < nFramed; i++) {
      var p = [xyz[i], xyz[n + i], xyz[2 * n + i]], z = -dot(p, a.f);
      var d = z + Math.max(s[0] * Math.abs(dot(p, a.r)), s[1] * Math.abs(dot(p, a.u))) / FILL;
      if (d > best) best = d;
      if (z > front) front = z;
    }
    // The nearest point stays in front of the near plane.
    return nFramed ? Math.max(best, front + 0.05 * R) : R / Math.sin(FOV / 2);
  }
  function frame() {  // eye, right, up, forward (world, offsets from the centre)
    if (cam.fit === null) cam.fit = fitDistance();  // when framed (home, a new size); zoom with the wheel
    var dist = cam.fit / cam.zoom, a = axes(cam.az, cam.el), f = a.f;
    var eye = [cam.target[0] - dist * f[0], cam.target[1] - dist * f[1], cam.target[2] - dist * f[2]];
    return {eye: eye, r: a.r, u: a.u, f: f, dist: dist};
  }
  function mvpMatrix() {  // column-major projection * view
    var c = frame();
    var near = Math.max(c.dist - 2 * R, Math.min(c.dist * 0.01, 0.02 * R)), far = c.dist + 2 * R;
    var s = scales(), sx = s[0], sy = s[1];
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
  // The slider scales the points' width (1: their spacing); 1.5 pixels at least.
  var pointSize = 1, pending = false, mvp = null;
  function draw() {
    pending = false;
    var dpr = window.devicePixelRatio || 1, w = Math.round(canvas.clientWidth * dpr),
        h = Math.round(canvas.clientHeight * dpr);
    if (canvas.width !== w || canvas.height !== h) { canvas.width = w; canvas.height = h; cam.fit = null; }
    gl.viewport(0, 0, canvas.width, canvas.height);
    gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
    mvp = mvpMatrix();
    gl.uniformMatrix4fv(uMvp, false, mvp);
    var c = frame();  // the view's rotation: rows right, up, towards the viewer (column-major)
    gl.uniformMatrix3fv(uRot, false, new Float32Array([c.r[0], c.u[0], -c.f[0], c.r[1], c.u[1], -c.f[1],
                                                        c.r[2], c.u[2], -c.f[2]]));
    gl.uniform1f(uSize, 1.5 * dpr);
    // Pixels of one world unit at clip depth w = 1: the projection's y scale times half the height.
    gl.uniform1f(uWsize, pointSize * (D.spacing || 0) * scales()[1] * canvas.height / 2);
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
    // Decimals to 1e-4 of the part's size, whatever the coordinates' offset (a georeferenced
    // y of 3999966.7 read 4.00000e+6 at 6 significant digits).
    var dec = Math.max(0, Math.min(10, 4 - Math.floor(Math.log10(D.radius))));
    out.textContent = (t.id < 0 ? "unsegmented" : "segment " + t.id + " (" + t.type + ")") + "\n" +
      [0, 1, 2].map(function (a) { return "xyz"[a] + " " + (c[a] + xyz[a * n + k]).toFixed(dec); }).join("  ");
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
