/**
 * Test-only hooks of the viewer: `window.kesbrdf`, used by the browser suite
 * (viewer/tests/run.mjs) to read canvases, load model documents, compare the GLSL and
 * CPU evaluators and probe the preview.
 *
 * This module is a separate chunk of the bundle.  main.ts loads it only when the page
 * URL carries `?testhooks`, so the page users open never loads it or exposes the hooks.
 */
import { evalPairsGL } from './glcheck';
import { evaluate, type KesModel, type Mapping, type Vec3 } from './model';
import type { Preview } from './preview';

/** What main.ts hands to the hooks: its state and the few functions the tests drive. */
export interface ViewerInternals<V extends string = string> {
  state: { model: KesModel | null; view: V; mapping: Mapping; thetaI: number; phiI: number };
  renderCount: () => number;
  setModel: (doc: any, name: string, measDoc: any) => void;
  ensurePreview: () => Preview;
  applyPreviewControls: () => void;
  lightDir: () => Vec3;
  drawLightPicker: () => void;
  renderView: () => void;
  views: readonly V[];
}

declare global {
  interface Window {
    kesbrdf: Record<string, unknown>;
  }
}

const DEG = Math.PI / 180;
const el = <T extends HTMLElement>(id: string) => document.getElementById(id) as T;

/** Mean and variance of a canvas' grey levels (a blank canvas has variance 0). */
function canvasStats(id: string): { mean: number; variance: number; width: number; height: number } {
  const src = el<HTMLCanvasElement>(id);
  const tmp = document.createElement('canvas');
  tmp.width = src.width;
  tmp.height = src.height;
  const ctx = tmp.getContext('2d')!;
  ctx.drawImage(src, 0, 0);
  const d = ctx.getImageData(0, 0, tmp.width, tmp.height).data;
  let s = 0;
  let s2 = 0;
  const n = d.length / 4;
  for (let k = 0; k < d.length; k += 4) {
    const l = (d[k] + d[k + 1] + d[k + 2]) / 3;
    s += l;
    s2 += l * l;
  }
  const mean = s / n;
  return { mean, variance: s2 / n - mean * mean, width: tmp.width, height: tmp.height };
}

export function installTestHooks<V extends string>(v: ViewerInternals<V>): void {
  const { state } = v;
  window.kesbrdf = {
    state,
    get renderCount() {
      return v.renderCount();
    },
    canvasStats,
    loadModelDoc: (doc: any, name = 'test', meas: any = null) => v.setModel(doc, name, meas),
    evalPairsGL: (pairs: Array<[Vec3, Vec3]>, mapping: Mapping, body: [number, number, number] | null = null) =>
      evalPairsGL(state.model!, pairs, mapping, body),
    evalPairsCPU: (pairs: Array<[Vec3, Vec3]>, mapping: Mapping) =>
      pairs.map(([wi, wr]) => Array.from(evaluate(state.model!, wi, wr, mapping))),
    benchPreview: (frames = 20) => {
      const p = v.ensurePreview();
      v.applyPreviewControls();
      return p.benchmark(frames);
    },
    /** Preview pixel on the swatch vs the CPU evaluator for a light (degrees) and exposure (EV). */
    previewProbe: (thetaDeg: number, phiDeg: number, ev: number, px = 200, py = 300) => {
      const p = v.ensurePreview();
      state.thetaI = thetaDeg * DEG;
      state.phiI = phiDeg * DEG;
      el<HTMLSelectElement>('object').value = 'swatch';
      el<HTMLInputElement>('exposure').value = String(ev);
      v.applyPreviewControls();
      const got = p.probe(px, py);
      const m = state.model!;
      const wi = v.lightDir();
      const body = p.bodyOverride;
      const f = evaluate(m, wi, got.wr, state.mapping, new Float64Array(m.nChannels), body);
      const bodyRGB = body ?? [m.body[0], m.body[Math.min(1, m.nChannels - 1)], m.body[Math.min(2, m.nChannels - 1)]];
      const encode = (c: number) => {
        const x = Math.min(Math.max(c, 0), 1);
        return 255 * (x <= 0.0031308 ? 12.92 * x : 1.055 * x ** (1 / 2.4) - 0.055);
      };
      // the fragment shader's radiance: f cosθi π + 0.04 body π, times 2^EV
      const expected = [0, 1, 2].map((c) =>
        encode((f[Math.min(c, m.nChannels - 1)] * wi[2] * Math.PI + 0.04 * bodyRGB[c] * Math.PI) * 2 ** ev),
      );
      v.drawLightPicker();
      return { got: got.rgb, expected, wr: got.wr, hit: got.hit };
    },
    setView: (view: V) => {
      state.view = view;
      v.renderView();
    },
    views: v.views,
  };
}
