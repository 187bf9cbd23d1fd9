// Evaluate a GLSL function `vec3 BRDF(vec3 L, vec3 V, vec3 N, vec3 X, vec3 Y)` in headless
// Chromium (WebGL2, GLSL ES 3.00) for a list of direction pairs and print the results.
//   node scripts/glsl-eval.mjs IN.json OUT.json
// IN.json: {"glsl": "...", "uniforms": {"scale": 1, "halfvector": 0, "tint": [1,1,1]},
//           "wi": [[x,y,z],...], "wr": [[x,y,z],...]}   (fabric frame: X warp, Y weft, N = z)
// OUT.json: {"f": [[r,g,b],...], "compile_ms": ..., "renderer": "..."}
import fs from 'node:fs';
import os from 'node:os';
import path from 'node:path';
import { chromium } from 'playwright-core';

const CHROMIUM = process.env.CHROMIUM ?? '/usr/bin/chromium';
// same flags as tests/run.mjs (docs/architecture.md, "Tools it runs on"): WebGL on SwiftShader
const FLAGS = ['--no-sandbox', '--disable-background-networking', '--disable-component-update',
  '--disable-sync', '--no-first-run', '--enable-unsafe-swiftshader', '--use-angle=swiftshader'];

const [inPath, outPath] = process.argv.slice(2);
const input = JSON.parse(fs.readFileSync(inPath, 'utf-8'));
const profile = fs.mkdtempSync(path.join(os.tmpdir(), 'kesbrdf-glsl-'));
const ctx = await chromium.launchPersistentContext(profile, { executablePath: CHROMIUM, headless: true, args: FLAGS });
try {
  const page = ctx.pages()[0] ?? (await ctx.newPage());
  await page.setContent('<canvas id="c"></canvas>');
  const result = await page.evaluate((inp) => {
    const n = inp.wi.length;
    const W = Math.min(n, 256), H = Math.ceil(n / W);
    const canvas = document.getElementById('c');
    canvas.width = W; canvas.height = H;
    const gl = canvas.getContext('webgl2');
    if (!gl) throw new Error('WebGL2 is not available');
    if (!gl.getExtension('EXT_color_buffer_float')) throw new Error('EXT_color_buffer_float is not available');
    const vs = `#version 300 es
in vec2 aPos; void main() { gl_Position = vec4(aPos, 0.0, 1.0); }`;
    // the uniforms BRDF Explorer would declare for the file's parameters
    const fs = `#version 300 es
precision highp float;
precision highp int;
uniform float scale;
uniform bool halfvector;
uniform vec3 tint;
${inp.glsl}
uniform highp sampler2D pairWi;
uniform highp sampler2D pairWr;
out vec4 fragColor;
void main() {
  ivec2 p = ivec2(gl_FragCoord.xy);
  vec3 L = texelFetch(pairWi, p, 0).xyz;
  vec3 V = texelFetch(pairWr, p, 0).xyz;
  fragColor = vec4(BRDF(L, V, vec3(0.0, 0.0, 1.0), vec3(1.0, 0.0, 0.0), vec3(0.0, 1.0, 0.0)), 1.0);
}`;
    const t0 = performance.now();
    const sh = (type, src) => {
      const s = gl.createShader(type); gl.shaderSource(s, src); gl.compileShader(s);
      if (!gl.getShaderParameter(s, gl.COMPILE_STATUS)) throw new Error('GLSL: ' + gl.getShaderInfoLog(s));
      return s;
    };
    const prog = gl.createProgram();
    gl.attachShader(prog, sh(gl.VERTEX_SHADER, vs));
    gl.attachShader(prog, sh(gl.FRAGMENT_SHADER, fs));
    gl.linkProgram(prog);
    if (!gl.getProgramParameter(prog, gl.LINK_STATUS)) throw new Error('link: ' + gl.getProgramInfoLog(prog));
    const compileMs = performance.now() - t0;
    gl.useProgram(prog);
    const tex = (unit, data) => {
      const t = gl.createTexture(); gl.activeTexture(gl.TEXTURE0 + unit); gl.bindTexture(gl.TEXTURE_2D, t);
      gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MIN_FILTER, gl.NEAREST);
      gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MAG_FILTER, gl.NEAREST);
      gl.texImage2D(gl.TEXTURE_2D, 0, gl.RGBA32F, W, H, 0, gl.RGBA, gl.FLOAT, data);
    };
    const pack = (arr) => { const d = new Float32Array(W * H * 4); arr.forEach((v, k) => d.set([v[0], v[1], v[2], 0], 4 * k)); return d; };
    tex(1, pack(inp.wi)); tex(2, pack(inp.wr));
    gl.uniform1i(gl.getUniformLocation(prog, 'pairWi'), 1);
    gl.uniform1i(gl.getUniformLocation(prog, 'pairWr'), 2);
    const u = inp.uniforms;
    gl.uniform1f(gl.getUniformLocation(prog, 'scale'), u.scale);
    gl.uniform1i(gl.getUniformLocation(prog, 'halfvector'), u.halfvector);
    gl.uniform3fv(gl.getUniformLocation(prog, 'tint'), u.tint);
    const target = gl.createTexture(); gl.activeTexture(gl.TEXTURE3); gl.bindTexture(gl.TEXTURE_2D, target);
    gl.texStorage2D(gl.TEXTURE_2D, 1, gl.RGBA32F, W, H);
    const fb = gl.createFramebuffer(); gl.bindFramebuffer(gl.FRAMEBUFFER, fb);
    gl.framebufferTexture2D(gl.FRAMEBUFFER, gl.COLOR_ATTACHMENT0, gl.TEXTURE_2D, target, 0);
    const buf = gl.createBuffer(); gl.bindBuffer(gl.ARRAY_BUFFER, buf);
    gl.bufferData(gl.ARRAY_BUFFER, new Float32Array([-1, -1, 3, -1, -1, 3]), gl.STATIC_DRAW);
    const loc = gl.getAttribLocation(prog, 'aPos'); gl.enableVertexAttribArray(loc);
    gl.vertexAttribPointer(loc, 2, gl.FLOAT, false, 0, 0);
    gl.viewport(0, 0, W, H); gl.drawArrays(gl.TRIANGLES, 0, 3);
    const out = new Float32Array(W * H * 4); gl.readPixels(0, 0, W, H, gl.RGBA, gl.FLOAT, out);
    const f = []; for (let k = 0; k < n; k++) f.push([out[4 * k], out[4 * k + 1], out[4 * k + 2]]);
    const dbg = gl.getExtension('WEBGL_debug_renderer_info');
    return { f, compile_ms: compileMs, renderer: dbg ? gl.getParameter(dbg.UNMASKED_RENDERER_WEBGL) : gl.getParameter(gl.RENDERER) };
  }, input);
  fs.writeFileSync(outPath, JSON.stringify(result));
} finally {
  await ctx.close();
  fs.rmSync(profile, { recursive: true, force: true });
}
