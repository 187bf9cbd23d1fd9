/**
 * Real-time preview: a lit sphere, a flat swatch or a draped cloth (a drape mesh PLY
 * when given, else a procedural fold) shaded by the model in GLSL
 * (shaders/kes_table.glsl + src/kesbrdf/shaders/kes_brdf.glsl). The warp direction is the mesh's UV-u tangent dP/du, the
 * weft N × T, so a garment's UVs carry the weave like in the Mitsuba renderer.
 */
import * as THREE from 'three';
import { OrbitControls } from 'three/examples/jsm/controls/OrbitControls.js';
import kesTableGlsl from './shaders/kes_table.glsl?raw';
// the one copy of the model's GLSL, shared with the BRDF Explorer export
import kesEvalGlsl from '../../src/kesbrdf/shaders/kes_brdf.glsl?raw';
import { MAPPING_CODE, type KesModel, type Mapping, type Vec3 } from './model';
import { tableTextureData } from './texture';

export type PreviewObject = 'sphere' | 'swatch' | 'cloth';

const VERTEX = /* glsl */ `
in vec3 warpTangent;
out vec3 vPos;
out vec3 vNormal;
out vec3 vTangent;
void main() {
  vec4 wp = modelMatrix * vec4(position, 1.0);
  vPos = wp.xyz;
  vNormal = normalize(mat3(modelMatrix) * normal);
  vTangent = mat3(modelMatrix) * warpTangent;
  gl_Position = projectionMatrix * viewMatrix * wp;
}`;

const FRAGMENT = /* glsl */ `
precision highp float;
precision highp int;
${kesTableGlsl}
${kesEvalGlsl}
uniform vec3 lightDir;     // world space, toward the light
uniform float exposure;    // linear scale 2^EV
uniform float ambient;     // fraction of the body colour added as fill light
in vec3 vPos;
in vec3 vNormal;
in vec3 vTangent;
out vec4 fragColor;

vec3 linearToSRGB(vec3 c) {
  c = clamp(c, 0.0, 1.0);
  return mix(c * 12.92, 1.055 * pow(c, vec3(1.0 / 2.4)) - 0.055, step(vec3(0.0031308), c));
}

void main() {
  vec3 N = normalize(vNormal);
  if (!gl_FrontFacing) N = -N;
  vec3 T = vTangent - N * dot(N, vTangent);
  T = dot(T, T) > 1e-20 ? normalize(T) : normalize(cross(N, abs(N.z) < 0.9 ? vec3(0.0, 0.0, 1.0) : vec3(1.0, 0.0, 0.0)));
  vec3 B = cross(N, T);
  vec3 V = normalize(cameraPosition - vPos);
  vec3 L = normalize(lightDir);
  // fabric frame: x = warp (dP/du), y = weft, z = normal
  vec3 wi = vec3(dot(L, T), dot(L, B), dot(L, N));
  vec3 wr = vec3(dot(V, T), dot(V, B), dot(V, N));
  // irradiance pi from a directional light: a white Lambertian (f = 1/pi) shows as 1
  vec3 radiance = kesBRDF(wi, wr) * max(wi.z, 0.0) * KES_PI + ambient * kesBody * KES_PI;
  fragColor = vec4(linearToSRGB(radiance * exposure), 1.0);
}`;

/** Per-vertex warp tangent dP/du from the UVs (accumulated over the faces). */
export function computeWarpTangents(geom: THREE.BufferGeometry): void {
  const pos = geom.getAttribute('position');
  const uv = geom.getAttribute('uv');
  const n = pos.count;
  const tan = new Float32Array(n * 3);
  const index = geom.getIndex();
  const nTri = index ? index.count / 3 : n / 3;
  const p = [new THREE.Vector3(), new THREE.Vector3(), new THREE.Vector3()];
  const e1 = new THREE.Vector3();
  const e2 = new THREE.Vector3();
  for (let t = 0; t < nTri; t++) {
    const ids = [0, 1, 2].map((k) => (index ? index.getX(3 * t + k) : 3 * t + k));
    ids.forEach((id, k) => p[k].fromBufferAttribute(pos, id));
    e1.subVectors(p[1], p[0]);
    e2.subVectors(p[2], p[0]);
    const du1 = uv.getX(ids[1]) - uv.getX(ids[0]);
    const dv1 = uv.getY(ids[1]) - uv.getY(ids[0]);
    const du2 = uv.getX(ids[2]) - uv.getX(ids[0]);
    const dv2 = uv.getY(ids[2]) - uv.getY(ids[0]);
    const det = du1 * dv2 - du2 * dv1;
    if (Math.abs(det) < 1e-20) continue;
    // dP/du = (e1 dv2 − e2 dv1) / det; sign(det) keeps mirrored UV islands consistent
    const tx = (e1.x * dv2 - e2.x * dv1) / det;
    const ty = (e1.y * dv2 - e2.y * dv1) / det;
    const tz = (e1.z * dv2 - e2.z * dv1) / det;
    for (const id of ids) {
      tan[3 * id] += tx;
      tan[3 * id + 1] += ty;
      tan[3 * id + 2] += tz;
    }
  }
  for (let k = 0; k < n; k++) {
    const l = Math.hypot(tan[3 * k], tan[3 * k + 1], tan[3 * k + 2]) || 1;
    tan[3 * k] /= l;
    tan[3 * k + 1] /= l;
    tan[3 * k + 2] /= l;
  }
  geom.setAttribute('warpTangent', new THREE.BufferAttribute(tan, 3));
}

/** A cloth hanging in folds: deeper toward the hem, with one diagonal crease. */
export function proceduralFold(): THREE.BufferGeometry {
  const geom = new THREE.PlaneGeometry(2, 2, 128, 128);
  const pos = geom.getAttribute('position');
  for (let k = 0; k < pos.count; k++) {
    const x = pos.getX(k);
    const y = pos.getY(k);
    const depth = 0.05 + 0.12 * (1 - (y + 1) / 2);
    const folds = depth * Math.sin(2 * Math.PI * 1.6 * x + 0.6 * y);
    const crease = 0.08 * Math.exp(-(((x + y * 0.8 - 0.2) / 0.18) ** 2));
    pos.setZ(k, folds + crease - 0.12 * x * x);
  }
  geom.computeVertexNormals();
  return geom;
}

export class Preview {
  readonly renderer: THREE.WebGLRenderer;
  private scene = new THREE.Scene();
  private camera = new THREE.PerspectiveCamera(32, 1, 0.05, 50);
  private controls: OrbitControls;
  private material: THREE.ShaderMaterial;
  private mesh: THREE.Mesh;
  private table: THREE.DataTexture | null = null;
  private modelBody: [number, number, number] = [0, 0, 0];
  private drape: THREE.BufferGeometry | null = null;
  private pending = false;
  object: PreviewObject = 'sphere';
  bodyOverride: [number, number, number] | null = null;

  constructor(private canvas: HTMLCanvasElement) {
    this.renderer = new THREE.WebGLRenderer({ canvas, antialias: false, preserveDrawingBuffer: true });
    this.renderer.setPixelRatio(1);
    this.renderer.setClearColor(0x202428);
    this.camera.position.set(0, 0, 4.2);
    this.controls = new OrbitControls(this.camera, canvas);
    this.controls.addEventListener('change', () => this.invalidate());
    this.material = new THREE.ShaderMaterial({
      glslVersion: THREE.GLSL3,
      vertexShader: VERTEX,
      fragmentShader: FRAGMENT,
      side: THREE.DoubleSide,
      uniforms: {
        kesTable: { value: null },
        kesNPhi: { value: 1 },
        kesNGamma: { value: 2 },
        kesDGamma: { value: 1 },
        kesLambda: { value: 0 },
        kesGammaMax: { value: 1 },
        kesFadeSlope: { value: 0 },
        kesLineSum: { value: Math.PI / 2 },
        kesBody: { value: new THREE.Vector3() },
        kesBodyA: { value: 0 },
        kesBodyP: { value: 1 },
        kesMapping: { value: 0 },
        lightDir: { value: new THREE.Vector3(0, 0.5, 0.866) },
        exposure: { value: 1 },
        ambient: { value: 0.04 },
      },
    });
    this.mesh = new THREE.Mesh(new THREE.BufferGeometry(), this.material);
    this.scene.add(this.mesh);
    this.setObject('sphere');
  }

  setModel(m: KesModel): void {
    const t = tableTextureData(m);
    this.table?.dispose();
    const tex = new THREE.DataTexture(t.data, m.nPhi, m.nGamma, THREE.RGBAFormat, THREE.FloatType);
    tex.minFilter = THREE.NearestFilter;
    tex.magFilter = THREE.NearestFilter;
    tex.generateMipmaps = false;
    tex.needsUpdate = true;
    this.table = tex;
    this.modelBody = t.body;
    const u = this.material.uniforms;
    u.kesTable.value = tex;
    u.kesNPhi.value = m.nPhi;
    u.kesNGamma.value = m.nGamma;
    u.kesDGamma.value = m.dGamma;
    u.kesLambda.value = m.lambda;
    u.kesGammaMax.value = m.gammaMax;
    u.kesFadeSlope.value = m.fadeSlope;
    u.kesLineSum.value = m.lineSum;
    u.kesBodyA.value = m.bodyLaw[0];
    u.kesBodyP.value = m.bodyLaw[1];
    this.updateBody();
  }

  private updateBody(): void {
    const b = this.bodyOverride ?? this.modelBody;
    (this.material.uniforms.kesBody.value as THREE.Vector3).set(b[0], b[1], b[2]);
    this.invalidate();
  }

  /** Body colour (linear RGB albedo) or null for the model's own body term (docs/method.md, "Colour": f_body = base_color/π). */
  setBaseColor(linearRGB: [number, number, number] | null): void {
    this.bodyOverride = linearRGB ? [linearRGB[0] / Math.PI, linearRGB[1] / Math.PI, linearRGB[2] / Math.PI] : null;
    this.updateBody();
  }

  setMapping(mapping: Mapping): void {
    this.material.uniforms.kesMapping.value = MAPPING_CODE[mapping];
    this.invalidate();
  }

  setLight(w: Vec3): void {
    (this.material.uniforms.lightDir.value as THREE.Vector3).set(w[0], w[1], w[2]);
    this.invalidate();
  }

  setExposure(ev: number): void {
    this.material.uniforms.exposure.value = 2 ** ev;
    this.invalidate();
  }

  setDrapeMesh(geom: THREE.BufferGeometry): void {
    geom.computeBoundingSphere();
    const s = geom.boundingSphere!;
    geom.translate(-s.center.x, -s.center.y, -s.center.z);
    geom.scale(1.3 / s.radius, 1.3 / s.radius, 1.3 / s.radius);
    computeWarpTangents(geom);
    this.drape?.dispose();
    this.drape = geom;
    this.setObject('cloth');
  }

  get hasDrapeMesh(): boolean {
    return this.drape !== null;
  }

  setObject(kind: PreviewObject): void {
    this.object = kind;
    let geom: THREE.BufferGeometry;
    if (kind === 'sphere') {
      // poles at ±y (top, bottom) where the u-tangent field must vanish; at the front
      // centre the warp (dP/du) is +x, like on the swatch
      geom = new THREE.SphereGeometry(1.05, 96, 64);
    } else if (kind === 'swatch') {
      geom = new THREE.PlaneGeometry(2.2, 2.2, 1, 1);
    } else {
      geom = this.drape ?? proceduralFold();
    }
    if (!geom.getAttribute('warpTangent')) computeWarpTangents(geom);
    // a closed sphere needs no back faces (half the fragment work); cloth shows both sides
    this.material.side = kind === 'sphere' ? THREE.FrontSide : THREE.DoubleSide;
    this.material.needsUpdate = true;
    if (this.mesh.geometry !== this.drape) this.mesh.geometry.dispose();
    this.mesh.geometry = geom;
    this.invalidate();
  }

  invalidate(): void {
    if (this.pending) return;
    this.pending = true;
    requestAnimationFrame(() => {
      this.pending = false;
      this.render();
    });
  }

  resize(): void {
    const w = this.canvas.clientWidth || 512;
    const h = this.canvas.clientHeight || 512;
    if (this.canvas.width !== w || this.canvas.height !== h) this.renderer.setSize(w, h, false);
    this.camera.aspect = w / h;
    this.camera.updateProjectionMatrix();
  }

  render(): void {
    this.resize();
    this.renderer.render(this.scene, this.camera);
  }

  /**
   * Render and read one pixel (x right, y down from the top-left) with the viewing
   * direction there, for checking the preview's frame plumbing against the CPU
   * evaluator. Only meaningful on the flat swatch (the plane z = 0).
   */
  probe(px: number, py: number): { rgb: number[]; wr: Vec3; hit: boolean } {
    this.render();
    const gl = this.renderer.getContext();
    const buf = new Uint8Array(4);
    const h = this.canvas.height;
    gl.readPixels(px, h - 1 - py, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, buf);
    const ndc = new THREE.Vector2(((px + 0.5) / this.canvas.width) * 2 - 1, 1 - ((py + 0.5) / h) * 2);
    const ray = new THREE.Raycaster();
    ray.setFromCamera(ndc, this.camera);
    const hit = new THREE.Vector3();
    const ok = ray.ray.intersectPlane(new THREE.Plane(new THREE.Vector3(0, 0, 1), 0), hit) !== null;
    const wr = this.camera.position.clone().sub(hit).normalize();
    return { rgb: [buf[0], buf[1], buf[2]], wr: [wr.x, wr.y, wr.z], hit: ok };
  }

  /** Mean milliseconds per frame over `frames` synchronous renders (readPixels forces completion). */
  benchmark(frames: number): { msPerFrame: number; width: number; height: number; frames: number } {
    const gl = this.renderer.getContext();
    const px = new Uint8Array(4);
    this.render();
    gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, px);
    const t0 = performance.now();
    for (let k = 0; k < frames; k++) {
      this.renderer.render(this.scene, this.camera);
      gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, px);
    }
    const ms = (performance.now() - t0) / frames;
    return { msPerFrame: ms, width: this.canvas.width, height: this.canvas.height, frames };
  }
}
