/**
 * 2-D plots on <canvas>: ρ vs γ per orientation (paper Fig. 3a), polar ρ over φ at a
 * fixed γ (Fig. 4) and hemispherical maps for a fixed light (Fig. 6). The plots only
 * draw numbers computed by model.ts.
 */
import { evaluate, lookupChannel, pick, sph, type KesModel, type Mapping, type Measurement, type Reference, type Vec3 } from './model';

const DEG = 180 / Math.PI;
export const ORIENTATION_COLOURS = ['#d62728', '#2ca02c', '#1f77b4', '#9467bd'];
const FONT = '12px system-ui, sans-serif';

export function fitCanvas(canvas: HTMLCanvasElement): CanvasRenderingContext2D {
  const w = Math.max(64, Math.round(canvas.clientWidth || 480));
  const h = Math.max(64, Math.round(canvas.clientHeight || 360));
  if (canvas.width !== w || canvas.height !== h) {
    canvas.width = w;
    canvas.height = h;
  }
  const ctx = canvas.getContext('2d')!;
  ctx.setTransform(1, 0, 0, 1, 0, 0);
  ctx.fillStyle = '#ffffff';
  ctx.fillRect(0, 0, w, h);
  ctx.font = FONT;
  return ctx;
}

function niceTicks(lo: number, hi: number, n = 6): number[] {
  const span = hi - lo || 1;
  const step0 = span / n;
  const mag = 10 ** Math.floor(Math.log10(step0));
  const step = [1, 2, 5, 10].map((k) => k * mag).find((s) => s >= step0) ?? step0;
  const ticks: number[] = [];
  for (let t = Math.ceil(lo / step) * step; t <= hi + 1e-9 * span; t += step) ticks.push(Number(t.toPrecision(12)));
  return ticks;
}

function fmt(v: number): string {
  if (v === 0) return '0';
  const a = Math.abs(v);
  return a >= 1e4 || a < 1e-3 ? v.toExponential(1) : String(Number(v.toPrecision(3)));
}

interface Frame {
  x0: number;
  y0: number;
  w: number;
  h: number;
  xmin: number;
  xmax: number;
  ymin: number;
  ymax: number;
}

function sx(f: Frame, x: number): number {
  return f.x0 + ((x - f.xmin) / (f.xmax - f.xmin)) * f.w;
}
function sy(f: Frame, y: number): number {
  return f.y0 + f.h - ((y - f.ymin) / (f.ymax - f.ymin)) * f.h;
}

function axes(ctx: CanvasRenderingContext2D, f: Frame, xlabel: string, ylabel: string, logY: boolean): void {
  ctx.strokeStyle = '#333';
  ctx.fillStyle = '#333';
  ctx.lineWidth = 1;
  ctx.strokeRect(f.x0, f.y0, f.w, f.h);
  ctx.textAlign = 'center';
  ctx.textBaseline = 'top';
  for (const t of niceTicks(f.xmin, f.xmax)) {
    const x = sx(f, t);
    ctx.beginPath();
    ctx.moveTo(x, f.y0 + f.h);
    ctx.lineTo(x, f.y0 + f.h + 4);
    ctx.stroke();
    ctx.fillText(fmt(t), x, f.y0 + f.h + 6);
  }
  ctx.fillText(xlabel, f.x0 + f.w / 2, f.y0 + f.h + 22);
  ctx.textAlign = 'right';
  ctx.textBaseline = 'middle';
  for (const t of niceTicks(f.ymin, f.ymax)) {
    const y = sy(f, t);
    ctx.beginPath();
    ctx.moveTo(f.x0 - 4, y);
    ctx.lineTo(f.x0, y);
    ctx.stroke();
    ctx.fillText(logY ? fmt(10 ** t) : fmt(t), f.x0 - 6, y);
  }
  ctx.save();
  ctx.translate(14, f.y0 + f.h / 2);
  ctx.rotate(-Math.PI / 2);
  ctx.textAlign = 'center';
  ctx.fillText(ylabel, 0, 0);
  ctx.restore();
}

function qNode(m: KesModel, node: number, half: number, ch: number): number {
  const C = m.nChannels;
  const vals = m.qNodes.subarray((node * 8 + half) * C, (node * 8 + half + 1) * C);
  return pick(vals, ch);
}

const LOG_FLOOR = 1e-6;

/** Fig. 3a: lobe q against signed γ for ψ = 0, 45, 90, 135°: KES table curve + measured nodes. */
export function drawRhoGamma(canvas: HTMLCanvasElement, m: KesModel, ch: number, logY: boolean): void {
  const ctx = fitCanvas(canvas);
  const tr = (v: number) => (logY ? Math.log10(Math.max(v, LOG_FLOOR)) : v);
  const gmax = m.gammaMax;
  const curves: Array<Array<[number, number]>> = [];
  let ymin = Infinity;
  let ymax = -Infinity;
  for (let k = 0; k < 4; k++) {
    const psi = (k * Math.PI) / 4;
    const pts: Array<[number, number]> = [];
    for (let s = -200; s <= 200; s++) {
      const g = (s / 200) * gmax;
      // γ < 0 at orientation ψ is the deviation toward azimuth ψ + π
      const v = lookupChannel(m, g >= 0 ? psi : psi + Math.PI, Math.abs(g), ch);
      pts.push([g * DEG, tr(v)]);
      ymin = Math.min(ymin, tr(v));
      ymax = Math.max(ymax, tr(v));
    }
    curves.push(pts);
  }
  for (let n = 0; n < m.gammaNodes.length; n++) {
    for (let h = 0; h < 8; h++) {
      const v = tr(qNode(m, n, h, ch));
      ymin = Math.min(ymin, v);
      ymax = Math.max(ymax, v);
    }
  }
  if (!logY) ymin = Math.min(0, ymin);
  if (ymax <= ymin) ymax = ymin + 1;
  const f: Frame = { x0: 70, y0: 30, w: canvas.width - 90, h: canvas.height - 80, xmin: -gmax * DEG, xmax: gmax * DEG, ymin, ymax: ymax + 0.05 * (ymax - ymin) };
  axes(ctx, f, 'γ = θr − θi (deg)', logY ? 'q (1/sr, log)' : m.normalisation === 'bounded' ? 'q = (fr − body)·w  (1/sr)' : 'q = (fr − body)·√(cosθi cosθr)  (1/sr)', logY);
  curves.forEach((pts, k) => {
    ctx.strokeStyle = ORIENTATION_COLOURS[k];
    ctx.lineWidth = 1.5;
    ctx.beginPath();
    pts.forEach(([x, y], i) => (i ? ctx.lineTo(sx(f, x), sy(f, y)) : ctx.moveTo(sx(f, x), sy(f, y))));
    ctx.stroke();
    ctx.fillStyle = ORIENTATION_COLOURS[k];
    for (let n = 0; n < m.gammaNodes.length; n++) {
      const g = m.gammaNodes[n] * DEG;
      for (const [sign, half] of [[1, k], [-1, k + 4]] as const) {
        if (sign < 0 && g === 0) continue;
        ctx.beginPath();
        ctx.arc(sx(f, sign * g), sy(f, tr(qNode(m, n, half, ch))), 3, 0, 2 * Math.PI);
        ctx.fill();
      }
    }
    ctx.fillText(`ψ = ${k * 45}°`, f.x0 + f.w - 10, f.y0 + 14 + 16 * k);
  });
  ctx.fillStyle = '#333';
  ctx.textAlign = 'left';
  ctx.fillText('lines: KES model table   dots: measured', f.x0 + 8, f.y0 + 14);
}

/** Fig. 4: polar plot of q over φ at γ = gammaNodes[node], with the 8 measured half-samples. */
export function drawPolar(canvas: HTMLCanvasElement, m: KesModel, gamma: number, node: number, ch: number): void {
  const ctx = fitCanvas(canvas);
  const cx = canvas.width / 2;
  const cy = canvas.height / 2 + 22;
  const R = Math.min(canvas.width, canvas.height) / 2 - 56;
  const N = 360;
  const vals: number[] = [];
  let vmax = 0;
  for (let k = 0; k <= N; k++) {
    const v = lookupChannel(m, (k / N) * 2 * Math.PI, gamma, ch);
    vals.push(v);
    vmax = Math.max(vmax, v);
  }
  const meas: number[] = [];
  if (node >= 0) for (let h = 0; h < 8; h++) meas.push(qNode(m, node, h, ch));
  vmax = Math.max(vmax, ...meas, 1e-12) * 1.1;
  ctx.strokeStyle = '#bbb';
  ctx.fillStyle = '#666';
  ctx.textAlign = 'left';
  for (const t of niceTicks(0, vmax, 4).filter((t) => t > 0)) {
    ctx.beginPath();
    ctx.arc(cx, cy, (t / vmax) * R, 0, 2 * Math.PI);
    ctx.stroke();
    ctx.fillText(fmt(t), cx + (t / vmax) * R * 0.7071 + 2, cy - (t / vmax) * R * 0.7071);
  }
  for (let a = 0; a < 360; a += 45) {
    const r = (a * Math.PI) / 180;
    ctx.beginPath();
    ctx.moveTo(cx, cy);
    ctx.lineTo(cx + R * Math.cos(r), cy - R * Math.sin(r));
    ctx.stroke();
    ctx.textAlign = 'center';
    ctx.fillText(`${a}°`, cx + (R + 16) * Math.cos(r), cy - (R + 16) * Math.sin(r));
  }
  ctx.strokeStyle = '#000';
  ctx.lineWidth = 2;
  ctx.beginPath();
  vals.forEach((v, k) => {
    const a = (k / N) * 2 * Math.PI;
    const x = cx + (v / vmax) * R * Math.cos(a);
    const y = cy - (v / vmax) * R * Math.sin(a);
    k ? ctx.lineTo(x, y) : ctx.moveTo(x, y);
  });
  ctx.stroke();
  meas.forEach((v, h) => {
    const a = (h * Math.PI) / 4;
    ctx.fillStyle = ORIENTATION_COLOURS[h % 4];
    ctx.beginPath();
    ctx.arc(cx + (v / vmax) * R * Math.cos(a), cy - (v / vmax) * R * Math.sin(a), 5, 0, 2 * Math.PI);
    ctx.fill();
  });
  ctx.fillStyle = '#333';
  ctx.textAlign = 'left';
  ctx.fillText(`q(φ, γ = ${(gamma * DEG).toFixed(1)}°)  [1/sr]   x: warp (φ = 0°), y: weft (φ = 90°)`, 10, 16);
  ctx.fillText('line: KES interpolation   dots: measured half-samples at φ = k·45°', 10, 32);
}

// -- colour maps
const INFERNO: Array<[number, number, number]> = [
  [0, 0, 4], [40, 11, 84], [101, 21, 110], [159, 42, 99], [212, 72, 66], [245, 125, 21], [250, 193, 39], [252, 255, 164],
];
export function sequential(t: number): [number, number, number] {
  const x = Math.min(Math.max(t, 0), 1) * (INFERNO.length - 1);
  const i = Math.min(Math.floor(x), INFERNO.length - 2);
  const f = x - i;
  const a = INFERNO[i];
  const b = INFERNO[i + 1];
  return [a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1]), a[2] + f * (b[2] - a[2])];
}
export function diverging(t: number): [number, number, number] {
  const x = Math.min(Math.max(t, -1), 1);
  return x < 0
    ? [255 + x * (255 - 33), 255 + x * (255 - 102), 255 + x * (255 - 172)]
    : [255 - x * (255 - 178), 255 - x * (255 - 24), 255 - x * (255 - 43)];
}

export interface HemiResult {
  /** f_r of the model (display channel) at each pixel, NaN outside the disk */
  model: Float64Array;
  other: Float64Array | null;
  res: number;
}

/** Viewing direction of map pixel (px, py): θ_r linear in radius, φ_r from +x (warp) toward +y (weft, up). */
export function hemiDirection(px: number, py: number, res: number): Vec3 | null {
  const x = ((px + 0.5) / res) * 2 - 1;
  const y = 1 - ((py + 0.5) / res) * 2;
  const r = Math.hypot(x, y);
  if (r >= 1) return null;
  return sph((r * Math.PI) / 2, Math.atan2(y, x));
}

export function computeHemi(m: KesModel, ref: Reference | null, wi: Vec3, mapping: Mapping, ch: number, res: number): HemiResult {
  const model = new Float64Array(res * res).fill(NaN);
  const other = ref ? new Float64Array(res * res).fill(NaN) : null;
  const buf = new Float64Array(m.nChannels);
  const rbuf = new Float64Array(ref ? ref.channels : 1);
  for (let py = 0; py < res; py++) {
    for (let px = 0; px < res; px++) {
      const wr = hemiDirection(px, py, res);
      if (!wr) continue;
      model[py * res + px] = pick(evaluate(m, wi, wr, mapping, buf), ch);
      if (ref && other) other[py * res + px] = pick(ref.eval(wi, wr, rbuf), ch >= ref.channels ? -1 : ch);
    }
  }
  return { model, other, res };
}

function paintMap(canvas: HTMLCanvasElement, vals: Float64Array, res: number, colour: (v: number) => [number, number, number], title: string): CanvasRenderingContext2D {
  const ctx = fitCanvas(canvas);
  const size = Math.min(canvas.width, canvas.height - 24);
  const img = ctx.createImageData(res, res);
  for (let k = 0; k < res * res; k++) {
    const v = vals[k];
    const [r, g, b] = Number.isFinite(v) ? colour(v) : [255, 255, 255];
    img.data.set([r, g, b, 255], 4 * k);
  }
  const tmp = document.createElement('canvas');
  tmp.width = res;
  tmp.height = res;
  tmp.getContext('2d')!.putImageData(img, 0, 0);
  ctx.imageSmoothingEnabled = true;
  const ox = (canvas.width - size) / 2;
  ctx.drawImage(tmp, ox, 24, size, size);
  ctx.strokeStyle = '#888';
  ctx.beginPath();
  ctx.arc(ox + size / 2, 24 + size / 2, size / 2, 0, 2 * Math.PI);
  ctx.stroke();
  ctx.fillStyle = '#333';
  ctx.textAlign = 'center';
  ctx.fillText(title, canvas.width / 2, 14);
  return ctx;
}

/** Pixel position of a direction on a map canvas drawn by paintMap. */
export function hemiToCanvas(canvas: HTMLCanvasElement, w: Vec3): [number, number] {
  const size = Math.min(canvas.width, canvas.height - 24);
  const ox = (canvas.width - size) / 2;
  const theta = Math.atan2(Math.hypot(w[0], w[1]), w[2]);
  const phi = Math.atan2(w[1], w[0]);
  const r = theta / (Math.PI / 2);
  return [ox + size / 2 + (r * Math.cos(phi) * size) / 2, 24 + size / 2 - (r * Math.sin(phi) * size) / 2];
}

function mark(ctx: CanvasRenderingContext2D, canvas: HTMLCanvasElement, wi: Vec3): void {
  // the mirror direction of the light, for orientation
  const [x, y] = hemiToCanvas(canvas, [-wi[0], -wi[1], wi[2]]);
  ctx.strokeStyle = '#00e5ff';
  ctx.lineWidth = 1.5;
  ctx.beginPath();
  ctx.arc(x, y, 6, 0, 2 * Math.PI);
  ctx.stroke();
}

/** Fig. 6: model map, reference (or measured points) map, and their relative difference. */
export function drawHemi(
  canvases: [HTMLCanvasElement, HTMLCanvasElement, HTMLCanvasElement],
  h: HemiResult,
  wi: Vec3,
  refLabel: string,
  measured: Array<{ wr: Vec3; value: number; model: number }>,
): { maxRelDiff: number } {
  const { model, other, res } = h;
  let vmax = 0;
  for (const v of model) if (Number.isFinite(v)) vmax = Math.max(vmax, v);
  if (other) for (const v of other) if (Number.isFinite(v)) vmax = Math.max(vmax, v);
  for (const p of measured) vmax = Math.max(vmax, p.value);
  const lmax = Math.log10(Math.max(vmax, 1e-9));
  const lmin = lmax - 3; // three decades, like a log-scaled Fig. 6
  const col = (v: number) => sequential((Math.log10(Math.max(v, 1e-12)) - lmin) / (lmax - lmin));
  const c0 = paintMap(canvases[0], model, res, col, 'model fr (log, 3 decades)');
  mark(c0, canvases[0], wi);
  let maxRel = 0;
  if (other) {
    const c1 = paintMap(canvases[1], other, res, col, `reference: ${refLabel}`);
    mark(c1, canvases[1], wi);
    const diff = new Float64Array(res * res).fill(NaN);
    for (let k = 0; k < res * res; k++) {
      if (Number.isFinite(model[k]) && Number.isFinite(other[k]) && other[k] > 0) {
        diff[k] = (model[k] - other[k]) / other[k];
        maxRel = Math.max(maxRel, Math.abs(diff[k]));
      }
    }
    paintMap(canvases[2], diff, res, (v) => diverging(v / 0.5), '(model − reference) / reference, ±50 %');
  } else {
    const blank = new Float64Array(res * res).fill(NaN);
    for (let py = 0; py < res; py++) for (let px = 0; px < res; px++) if (hemiDirection(px, py, res)) blank[py * res + px] = 0;
    const c1 = paintMap(canvases[1], blank, res, () => [235, 235, 235], measured.length ? `measured (${measured.length} points near this light)` : 'no reference or measured points for this light');
    const c2 = paintMap(canvases[2], blank, res, () => [235, 235, 235], '(model − measured) / measured, ±50 %');
    for (const p of measured) {
      const [x1, y1] = hemiToCanvas(canvases[1], p.wr);
      const [r, g, b] = col(p.value);
      c1.fillStyle = `rgb(${r},${g},${b})`;
      c1.beginPath();
      c1.arc(x1, y1, 5, 0, 2 * Math.PI);
      c1.fill();
      const rel = p.value > 0 ? (p.model - p.value) / p.value : 0;
      maxRel = Math.max(maxRel, Math.abs(rel));
      const [x2, y2] = hemiToCanvas(canvases[2], p.wr);
      const [r2, g2, b2] = diverging(rel / 0.5);
      c2.fillStyle = `rgb(${r2},${g2},${b2})`;
      c2.strokeStyle = '#555';
      c2.beginPath();
      c2.arc(x2, y2, 5, 0, 2 * Math.PI);
      c2.fill();
      c2.stroke();
    }
    mark(c1, canvases[1], wi);
  }
  return { maxRelDiff: maxRel };
}

/** Measured samples whose light direction is within `tol` radians of wi. */
export function measuredNear(meas: Measurement | null, m: KesModel, wi: Vec3, mapping: Mapping, ch: number, tol: number) {
  const out: Array<{ wr: Vec3; value: number; model: number }> = [];
  if (!meas) return out;
  const buf = new Float64Array(m.nChannels);
  const C = meas.channels.length;
  for (let k = 0; k < meas.n; k++) {
    const li = sph(meas.thetaI[k], meas.phiI[k]);
    const cosA = li[0] * wi[0] + li[1] * wi[1] + li[2] * wi[2];
    if (Math.acos(Math.min(1, cosA)) > tol) continue;
    const wr = sph(meas.thetaR[k], meas.phiR[k]);
    const value = pick(meas.values.subarray(k * C, (k + 1) * C), ch >= C ? -1 : ch);
    out.push({ wr, value, model: pick(evaluate(m, li, wr, mapping, buf), ch) });
  }
  return out;
}
