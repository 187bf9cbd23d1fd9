/**
 * GLSL–Python agreement: evaluate the preview's GLSL (shaders/kes_table.glsl + src/kesbrdf/shaders/kes_brdf.glsl)
 * for a list of direction pairs into an RGBA32F framebuffer and read the pixels back.
 * Used by the browser tests (window.kesbrdf.evalPairsGL) and nothing else.
 */
import kesTableGlsl from './shaders/kes_table.glsl?raw';
// the one copy of the model's GLSL, shared with the BRDF Explorer export
import kesEvalGlsl from '../../src/kesbrdf/shaders/kes_brdf.glsl?raw';
import { MAPPING_CODE, type KesModel, type Mapping, type Vec3 } from './model';
import { tableTextureData } from './texture';

const VERT = `#version 300 es
in vec2 aPos;
void main() { gl_Position = vec4(aPos, 0.0, 1.0); }`;

const FRAG = `#version 300 es
precision highp float;
precision highp int;
${kesTableGlsl}
${kesEvalGlsl}
uniform highp sampler2D pairWi;
uniform highp sampler2D pairWr;
out vec4 fragColor;
void main() {
  ivec2 p = ivec2(gl_FragCoord.xy);
  vec3 wi = texelFetch(pairWi, p, 0).xyz;
  vec3 wr = texelFetch(pairWr, p, 0).xyz;
  fragColor = vec4(kesBRDF(wi, wr), 1.0);
}`;

function compile(gl: WebGL2RenderingContext, type: number, src: string): WebGLShader {
  const s = gl.createShader(type)!;
  gl.shaderSource(s, src);
  gl.compileShader(s);
  if (!gl.getShaderParameter(s, gl.COMPILE_STATUS)) throw new Error(`GLSL: ${gl.getShaderInfoLog(s)}`);
  return s;
}

function floatTexture(gl: WebGL2RenderingContext, unit: number, w: number, h: number, data: Float32Array): WebGLTexture {
  const tex = gl.createTexture()!;
  gl.activeTexture(gl.TEXTURE0 + unit);
  gl.bindTexture(gl.TEXTURE_2D, tex);
  gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MIN_FILTER, gl.NEAREST);
  gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MAG_FILTER, gl.NEAREST);
  gl.texImage2D(gl.TEXTURE_2D, 0, gl.RGBA32F, w, h, 0, gl.RGBA, gl.FLOAT, data);
  return tex;
}

/**
 * f_r (first three display channels) of `model` for each pair, computed on the GPU.
 * `body` overrides the model's body term (RGB, 1/sr) when given.
 */
export function evalPairsGL(
  model: KesModel,
  pairs: Array<[Vec3, Vec3]>,
  mapping: Mapping,
  body: [number, number, number] | null = null,
): number[][] {
  const n = pairs.length;
  const W = Math.min(n, 256);
  const H = Math.ceil(n / W);
  const canvas = document.createElement('canvas');
  canvas.width = W;
  canvas.height = H;
  const gl = canvas.getContext('webgl2');
  if (!gl) throw new Error('WebGL2 is not available');
  if (!gl.getExtension('EXT_color_buffer_float')) throw new Error('EXT_color_buffer_float is not available');
  const prog = gl.createProgram()!;
  gl.attachShader(prog, compile(gl, gl.VERTEX_SHADER, VERT));
  gl.attachShader(prog, compile(gl, gl.FRAGMENT_SHADER, FRAG));
  gl.linkProgram(prog);
  if (!gl.getProgramParameter(prog, gl.LINK_STATUS)) throw new Error(`GLSL link: ${gl.getProgramInfoLog(prog)}`);
  gl.useProgram(prog);

  const wiData = new Float32Array(W * H * 4);
  const wrData = new Float32Array(W * H * 4);
  pairs.forEach(([wi, wr], k) => {
    wiData.set([wi[0], wi[1], wi[2], 0], 4 * k);
    wrData.set([wr[0], wr[1], wr[2], 0], 4 * k);
  });
  const t = tableTextureData(model);
  floatTexture(gl, 0, model.nPhi, model.nGamma, t.data);
  floatTexture(gl, 1, W, H, wiData);
  floatTexture(gl, 2, W, H, wrData);
  gl.uniform1i(gl.getUniformLocation(prog, 'kesTable'), 0);
  gl.uniform1i(gl.getUniformLocation(prog, 'pairWi'), 1);
  gl.uniform1i(gl.getUniformLocation(prog, 'pairWr'), 2);
  gl.uniform1i(gl.getUniformLocation(prog, 'kesNPhi'), model.nPhi);
  gl.uniform1i(gl.getUniformLocation(prog, 'kesNGamma'), model.nGamma);
  gl.uniform1f(gl.getUniformLocation(prog, 'kesDGamma'), model.dGamma);
  gl.uniform1f(gl.getUniformLocation(prog, 'kesLambda'), model.lambda);
  gl.uniform1f(gl.getUniformLocation(prog, 'kesGammaMax'), model.gammaMax);
  gl.uniform1f(gl.getUniformLocation(prog, 'kesFadeSlope'), model.fadeSlope);
  gl.uniform1f(gl.getUniformLocation(prog, 'kesLineSum'), model.lineSum);
  gl.uniform1i(gl.getUniformLocation(prog, 'kesMapping'), MAPPING_CODE[mapping]);
  gl.uniform3fv(gl.getUniformLocation(prog, 'kesBody'), body ?? t.body);
  gl.uniform1f(gl.getUniformLocation(prog, 'kesBodyA'), model.bodyLaw[0]);
  gl.uniform1f(gl.getUniformLocation(prog, 'kesBodyP'), model.bodyLaw[1]);

  const target = gl.createTexture()!;
  gl.activeTexture(gl.TEXTURE3);
  gl.bindTexture(gl.TEXTURE_2D, target);
  gl.texStorage2D(gl.TEXTURE_2D, 1, gl.RGBA32F, W, H);
  const fb = gl.createFramebuffer();
  gl.bindFramebuffer(gl.FRAMEBUFFER, fb);
  gl.framebufferTexture2D(gl.FRAMEBUFFER, gl.COLOR_ATTACHMENT0, gl.TEXTURE_2D, target, 0);
  if (gl.checkFramebufferStatus(gl.FRAMEBUFFER) !== gl.FRAMEBUFFER_COMPLETE) throw new Error('float framebuffer incomplete');

  const buf = gl.createBuffer();
  gl.bindBuffer(gl.ARRAY_BUFFER, buf);
  gl.bufferData(gl.ARRAY_BUFFER, new Float32Array([-1, -1, 3, -1, -1, 3]), gl.STATIC_DRAW);
  const loc = gl.getAttribLocation(prog, 'aPos');
  gl.enableVertexAttribArray(loc);
  gl.vertexAttribPointer(loc, 2, gl.FLOAT, false, 0, 0);
  gl.viewport(0, 0, W, H);
  gl.drawArrays(gl.TRIANGLES, 0, 3);
  const out = new Float32Array(W * H * 4);
  gl.readPixels(0, 0, W, H, gl.RGBA, gl.FLOAT, out);
  gl.getExtension('WEBGL_lose_context')?.loseContext();
  const result: number[][] = [];
  for (let k = 0; k < n; k++) result.push([out[4 * k], out[4 * k + 1], out[4 * k + 2]]);
  return result;
}
