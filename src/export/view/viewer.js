// fibrefit view: a hand-written WebGL2 viewer of a fitted material (src/export/view/viewer.js).
// Everything it draws comes from the page's data (src/export/view/mod.rs, src/api/view.rs): the
// exported shaders (the exact model, the glTF route's material through the gltf rung), the
// meshes, the measured-against-fitted grid, the parameter table. Conventions as `fibrefit
// render`: world z up, angles in degrees, theta from +z, phi from +x towards +y; directional
// light of unit irradiance, a fill light from the camera of irradiance `fill`, orthographic
// camera; radiance = sum f(l, v) E (n.l); shown as sRGB of radiance x exposure, clipped at 1.
'use strict';
(() => {
  const T0 = performance.now();
  const D = JSON.parse(document.getElementById('fibrefit-data').textContent);
  const DEG = Math.PI / 180;
  const S = { light: [40, 120], camera: [50, 270], exposure: D.exposure, fill: D.fill, object: 'swatch', fibres: true };
  const timings = { parse_ms: performance.now() - T0 };

  // ---------- the address's hash: light=T,P&camera=T,P&exposure=E&fill=F&object=NAME&fibres=0
  function readHash() {
    const h = new URLSearchParams(location.hash.replace(/^#/, ''));
    const pair = (k) => {
      const v = (h.get(k) || '').split(',').map(Number);
      return v.length === 2 && v.every(Number.isFinite) ? v : null;
    };
    S.light = pair('light') || S.light;
    S.camera = pair('camera') || S.camera;
    for (const k of ['exposure', 'fill']) {
      const x = Number(h.get(k));
      if (h.has(k) && Number.isFinite(x) && x >= 0) S[k] = x;
    }
    if (h.has('object') && D.meshes.some((m) => m.name === h.get('object'))) S.object = h.get('object');
    if (h.has('fibres')) S.fibres = h.get('fibres') !== '0';
  }
  readHash();

  // ---------- vectors
  const dir = ([t, p]) => [Math.sin(t * DEG) * Math.cos(p * DEG), Math.sin(t * DEG) * Math.sin(p * DEG), Math.cos(t * DEG)];
  const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
  const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
  const norm = (a) => { const l = Math.hypot(...a); return a.map((x) => x / l); };

  // ---------- the page
  const el = (tag, attrs = {}, ...kids) => {
    const e = document.createElement(tag);
    for (const [k, v] of Object.entries(attrs)) {
      if (k === 'text') e.textContent = v; else e.setAttribute(k, v);
    }
    for (const k of kids) e.append(k);
    return e;
  };
  const fmt = (x) => {
    if (x === null || x === undefined) return '—';
    if (Array.isArray(x)) return x.map(fmt).join(', ');
    if (typeof x !== 'number') return String(x);
    if (x === 0) return '0';
    const a = Math.abs(x);
    return a >= 1e4 || a < 1e-3 ? x.toExponential(3) : x.toPrecision(4);
  };
  const body = document.body;
  body.append(el('header', {}, el('h1', { text: `fibrefit view: ${D.title}` }),
    el('p', { text: `model ${D.model}; fibres at ${fmt(D.fibre_azimuth_deg)} deg from x; ${D.tool}` })));
  const glCanvas = el('canvas', { id: 'gl', width: 960, height: 480 });
  const views = el('section', { id: 'views' },
    el('div', { class: 'labels' }, el('span', { text: 'exact model (exported shader, GLSL ES 3.00)' }),
      el('span', { text: `glTF route (${D.gltf_route.kind}) through the gltf rung's shader` })),
    glCanvas);
  const lightCanvas = el('canvas', { id: 'light', width: 220, height: 220 });
  const objectSel = el('select', { id: 'object' }, ...D.meshes.map((m) => el('option', { value: m.name, text: m.name })));
  const expo = el('input', { id: 'exposure', type: 'range', min: -10, max: 10, step: 0.05 });
  const fill = el('input', { id: 'fill', type: 'range', min: 0, max: 1, step: 0.01 });
  const fibres = el('input', { id: 'fibres', type: 'checkbox' });
  const readout = el('p', { id: 'readout' });
  const controls = el('section', { id: 'controls' },
    el('div', {}, el('h2', { text: 'Light' }), lightCanvas,
      el('p', { class: 'hint', text: 'drag the light (yellow) over the hemisphere, seen from above (theta from the centre, 90 deg at the rim); the line is the fibre direction, the ring the camera; drag the objects to turn the camera' })),
    el('div', {},
      el('label', {}, 'object ', objectSel),
      el('label', {}, 'exposure ', expo, el('output', { id: 'exposure-out' })),
      el('label', {}, 'fill light ', fill, el('output', { id: 'fill-out' })),
      el('label', {}, fibres, ' fibre direction'),
      readout));
  const compareCanvas = el('canvas', { id: 'compare', width: 960, height: 330 });
  const compareText = el('p', { id: 'compare-note' });
  const compare = el('section', { id: 'comparison' }, el('h2', { text: 'Measured against fitted at the light' }), compareText);
  if (D.comparison.available) compare.append(compareCanvas, el('p', { class: 'hint', text: D.comparison.note }));
  body.append(el('main', {}, views, controls), compare, tables());
  const objectLabel = el('p', { id: 'object-label' });
  controls.append(objectLabel);

  function tables() {
    const R = D.result;
    const sec = el('section', { id: 'result' }, el('h2', { text: 'The fit' }));
    if (!R.fitted) {
      sec.append(el('p', { text: R.note }));
    } else {
      const st = R.statistics;
      sec.append(el('p', { id: 'verdict', text: `verdict: ${R.verdict ?? 'none stated'}` }),
        el('p', { text: `${R.data?.samples ?? '?'} samples of ${R.data?.file ?? '?'} (${R.data?.kind ?? '?'}); RMS error ${fmt(st.rmse)} 1/sr, relative ${fmt(100 * st.relative_rmse)} %` +
          (st.reduced_chi_square != null ? `; reduced chi-square ${fmt(st.reduced_chi_square)}` : '') +
          (st.residual_variance != null ? `; residual variance ${fmt(st.residual_variance)}` : '') +
          (R.floor ? `; held-out error ${fmt(R.floor.heldout_error)}, ${fmt(R.floor.ratio)} x the floor ${fmt(R.floor.floor)}` : '') }));
      const t = el('table', { id: 'parameters' }, el('tr', {}, ...['parameter', 'value', 'standard error', 'state'].map((h) => el('th', { text: h }))));
      for (const p of R.parameters) {
        t.append(el('tr', p.undetermined ? { class: 'undetermined' } : {},
          el('td', { text: p.name }), el('td', { text: fmt(p.value) }), el('td', { text: fmt(p.std_error) }), el('td', { text: p.state })));
      }
      sec.append(t);
      const w = R.warnings || [];
      sec.append(el('h3', { text: `Warnings (${w.length})` }), el('ul', { id: 'warnings' }, ...w.map((x) => el('li', { text: x }))));
    }
    const g = D.gltf_route;
    sec.append(el('h3', { text: `The glTF route: ${g.kind}` }), el('p', { text: g.text }));
    if (g.why_converted) sec.append(el('p', { text: g.why_converted }));
    sec.append(el('table', { id: 'gltf' }, ...Object.entries(g.values).map(([k, v]) => el('tr', {}, el('td', { text: k }), el('td', { text: fmt(v) })))));
    if (D.notes.length) sec.append(el('h3', { text: 'Not shown' }), el('ul', {}, ...D.notes.map((x) => el('li', { text: x }))));
    return sec;
  }

  // ---------- WebGL2
  const gl = glCanvas.getContext('webgl2', { antialias: true, preserveDrawingBuffer: true });
  if (!gl) {
    console.error('fibrefit view: this browser has no WebGL2');
    return;
  }
  const floatTargets = !!gl.getExtension('EXT_color_buffer_float');
  const VS = `#version 300 es
in vec3 aP; in vec3 aN; in vec3 aT; in float aH;
uniform mat4 uM;
out vec3 vN; out vec3 vT; out float vH;
void main() { vN = aN; vT = aT; vH = aH; gl_Position = uM * vec4(aP, 1.0); }
`;
  const FS_MAIN = `
in vec3 vN; in vec3 vT; in float vH;
uniform vec3 uL; uniform vec3 uV; uniform float uExposure; uniform float uFill; uniform float uOffset;
uniform int uRoute; uniform int uLinear; uniform int uTwoSided;
out vec4 viewColour;
vec3 view_brdf(vec3 l, vec3 v, vec3 n, vec3 t) {
  if (uRoute == 1) return fibrefit_brdf_at(l, v, n, t, 0.0, uOffset);
  if (vH >= 0.0) return fibrefit_brdf_at(l, v, n, t, vH, 0.0);
  return fibrefit_brdf(l, v, n, t);
}
float view_srgb(float x) {
  x = clamp(x, 0.0, 1.0);
  return x <= 0.0031308 ? 12.92 * x : 1.055 * pow(x, 1.0 / 2.4) - 0.055;
}
void main() {
  vec3 n = normalize(vN);
  if (uTwoSided == 1 && dot(n, uV) < 0.0) n = -n;
  vec3 radiance = vec3(0.0);
  float cl = dot(n, uL);
  if (cl > 0.0) radiance += view_brdf(uL, uV, n, vT) * cl;
  float cv = dot(n, uV);
  if (uFill > 0.0 && cv > 0.0) radiance += uFill * view_brdf(uV, uV, n, vT) * cv;
  if (uLinear == 1) { viewColour = vec4(radiance, 1.0); return; }
  vec3 c = radiance * uExposure;
  viewColour = vec4(view_srgb(c.r), view_srgb(c.g), view_srgb(c.b), 1.0);
}
`;
  const LINE_VS = `#version 300 es
in vec3 aP; uniform mat4 uM;
void main() { gl_Position = uM * vec4(aP, 1.0); }
`;
  const LINE_FS = `#version 300 es
precision highp float; uniform vec3 uColour; out vec4 o;
void main() { o = vec4(uColour, 1.0); }
`;
  function program(vs, fs, what) {
    const p = gl.createProgram();
    for (const [type, src] of [[gl.VERTEX_SHADER, vs], [gl.FRAGMENT_SHADER, fs]]) {
      const s = gl.createShader(type);
      gl.shaderSource(s, src);
      gl.compileShader(s);
      if (!gl.getShaderParameter(s, gl.COMPILE_STATUS)) {
        throw new Error(`fibrefit view: the ${what} shader does not compile: ${gl.getShaderInfoLog(s)}`);
      }
      gl.attachShader(p, s);
    }
    gl.bindAttribLocation(p, 0, 'aP');
    gl.bindAttribLocation(p, 1, 'aN');
    gl.bindAttribLocation(p, 2, 'aT');
    gl.bindAttribLocation(p, 3, 'aH');
    gl.linkProgram(p);
    if (!gl.getProgramParameter(p, gl.LINK_STATUS)) {
      throw new Error(`fibrefit view: the ${what} program does not link: ${gl.getProgramInfoLog(p)}`);
    }
    const u = {};
    const n = gl.getProgramParameter(p, gl.ACTIVE_UNIFORMS);
    for (let i = 0; i < n; i++) {
      const name = gl.getActiveUniform(p, i).name;
      u[name] = gl.getUniformLocation(p, name);
    }
    return { p, u };
  }
  const t1 = performance.now();
  const programs = {
    exact: program(VS, D.glsl_es_preamble + D.shaders.exact + FS_MAIN, 'exact model'),
    gltf: program(VS, D.glsl_es_preamble + D.shaders.gltf + FS_MAIN, 'glTF route'),
    line: program(LINE_VS, LINE_FS, 'line'),
  };
  timings.compile_ms = performance.now() - t1;

  const bytes = (b64) => Uint8Array.from(atob(b64), (c) => c.charCodeAt(0));
  const f32 = (b64) => new Float32Array(bytes(b64).buffer);
  // an i16 array times scale / 32767 (src/export/view/mod.rs, mesh_json)
  const q16 = (a) => Float32Array.from(new Int16Array(bytes(a.data).buffer), (x) => x * a.scale / 32767);
  function buffer(target, data) {
    const b = gl.createBuffer();
    gl.bindBuffer(target, b);
    gl.bufferData(target, data, gl.STATIC_DRAW);
    return b;
  }
  const meshes = {};
  for (const m of D.meshes) {
    const vao = gl.createVertexArray();
    gl.bindVertexArray(vao);
    const P = q16(m.positions), N = q16(m.normals), Tn = q16(m.tangents);
    [P, N, Tn].forEach((a, i) => {
      buffer(gl.ARRAY_BUFFER, a);
      gl.enableVertexAttribArray(i);
      gl.vertexAttribPointer(i, 3, gl.FLOAT, false, 0, 0);
    });
    if (m.heights) {
      buffer(gl.ARRAY_BUFFER, f32(m.heights));
      gl.enableVertexAttribArray(3);
      gl.vertexAttribPointer(3, 1, gl.FLOAT, false, 0, 0);
    } else {
      gl.disableVertexAttribArray(3);
    }
    const raw = bytes(m.indices);
    const idx = m.index_bytes === 4 ? new Uint32Array(raw.buffer) : new Uint16Array(raw.buffer);
    buffer(gl.ELEMENT_ARRAY_BUFFER, idx);
    gl.bindVertexArray(null);
    // the fibre direction: short segments along the tangent at about 400 vertices
    const step = Math.max(1, Math.floor(m.vertices / 400));
    const seg = [];
    const len = 0.05 * m.bound, lift = 0.004 * m.bound;
    for (let i = 0; i < m.vertices; i += step) {
      const p = [0, 1, 2].map((k) => P[3 * i + k] + lift * N[3 * i + k]);
      const t = [0, 1, 2].map((k) => Tn[3 * i + k] * len);
      seg.push(...p.map((x, k) => x - t[k]), ...p.map((x, k) => x + t[k]));
    }
    const lineVao = gl.createVertexArray();
    gl.bindVertexArray(lineVao);
    buffer(gl.ARRAY_BUFFER, new Float32Array(seg));
    gl.enableVertexAttribArray(0);
    gl.vertexAttribPointer(0, 3, gl.FLOAT, false, 0, 0);
    gl.bindVertexArray(null);
    meshes[m.name] = { vao, count: idx.length, type: m.index_bytes === 4 ? gl.UNSIGNED_INT : gl.UNSIGNED_SHORT,
      heights: !!m.heights, bound: m.bound, label: m.label, lineVao, lines: seg.length / 3 };
  }
  const arrowVao = gl.createVertexArray();
  gl.bindVertexArray(arrowVao);
  const arrowBuf = buffer(gl.ARRAY_BUFFER, new Float32Array(6));
  gl.enableVertexAttribArray(0);
  gl.vertexAttribPointer(0, 3, gl.FLOAT, false, 0, 0);
  gl.bindVertexArray(null);

  // the orthographic camera of `render`: looking from `d` at the origin, up towards +z where it
  // can be, half width 1.05 x the object's bound
  function cameraMatrix(d, bound) {
    const forward = d.map((x) => -x);
    const worldUp = Math.abs(d[2]) > 0.999 ? [0, 1, 0] : [0, 0, 1];
    const right = norm(cross(forward, worldUp));
    const up = cross(right, forward);
    const hw = 1.05 * bound, zr = 2.5 * bound;
    return new Float32Array([
      right[0] / hw, up[0] / hw, -d[0] / zr, 0,
      right[1] / hw, up[1] / hw, -d[1] / zr, 0,
      right[2] / hw, up[2] / hw, -d[2] / zr, 0,
      0, 0, 0, 1]);
  }

  function drawObject(route, state, linear) {
    const m = meshes[state.object];
    const pr = programs[route];
    const M = cameraMatrix(dir(state.camera), m.bound);
    gl.useProgram(pr.p);
    gl.uniformMatrix4fv(pr.u.uM, false, M);
    gl.uniform3fv(pr.u.uL, dir(state.light));
    gl.uniform3fv(pr.u.uV, dir(state.camera));
    gl.uniform1f(pr.u.uExposure, state.exposure);
    gl.uniform1f(pr.u.uFill, state.fill);
    gl.uniform1f(pr.u.uOffset, route === 'gltf' ? D.gltf_route.azimuth_offset_rad : 0);
    gl.uniform1i(pr.u.uRoute, route === 'gltf' ? 1 : 0);
    gl.uniform1i(pr.u.uLinear, linear ? 1 : 0);
    gl.uniform1i(pr.u.uTwoSided, state.object === 'cloth' ? 1 : 0);
    gl.bindVertexArray(m.vao);
    if (!m.heights) gl.vertexAttrib1f(3, -1);
    gl.drawElements(gl.TRIANGLES, m.count, m.type, 0);
    gl.bindVertexArray(null);
    return M;
  }

  function drawLines(M, state) {
    const m = meshes[state.object];
    const pr = programs.line;
    gl.useProgram(pr.p);
    gl.uniformMatrix4fv(pr.u.uM, false, M);
    if (state.fibres) {
      gl.uniform3fv(pr.u.uColour, [0.1, 0.85, 0.95]);
      gl.bindVertexArray(m.lineVao);
      gl.drawArrays(gl.LINES, 0, m.lines);
    }
    const l = dir(state.light).map((x) => x * 1.3 * m.bound);
    gl.bindBuffer(gl.ARRAY_BUFFER, arrowBuf);
    gl.bufferSubData(gl.ARRAY_BUFFER, 0, new Float32Array([0, 0, 0, ...l]));
    gl.uniform3fv(pr.u.uColour, [1, 0.85, 0.2]);
    gl.bindVertexArray(arrowVao);
    gl.drawArrays(gl.LINES, 0, 2);
    gl.bindVertexArray(null);
  }

  function draw() {
    const w = glCanvas.width, h = glCanvas.height;
    gl.enable(gl.DEPTH_TEST);
    gl.bindFramebuffer(gl.FRAMEBUFFER, null);
    gl.viewport(0, 0, w, h);
    gl.clearColor(0.08, 0.08, 0.09, 1);
    gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
    ['exact', 'gltf'].forEach((route, i) => {
      gl.viewport(i * (w / 2), 0, w / 2, h);
      const M = drawObject(route, S, false);
      drawLines(M, S);
    });
    drawLight();
    drawComparison();
    // the controls follow the state (set from the hash or window.fibrefitView.set too)
    objectSel.value = S.object;
    expo.value = Math.log2(S.exposure / D.exposure);
    fill.value = S.fill;
    fibres.checked = S.fibres;
    objectLabel.textContent = meshes[S.object].label;
    readout.textContent = `light theta ${S.light[0].toFixed(1)}, phi ${S.light[1].toFixed(1)}; camera theta ${S.camera[0].toFixed(1)}, phi ${S.camera[1].toFixed(1)} (deg)`;
    document.getElementById('exposure-out').textContent = ` ${fmt(S.exposure)}`;
    document.getElementById('fill-out').textContent = ` ${S.fill.toFixed(2)}`;
  }

  // the linear radiance at the view's centre (the object's centre: the swatch's middle), as
  // `fibrefit render` computes it for the same light, camera and fill; for tests
  function probe(opts = {}) {
    const state = { ...S, ...opts };
    const route = opts.route || 'exact';
    if (!floatTargets) throw new Error('fibrefit view: no float render targets (EXT_color_buffer_float)');
    const fb = gl.createFramebuffer();
    const tex = gl.createTexture();
    gl.bindTexture(gl.TEXTURE_2D, tex);
    gl.texStorage2D(gl.TEXTURE_2D, 1, gl.RGBA32F, 1, 1);
    const depth = gl.createRenderbuffer();
    gl.bindRenderbuffer(gl.RENDERBUFFER, depth);
    gl.renderbufferStorage(gl.RENDERBUFFER, gl.DEPTH_COMPONENT24, 1, 1);
    gl.bindFramebuffer(gl.FRAMEBUFFER, fb);
    gl.framebufferTexture2D(gl.FRAMEBUFFER, gl.COLOR_ATTACHMENT0, gl.TEXTURE_2D, tex, 0);
    gl.framebufferRenderbuffer(gl.FRAMEBUFFER, gl.DEPTH_ATTACHMENT, gl.RENDERBUFFER, depth);
    gl.viewport(0, 0, 1, 1);
    gl.clearColor(0, 0, 0, 0);
    gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
    drawObject(route, state, true);
    const px = new Float32Array(4);
    gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.FLOAT, px);
    gl.bindFramebuffer(gl.FRAMEBUFFER, null);
    gl.deleteFramebuffer(fb);
    gl.deleteTexture(tex);
    gl.deleteRenderbuffer(depth);
    draw();
    return Array.from(px.slice(0, 3));
  }

  // ---------- the light widget: the hemisphere seen from above, theta linear in the radius
  const lc = lightCanvas.getContext('2d');
  function drawLight() {
    const W = lightCanvas.width, R = W / 2 - 12, c = W / 2;
    const at = ([t, p]) => [c + R * (t / 90) * Math.cos(p * DEG), c - R * (t / 90) * Math.sin(p * DEG)];
    lc.clearRect(0, 0, W, W);
    lc.fillStyle = '#1b1d22';
    lc.beginPath(); lc.arc(c, c, R, 0, 2 * Math.PI); lc.fill();
    lc.strokeStyle = '#3a3f48';
    for (const t of [30, 60, 90]) { lc.beginPath(); lc.arc(c, c, R * t / 90, 0, 2 * Math.PI); lc.stroke(); }
    const psi = D.fibre_azimuth_deg;
    const [a, b] = [at([90, psi]), at([90, psi + 180])];
    lc.strokeStyle = '#1ad9f2'; lc.lineWidth = 2;
    lc.beginPath(); lc.moveTo(...a); lc.lineTo(...b); lc.stroke(); lc.lineWidth = 1;
    lc.fillStyle = '#8a93a3'; lc.font = '11px sans-serif';
    lc.fillText('x', c + R + 2, c + 4); lc.fillText('y', c - 3, c - R - 2);
    const cam = at([Math.min(S.camera[0], 90), S.camera[1]]);
    lc.strokeStyle = '#e8e8e8'; lc.beginPath(); lc.arc(...cam, 7, 0, 2 * Math.PI); lc.stroke();
    const l = at(S.light);
    lc.fillStyle = '#ffd633'; lc.beginPath(); lc.arc(...l, 7, 0, 2 * Math.PI); lc.fill();
  }
  function lightFrom(ev) {
    const r = lightCanvas.getBoundingClientRect();
    const W = lightCanvas.width, R = W / 2 - 12, c = W / 2;
    const x = ((ev.clientX - r.left) * W / r.width - c) / R, y = (c - (ev.clientY - r.top) * W / r.height) / R;
    S.light = [Math.min(Math.hypot(x, y), 1) * 90, (Math.atan2(y, x) / DEG + 360) % 360];
    draw();
  }
  let draggingLight = false;
  lightCanvas.addEventListener('pointerdown', (e) => { draggingLight = true; lightFrom(e); });
  window.addEventListener('pointerup', () => { draggingLight = false; draggingCamera = null; });
  lightCanvas.addEventListener('pointermove', (e) => { if (draggingLight) lightFrom(e); });
  let draggingCamera = null;
  glCanvas.addEventListener('pointerdown', (e) => { draggingCamera = [e.clientX, e.clientY]; });
  glCanvas.addEventListener('pointermove', (e) => {
    if (!draggingCamera) return;
    const [x0, y0] = draggingCamera;
    draggingCamera = [e.clientX, e.clientY];
    S.camera = [Math.min(179, Math.max(0, S.camera[0] - 0.5 * (e.clientY - y0))), (S.camera[1] - 0.5 * (e.clientX - x0) + 360) % 360];
    draw();
  });
  objectSel.addEventListener('change', () => { S.object = objectSel.value; draw(); });
  expo.addEventListener('input', () => { S.exposure = D.exposure * 2 ** Number(expo.value); draw(); });
  fill.addEventListener('input', () => { S.fill = Number(fill.value); draw(); });
  fibres.addEventListener('change', () => { S.fibres = fibres.checked; draw(); });

  // ---------- measured against fitted at the grid light nearest to the light
  const cc = compareCanvas.getContext('2d');
  const colours = [[68, 1, 84], [59, 82, 139], [33, 145, 140], [94, 201, 98], [253, 231, 37]];
  function colour(x) {
    const t = Math.min(Math.max(x, 0), 1) * (colours.length - 1);
    const i = Math.min(Math.floor(t), colours.length - 2), f = t - i;
    const c = colours[i].map((a, k) => Math.round(a + (colours[i + 1][k] - a) * f));
    return `rgb(${c[0]},${c[1]},${c[2]})`;
  }
  function nearestNode() {
    const l = dir(S.light);
    let best = null, bestCos = -2;
    for (const n of D.comparison.nodes) {
      const c = dot(l, dir([n.theta, n.phi]));
      if (c > bestCos) { bestCos = c; best = n; }
    }
    return best;
  }
  function drawComparison() {
    if (!D.comparison.available) {
      compareText.textContent = `Not shown: ${D.comparison.note}`;
      return;
    }
    const node = nearestNode();
    const W = compareCanvas.width, H = compareCanvas.height;
    cc.fillStyle = '#101114'; cc.fillRect(0, 0, W, H);
    const vals = [];
    for (const s of node.samples) vals.push(s[2], s[3]);
    for (const v of node.fitted_map) if (v !== null) vals.push(v);
    const pos = vals.filter((v) => v > 0).sort((a, b) => a - b);
    const lo = Math.log10(pos[Math.floor(0.02 * (pos.length - 1))] || 1e-3);
    const hi = Math.log10(pos[Math.floor(0.98 * (pos.length - 1))] || 1);
    const scale = (v) => (v > 0 ? (Math.log10(v) - lo) / Math.max(hi - lo, 1e-6) : 0);
    const R = 120, cy = 155;
    const disc = (cx, title) => {
      cc.fillStyle = '#1b1d22'; cc.beginPath(); cc.arc(cx, cy, R, 0, 2 * Math.PI); cc.fill();
      cc.fillStyle = '#d0d4dc'; cc.font = '13px sans-serif'; cc.fillText(title, cx - R, 20);
    };
    const ortho = (t, p, cx) => [cx + R * Math.sin(t * DEG) * Math.cos(p * DEG), cy - R * Math.sin(t * DEG) * Math.sin(p * DEG)];
    const marks = (cx) => {
      const psi = D.fibre_azimuth_deg;
      cc.strokeStyle = '#1ad9f2';
      cc.beginPath(); cc.moveTo(...ortho(90, psi, cx)); cc.lineTo(...ortho(90, psi + 180, cx)); cc.stroke();
      cc.fillStyle = '#ffd633'; cc.beginPath(); cc.arc(...ortho(node.theta, node.phi, cx), 5, 0, 2 * Math.PI); cc.fill();
    };
    const c1 = 20 + R, c2 = 60 + 3 * R;
    disc(c1, `measured: ${node.samples.length} samples`);
    disc(c2, 'fitted: every view, and at the samples');
    const n = D.comparison.map_size, cell = (2 * R) / n;
    node.fitted_map.forEach((v, k) => {
      if (v === null) return;
      const i = k % n, j = Math.floor(k / n);
      cc.fillStyle = colour(scale(v));
      cc.fillRect(c2 - R + i * cell, cy - R + j * cell, cell + 0.5, cell + 0.5);
    });
    for (const [to, po, meas, fit] of node.samples) {
      for (const [cx, v] of [[c1, meas], [c2, fit]]) {
        cc.fillStyle = colour(scale(v)); cc.strokeStyle = '#000';
        cc.beginPath(); cc.arc(...ortho(to, po, cx), 4, 0, 2 * Math.PI); cc.fill(); cc.stroke();
      }
    }
    marks(c1); marks(c2);
    // measured against fitted, log-log
    const x0 = 100 + 4 * R, size = 2 * R, y0 = cy + R;
    cc.strokeStyle = '#3a3f48'; cc.strokeRect(x0, y0 - size, size, size);
    cc.beginPath(); cc.moveTo(x0, y0); cc.lineTo(x0 + size, y0 - size); cc.stroke();
    cc.fillStyle = '#d0d4dc';
    cc.fillText('fitted against measured (log, 1/sr)', x0, 20);
    cc.fillText(`${fmt(10 ** lo)}`, x0, y0 + 14); cc.fillText(`${fmt(10 ** hi)}`, x0 + size - 40, y0 + 14);
    let sum = 0, m = 0;
    for (const [, , meas, fit] of node.samples) {
      if (!(meas > 0 && fit > 0)) continue;
      const r = (fit - meas) / meas; sum += r * r; m++;
      cc.fillStyle = '#ffd633';
      cc.beginPath(); cc.arc(x0 + size * Math.min(Math.max(scale(meas), 0), 1), y0 - size * Math.min(Math.max(scale(fit), 0), 1), 2.5, 0, 2 * Math.PI); cc.fill();
    }
    // the colour bar
    for (let k = 0; k < 100; k++) { cc.fillStyle = colour(k / 99); cc.fillRect(x0 + size + 30, y0 - (k + 1) * size / 100, 14, size / 100 + 1); }
    cc.fillStyle = '#d0d4dc';
    cc.fillText(fmt(10 ** hi), x0 + size + 48, y0 - size + 10); cc.fillText(fmt(10 ** lo), x0 + size + 48, y0);
    compareText.textContent = `grid light theta ${node.theta}, phi ${node.phi} deg (nearest to the light): ${node.samples.length} samples within ${D.comparison.near_deg} deg; relative RMS of fitted - measured ${m ? (100 * Math.sqrt(sum / m)).toFixed(1) : '?'} %`;
  }

  // ---------- start
  draw();
  timings.first_frame_ms = performance.now() - T0;
  window.addEventListener('hashchange', () => { readHash(); draw(); });
  window.fibrefitView = {
    probe,
    state: () => ({ ...S }),
    set: (o) => { Object.assign(S, o); draw(); },
    timings,
    floatTargets,
  };
  window.fibrefitReady = true;
})();
