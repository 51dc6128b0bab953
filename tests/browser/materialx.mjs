// Issue 37 item 5: the `openpbr` rung proven in MaterialX itself. For fits of the shipped felt,
// silk and brushed data (`fibrefit fit --model openpbr`), `fibrefit export --materialx` writes the
// document; MaterialX (the `materialx` package, scripts/materialx_essl.py) generates its GLSL ES
// shaders with one directional light, as MaterialX's own viewer does (the environment black), and the
// uniform values it reads from the document. Headless Chromium (SwiftShader WebGL2) runs those
// shaders on a flat swatch (normal +z, UV tangent +x) into a float target, one pixel per
// direction pair, with the camera at the view direction and the light of intensity E along the
// light direction; the check is pixel = eval x cos(theta_i) x E within 1 % at 14 pairs per fit
// (normal, 45 and 80 deg; along, across and between the fibres; light or view grazing).
//
// Usage: node materialx.mjs  (env FIBREFIT: the fibrefit binary, default $CARGO_TARGET_DIR or
// ../../target, debug/fibrefit; PYTHON: a Python with `materialx`, default ../../.venv-test;
// CHROMIUM: the browser, default /usr/bin/chromium)
import { chromium } from 'playwright-core';
import { execFileSync } from 'node:child_process';
import fs from 'node:fs';
import os from 'node:os';
import path from 'node:path';
import { fileURLToPath } from 'node:url';

const started = Date.now();
const here = path.dirname(fileURLToPath(import.meta.url));
const repo = path.resolve(here, '../..');
const targetDir = process.env.CARGO_TARGET_DIR || path.join(repo, 'target');
const fibrefit = process.env.FIBREFIT || path.join(targetDir, 'debug', 'fibrefit');
const python = process.env.PYTHON || path.join(repo, '.venv-test', 'bin', 'python');
const browserPath = process.env.CHROMIUM || '/usr/bin/chromium';
const TOLERANCE = 0.01;
const E = 3.0;

const DATA = [
  ['felt', path.join(repo, 'tests/data/rgl/acrylic_felt_green_rgb.bsdf'), ['--directions', '1500']],
  ['silk', path.join(repo, 'data_synthetic/silk/gonio.csv'), []],
  ['brushed', path.join(repo, 'data_synthetic/brushed/gonio.csv'), []],
];

// (theta_l, phi_l, theta_v, phi_v), degrees, about the fibre azimuth psi
function pairs(psi) {
  return [
    [0, 0, 0, 0], [45, psi, 45, psi + 180], [45, psi + 90, 45, psi + 270], [45, psi + 45, 45, psi + 225],
    [80, psi, 45, psi + 180], [45, psi + 90, 80, psi + 270], [80, psi, 80, psi + 180],
    [80, psi + 90, 80, psi + 270], [0, 0, 80, psi], [80, psi + 90, 0, 0], [45, psi, 45, psi + 90],
    [30, psi + 90, 60, psi], [60, psi + 200, 20, psi + 70], [80, psi + 135, 45, psi + 10],
  ];
}

function run(cmd, args) {
  return execFileSync(cmd, args, { encoding: 'utf8', stdio: ['ignore', 'pipe', 'pipe'], maxBuffer: 1 << 28 });
}

function readCsv(file) {
  const [head, ...rows] = fs.readFileSync(file, 'utf8').trim().split('\n');
  const cols = head.split(',');
  return rows.map((r) => Object.fromEntries(r.split(',').map((x, i) => [cols[i], Number(x)])));
}

// In the page: render each pair of `P` with MaterialX's shaders, one pixel each; returns RGB
// per pair (the float target's values).
function renderInPage([shaders, P, E]) {
  const n = P.length;
  const canvas = document.createElement('canvas');
  const gl = canvas.getContext('webgl2');
  if (!gl) throw new Error('no WebGL2');
  if (!gl.getExtension('EXT_color_buffer_float')) throw new Error('no EXT_color_buffer_float');
  const compile = (type, src) => {
    const s = gl.createShader(type);
    gl.shaderSource(s, src);
    gl.compileShader(s);
    if (!gl.getShaderParameter(s, gl.COMPILE_STATUS)) throw new Error(gl.getShaderInfoLog(s));
    return s;
  };
  const prog = gl.createProgram();
  gl.attachShader(prog, compile(gl.VERTEX_SHADER, shaders.vertex));
  gl.attachShader(prog, compile(gl.FRAGMENT_SHADER, shaders.pixel));
  gl.linkProgram(prog);
  if (!gl.getProgramParameter(prog, gl.LINK_STATUS)) throw new Error(gl.getProgramInfoLog(prog));
  gl.useProgram(prog);
  const u = (name) => gl.getUniformLocation(prog, name);
  // MaterialX's values from the document
  for (const [name, type, value] of shaders.uniforms) {
    const loc = u(name);
    if (loc === null) continue;
    if (type === 'float') gl.uniform1f(loc, value);
    else if (type === 'integer' || type === 'boolean') gl.uniform1i(loc, Number(value));
    else if (type === 'color3' || type === 'vector3') gl.uniform3fv(loc, value);
    else if (type === 'matrix44') gl.uniformMatrix4fv(loc, false, value);
    else throw new Error(`uniform ${name}: type ${type}`);
  }
  const id = new Float32Array([1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]);
  for (const m of ['u_worldMatrix', 'u_viewProjectionMatrix', 'u_worldInverseTransposeMatrix']) {
    gl.uniformMatrix4fv(u(m), false, id);
  }
  // a black environment: the light alone
  gl.uniform1f(u('u_envLightIntensity'), 0);
  gl.uniform1i(u('u_numActiveLightSources'), 1);
  gl.uniform1i(u('u_lightData[0].type'), 1);
  gl.uniform3fv(u('u_lightData[0].color'), [1, 1, 1]);
  gl.uniform1f(u('u_lightData[0].intensity'), E);
  // a quad over the viewport: world = clip space, z = 0; the pixel's centre is the origin
  const attr = (name, data) => {
    const loc = gl.getAttribLocation(prog, name);
    if (loc < 0) return;
    const b = gl.createBuffer();
    gl.bindBuffer(gl.ARRAY_BUFFER, b);
    gl.bufferData(gl.ARRAY_BUFFER, new Float32Array(data), gl.STATIC_DRAW);
    gl.enableVertexAttribArray(loc);
    gl.vertexAttribPointer(loc, 3, gl.FLOAT, false, 0, 0);
  };
  attr('i_position', [-1, -1, 0, 1, -1, 0, -1, 1, 0, 1, 1, 0]);
  attr('i_normal', [0, 0, 1, 0, 0, 1, 0, 0, 1, 0, 0, 1]);
  attr('i_tangent', [1, 0, 0, 1, 0, 0, 1, 0, 0, 1, 0, 0]);
  const tex = gl.createTexture();
  gl.bindTexture(gl.TEXTURE_2D, tex);
  gl.texStorage2D(gl.TEXTURE_2D, 1, gl.RGBA32F, n, 1);
  const fb = gl.createFramebuffer();
  gl.bindFramebuffer(gl.FRAMEBUFFER, fb);
  gl.framebufferTexture2D(gl.FRAMEBUFFER, gl.COLOR_ATTACHMENT0, gl.TEXTURE_2D, tex, 0);
  gl.clearColor(0, 0, 0, 0);
  gl.clear(gl.COLOR_BUFFER_BIT);
  const dir = (t, p) => {
    const [tr, pr] = [t * Math.PI / 180, p * Math.PI / 180];
    return [Math.sin(tr) * Math.cos(pr), Math.sin(tr) * Math.sin(pr), Math.cos(tr)];
  };
  P.forEach(([tl, pl, tv, pv], i) => {
    const l = dir(tl, pl);
    gl.viewport(i, 0, 1, 1);
    gl.uniform3fv(u('u_viewPosition'), dir(tv, pv));
    gl.uniform3fv(u('u_lightData[0].direction'), l.map((x) => -x));
    gl.drawArrays(gl.TRIANGLE_STRIP, 0, 4);
  });
  const px = new Float32Array(4 * n);
  gl.readPixels(0, 0, n, 1, gl.RGBA, gl.FLOAT, px);
  return P.map((_, i) => [px[4 * i], px[4 * i + 1], px[4 * i + 2]]);
}

async function main() {
  if (!fs.existsSync(fibrefit)) throw new Error(`${fibrefit}: no fibrefit binary (cargo build, or set FIBREFIT)`);
  const work = fs.mkdtempSync(path.join(os.tmpdir(), 'fibrefit-materialx-'));
  const browser = await chromium.launch({
    executablePath: browserPath,
    headless: true,
    args: ['--no-sandbox', '--use-angle=swiftshader', '--enable-unsafe-swiftshader', '--disable-quic',
      '--no-first-run', '--disable-background-networking', '--disable-component-update', '--disable-sync'],
  });
  let failed = false;
  try {
    const page = await browser.newPage();
    const errors = [];
    page.on('pageerror', (e) => errors.push(e.message));
    await page.setContent('<!doctype html><title>fibrefit MaterialX</title>');
    console.log('OpenPBR (fibrefit export --materialx) in MaterialX\'s generated GLSL ES, WebGL2, against eval x cos x E:');
    for (const [name, data, extra] of DATA) {
      const result = path.join(work, `${name}.json`);
      const doc = path.join(work, `${name}.mtlx`);
      run(fibrefit, ['fit', data, '--model', 'openpbr', ...extra, '--out', result, '-q']);
      run(fibrefit, ['export', result, '--materialx', doc, '--name', `fibrefit_${name}`, '-q']);
      const shaders = JSON.parse(run(python, [path.join(repo, 'scripts/materialx_essl.py'), doc, `fibrefit_${name}`]));
      const psi = JSON.parse(fs.readFileSync(result, 'utf8')).parameters.fibre_azimuth_deg.value;
      const P = pairs(psi);
      const q = path.join(work, `${name}-q.csv`);
      fs.writeFileSync(q, 'theta_i,phi_i,theta_o,phi_o\n' + P.map((p) => p.join(',')).join('\n') + '\n');
      const csv = path.join(work, `${name}-eval.csv`);
      run(fibrefit, ['eval', '--params', result, '--queries', q, '--out', csv, '-q']);
      const want = readCsv(csv).map((r, i) => {
        const cos = Math.cos(P[i][0] * Math.PI / 180);
        const g = r.brdf_r === undefined ? [r.brdf, r.brdf, r.brdf] : [r.brdf_r, r.brdf_g, r.brdf_b];
        return g.map((x) => x * cos * E);
      });
      const got = await page.evaluate(renderInPage, [shaders, P, E]);
      let worst = { d: 0, i: 0 };
      got.forEach((rgb, i) => rgb.forEach((x, c) => {
        const d = Math.abs(x - want[i][c]) / Math.max(want[i][c], 1e-4 * E);
        if (d > worst.d) worst = { d, i };
      }));
      const lo = Math.min(...want.flat());
      const hi = Math.max(...want.flat());
      console.log(`  ${name.padEnd(8)} ${P.length} pairs: worst relative difference ${worst.d.toExponential(2)} (at ${P[worst.i].map((x) => x.toFixed(1)).join(', ')}); values ${lo.toPrecision(3)}..${hi.toPrecision(3)}`);
      if (!(worst.d < TOLERANCE)) {
        failed = true;
        console.log(`FAIL: ${name}: MaterialX renders ${JSON.stringify(got[worst.i])}, the rung ${JSON.stringify(want[worst.i])}`);
      }
    }
    if (errors.length) {
      failed = true;
      console.log(`FAIL: page errors: ${errors.join('; ')}`);
    }
  } finally {
    await browser.close();
    fs.rmSync(work, { recursive: true, force: true });
  }
  console.log(`materialx.mjs: ${failed ? 'FAILED' : 'passed'} in ${((Date.now() - started) / 1000).toFixed(1)} s`);
  if (failed) process.exit(1);
}

main().catch((e) => {
  console.error(e);
  process.exit(1);
});
