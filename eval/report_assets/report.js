/* SShaDe report: sortable tables and a small WebGL mesh viewer (no network, no library).
   Tables: click a header to sort (numbers by data-v, text otherwise; again: reverse).
   Viewer: window.SSHADE_VIEWS[case] = {faces (base64 Uint16/Uint32), idx32, lo, step,
   scales: {edge|gt: {max, legend}}, meshes: [{label, kind, pos (base64 Uint16 x, y, z quantised),
   edge, gt (base64 Uint8 per cluster, 255 = the scale's max, or null)}]}; one canvas per case,
   one panel per mesh, flat Lambert shading; each mesh coloured by the chosen quantity on the
   case's one scale (buttons above the canvas; the page's #mode=edge|gt|plain picks the first),
   its plain colour where it has none; drag rotates, wheel zooms, double-click resets. */
(function () {
  "use strict";

  function sortable(table) {
    var heads = table.tHead ? table.tHead.rows[0].cells : [];
    Array.prototype.forEach.call(heads, function (th, col) {
      th.addEventListener("click", function () {
        var body = table.tBodies[0];
        var rows = Array.prototype.slice.call(body.rows);
        var dir = th.getAttribute("data-dir") === "asc" ? -1 : 1;
        Array.prototype.forEach.call(heads, function (h) { h.removeAttribute("data-dir"); });
        th.setAttribute("data-dir", dir === 1 ? "asc" : "desc");
        function key(r) {
          var c = r.cells[col];
          var v = c ? c.getAttribute("data-v") : null;
          return v !== null && v !== "" && !isNaN(Number(v)) ? Number(v) : (c ? c.textContent : "");
        }
        rows.sort(function (a, b) {
          var x = key(a), y = key(b);
          if (typeof x === "number" && typeof y === "number") { return dir * (x - y); }
          if (typeof x === "number") { return -1; }
          if (typeof y === "number") { return 1; }
          return dir * String(x).localeCompare(String(y));
        });
        rows.forEach(function (r) { body.appendChild(r); });
      });
    });
  }

  function decode(b64, Type) {
    var bin = atob(b64), bytes = new Uint8Array(bin.length);
    for (var i = 0; i < bin.length; i++) { bytes[i] = bin.charCodeAt(i); }
    return new Type(bytes.buffer);
  }

  var VS = "attribute vec3 p; attribute vec3 n; attribute float e; uniform mat3 R; uniform vec3 c;" +
    "uniform float s; uniform vec2 a; varying float shade; varying float ev; void main() { ev = e;" +
    "vec3 q = R * ((p - c) * s);" +
    "gl_Position = vec4(q.x * a.x, q.y * a.y, -q.z * 0.5, 1.0); vec3 m = normalize(R * n);" +
    "shade = 0.3 + 0.7 * abs(dot(m, normalize(vec3(0.35, 0.5, 1.0)))); }";
  /* RAMP: low (blue) to high (red) through cyan and yellow, as in the legend's gradient. */
  var RAMP = [[0.23, 0.33, 0.85], [0.25, 0.78, 0.85], [0.96, 0.86, 0.25], [0.85, 0.14, 0.1]];
  var FS = "precision mediump float; uniform vec3 col; uniform float mode; varying float shade;" +
    "varying float ev; vec3 ramp(float t) { t = clamp(t, 0.0, 1.0) * 3.0;" +
    "vec3 c0 = vec3(" + RAMP[0] + "), c1 = vec3(" + RAMP[1] + "), c2 = vec3(" + RAMP[2] + ")," +
    " c3 = vec3(" + RAMP[3] + "); if (t < 1.0) { return mix(c0, c1, t); }" +
    "if (t < 2.0) { return mix(c1, c2, t - 1.0); } return mix(c2, c3, t - 2.0); }" +
    "void main() { vec3 k = mode > 0.5 ? ramp(ev) : col; gl_FragColor = vec4(k * shade, 1.0); }";
  var MODES = ["edge", "gt"];
  var COLORS = {rest: [0.78, 0.78, 0.78], target: [0.55, 0.8, 0.55], result: [0.5, 0.68, 0.92]};

  function program(gl) {
    function shader(type, src) {
      var sh = gl.createShader(type);
      gl.shaderSource(sh, src);
      gl.compileShader(sh);
      if (!gl.getShaderParameter(sh, gl.COMPILE_STATUS)) { throw new Error(gl.getShaderInfoLog(sh)); }
      return sh;
    }
    var pr = gl.createProgram();
    gl.attachShader(pr, shader(gl.VERTEX_SHADER, VS));
    gl.attachShader(pr, shader(gl.FRAGMENT_SHADER, FS));
    gl.linkProgram(pr);
    if (!gl.getProgramParameter(pr, gl.LINK_STATUS)) { throw new Error(gl.getProgramInfoLog(pr)); }
    return pr;
  }

  /* One mesh: flat (per-face) normals, triangles expanded, centred on its bounding box;
     per colour quantity a buffer of its per-corner values in [0, 1]. */
  function buildMesh(gl, data, faces, m) {
    var q = decode(m.pos, Uint16Array), nf = faces.length / 3;
    var P = new Float32Array(nf * 9), N = new Float32Array(nf * 9);
    var lo = [Infinity, Infinity, Infinity], hi = [-Infinity, -Infinity, -Infinity];
    var v = new Float32Array(q.length);
    for (var i = 0; i < q.length; i++) {
      var k = i % 3;
      v[i] = data.lo[k] + q[i] * data.step[k];
      if (v[i] < lo[k]) { lo[k] = v[i]; }
      if (v[i] > hi[k]) { hi[k] = v[i]; }
    }
    for (var f = 0; f < nf; f++) {
      var a = faces[3 * f] * 3, b = faces[3 * f + 1] * 3, c = faces[3 * f + 2] * 3;
      var ux = v[b] - v[a], uy = v[b + 1] - v[a + 1], uz = v[b + 2] - v[a + 2];
      var wx = v[c] - v[a], wy = v[c + 1] - v[a + 1], wz = v[c + 2] - v[a + 2];
      var nx = uy * wz - uz * wy, ny = uz * wx - ux * wz, nz = ux * wy - uy * wx;
      var l = Math.sqrt(nx * nx + ny * ny + nz * nz) || 1;
      [a, b, c].forEach(function (j, t) {
        for (var d = 0; d < 3; d++) { P[9 * f + 3 * t + d] = v[j + d]; }
        N[9 * f + 3 * t] = nx / l; N[9 * f + 3 * t + 1] = ny / l; N[9 * f + 3 * t + 2] = nz / l;
      });
    }
    function buffer(arr) {
      var bf = gl.createBuffer();
      gl.bindBuffer(gl.ARRAY_BUFFER, bf);
      gl.bufferData(gl.ARRAY_BUFFER, arr, gl.STATIC_DRAW);
      return bf;
    }
    var ev = {};
    MODES.forEach(function (mode) {
      if (!m[mode]) { return; }
      var u = decode(m[mode], Uint8Array), E = new Float32Array(nf * 3);
      for (var i = 0; i < nf * 3; i++) { E[i] = u[faces[i]] / 255; }
      ev[mode] = buffer(E);
    });
    return {p: buffer(P), n: buffer(N), e: ev, count: nf * 3, lo: lo, hi: hi,
            centre: [(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, (lo[2] + hi[2]) / 2]};
  }

  function rotation(yaw, pitch) {
    var cy = Math.cos(yaw), sy = Math.sin(yaw), cp = Math.cos(pitch), sp = Math.sin(pitch);
    // R = Rx(pitch) * Ry(yaw), column-major for uniformMatrix3fv
    return new Float32Array([cy, sp * sy, -cp * sy, 0, cp, sp, sy, -sp * cy, cp * cy]);
  }

  function viewer(root, data) {
    var canvas = root.querySelector("canvas");
    var gl = canvas.getContext("webgl", {preserveDrawingBuffer: true, antialias: true});
    if (!gl) { throw new Error("WebGL is not available: the 3D view of " + data.case + " cannot be drawn"); }
    var pr = program(gl), loc = {};
    ["R", "c", "s", "a", "col", "mode"].forEach(function (u) { loc[u] = gl.getUniformLocation(pr, u); });
    var ap = gl.getAttribLocation(pr, "p"), an = gl.getAttribLocation(pr, "n"), ae = gl.getAttribLocation(pr, "e");
    var faces = decode(data.faces, data.idx32 ? Uint32Array : Uint16Array);
    var panels = data.meshes.map(function (m) { return m.pos ? buildMesh(gl, data, faces, m) : null; });
    var ref = panels.filter(function (p) { return p; })[0];
    var diag = ref ? Math.hypot(ref.hi[0] - ref.lo[0], ref.hi[1] - ref.lo[1], ref.hi[2] - ref.lo[2]) || 1 : 1;
    var st = {yaw: 0, pitch: 0, zoom: 1, mode: firstMode(data)};
    var cols = Math.min(panels.length, 4), rows = Math.ceil(panels.length / cols);
    function draw() {
      var dpr = window.devicePixelRatio || 1, w = canvas.clientWidth, h = canvas.clientHeight;
      canvas.width = Math.round(w * dpr); canvas.height = Math.round(h * dpr);
      var pw = Math.floor(canvas.width / cols), ph = Math.floor(canvas.height / rows);
      gl.useProgram(pr);
      gl.enable(gl.DEPTH_TEST); gl.enable(gl.SCISSOR_TEST);
      gl.uniformMatrix3fv(loc.R, false, rotation(st.yaw, st.pitch));
      gl.uniform1f(loc.s, 1.8 / diag);
      panels.forEach(function (m, i) {
        var x = (i % cols) * pw, y = canvas.height - (Math.floor(i / cols) + 1) * ph;
        gl.viewport(x, y, pw, ph); gl.scissor(x, y, pw, ph);
        var shade = (i % 2) ? 0.97 : 1.0;
        gl.clearColor(shade, shade, shade, 1); gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
        if (!m) { return; }
        var asp = pw / ph;
        gl.uniform2f(loc.a, st.zoom * Math.min(1, 1 / asp), st.zoom * Math.min(1, asp));
        gl.uniform3fv(loc.c, m.centre);
        gl.uniform3fv(loc.col, COLORS[data.meshes[i].kind] || COLORS.result);
        gl.bindBuffer(gl.ARRAY_BUFFER, m.p); gl.enableVertexAttribArray(ap);
        gl.vertexAttribPointer(ap, 3, gl.FLOAT, false, 0, 0);
        gl.bindBuffer(gl.ARRAY_BUFFER, m.n); gl.enableVertexAttribArray(an);
        gl.vertexAttribPointer(an, 3, gl.FLOAT, false, 0, 0);
        var eb = m.e[st.mode];
        gl.uniform1f(loc.mode, eb ? 1 : 0);
        if (eb && ae >= 0) {
          gl.bindBuffer(gl.ARRAY_BUFFER, eb); gl.enableVertexAttribArray(ae);
          gl.vertexAttribPointer(ae, 1, gl.FLOAT, false, 0, 0);
        } else if (ae >= 0) { gl.disableVertexAttribArray(ae); gl.vertexAttrib1f(ae, 0); }
        gl.drawArrays(gl.TRIANGLES, 0, m.count);
      });
    }
    // each label over its own panel (the panels wrap to rows of `cols`)
    var labels = root.querySelector(".view-labels");
    labels.style.position = "relative"; labels.style.height = "0";
    Array.prototype.forEach.call(labels.children, function (el, i) {
      el.style.position = "absolute"; el.style.width = (100 / cols) + "%";
      el.style.left = ((i % cols) * 100 / cols) + "%"; el.style.top = (Math.floor(i / cols) * 300 + 4) + "px";
    });
    canvas.style.height = (rows * 300) + "px";
    colourControls(root, data, st, function () { redraw(); });
    var drag = null, queued = false;
    function redraw() {
      if (queued) { return; }
      queued = true;
      window.requestAnimationFrame(function () { queued = false; draw(); });
    }
    canvas.addEventListener("mousedown", function (e) { drag = [e.clientX, e.clientY]; e.preventDefault(); });
    window.addEventListener("mouseup", function () { drag = null; });
    window.addEventListener("mousemove", function (e) {
      if (!drag) { return; }
      st.yaw += (e.clientX - drag[0]) * 0.01;
      st.pitch = Math.max(-1.55, Math.min(1.55, st.pitch + (e.clientY - drag[1]) * 0.01));
      drag = [e.clientX, e.clientY];
      redraw();
    });
    canvas.addEventListener("wheel", function (e) {
      st.zoom = Math.max(0.2, Math.min(20, st.zoom * Math.exp(-e.deltaY * 0.001)));
      e.preventDefault();
      redraw();
    }, {passive: false});
    canvas.addEventListener("dblclick", function () { st.yaw = 0; st.pitch = 0; st.zoom = 1; redraw(); });
    window.addEventListener("resize", redraw);
    draw();
  }

  /* The first colour quantity: the page's #mode=... when the case has it, else edge error. */
  function firstMode(data) {
    var m = /(?:^#|&)mode=(edge|gt|plain)/.exec(window.location.hash || "");
    var scales = data.scales || {};
    if (m && (m[1] === "plain" || scales[m[1]])) { return m[1]; }
    return scales.edge ? "edge" : "plain";
  }

  /* Buttons (one per quantity the case has, and plain) and a legend: the ramp from 0 to the
     case's scale max; the chosen mode is the view's data-mode attribute. */
  function colourControls(root, data, st, changed) {
    var scales = data.scales || {}, bar = document.createElement("div");
    bar.className = "view-colour";
    var legend = document.createElement("span");
    legend.className = "view-legend";
    var stops = RAMP.map(function (c) { return "rgb(" + c.map(function (x) { return Math.round(255 * x); }) + ")"; });
    function show() {
      root.setAttribute("data-mode", st.mode);
      var sc = scales[st.mode];
      legend.innerHTML = "";
      if (!sc) { legend.textContent = "plain colours: rest grey, ground truth green, results blue"; return; }
      var g = document.createElement("span");
      g.className = "view-ramp";
      g.style.background = "linear-gradient(to right," + stops.join(",") + ")";
      legend.appendChild(document.createTextNode("0 "));
      legend.appendChild(g);
      legend.appendChild(document.createTextNode(" \u2265 " + Number(sc.max).toPrecision(3) + ": " + sc.legend));
    }
    MODES.concat(["plain"]).forEach(function (mode) {
      if (mode !== "plain" && !scales[mode]) { return; }
      var b = document.createElement("button");
      b.type = "button";
      b.textContent = mode === "edge" ? "edge error" : mode === "gt" ? "distance to ground truth" : "plain";
      b.setAttribute("data-mode", mode);
      b.addEventListener("click", function () { st.mode = mode; show(); changed(); });
      bar.appendChild(b);
    });
    bar.appendChild(legend);
    root.insertBefore(bar, root.querySelector(".view-labels"));
    show();
  }

  function start() {
    Array.prototype.forEach.call(document.querySelectorAll("table.sortable"), sortable);
    var views = window.SSHADE_VIEWS || {}, drawn = 0;
    Array.prototype.forEach.call(document.querySelectorAll(".view"), function (root) {
      var data = views[root.getAttribute("data-case")];
      if (!data) {
        window.sshadeRecordError("no view data for case " + root.getAttribute("data-case") +
                                 " (its .js file next to index.html is missing)");
        return;
      }
      viewer(root, data);
      drawn += 1;
      root.setAttribute("data-drawn", "1");
    });
    var status = document.getElementById("views-status");
    if (status) { status.setAttribute("data-drawn", String(drawn)); }
  }

  if (document.readyState === "loading") { document.addEventListener("DOMContentLoaded", start); } else { start(); }
})();
