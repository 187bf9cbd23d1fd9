// End-to-end tests of the kesbrdf viewer: the Python server (`kesbrdf view`) plus the
// built bundle in src/kesbrdf/viewer/static, driven in Debian's Chromium through
// playwright-core (software WebGL2 on SwiftShader). Run with `npm test` in viewer/.
//
// Environment: KESBRDF_PYTHON (default ../.venv/bin/python), CHROMIUM (default
// /usr/bin/chromium). Screenshots and measured numbers go to viewer/test-output/.
import { chromium } from 'playwright-core';
import { spawn, spawnSync } from 'node:child_process';
import fs from 'node:fs';
import os from 'node:os';
import path from 'node:path';
import { fileURLToPath } from 'node:url';

const HERE = path.dirname(fileURLToPath(import.meta.url));
const VIEWER = path.resolve(HERE, '..');
const REPO = path.resolve(VIEWER, '..');
const PYTHON = path.resolve(VIEWER, process.env.KESBRDF_PYTHON ?? '../.venv/bin/python');
const CHROMIUM = process.env.CHROMIUM ?? '/usr/bin/chromium';
const OUT = path.join(VIEWER, 'test-output');
// the flags of docs/architecture.md, "Tools it runs on"; --enable-unsafe-swiftshader keeps WebGL on SwiftShader where the
// automatic software fallback is switched off in newer Chromium builds.
const CHROMIUM_FLAGS = [
  '--no-sandbox', '--disable-background-networking', '--disable-component-update',
  '--disable-sync', '--no-first-run', '--enable-unsafe-swiftshader', '--use-angle=swiftshader',
];

/** GLSL vs Python f_r: float32 shading against float64 numpy (issue 5: 1e-3 relative). */
const GLSL_REL_TOL = 1e-3;
/** The TypeScript CPU evaluator (float64, same recipe) must agree to rounding. */
const CPU_REL_TOL = 1e-9;
/** Preview pixel vs CPU evaluator, 8-bit sRGB levels: rounding (0.5) plus float32 shading. */
const PREVIEW_PIXEL_TOL = 1.5;
/** A canvas counts as rendered when its grey-level variance exceeds this (a blank one is 0). */
const MIN_VARIANCE = 20;
/** Upload limit given to the server under test (bytes): small so the oversize test is fast. */
const UPLOAD_LIMIT_MB = 0.2;
const UPLOAD_LIMIT = Math.floor(UPLOAD_LIMIT_MB * 1024 * 1024);
/** Frames averaged for the preview frame time. */
const BENCH_FRAMES = 10;

const results = [];
let failed = 0;
async function test(name, fn) {
  const t0 = Date.now();
  try {
    await fn();
    results.push({ name, ok: true });
    console.log(`ok - ${name} (${((Date.now() - t0) / 1000).toFixed(1)} s)`);
  } catch (e) {
    failed++;
    results.push({ name, ok: false, error: String(e?.stack ?? e) });
    console.log(`not ok - ${name}\n  ${String(e?.message ?? e).split('\n').join('\n  ')}`);
  }
}
function assert(cond, msg) {
  if (!cond) throw new Error(msg);
}

function python(args, opts = {}) {
  const env = { ...process.env, PYTHONPATH: path.join(REPO, 'src'), MPLBACKEND: 'Agg' };
  const r = spawnSync(PYTHON, args, { env, encoding: 'utf-8', ...opts });
  if (r.error) throw r.error;
  return r;
}

function startServer(modelPath) {
  const env = { ...process.env, PYTHONPATH: path.join(REPO, 'src') };
  const proc = spawn(PYTHON, ['-m', 'kesbrdf.cli.main', 'view', modelPath, '--port', '0', '--no-browser', '--max-upload-mb', String(UPLOAD_LIMIT_MB)], { env, stdio: ['ignore', 'pipe', 'pipe'] });
  return new Promise((resolve, reject) => {
    let out = '';
    let err = '';
    const timer = setTimeout(() => reject(new Error(`server did not print its URL: ${out} ${err}`)), 60000);
    proc.stdout.on('data', (d) => {
      out += d;
      const m = out.match(/(http:\/\/127\.0\.0\.1:\d+\/)/);
      if (m) {
        clearTimeout(timer);
        resolve({ proc, url: m[1], stderr: () => err });
      }
    });
    proc.stderr.on('data', (d) => (err += d));
    proc.on('exit', (code) => reject(new Error(`server exited with ${code}: ${err}`)));
  });
}

function writePLY(file) {
  // a small hanging cloth with UVs (u = warp), like kesbrdf drape writes
  const n = 40;
  const verts = [];
  const faces = [];
  for (let j = 0; j <= n; j++) {
    for (let i = 0; i <= n; i++) {
      const u = i / n;
      const v = j / n;
      const x = 2 * u - 1;
      const y = 2 * v - 1;
      const z = 0.25 * Math.sin(5 * x) * (1 - v) - 0.3 * x * x;
      verts.push(`${x} ${y} ${z} ${u} ${v}`);
      if (i < n && j < n) {
        const a = j * (n + 1) + i;
        faces.push(`3 ${a} ${a + 1} ${a + n + 2}`, `3 ${a} ${a + n + 2} ${a + n + 1}`);
      }
    }
  }
  const head = ['ply', 'format ascii 1.0', `element vertex ${verts.length}`, 'property float x', 'property float y', 'property float z', 'property float u', 'property float v', `element face ${faces.length}`, 'property list uchar int vertex_indices', 'end_header'];
  fs.writeFileSync(file, [...head, ...verts, ...faces].join('\n') + '\n');
}

async function main() {
  fs.mkdirSync(OUT, { recursive: true });
  const tmp = fs.mkdtempSync(path.join(os.tmpdir(), 'kesbrdf-viewer-test-'));
  const profile = path.join(tmp, 'profile');
  let server = null;
  let ctx = null;
  try {
    let r = python([path.join(HERE, 'pyhelper.py'), 'fixtures', tmp, String(UPLOAD_LIMIT)]);
    assert(r.status === 0, `fixtures failed: ${r.stderr}`);
    const modelPath = path.join(tmp, 'model', 'ward.kes.json');
    r = python([path.join(HERE, 'pyhelper.py'), 'reference', modelPath, path.join(tmp, 'ref.json')]);
    assert(r.status === 0, `reference failed: ${r.stderr}`);
    const ref = JSON.parse(fs.readFileSync(path.join(tmp, 'ref.json'), 'utf-8'));
    const asymPath = path.join(tmp, 'asym', 'asym.kes.json');
    r = python([path.join(HERE, 'pyhelper.py'), 'reference', asymPath, path.join(tmp, 'ref-asym.json')]);
    assert(r.status === 0, `reference (asymmetric) failed: ${r.stderr}`);
    const refAsym = JSON.parse(fs.readFileSync(path.join(tmp, 'ref-asym.json'), 'utf-8'));
    const asymDoc = JSON.parse(fs.readFileSync(asymPath, 'utf-8'));
    // the CLI's message for the bad CSV, run where the file is so it reads "bad.csv:<line>: ..."
    r = python(['-m', 'kesbrdf.cli.main', 'fit', 'bad.csv', '-o', path.join(tmp, 'bad.kes.json')], { cwd: tmp });
    const cliError = r.stderr.trim().replace(/^kesbrdf: error: /, '');
    writePLY(path.join(tmp, 'drape.ply'));

    server = await startServer(modelPath);
    ctx = await chromium.launchPersistentContext(profile, {
      executablePath: CHROMIUM,
      headless: true,
      args: CHROMIUM_FLAGS,
      viewport: { width: 1400, height: 900 },
    });
    const page = ctx.pages()[0] ?? (await ctx.newPage());
    const consoleErrors = [];
    page.on('pageerror', (e) => consoleErrors.push(String(e)));
    // the 400 and 413 answers to the bad and oversize uploads are expected
    const EXPECTED = /Failed to load resource: the server responded with a status of (400|413)/;
    page.on('console', (m) => m.type() === 'error' && !EXPECTED.test(m.text()) && consoleErrors.push(m.text()));
    const settle = () => page.evaluate(() => new Promise((res) => requestAnimationFrame(() => requestAnimationFrame(res))));
    const ready = () => page.waitForFunction(() => document.body.dataset.status === 'ready');
    const stats = (id) => page.evaluate((i) => window.kesbrdf.canvasStats(i), id);
    const shot = (name) => page.screenshot({ path: path.join(OUT, `${name}.png`) });
    const VIEW_CANVASES = {
      rhogamma: ['c-rhogamma'],
      polar: ['c-polar'],
      sphere: ['c-sphere'],
      hemi: ['c-hemi-model', 'c-hemi-ref', 'c-hemi-diff'],
      preview: ['c-preview'],
    };
    async function showView(view) {
      await page.click(`#tabs button[data-view="${view}"]`);
      await settle();
      assert((await page.evaluate(() => document.body.dataset.view)) === view, `view ${view} not shown`);
    }
    async function checkViews(prefix) {
      for (const [view, ids] of Object.entries(VIEW_CANVASES)) {
        await showView(view);
        for (const id of ids) {
          const s = await stats(id);
          assert(s.variance > MIN_VARIANCE, `${view}: canvas #${id} looks blank (variance ${s.variance.toFixed(2)})`);
        }
        await shot(`${prefix}-${view}`);
      }
    }

    await test('page opens and loads the model given to `kesbrdf view`', async () => {
      await page.goto(`${server.url}?testhooks`); // loads the test-only hooks (src/testhooks.ts)
      await ready();
      const model = await page.evaluate(() => document.body.dataset.model);
      assert(model === 'ward.kes.json', `expected model ward.kes.json, got ${model}`);
      assert(await page.isHidden('#error'), `error shown: ${await page.textContent('#error')}`);
    });

    await test('the mapping starts at the one the model records (parameters.mapping)', async () => {
      const recorded = JSON.parse(fs.readFileSync(modelPath, 'utf-8')).parameters?.mapping ?? 'deviation';
      assert(recorded === 'halfvector', `a new kes fit records mapping halfvector, got ${recorded}`);
      const shown = await page.evaluate(() => document.getElementById('mapping').value);
      assert(shown === recorded, `mapping select shows ${shown}, the model records ${recorded}`);
    });

    await test('every view renders non-blank', () => checkViews('view'));

    await test('every view renders for every mapping (deviation, halfvector, paper)', async () => {
      for (const mapping of ['halfvector', 'paper', 'deviation']) {
        await page.selectOption('#mapping', mapping);
        for (const view of ['hemi', 'preview']) {
          await showView(view);
          const s = await stats(view === 'hemi' ? 'c-hemi-model' : 'c-preview');
          assert(s.variance > MIN_VARIANCE, `${view} blank with mapping ${mapping}`);
          if (mapping !== 'deviation') await shot(`mapping-${mapping}-${view}`);
        }
      }
    });

    async function agreement(refData, label) {
      const report = { source: refData.source };
      for (const mapping of ['deviation', 'halfvector', 'paper']) {
        const gl = await page.evaluate(([p, m]) => window.kesbrdf.evalPairsGL(p, m), [refData.pairs, mapping]);
        const cpu = await page.evaluate(([p, m]) => window.kesbrdf.evalPairsCPU(p, m), [refData.pairs, mapping]);
        let worst = 0;
        let worstCpu = 0;
        let where = -1;
        let n = 0;
        refData.values[mapping].forEach((want, k) => {
          if (mapping === 'paper' && !refData.paper_ok[k]) return;
          n++;
          for (let c = 0; c < 3; c++) {
            const scale = Math.max(Math.abs(want[c]), 1e-12);
            const e = Math.abs(gl[k][c] - want[c]) / scale;
            if (!(e <= worst)) {
              worst = e;
              where = k;
            }
            worstCpu = Math.max(worstCpu, Math.abs(cpu[k][c] - want[c]) / scale);
          }
        });
        report[mapping] = { pairs: n, maxRelGLSL: worst, maxRelCPU: worstCpu };
        assert(worst <= GLSL_REL_TOL, `${label} ${mapping}: GLSL max rel. error ${worst} at pair ${where} ${JSON.stringify(refData.pairs[where])}: GLSL ${gl[where]}, Python ${refData.values[mapping][where]}`);
        assert(worstCpu <= CPU_REL_TOL, `${label} ${mapping}: TypeScript evaluator max rel. error ${worstCpu}`);
      }
      console.log(`  ${label}: ${JSON.stringify(report)}`);
      return report;
    }

    await test('a model kind the viewer cannot show is refused with a clear message', async () => {
      const message = await page.evaluate(([doc]) => {
        try {
          window.kesbrdf.loadModelDoc({ ...doc, kind: 'kes-halfdiff' }, 'hd.kes.json');
          return null;
        } catch (e) {
          return e.message;
        }
      }, [asymDoc]);
      assert(message !== null && message.startsWith("hd.kes.json: the viewer shows models of kind 'kes'; this is a 'kes-halfdiff' model"),
        `unexpected message ${message}`);
    });

    await test('a model file with an unknown normalisation or extrapolation is refused', async () => {
      // the Python reader refuses these (kesbrdf.models.kes.Model.from_payload); shading them
      // the old way would disagree with kesbrdf.models.brdf.evaluate silently
      for (const [key, value] of [['normalisation', 'cosine'], ['extrapolation', 'mirror']]) {
        const message = await page.evaluate(([doc, k, v]) => {
          try {
            window.kesbrdf.loadModelDoc({ ...doc, parameters: { ...doc.parameters, [k]: v } }, 'odd.kes.json');
            return null;
          } catch (e) {
            return e.message;
          }
        }, [asymDoc, key, value]);
        assert(message !== null && message.startsWith(`odd.kes.json: parameters.${key}: expected one of`) && message.includes(`"${value}"`),
          `unexpected message for ${key} = ${value}: ${message}`);
      }
    });

    await test(`GLSL shading agrees with Python (${ref.source}) within ${GLSL_REL_TOL} relative`, async () => {
      const report = { ward: await agreement(ref, 'fitted Ward model') };
      // an asymmetric lobe: a mirrored or transposed table lookup would fail here
      await page.evaluate(([doc]) => window.kesbrdf.loadModelDoc(doc, 'asym.kes.json'), [asymDoc]);
      try {
        report.asymmetric = await agreement(refAsym, 'asymmetric lobe');
        // the preview's own plumbing (warp = dP/du, light and view in the fabric frame,
        // body, exposure, sRGB) against the CPU evaluator on the flat swatch
        await showView('preview');
        const probes = [];
        for (const [theta, phi, ev, px, py] of [[12, 60, -1.5, 256, 256], [12, 240, -1.5, 256, 256], [50, 150, 0, 330, 220], [20, 300, -2, 200, 300]]) {
          const p = await page.evaluate((a) => window.kesbrdf.previewProbe(...a), [theta, phi, ev, px, py]);
          assert(p.hit, 'probe pixel is not on the swatch');
          const err = Math.max(...p.got.map((g, c) => Math.abs(g - p.expected[c])));
          probes.push({ theta, phi, got: p.got, expected: p.expected.map((x) => Number(x.toFixed(2))) });
          assert(err <= PREVIEW_PIXEL_TOL, `preview pixel ${p.got} vs CPU ${p.expected.map((x) => x.toFixed(1))} for light θ=${theta}°, φ=${phi}°`);
        }
        // the test lobe is twice as wide toward φ = 60° as toward 240°: the pixels must show it
        assert(probes[0].got[0] - probes[1].got[0] > 10, `asymmetric lobe: ${probes[0].got} vs ${probes[1].got} from opposite light azimuths`);
        report.previewProbes = probes;
      } finally {
        await page.selectOption('#model-select', { label: 'ward.kes.json' });
        await page.waitForFunction(() => document.body.dataset.model === 'ward.kes.json');
        await ready();
      }
      fs.writeFileSync(path.join(OUT, 'glsl-agreement.json'), JSON.stringify(report, null, 2));
    });

    await test('dragging the light moves it and changes the preview and the maps', async () => {
      await showView('preview');
      const before = await stats('c-preview');
      const box = await page.locator('#light').boundingBox();
      const cx = box.x + box.width / 2;
      const cy = box.y + box.height / 2;
      await page.mouse.move(cx, cy - box.height * 0.15);
      await page.mouse.down();
      for (let k = 1; k <= 5; k++) await page.mouse.move(cx + box.width * 0.06 * k, cy - box.height * 0.15 + box.height * 0.02 * k);
      await page.mouse.up();
      await settle();
      const st = await page.evaluate(() => ({ t: window.kesbrdf.state.thetaI, p: window.kesbrdf.state.phiI }));
      assert(Math.abs(st.p - Math.PI / 2) > 0.3, `light azimuth did not follow the drag: φi = ${st.p}`);
      const after = await stats('c-preview');
      assert(Math.abs(after.mean - before.mean) > 0.05 || Math.abs(after.variance - before.variance) > 0.5, 'preview did not change after dragging the light');
      await shot('light-dragged-preview');
      await showView('hemi');
      const s = await stats('c-hemi-model');
      assert(s.variance > MIN_VARIANCE, 'hemisphere map blank after drag');
      await shot('light-dragged-hemi');
    });

    await test('changing the body colour recolours the preview (docs/method.md, "Colour")', async () => {
      await showView('preview');
      await page.selectOption('#object', 'cloth');
      await settle();
      const grab = () => page.evaluate(() => {
        const c = document.getElementById('c-preview');
        const t = document.createElement('canvas');
        t.width = c.width;
        t.height = c.height;
        const x = t.getContext('2d');
        x.drawImage(c, 0, 0);
        const d = x.getImageData(0, 0, t.width, t.height).data;
        let r = 0, g = 0, b = 0;
        for (let k = 0; k < d.length; k += 4) { r += d[k]; g += d[k + 1]; b += d[k + 2]; }
        const n = d.length / 4;
        return [r / n, g / n, b / n];
      });
      await page.$eval('#color', (el) => { el.value = '#1040c0'; el.dispatchEvent(new Event('input', { bubbles: true })); });
      await settle();
      const blue = await grab();
      await page.$eval('#color', (el) => { el.value = '#c04010'; el.dispatchEvent(new Event('input', { bubbles: true })); });
      await settle();
      const orange = await grab();
      assert(blue[2] > blue[0] && orange[0] > orange[2], `colour did not follow the picker: blue ${blue}, orange ${orange}`);
      assert(await page.isChecked('#use-color'), 'picking a colour should switch to the picked body colour');
      await shot('colour-orange-cloth');
      await page.$eval('#exposure', (el) => { el.value = '1.5'; el.dispatchEvent(new Event('input', { bubbles: true })); });
      await settle();
      const bright = await grab();
      assert(bright[0] > orange[0], 'exposure did not brighten the preview');
      await page.selectOption('#object', 'swatch');
      await settle();
      assert((await stats('c-preview')).variance > 0, 'swatch not drawn');
      await shot('colour-orange-swatch');
      await page.selectOption('#object', 'sphere');
      await settle();
      await shot('colour-orange-sphere');
    });

    await test('a drape mesh PLY replaces the procedural fold', async () => {
      await page.setInputFiles('#ply', path.join(tmp, 'drape.ply'));
      await settle();
      await settle();
      const info = await page.textContent('#preview-info');
      assert(info.includes('drape mesh'), `preview info: ${info}`);
      assert((await stats('c-preview')).variance > MIN_VARIANCE, 'drape mesh preview blank');
      await shot('drape-mesh');
    });

    await test('uploading a good CSV fits it and compares with its reference', async () => {
      await page.setInputFiles('#upload', path.join(tmp, 'good.csv'));
      await page.waitForFunction(() => document.body.dataset.model === 'good.csv', null, { timeout: 60000 });
      await ready();
      assert(await page.isHidden('#error'), `error shown: ${await page.textContent('#error')}`);
      const options = await page.$$eval('#model-select option', (o) => o.map((x) => x.textContent));
      assert(options.some((t) => t.includes('good.csv')), `fitted upload not listed: ${options}`);
      await showView('hemi');
      const info = await page.textContent('#hemi-info');
      assert(/max \|relative difference\|/.test(info), `no comparison shown: ${info}`);
      for (const id of VIEW_CANVASES.hemi) assert((await stats(id)).variance > MIN_VARIANCE, `#${id} blank after upload`);
      await shot('upload-good-hemi');
    });

    await test('uploading a bad CSV shows the CLI\'s one-line error and the page keeps working', async () => {
      await page.setInputFiles('#upload', path.join(tmp, 'bad.csv'));
      await page.waitForSelector('#error:not([hidden])');
      const msg = (await page.textContent('#error')).trim();
      assert(cliError.length > 0, 'the CLI gave no error for bad.csv');
      assert(msg === cliError, `page error ${JSON.stringify(msg)} differs from the CLI's ${JSON.stringify(cliError)}`);
      await shot('upload-bad-error');
      await checkViews('after-error');
    });

    await test('an oversize upload is refused with 413 and the server keeps serving', async () => {
      const big = fs.readFileSync(path.join(tmp, 'big.csv'));
      assert(big.length > UPLOAD_LIMIT, 'fixture not over the limit');
      await page.setInputFiles('#upload', { name: 'big.csv', mimeType: 'text/csv', buffer: big });
      await page.waitForFunction(() => /too large/.test(document.getElementById('error').textContent));
      const res = await page.evaluate(async () => (await fetch('api/models')).status);
      assert(res === 200, `server not answering after oversize upload: ${res}`);
    });

    await test(`preview frame time at 512×512 on SwiftShader (${BENCH_FRAMES} frames)`, async () => {
      await showView('preview');
      await page.selectOption('#mapping', 'deviation');
      const renderer = await page.evaluate(() => {
        const gl = document.createElement('canvas').getContext('webgl2');
        const ext = gl.getExtension('WEBGL_debug_renderer_info');
        return gl.getParameter(ext ? ext.UNMASKED_RENDERER_WEBGL : gl.RENDERER);
      });
      const timing = { renderer };
      for (const obj of ['sphere', 'swatch', 'cloth']) {
        await page.selectOption('#object', obj);
        await settle();
        await page.evaluate(() => window.kesbrdf.benchPreview(2)); // warm-up: SwiftShader compiles per state
        const t = await page.evaluate((n) => window.kesbrdf.benchPreview(n), BENCH_FRAMES);
        assert(t.width === 512 && t.height === 512, `preview canvas is ${t.width}×${t.height}`);
        timing[obj] = Number(t.msPerFrame.toFixed(1));
      }
      fs.writeFileSync(path.join(OUT, 'frame-time.json'), JSON.stringify(timing, null, 2));
      console.log(`  ms/frame at 512×512: ${JSON.stringify(timing)}`);
    });

    await test('no uncaught errors in the page', async () => {
      assert(consoleErrors.length === 0, consoleErrors.join('\n'));
    });
  } catch (e) {
    failed++;
    console.log(`not ok - setup: ${e?.stack ?? e}`);
  } finally {
    if (ctx) await ctx.close();
    if (server) server.proc.kill('SIGTERM');
    fs.rmSync(tmp, { recursive: true, force: true });
  }
  fs.writeFileSync(path.join(OUT, 'results.json'), JSON.stringify(results, null, 2));
  console.log(`${results.length - failed} passed, ${failed} failed; screenshots in ${OUT}`);
  process.exit(failed ? 1 : 0);
}

main();
