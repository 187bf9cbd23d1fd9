/**
 * The kesbrdf model file (docs/formats.md, format version 1) and its evaluation.
 *
 * Everything here follows the recipe of docs/formats.md "How to evaluate a model"
 * exactly; the GLSL in src/kesbrdf/shaders/kes_brdf.glsl is the same recipe on the GPU.
 * Fabric frame: x = warp, y = weft, z = normal; wi toward the light, wr toward the
 * viewer; radians; f_r in 1/sr.
 */

export type Vec3 = [number, number, number];
export type Mapping = 'deviation' | 'halfvector' | 'paper';
export const MAPPINGS: Mapping[] = ['deviation', 'halfvector', 'paper'];
/** Integer codes used by the GLSL chunk (uniform kesMapping). */
export const MAPPING_CODE: Record<Mapping, number> = { deviation: 0, halfvector: 1, paper: 2 };

/** Foreshortening normalisations (docs/formats.md step 3; kesbrdf.mappings.NORMALISATIONS). */
export type Normalisation = 'bounded' | 'sqrtcos';
export const NORMALISATIONS: Normalisation[] = ['bounded', 'sqrtcos'];
/** The lobe beyond the last measured γ (docs/formats.md step 2; kesbrdf.mappings.EXTRAPOLATIONS). */
export type Extrapolation = 'fade' | 'hold';
export const EXTRAPOLATIONS: Extrapolation[] = ['fade', 'hold'];
/** λ of the `bounded` normalisation (kesbrdf.mappings.BOUNDED_LAMBDA). */
export const BOUNDED_LAMBDA = 0.5;
/** Width of the `fade`, radians of γ (kesbrdf.mappings.FADE_DEG = 6°). */
export const FADE_WIDTH = (6 * Math.PI) / 180;

export interface ArrayJson {
  dtype: string;
  shape: number[];
  data: string;
}

export interface KesModel {
  name: string;
  channels: string[];
  nChannels: number;
  nPhi: number;
  nGamma: number;
  /** grid step in γ, radians */
  dGamma: number;
  gammaMax: number;
  /** parameters.normalisation; absent (files written before it): 'sqrtcos' */
  normalisation: Normalisation;
  /** parameters.extrapolation; absent: 'hold' */
  extrapolation: Extrapolation;
  /** parameters.mapping, the mapping the table was fitted for; absent (files written before it): 'deviation' */
  mapping: Mapping;
  /**
   * λ of w = max(√(cos θ_i cos θ_r), λ·max(cos θ_i, cos θ_r)): BOUNDED_LAMBDA for
   * 'bounded', 0 for 'sqrtcos' (w is then the geometric mean); uniform kesLambda.
   */
  lambda: number;
  /** fade(γ) = clamp(1 − (γ − gammaMax)·fadeSlope, 0, 1): 1/FADE_WIDTH for 'fade', 0 for 'hold'. */
  fadeSlope: number;
  /** θ_i + θ_r of the incidence line the table was fitted on, radians (the paper mapping). */
  lineSum: number;
  /** (nPhi, nGamma, C) lobe q, C-order */
  table: Float64Array;
  /** (C,) body term c, 1/sr */
  body: Float64Array;
  /** the body's shape g(μ) = 1 − a(1 − μ)^p, body c·g(cos θ_i)·g(cos θ_r) (doc.body_law; absent: [0, 1], Lambertian) */
  bodyLaw: [number, number];
  /** (nNodes,) measured |γ|, radians */
  gammaNodes: Float64Array;
  /** (nNodes, 8, C) measured q at half-azimuths k·45° */
  qNodes: Float64Array;
  doc: Record<string, unknown>;
}

export interface Measurement {
  channels: string[];
  n: number;
  thetaI: Float64Array;
  phiI: Float64Array;
  thetaR: Float64Array;
  phiR: Float64Array;
  /** (N, C) f_r in 1/sr */
  values: Float64Array;
  metadata: Record<string, string>;
}

/** Decode `{"dtype": "<f8", "shape", "data": base64}` into a Float64Array. */
export function decodeArray(a: ArrayJson, what: string): { data: Float64Array<ArrayBuffer>; shape: number[] } {
  if (!a || a.dtype !== '<f8' || !Array.isArray(a.shape) || typeof a.data !== 'string') {
    throw new Error(`${what}: expected an array {"dtype": "<f8", "shape", "data"}, got ${JSON.stringify(a)?.slice(0, 80)}`);
  }
  const bin = atob(a.data);
  const n = a.shape.reduce((x, y) => x * y, 1);
  if (bin.length !== 8 * n) {
    throw new Error(`${what}: expected ${8 * n} bytes for shape [${a.shape}], got ${bin.length}`);
  }
  const bytes = new Uint8Array(bin.length);
  for (let i = 0; i < bin.length; i++) bytes[i] = bin.charCodeAt(i);
  const view = new DataView(bytes.buffer);
  const data = new Float64Array(n);
  for (let i = 0; i < n; i++) data[i] = view.getFloat64(8 * i, true);
  return { data, shape: a.shape };
}

/** Model kinds (the file's `kind`, docs/models.md) this viewer can show: the `kes` table. */
export const VIEWABLE_KINDS = ['kes'];

/** Parse a model file document (docs/formats.md) into a KesModel; other kinds are refused. */
export function parseModel(doc: any, name: string): KesModel {
  if (!doc || doc.format !== 'kesbrdf-model') throw new Error(`${name}: expected a kesbrdf model file`);
  if (doc.format_version !== 1) throw new Error(`${name}: expected format_version 1, got ${doc.format_version}`);
  const kind = doc.kind ?? 'kes';
  if (!VIEWABLE_KINDS.includes(kind)) {
    throw new Error(
      `${name}: the viewer shows models of kind ${VIEWABLE_KINDS.map((k) => `'${k}'`).join(', ')}; ` +
        `this is a '${String(kind).slice(0, 40)}' model (use kesbrdf plot --figure 6 or kesbrdf eval for it)`,
    );
  }
  const arrays = doc.arrays ?? {};
  const phi = decodeArray(arrays.phi_grid, 'phi_grid');
  const gamma = decodeArray(arrays.gamma_grid, 'gamma_grid');
  const table = decodeArray(arrays.table, 'table');
  const body = decodeArray(arrays.body, 'body');
  const channels: string[] = Array.isArray(doc.channels) ? doc.channels.map(String) : [];
  const nPhi = phi.data.length;
  const nGamma = gamma.data.length;
  const C = table.shape[2];
  if (table.shape.length !== 3 || table.shape[0] !== nPhi || table.shape[1] !== nGamma) {
    throw new Error(`${name}: expected table of shape [${nPhi}, ${nGamma}, C], got [${table.shape}]`);
  }
  if (channels.length !== C || body.data.length !== C) {
    throw new Error(`${name}: expected ${C} channels and body values, got ${channels.length} and ${body.data.length}`);
  }
  if (nGamma < 2) throw new Error(`${name}: expected at least 2 gamma grid points, got ${nGamma}`);
  const params = doc.parameters ?? {};
  const normalisation = params.normalisation ?? 'sqrtcos';
  const extrapolation = params.extrapolation ?? 'hold';
  const mapping = params.mapping ?? 'deviation';
  const law = doc.body_law ?? { a: 0, p: 1 };
  const bodyLaw: [number, number] = [Number(law.a), Number(law.p)];
  if (!(bodyLaw[0] >= 0 && bodyLaw[0] <= 1 && bodyLaw[1] > 0 && bodyLaw[1] <= 64)) {
    throw new Error(`${name}: body_law: expected a in [0, 1] and p in (0, 64], got ${JSON.stringify(law)?.slice(0, 60)}`);
  }
  if (mapping !== 'deviation' && mapping !== 'halfvector') {
    throw new Error(`${name}: parameters.mapping: expected deviation or halfvector, got ${JSON.stringify(mapping)?.slice(0, 40)}`);
  }
  if (!NORMALISATIONS.includes(normalisation)) {
    throw new Error(`${name}: parameters.normalisation: expected one of ${NORMALISATIONS.join(', ')}, got ${JSON.stringify(normalisation)?.slice(0, 40)}`);
  }
  if (!EXTRAPOLATIONS.includes(extrapolation)) {
    throw new Error(`${name}: parameters.extrapolation: expected one of ${EXTRAPOLATIONS.join(', ')}, got ${JSON.stringify(extrapolation)?.slice(0, 40)}`);
  }
  // kesbrdf.model.Model.line_sum: diagnostics first, then parameters, 90° by default
  const lineDeg = Number(doc.diagnostics?.incidence_line_deg ?? params.incidence_line_deg ?? 90);
  const lineSum = Number.isFinite(lineDeg) ? (lineDeg * Math.PI) / 180 : Math.PI / 2;
  let gammaNodes: Float64Array<ArrayBuffer> = new Float64Array(0);
  let qNodes: Float64Array<ArrayBuffer> = new Float64Array(0);
  if (arrays.gamma_nodes && arrays.q_nodes) {
    gammaNodes = decodeArray(arrays.gamma_nodes, 'gamma_nodes').data;
    qNodes = decodeArray(arrays.q_nodes, 'q_nodes').data;
  }
  return {
    name,
    channels,
    nChannels: C,
    nPhi,
    nGamma,
    dGamma: gamma.data[1] - gamma.data[0],
    gammaMax: gamma.data[nGamma - 1],
    normalisation,
    extrapolation,
    mapping,
    lambda: normalisation === 'bounded' ? BOUNDED_LAMBDA : 0,
    fadeSlope: extrapolation === 'fade' ? 1 / FADE_WIDTH : 0,
    lineSum,
    table: table.data,
    body: body.data,
    bodyLaw,
    gammaNodes,
    qNodes,
    doc,
  };
}

export function parseMeasurement(doc: any): Measurement | null {
  if (!doc) return null;
  const ti = decodeArray(doc.theta_i, 'theta_i').data;
  const values = decodeArray(doc.values, 'values').data;
  return {
    channels: doc.channels,
    n: ti.length,
    thetaI: ti,
    phiI: decodeArray(doc.phi_i, 'phi_i').data,
    thetaR: decodeArray(doc.theta_r, 'theta_r').data,
    phiR: decodeArray(doc.phi_r, 'phi_r').data,
    values,
    metadata: doc.metadata ?? {},
  };
}

const TWO_PI = 2 * Math.PI;

/**
 * Bilinear lookup of the table at (φ, γ) into `out` (C values): φ periodic with nPhi
 * cells, γ clamped to [0, γ_max] (docs/formats.md step 2).
 */
export function lookup(m: KesModel, phi: number, gamma: number, out: Float64Array): Float64Array {
  const C = m.nChannels;
  let wrapped = phi % TWO_PI;
  if (wrapped < 0) wrapped += TWO_PI;
  const u = (wrapped / TWO_PI) * m.nPhi;
  const u0 = Math.floor(u);
  const fu = u - u0;
  const i0 = ((u0 % m.nPhi) + m.nPhi) % m.nPhi;
  const i1 = (i0 + 1) % m.nPhi;
  const v = Math.min(Math.max(gamma / m.dGamma, 0), m.nGamma - 1);
  const j0 = Math.min(Math.floor(v), m.nGamma - 1);
  const j1 = Math.min(j0 + 1, m.nGamma - 1);
  const fv = v - j0;
  const t = m.table;
  const g = m.nGamma;
  for (let c = 0; c < C; c++) {
    const a = t[(i0 * g + j0) * C + c];
    const b = t[(i1 * g + j0) * C + c];
    const d = t[(i0 * g + j1) * C + c];
    const e = t[(i1 * g + j1) * C + c];
    out[c] = (1 - fu) * ((1 - fv) * a + fv * d) + fu * ((1 - fv) * b + fv * e);
  }
  return out;
}

/** Lookup of one channel (or the channel mean when ch < 0). */
export function lookupChannel(m: KesModel, phi: number, gamma: number, ch: number): number {
  const out = new Float64Array(m.nChannels);
  lookup(m, phi, gamma, out);
  return pick(out, ch);
}

export function pick(values: ArrayLike<number>, ch: number): number {
  if (ch >= 0) return values[ch];
  let s = 0;
  for (let i = 0; i < values.length; i++) s += values[i];
  return s / values.length;
}

const GAMMA0_EPS = 1e-12;

/**
 * Foreshortening weight w of f_r = c + fade·q/w (docs/formats.md step 3,
 * kesbrdf.mappings.foreshortening): max(√(cos θ_i cos θ_r), λ·max(cos θ_i, cos θ_r)).
 */
export function foreshortening(m: KesModel, cosI: number, cosR: number): number {
  const ci = Math.max(cosI, 0);
  const cr = Math.max(cosR, 0);
  return Math.max(Math.sqrt(ci * cr), m.lambda * Math.max(ci, cr));
}

/** The lobe's factor beyond the last measured γ (docs/formats.md step 2, kesbrdf.mappings.fade). */
export function fade(m: KesModel, gamma: number): number {
  return Math.min(Math.max(1 - (gamma - m.gammaMax) * m.fadeSlope, 0), 1);
}

/**
 * √(cos θ_i cos θ_r) / w on the incidence line θ_i + θ_r = lineSum at deviation |γ|
 * (kesbrdf.mappings.line_foreshortening): 1 for 'sqrtcos'. The paper mapping reads the
 * measured (f − c)·√(cos θ_i cos θ_r) back from a table that holds (f − c)·w.
 */
export function lineRatio(m: KesModel, gamma: number): number {
  if (m.lambda === 0) return 1;
  const g = Math.abs(gamma);
  const geo = Math.sqrt(Math.max((Math.cos(g) + Math.cos(m.lineSum)) / 2, 0));
  const cosHi = Math.cos(Math.min(Math.max((m.lineSum - g) / 2, 0), Math.PI / 2));
  return geo / Math.max(geo, m.lambda * cosHi);
}

/**
 * (φ, γ) of a direction pair for the deviation or halfvector mapping (docs/formats.md step 1).
 */
export function toPhiGamma(wi: Vec3, wr: Vec3, mapping: Mapping): [number, number] {
  if (mapping === 'deviation') {
    const m: Vec3 = [-wi[0], -wi[1], wi[2]];
    const cx = wr[1] * m[2] - wr[2] * m[1];
    const cy = wr[2] * m[0] - wr[0] * m[2];
    const cz = wr[0] * m[1] - wr[1] * m[0];
    const gamma = Math.atan2(Math.hypot(cx, cy, cz), wr[0] * m[0] + wr[1] * m[1] + wr[2] * m[2]);
    let sx = wi[0] + wr[0];
    let sy = wi[1] + wr[1];
    if (Math.hypot(sx, sy) < GAMMA0_EPS) {
      sx = wr[0] - wi[0];
      sy = wr[1] - wi[1];
    }
    return [Math.atan2(sy, sx), gamma];
  }
  if (mapping === 'halfvector') {
    let hx = wi[0] + wr[0];
    let hy = wi[1] + wr[1];
    let hz = wi[2] + wr[2];
    const n = Math.hypot(hx, hy, hz);
    hx /= n;
    hy /= n;
    hz /= n;
    const gamma = 2 * Math.atan2(Math.hypot(hx, hy), hz);
    let sx = hx;
    let sy = hy;
    if (Math.hypot(sx, sy) < GAMMA0_EPS) {
      sx = wr[0] - wi[0];
      sy = wr[1] - wi[1];
    }
    return [Math.atan2(sy, sx), gamma];
  }
  throw new Error(`toPhiGamma: expected mapping deviation or halfvector, got ${mapping}`);
}

/** eq. 3 divides by sin β; clamped like kesbrdf.brdf.PAPER_MIN_SIN_BETA. */
const PAPER_MIN_SIN_BETA = 1e-6;

/**
 * Paper eq. 3–4 literally, as kesbrdf.model evaluates it: ρ_KES = q(φ, |γ|)·lineRatio +
 * body·√(cos γ / 2) (the measured quantity on the θ_i + θ_r = 90° line) with
 * φ = π/2 − (φ_i + φ_r) (+π when γ = θ_r − θ_i < 0), divided by √(cos θ_i cos θ_r)·sin β.
 */
/** g(cos θ_i)·g(cos θ_r) of the body (kesbrdf.models.body.BodyLaw); 1 for a Lambertian body. */
export function bodyShape(m: KesModel, cosI: number, cosR: number): number {
  const [a, p] = m.bodyLaw;
  if (a === 0) return 1;
  const g = (mu: number) => 1 - a * Math.pow(Math.min(Math.max(1 - mu, 0), 1), p);
  return g(cosI) * g(cosR);
}

function paperEvaluate(m: KesModel, wi: Vec3, wr: Vec3, out: Float64Array, body: ArrayLike<number>): Float64Array {
  const thetaI = Math.atan2(Math.hypot(wi[0], wi[1]), wi[2]);
  const thetaR = Math.atan2(Math.hypot(wr[0], wr[1]), wr[2]);
  const phiI = Math.atan2(wi[1], wi[0]);
  const phiR = Math.atan2(wr[1], wr[0]);
  const gamma = thetaR - thetaI;
  const phi = Math.PI / 2 - (phiI + phiR) + (gamma < 0 ? Math.PI : 0);
  const s = Math.sin(phiR - phiI - Math.PI);
  const c = Math.cos(thetaR);
  const sinHalfBeta = Math.min(Math.max(0.5 * Math.sqrt(s * s + c * c), 0), 1);
  const sinBeta = Math.max(Math.sin(2 * Math.asin(sinHalfBeta)), PAPER_MIN_SIN_BETA);
  lookup(m, phi, Math.abs(gamma), out);
  const ratio = lineRatio(m, gamma);
  const g = Math.abs(gamma);
  const bodyScale = Math.sqrt(Math.max(Math.cos(gamma), 0) / 2) * bodyShape(m, Math.cos((m.lineSum - g) / 2), Math.cos((m.lineSum + g) / 2));
  const norm = 1 / (Math.sqrt(wi[2] * wr[2]) * sinBeta);
  for (let k = 0; k < m.nChannels; k++) out[k] = (out[k] * ratio + body[Math.min(k, body.length - 1)] * bodyScale) * norm;
  return out;
}

/**
 * f_r = c·g(cos θ_i)·g(cos θ_r) + fade(γ)·q/w (1/sr) of the model for one pair, per channel (docs/formats.md steps 1–3).
 * `body` replaces the model's body term when given (colourways: docs/method.md, "Colour").
 */
export function evaluate(
  m: KesModel,
  wi: Vec3,
  wr: Vec3,
  mapping: Mapping,
  out: Float64Array = new Float64Array(m.nChannels),
  body: ArrayLike<number> | null = null,
): Float64Array {
  if (!(wi[2] > 0) || !(wr[2] > 0)) {
    out.fill(0);
    return out;
  }
  if (mapping === 'paper') return paperEvaluate(m, wi, wr, out, body ?? m.body);
  const [phi, gamma] = toPhiGamma(wi, wr, mapping);
  lookup(m, phi, gamma, out);
  const norm = fade(m, gamma) / foreshortening(m, wi[2], wr[2]);
  const shape = bodyShape(m, wi[2], wr[2]);
  for (let c = 0; c < m.nChannels; c++) out[c] = (body ? body[Math.min(c, body.length - 1)] : m.body[c]) * shape + out[c] * norm;
  return out;
}

export function sph(theta: number, phi: number): Vec3 {
  const s = Math.sin(theta);
  return [s * Math.cos(phi), s * Math.sin(phi), Math.cos(theta)];
}

/** Three display channels (RGB) of a model: RGB as is, one channel grey, others the mean. */
export function rgbOf(values: ArrayLike<number>, channels: string[]): [number, number, number] {
  if (channels.length === 3) return [values[0], values[1], values[2]];
  const v = pick(values, channels.length === 1 ? 0 : -1);
  return [v, v, v];
}

/** Ward (1992) anisotropic reference, for generator metadata {"reference": "ward", ...}. */
export interface Reference {
  label: string;
  channels: number;
  eval(wi: Vec3, wr: Vec3, out: Float64Array): Float64Array;
}

export function referenceFromMetadata(meta: Record<string, string> | undefined): Reference | null {
  const text = meta?.generator;
  if (!text) return null;
  let g: any;
  try {
    g = JSON.parse(text);
  } catch {
    return null;
  }
  if (!g || String(g.reference).toLowerCase() !== 'ward') return null;
  const ax = Number(g.alpha_x);
  const ay = Number(g.alpha_y);
  const rd = ([] as number[]).concat(g.rho_d ?? 0).map(Number);
  const rs = ([] as number[]).concat(g.rho_s ?? 0).map(Number);
  if (!(ax > 0) || !(ay > 0)) return null;
  const C = Math.max(rd.length, rs.length);
  return {
    label: `Ward α=(${ax}, ${ay})`,
    channels: C,
    eval(wi: Vec3, wr: Vec3, out: Float64Array) {
      if (!(wi[2] > 0) || !(wr[2] > 0)) return out.fill(0);
      const hx = wi[0] + wr[0];
      const hy = wi[1] + wr[1];
      const hz = wi[2] + wr[2];
      // tan²θ_h (cos²φ_h/αx² + sin²φ_h/αy²) = ((hx/αx)² + (hy/αy)²) / hz²
      const e = ((hx / ax) ** 2 + (hy / ay) ** 2) / (hz * hz);
      const spec = Math.exp(-e) / (4 * Math.PI * ax * ay * Math.sqrt(wi[2] * wr[2]));
      for (let c = 0; c < out.length; c++) {
        out[c] = rd[Math.min(c, rd.length - 1)] / Math.PI + rs[Math.min(c, rs.length - 1)] * spec;
      }
      return out;
    },
  };
}
