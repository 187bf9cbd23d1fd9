/** The model table as RGBA float texture data for the GLSL chunk (shaders/kes_table.glsl). */
import type { KesModel } from './model';

/**
 * Texel (i, j) = q(φ_i, γ_j) in RGB: three channels as they are, one channel
 * replicated, more channels (spectral) averaged. Row j of the texture is γ_j.
 */
export function tableTextureData(m: KesModel): { data: Float32Array; body: [number, number, number] } {
  const C = m.nChannels;
  const data = new Float32Array(m.nPhi * m.nGamma * 4);
  const rgb = (src: Float64Array, base: number): [number, number, number] => {
    if (C === 3) return [src[base], src[base + 1], src[base + 2]];
    let s = 0;
    for (let c = 0; c < C; c++) s += src[base + c];
    const v = s / C;
    return [v, v, v];
  };
  for (let i = 0; i < m.nPhi; i++) {
    for (let j = 0; j < m.nGamma; j++) {
      const [r, g, b] = rgb(m.table, (i * m.nGamma + j) * C);
      const o = 4 * (j * m.nPhi + i);
      data[o] = r;
      data[o + 1] = g;
      data[o + 2] = b;
      data[o + 3] = 1;
    }
  }
  return { data, body: rgb(m.body, 0) };
}
