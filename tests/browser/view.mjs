// Issue 38 item 4: `fibrefit view`'s page in headless Chromium (SwiftShader WebGL2).
//
// The page is opened from a file:// address with every other request refused (it must need no
// network). Checked: no console errors, a non-blank canvas, the measured-against-fitted picture
// drawn for a fit with enough directions (the silk gonio data) and said to be missing for a
// parameter file, and the exact model's linear radiance at the swatch's centre (the page's
// fibrefitView.probe, a float render target) equal to `fibrefit render`'s for the same light,
// camera and fill light (a 1 x 1 EXR whose only ray hits the swatch's centre) within 2 %, for
// several rungs and set-ups; for a `gltf` parameter file the glTF route's side too (it is the
// same material). Printed: the page's size and load time (navigation to the first frame).
//
// Usage: node view.mjs [--screenshot FILE.png]  (env FIBREFIT: the fibrefit binary, default
// $CARGO_TARGET_DIR or ../../target, debug/fibrefit; CHROMIUM: the browser, default
// /usr/bin/chromium)
import { chromium } from 'playwright-core';
import { execFileSync } from 'node:child_process';
import fs from 'node:fs';
import os from 'node:os';
import path from 'node:path';
import { fileURLToPath, pathToFileURL } from 'node:url';

const started = Date.now();
const here = path.dirname(fileURLToPath(import.meta.url));
const repo = path.resolve(here, '../..');
const targetDir = process.env.CARGO_TARGET_DIR || path.join(repo, 'target');
const fibrefit = process.env.FIBREFIT || path.join(targetDir, 'debug', 'fibrefit');
const browserPath = process.env.CHROMIUM || '/usr/bin/chromium';
const shotAt = process.argv.indexOf('--screenshot');
const screenshot = shotAt > 0 ? path.resolve(process.argv[shotAt + 1]) : null;
const TOLERANCE = 0.02;

// parameter files (no data: the page says the comparison is missing)
const PARAMS = {
  'poulin-fournier': 'model = "poulin-fournier"\nkd = [0.55, 0.35, 0.30]\nks = 0.25\nexponent = 60\nspacing = 2.0\nfibre_azimuth_deg = 20\n',
  'varying-topology': 'model = "varying-topology"\nkd = [0.5, 0.4, 0.3]\nks = 0.3\nexponent = 40\nspacing = 2.0\nheight = 0.9\nfibre_azimuth_deg = -35\nquadrature_order = 16\nhistogram_bins = 16\n',
  gltf: 'model = "gltf"\nkd = [0.55, 0.40, 0.30]\nmetallic = 0\nroughness = 0.35\nanisotropy_strength = 0.6\nspecular_factor = 0.8\nior = 1.5\nsheen = 0.4\nsheen_roughness = 0.5\nfibre_azimuth_deg = 30\n',
};
// light, camera (THETA,PHI degrees) and fill light irradiance
const SETUPS = [
  { light: [40, 120], camera: [50, 270], fill: 0.25 },
  { light: [60, 20], camera: [30, 200], fill: 0 },
  { light: [10, 300], camera: [70, 100], fill: 0.5 },
];

function run(args) {
  return execFileSync(fibrefit, args, { encoding: 'utf8', stdio: ['ignore', 'pipe', 'pipe'] });
}

// R, G, B of pixel (0, 0) of an EXR written by fibrefit (single part, scanlines or tiles, FLOAT
// channels, uncompressed or RLE: the writer stores a block uncompressed when RLE does not
// shrink it)
function exrPixel(file) {
  const b = fs.readFileSync(file);
  let o = 8;
  const header = {};
  for (;;) {
    const end = b.indexOf(0, o);
    const name = b.toString('latin1', o, end);
    o = end + 1;
    if (!name) break;
    const tEnd = b.indexOf(0, o);
    const type = b.toString('latin1', o, tEnd);
    o = tEnd + 1;
    const size = b.readInt32LE(o);
    o += 4;
    header[name] = { type, value: b.subarray(o, o + size) };
    o += size;
  }
  const channels = [];
  const list = header.channels.value;
  for (let p = 0; list[p] !== 0;) {
    const e = list.indexOf(0, p);
    channels.push({ name: list.toString('latin1', p, e), type: list.readInt32LE(e + 1) });
    p = e + 1 + 16;
  }
  const comp = header.compression.value[0];
  const dw = header.dataWindow.value;
  let width = dw.readInt32LE(8) - dw.readInt32LE(0) + 1;
  if (channels.some((c) => c.type !== 2)) throw new Error(`${file}: not all channels FLOAT`);
  // the first block: a scanline block (y, size) or a tile (x, y, level x, level y, size)
  const first = Number(b.readBigUInt64LE(o));
  const skip = header.tiles ? 16 : 4;
  if (header.tiles) width = Math.min(width, header.tiles.value.readUInt32LE(0));
  const size = b.readInt32LE(first + skip);
  let data = b.subarray(first + skip + 4, first + skip + 4 + size);
  const raw = channels.length * width * 4;
  if (size < raw) {
    if (comp !== 1) throw new Error(`${file}: compression ${comp} is not read here`);
    const out = [];
    for (let p = 0; p < data.length;) {
      const n = data.readInt8(p++);
      if (n < 0) { for (let k = 0; k < -n; k++) out.push(data[p++]); } else { for (let k = 0; k <= n; k++) out.push(data[p]); p++; }
    }
    for (let k = 1; k < out.length; k++) out[k] = (out[k - 1] + out[k] - 128) & 255;
    const half = Math.ceil(out.length / 2);
    const t = Buffer.alloc(out.length);
    for (let k = 0; k < out.length; k++) t[k] = k % 2 === 0 ? out[k / 2] : out[half + (k - 1) / 2];
    data = t;
  }
  const at = (name) => data.readFloatLE(channels.findIndex((c) => c.name === name) * width * 4);
  return [at('R'), at('G'), at('B')];
}

async function openPage(browser, file, errors) {
  const page = await browser.newPage({ viewport: { width: 1320, height: 1000 } });
  const name = path.basename(file);
  page.on('console', (m) => { if (m.type() === 'error') errors.push(`${name}: ${m.text()}`); });
  page.on('pageerror', (e) => errors.push(`${name}: ${e.message}`));
  // self-contained: any request but the page itself is refused and counted as an error
  await page.route('**/*', (r) => {
    if (r.request().url().startsWith('file:')) return r.continue();
    errors.push(`${name}: requested ${r.request().url()}`);
    return r.abort();
  });
  const t0 = Date.now();
  await page.goto(pathToFileURL(file).href);
  await page.waitForFunction(() => window.fibrefitReady === true, null, { timeout: 120000 });
  return { page, loadMs: Date.now() - t0 };
}

// the fraction of the canvas's pixels that differ from its background, and how many distinct
// colours it has
function canvasStats(page, id) {
  return page.evaluate((id) => {
    const c = document.getElementById(id);
    const t = document.createElement('canvas');
    t.width = c.width; t.height = c.height;
    const g = t.getContext('2d');
    g.drawImage(c, 0, 0);
    const d = g.getImageData(0, 0, t.width, t.height).data;
    const bg = [d[0], d[1], d[2]];
    let differ = 0;
    const seen = new Set();
    for (let i = 0; i < d.length; i += 4) {
      if (Math.abs(d[i] - bg[0]) + Math.abs(d[i + 1] - bg[1]) + Math.abs(d[i + 2] - bg[2]) > 6) differ++;
      seen.add((d[i] << 16) | (d[i + 1] << 8) | d[i + 2]);
    }
    return { covered: differ / (d.length / 4), colours: seen.size };
  }, id);
}

async function main() {
  if (!fs.existsSync(fibrefit)) throw new Error(`${fibrefit}: no fibrefit binary (cargo build, or set FIBREFIT)`);
  const work = fs.mkdtempSync(path.join(os.tmpdir(), 'fibrefit-view-'));
  const errors = [];
  let failed = false;
  const fail = (why) => { failed = true; console.log(`FAIL: ${why}`); };

  // a fit with enough directions: the silk gonio data, beside the result as the page looks for it
  fs.copyFileSync(path.join(repo, 'data_synthetic/silk/gonio.csv'), path.join(work, 'gonio.csv'));
  run(['fit', path.join(work, 'gonio.csv'), '--model', 'hast-diffuse', '--quiet', '--out', path.join(work, 'fit.json')]);
  const t0 = Date.now();
  run(['view', path.join(work, 'fit.json'), '--out', path.join(work, 'fit.html'), '-q']);
  const buildMs = Date.now() - t0;
  for (const [name, text] of Object.entries(PARAMS)) {
    fs.writeFileSync(path.join(work, `${name}.toml`), text);
    run(['view', path.join(work, `${name}.toml`), '--out', path.join(work, `${name}.html`), '-q']);
  }

  const browser = await chromium.launch({
    executablePath: browserPath,
    headless: true,
    args: ['--no-sandbox', '--use-angle=swiftshader', '--enable-unsafe-swiftshader', '--disable-quic',
      '--no-first-run', '--disable-background-networking', '--disable-component-update', '--disable-sync'],
  });
  try {
    // the fit's page: size, load time, a drawn canvas and comparison
    const fitHtml = path.join(work, 'fit.html');
    const { page, loadMs } = await openPage(browser, fitHtml, errors);
    const timings = await page.evaluate(() => window.fibrefitView.timings);
    const size = fs.statSync(fitHtml).size;
    console.log(`the page of a hast-diffuse fit of data_synthetic/silk/gonio.csv: ${size} bytes (built in ${(buildMs / 1000).toFixed(1)} s by the debug binary); ` +
      `load in headless Chromium (SwiftShader) ${loadMs} ms from navigation to the first frame ` +
      `(in the page: data parsed ${timings.parse_ms.toFixed(0)} ms, shaders compiled ${timings.compile_ms.toFixed(0)} ms, first frame at ${timings.first_frame_ms.toFixed(0)} ms)`);
    const gl = await canvasStats(page, 'gl');
    const cmp = await canvasStats(page, 'compare');
    console.log(`  canvas: ${(100 * gl.covered).toFixed(1)} % of the pixels drawn, ${gl.colours} colours; comparison canvas ${(100 * cmp.covered).toFixed(1)} %, ${cmp.colours} colours`);
    console.log(`  ${await page.textContent('#compare-note')}`);
    if (!(gl.covered > 0.05 && gl.colours >= 4)) fail('the viewer canvas is blank');
    if (!(cmp.covered > 0.1 && cmp.colours > 20)) fail('the measured-against-fitted canvas is blank');
    for (const object of ['sphere', 'torus', 'cloth']) {
      await page.evaluate((o) => window.fibrefitView.set({ object: o }), object);
      const s = await canvasStats(page, 'gl');
      if (!(s.covered > 0.05 && s.colours >= 20)) fail(`the ${object} draws blank`);
    }
    if (screenshot) {
      await page.evaluate(() => window.fibrefitView.set({ object: 'cloth', light: [55, 150], camera: [55, 250] }));
      await page.screenshot({ path: screenshot, fullPage: true });
      console.log(`  screenshot: ${screenshot}`);
    }
    await page.close();

    // the exact model at the swatch's centre against `fibrefit render`
    let worst = { d: 0 };
    for (const [name] of Object.entries(PARAMS)) {
      const params = path.join(work, `${name}.toml`);
      const { page: p } = await openPage(browser, path.join(work, `${name}.html`), errors);
      const note = await p.textContent('#compare-note');
      if (!note.startsWith('Not shown')) fail(`${name}: a parameter file's page does not say the comparison is missing`);
      const routes = name === 'gltf' ? ['exact', 'gltf'] : ['exact'];
      for (const s of SETUPS) {
        const exr = path.join(work, `${name}.exr`);
        run(['render', '--params', params, '--object', 'swatch', '--preset', 'flat', '--light', s.light.join(','),
          '--camera', s.camera.join(','), '--fill', String(s.fill), '--size', '1', '1', '--supersample', '1', '--out', exr, '-q']);
        const want = exrPixel(exr);
        for (const route of routes) {
          const got = await p.evaluate(([o]) => window.fibrefitView.probe(o), [{ ...s, object: 'swatch', route }]);
          const rel = got.map((g, c) => (g - want[c]) / want[c]);
          const d = rel.reduce((a, b) => (Math.abs(b) > Math.abs(a) ? b : a), 0);
          if (!(Math.abs(d) <= Math.abs(worst.d)) || !Number.isFinite(d)) worst = { d, name, route, s };
          console.log(`  ${name.padEnd(17)} ${route.padEnd(5)} light ${s.light} camera ${s.camera} fill ${s.fill}: render ${want.map((x) => x.toPrecision(5)).join('/')}, page ${got.map((x) => x.toPrecision(5)).join('/')}, ${(100 * d).toFixed(4)} %`);
        }
      }
      await p.close();
    }
    console.log(`the exact model's pixel at the swatch's centre against fibrefit render: worst ${(100 * worst.d).toFixed(4)} % (${worst.name}, ${worst.route}); tolerance ${100 * TOLERANCE} %`);
    if (!(Math.abs(worst.d) <= TOLERANCE)) fail('the page disagrees with fibrefit render beyond the tolerance');
  } finally {
    await browser.close();
  }
  if (errors.length) fail(`errors in the page: ${errors.join(' | ')}`);
  console.log(`\nviewer tests: ${failed ? 'FAILED' : 'passed'} in ${((Date.now() - started) / 1000).toFixed(1)} s`);
  process.exit(failed ? 1 : 0);
}

main().catch((e) => {
  console.error(e);
  process.exit(1);
});
