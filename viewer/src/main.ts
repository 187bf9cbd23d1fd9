/**
 * kesbrdf viewer: wires the page, the JSON API of `kesbrdf view` and the views.
 * The page reads only the versioned model file (docs/formats.md) and, for uploads,
 * the measurement the server read.
 */
import './style.css';
import { parseMeasurement, parseModel, referenceFromMetadata, sph, type KesModel, type Mapping, type Measurement, type Reference, type Vec3 } from './model';
import { computeHemi, drawHemi, drawPolar, drawRhoGamma, measuredNear } from './plots';
import { parsePLY } from './ply';
import { Preview, type PreviewObject } from './preview';
import { SphereView } from './sphere3d';

type View = 'rhogamma' | 'polar' | 'sphere' | 'hemi' | 'preview';
const VIEWS: View[] = ['rhogamma', 'polar', 'sphere', 'hemi', 'preview'];
const DEG = Math.PI / 180;
/** Measured samples count as "at this light" within this angle (the paper's 3° step). */
const MEASURED_LIGHT_TOL = 1.6 * DEG;
const HEMI_RES = 96;

interface State {
  model: KesModel | null;
  measurement: Measurement | null;
  reference: Reference | null;
  view: View;
  mapping: Mapping;
  channel: number;
  logY: boolean;
  gammaNode: number;
  thetaI: number;
  phiI: number;
}

const state: State = {
  model: null,
  measurement: null,
  reference: null,
  view: 'rhogamma',
  mapping: 'deviation',
  channel: -1,
  logY: false,
  gammaNode: 0,
  thetaI: 30 * DEG, // the paper's Fig. 6 light: θ_i = π/6, φ_i = π/2
  phiI: 90 * DEG,
};

const $ = <T extends HTMLElement>(id: string) => document.getElementById(id) as T;
let sphereView: SphereView | null = null;
let gammaNodeChosen = false;
let preview: Preview | null = null;
let renderCount = 0;

function showError(message: string | null): void {
  const el = $('error');
  el.textContent = message ?? '';
  el.hidden = !message;
}

async function api(path: string, init?: RequestInit): Promise<any> {
  const res = await fetch(path, init);
  let doc: any;
  try {
    doc = await res.json();
  } catch {
    throw new Error(`${path}: expected JSON from the server, got HTTP ${res.status}`);
  }
  if (!res.ok || doc.error) throw new Error(doc.error ?? `HTTP ${res.status}`);
  return doc;
}

function lightDir(): Vec3 {
  return sph(state.thetaI, state.phiI);
}

// -- model loading ----------------------------------------------------------------
function setModel(doc: any, name: string, measDoc: any): void {
  const model = parseModel(doc, name);
  const measurement = parseMeasurement(measDoc);
  const previous = state.model;
  state.model = model;
  state.measurement = measurement;
  if (previous !== model) {
    // a new model is shown with the mapping its table was fitted for (the select can change it)
    state.mapping = model.mapping;
    $<HTMLSelectElement>('mapping').value = model.mapping;
  }
  state.reference =
    referenceFromMetadata(measurement?.metadata) ??
    referenceFromMetadata((doc.input ?? {}) as Record<string, string>);
  const chSel = $<HTMLSelectElement>('channel');
  chSel.innerHTML = '';
  const opts: Array<[number, string]> = model.nChannels > 1 ? [[-1, 'mean of channels']] : [];
  model.channels.forEach((c, k) => opts.push([k, c]));
  for (const [v, label] of opts) chSel.add(new Option(label, String(v)));
  state.channel = model.nChannels > 1 ? -1 : 0;
  chSel.value = String(state.channel);
  const g = $<HTMLInputElement>('gamma');
  const nodes = model.gammaNodes.length;
  g.max = String(Math.max(nodes - 1, 0));
  if (previous !== model && !gammaNodeChosen) {
    // start where the lobe's anisotropy shows: the measured γ nearest 30°
    let best = 0;
    model.gammaNodes.forEach((g, k) => (Math.abs(g - 30 * DEG) < Math.abs(model.gammaNodes[best] - 30 * DEG) ? (best = k) : 0));
    state.gammaNode = best;
  }
  state.gammaNode = Math.min(state.gammaNode, Math.max(nodes - 1, 0));
  g.value = String(state.gammaNode);
  const input = (doc.input ?? {}) as Record<string, unknown>;
  $('model-info').textContent = `${model.channels.join(',')} · ${model.nPhi}×${model.nGamma} table · γmax ${(model.gammaMax / DEG).toFixed(0)}° · ${input.sample ?? ''}`;
  preview?.setModel(model);
  sphereModel = null;
  document.body.dataset.model = name;
  renderView();
}

async function loadModel(id: string): Promise<void> {
  document.body.dataset.status = 'busy';
  try {
    const doc = await api(`api/model/${encodeURIComponent(id)}`);
    setModel(doc.model, doc.name, doc.measurement);
    showError(null);
  } catch (e) {
    showError((e as Error).message);
  } finally {
    document.body.dataset.status = 'ready';
  }
}

async function refreshModels(select?: string): Promise<void> {
  const { models } = await api('api/models');
  const sel = $<HTMLSelectElement>('model-select');
  sel.innerHTML = '';
  for (const m of models) sel.add(new Option(`${m.name}${m.kind === 'upload' ? ' (fitted upload)' : ''}`, m.id));
  if (select) sel.value = select;
}

async function uploadCSV(file: File): Promise<void> {
  document.body.dataset.status = 'busy';
  try {
    const body = await file.arrayBuffer();
    const fallback = $<HTMLInputElement>('strict-fit').checked ? '&fallback=error' : ''; // --strict
    const doc = await api(`api/fit?name=${encodeURIComponent(file.name)}${fallback}`, {
      method: 'POST',
      headers: { 'Content-Type': 'text/csv' },
      body,
    });
    await refreshModels(doc.id);
    setModel(doc.model, doc.name, doc.measurement);
    showError(null);
  } catch (e) {
    showError((e as Error).message);
  } finally {
    document.body.dataset.status = 'ready';
  }
}

// -- views ------------------------------------------------------------------------
let sphereModel: KesModel | null = null;
let sphereChannel = NaN;

function renderView(): void {
  const m = state.model;
  renderCount++;
  for (const el of document.querySelectorAll<HTMLElement>('.view')) el.hidden = el.dataset.view !== state.view;
  for (const b of document.querySelectorAll<HTMLElement>('#tabs button')) b.classList.toggle('active', b.dataset.view === state.view);
  document.body.dataset.view = state.view;
  drawLightPicker();
  if (!m) return;
  const nodeGamma = m.gammaNodes.length ? m.gammaNodes[state.gammaNode] : 0;
  $('gamma-label').textContent = `γ = ${(nodeGamma / DEG).toFixed(1)}° (measured node ${state.gammaNode + 1}/${m.gammaNodes.length})`;
  switch (state.view) {
    case 'rhogamma':
      drawRhoGamma($('c-rhogamma'), m, state.channel, state.logY);
      break;
    case 'polar':
      drawPolar($('c-polar'), m, nodeGamma, m.gammaNodes.length ? state.gammaNode : -1, state.channel);
      break;
    case 'sphere':
      sphereView ??= new SphereView($('c-sphere'));
      if (sphereModel !== m || sphereChannel !== state.channel) {
        sphereView.setModel(m, state.channel);
        sphereModel = m;
        sphereChannel = state.channel;
      } else sphereView.render();
      break;
    case 'hemi': {
      const wi = lightDir();
      const h = computeHemi(m, state.reference, wi, state.mapping, state.channel, HEMI_RES);
      const near = state.reference ? [] : measuredNear(state.measurement, m, wi, state.mapping, state.channel, MEASURED_LIGHT_TOL);
      const { maxRelDiff } = drawHemi([$('c-hemi-model'), $('c-hemi-ref'), $('c-hemi-diff')], h, wi, state.reference?.label ?? '', near);
      $('hemi-info').textContent =
        `light θi = ${(state.thetaI / DEG).toFixed(1)}°, φi = ${(state.phiI / DEG).toFixed(1)}°; mapping ${state.mapping}; ` +
        `viewing hemisphere: centre = normal, rim = grazing, right = warp, up = weft; ring = mirror direction. ` +
        (state.reference || near.length ? `max |relative difference| ${(100 * maxRelDiff).toFixed(1)} %` : 'upload a measurement to compare');
      break;
    }
    case 'preview':
      ensurePreview();
      preview!.render();
      break;
  }
}

function ensurePreview(): Preview {
  if (!preview) {
    preview = new Preview($('c-preview'));
    if (state.model) preview.setModel(state.model);
    applyPreviewControls();
  }
  return preview;
}

function srgbToLinear(c: number): number {
  return c <= 0.04045 ? c / 12.92 : ((c + 0.055) / 1.055) ** 2.4;
}

function applyPreviewControls(): void {
  if (!preview) return;
  preview.setLight(lightDir());
  preview.setMapping(state.mapping);
  const ev = Number($<HTMLInputElement>('exposure').value);
  preview.setExposure(ev);
  $('exposure-label').textContent = `${ev} EV`;
  const hex = $<HTMLInputElement>('color').value;
  const rgb = [1, 3, 5].map((k) => srgbToLinear(parseInt(hex.slice(k, k + 2), 16) / 255)) as [number, number, number];
  preview.setBaseColor($<HTMLInputElement>('use-color').checked ? rgb : null);
  const obj = $<HTMLSelectElement>('object').value as PreviewObject;
  if (preview.object !== obj) preview.setObject(obj);
  $('preview-info').textContent =
    `${preview.object === 'cloth' ? (preview.hasDrapeMesh ? 'drape mesh' : 'procedural fold') : preview.object}; ` +
    `mapping ${state.mapping}; body ${$<HTMLInputElement>('use-color').checked ? `colour ${hex} (fbody = base_color/π)` : 'from the model'}; ` +
    `light θi = ${(state.thetaI / DEG).toFixed(0)}°, φi = ${(state.phiI / DEG).toFixed(0)}°. Drag to orbit; warp = mesh UV u.`;
}

// -- light picker -------------------------------------------------------------------
function drawLightPicker(): void {
  const c = $<HTMLCanvasElement>('light');
  const ctx = c.getContext('2d')!;
  const R = c.width / 2 - 6;
  const cx = c.width / 2;
  const cy = c.height / 2;
  ctx.clearRect(0, 0, c.width, c.height);
  ctx.strokeStyle = '#999';
  for (const t of [30, 60, 90]) {
    ctx.beginPath();
    ctx.arc(cx, cy, (R * t) / 90, 0, 2 * Math.PI);
    ctx.stroke();
  }
  ctx.beginPath();
  ctx.moveTo(cx - R, cy);
  ctx.lineTo(cx + R, cy);
  ctx.moveTo(cx, cy - R);
  ctx.lineTo(cx, cy + R);
  ctx.stroke();
  const r = (R * state.thetaI) / (Math.PI / 2);
  ctx.fillStyle = '#ffb300';
  ctx.strokeStyle = '#333';
  ctx.beginPath();
  ctx.arc(cx + r * Math.cos(state.phiI), cy - r * Math.sin(state.phiI), 7, 0, 2 * Math.PI);
  ctx.fill();
  ctx.stroke();
  $('light-label').textContent = `θi = ${(state.thetaI / DEG).toFixed(1)}°, φi = ${(((state.phiI / DEG) % 360) + 360) % 360 | 0}°`;
}

function lightFromPointer(ev: PointerEvent): void {
  const c = $<HTMLCanvasElement>('light');
  const rect = c.getBoundingClientRect();
  const R = c.width / 2 - 6;
  const x = ((ev.clientX - rect.left) * c.width) / rect.width - c.width / 2;
  const y = c.height / 2 - ((ev.clientY - rect.top) * c.height) / rect.height;
  const r = Math.min(Math.hypot(x, y) / R, 0.98);
  state.thetaI = (r * Math.PI) / 2;
  state.phiI = Math.atan2(y, x);
  applyPreviewControls();
  scheduleRender();
}

let renderQueued = false;
function scheduleRender(): void {
  if (renderQueued) return;
  renderQueued = true;
  requestAnimationFrame(() => {
    renderQueued = false;
    renderView();
  });
}

// -- wiring -----------------------------------------------------------------------
function wire(): void {
  for (const b of document.querySelectorAll<HTMLButtonElement>('#tabs button')) {
    b.addEventListener('click', () => {
      state.view = b.dataset.view as View;
      renderView();
    });
  }
  $('model-select').addEventListener('change', (e) => loadModel((e.target as HTMLSelectElement).value));
  $('upload').addEventListener('change', (e) => {
    const input = e.target as HTMLInputElement;
    const f = input.files?.[0];
    if (f) uploadCSV(f).finally(() => (input.value = ''));
  });
  $('ply').addEventListener('change', async (e) => {
    const input = e.target as HTMLInputElement;
    const f = input.files?.[0];
    if (!f) return;
    try {
      const geom = parsePLY(await f.arrayBuffer(), f.name);
      ensurePreview().setDrapeMesh(geom);
      $<HTMLSelectElement>('object').value = 'cloth';
      state.view = 'preview';
      showError(null);
      applyPreviewControls();
      renderView();
    } catch (err) {
      showError((err as Error).message);
    } finally {
      input.value = '';
    }
  });
  $('channel').addEventListener('change', (e) => {
    state.channel = Number((e.target as HTMLSelectElement).value);
    renderView();
  });
  $('log-y').addEventListener('change', (e) => {
    state.logY = (e.target as HTMLInputElement).checked;
    renderView();
  });
  $('mapping').addEventListener('change', (e) => {
    state.mapping = (e.target as HTMLSelectElement).value as Mapping;
    applyPreviewControls();
    renderView();
  });
  $('gamma').addEventListener('input', (e) => {
    state.gammaNode = Number((e.target as HTMLInputElement).value);
    gammaNodeChosen = true;
    scheduleRender();
  });
  const light = $<HTMLCanvasElement>('light');
  let dragging = false;
  light.addEventListener('pointerdown', (e) => {
    dragging = true;
    light.setPointerCapture?.(e.pointerId);
    lightFromPointer(e);
  });
  light.addEventListener('pointermove', (e) => dragging && lightFromPointer(e));
  light.addEventListener('pointerup', () => (dragging = false));
  light.addEventListener('pointercancel', () => (dragging = false));
  $('color').addEventListener('input', () => {
    $<HTMLInputElement>('use-color').checked = true;
    applyPreviewControls();
  });
  for (const id of ['use-color', 'exposure', 'object']) $(id).addEventListener('input', () => applyPreviewControls());
  $('object').addEventListener('change', () => applyPreviewControls());
  window.addEventListener('resize', () => scheduleRender());
}

// -- hooks for the browser tests: a separate chunk (testhooks.ts), loaded only with ?testhooks
async function loadTestHooks(): Promise<void> {
  if (!new URLSearchParams(location.search).has('testhooks')) return;
  const { installTestHooks } = await import('./testhooks');
  installTestHooks<View>({
    state,
    renderCount: () => renderCount,
    setModel,
    ensurePreview,
    applyPreviewControls,
    lightDir,
    drawLightPicker,
    renderView,
    views: VIEWS,
  });
}

async function start(): Promise<void> {
  wire();
  drawLightPicker();
  await loadTestHooks();
  try {
    const config = await api('api/config');
    await refreshModels(config.initial ?? undefined);
    const first = config.initial ?? $<HTMLSelectElement>('model-select').value;
    if (first) await loadModel(first);
    else showError('no model yet: fit a measurement CSV (button above) or start with `kesbrdf view MODEL.kes.json`');
  } catch (e) {
    showError((e as Error).message);
  }
  document.body.dataset.status = 'ready';
}

start();
