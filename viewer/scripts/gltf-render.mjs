// Load a .glb with three.js GLTFLoader in headless Chromium and render its sphere next to
// the kesbrdf GLSL preview (src/shaders/kes_table.glsl + ../src/kesbrdf/shaders/kes_brdf.glsl) of the same model, same light and
// camera; print both linear images' statistics and their difference.
//   node scripts/gltf-render.mjs IN.json OUT.json
// IN.json: {"glb": "path.glb" (or "glbs": [paths]: one result per file, in "results"), "model": {"nPhi","nGamma","dGamma","table": [RGBA...], "body": [r,g,b]},
//           "light": [x,y,z] (fabric-independent world direction to the light), "size": 96}
// OUT.json: {"material": {...GLTFLoader's MeshPhysicalMaterial fields}, "rel_rmse", "pixels",
//            "mean_gltf", "mean_kes", "gltf": [...], "kes": [...]}  (images: linear RGB, row-major)
import fs from 'node:fs';
import path from 'node:path';
import { VIEWER, openThreePage } from './three-page.mjs';

const [inPath, outPath] = process.argv.slice(2);
const input = JSON.parse(fs.readFileSync(inPath, 'utf-8'));
const glbPaths = input.glbs ?? [input.glb];
const kesGlsl = fs.readFileSync(path.join(VIEWER, 'src', 'shaders', 'kes_table.glsl'), 'utf-8') + '\n' +
  fs.readFileSync(path.join(VIEWER, '..', 'src', 'kesbrdf', 'shaders', 'kes_brdf.glsl'), 'utf-8');

const { page, errors, close } = await openThreePage();
try {
  const results = [];
  for (const glbPath of glbPaths) {
  const glb = fs.readFileSync(glbPath).toString('base64');
  const result = await page.evaluate(async ({ glb, inp, kesGlsl }) => {
    const THREE = window.__three;
    const bytes = Uint8Array.from(atob(glb), (c) => c.charCodeAt(0));
    const gltf = await new Promise((res, rej) => new window.__GLTFLoader().parse(bytes.buffer, '', res, rej));
    let sphere = null;
    gltf.scene.traverse((o) => { if (o.isMesh && o.name.startsWith('sphere')) sphere = o; });
    if (!sphere) throw new Error('no sphere mesh in the glTF');
    const m = sphere.material;
    const material = {
      type: m.type, anisotropy: m.anisotropy, anisotropyRotation: m.anisotropyRotation, roughness: m.roughness,
      sheen: m.sheen, sheenRoughness: m.sheenRoughness, sheenColor: m.sheenColor.toArray(),
      specularIntensity: m.specularIntensity, specularColor: m.specularColor.toArray(), color: m.color.toArray(),
      metalness: m.metalness, hasTangents: !!sphere.geometry.attributes.tangent,
    };
    const N = inp.size;
    const renderer = new THREE.WebGLRenderer({ antialias: false });
    renderer.setSize(N, N);
    renderer.toneMapping = THREE.NoToneMapping;
    const target = new THREE.WebGLRenderTarget(N, N, { type: THREE.FloatType, format: THREE.RGBAFormat });
    const camera = new THREE.OrthographicCamera(-0.55, 0.55, 0.55, -0.55, 0.1, 10);
    const center = new THREE.Vector3();
    sphere.getWorldPosition(center);
    camera.position.set(center.x, center.y, center.z + 3);
    camera.lookAt(center);
    const lightDir = new THREE.Vector3(...inp.light).normalize();
    const read = (scene) => {
      renderer.setRenderTarget(target);
      renderer.setClearColor(0x000000, 0);
      renderer.clear();
      renderer.render(scene, camera);
      const px = new Float32Array(N * N * 4);
      renderer.readRenderTargetPixels(target, 0, 0, N, N, px);
      return px;
    };
    // 1. three.js's own glTF material (MeshPhysicalMaterial), one directional light of 1
    const s1 = new THREE.Scene();
    const mesh1 = new THREE.Mesh(sphere.geometry, m);
    mesh1.position.copy(center);
    s1.add(mesh1);
    const light = new THREE.DirectionalLight(0xffffff, 1.0);
    light.position.copy(center.clone().add(lightDir));
    light.target.position.copy(center);
    s1.add(light, light.target);
    const img1 = read(s1);
    // 2. kesbrdf GLSL preview: f_r(wi, wr) cos(theta_i) in the warp/weft frame of each pixel
    const md = inp.model;
    const tex = new THREE.DataTexture(new Float32Array(md.table), md.nPhi, md.nGamma, THREE.RGBAFormat, THREE.FloatType);
    tex.needsUpdate = true;
    const kesMat = new THREE.ShaderMaterial({
      glslVersion: THREE.GLSL3,
      uniforms: {
        kesTable: { value: tex }, kesNPhi: { value: md.nPhi }, kesNGamma: { value: md.nGamma },
        kesDGamma: { value: md.dGamma }, kesBody: { value: new THREE.Vector3(...md.body) }, kesMapping: { value: 0 },
        lightDirWorld: { value: lightDir }, camPos: { value: camera.position },
      },
      vertexShader: `
        in vec4 tangent;
        out vec3 vN; out vec3 vT; out vec3 vP;
        void main() {
          vN = normalize(mat3(modelMatrix) * normal);
          vT = normalize(mat3(modelMatrix) * tangent.xyz);
          vP = (modelMatrix * vec4(position, 1.0)).xyz;
          gl_Position = projectionMatrix * viewMatrix * vec4(vP, 1.0);
        }`,
      fragmentShader: `
        precision highp float; precision highp int;
        ${kesGlsl}
        uniform vec3 lightDirWorld; uniform vec3 camPos;
        in vec3 vN; in vec3 vT; in vec3 vP;
        out vec4 outColor;
        void main() {
          vec3 n = normalize(vN);
          vec3 t = normalize(vT - dot(vT, n) * n);
          vec3 b = cross(n, t);
          vec3 v = normalize(vec3(0.0, 0.0, 1.0));  // orthographic camera looking down -z
          vec3 l = normalize(lightDirWorld);
          vec3 wi = vec3(dot(l, t), dot(l, b), dot(l, n));
          vec3 wr = vec3(dot(v, t), dot(v, b), dot(v, n));
          outColor = vec4(kesBRDF(wi, wr) * max(wi.z, 0.0), 1.0);
        }`,
    });
    const s2 = new THREE.Scene();
    const mesh2 = new THREE.Mesh(sphere.geometry, kesMat);
    mesh2.position.copy(center);
    s2.add(mesh2);
    const img2 = read(s2);
    // difference over pixels covered by the sphere and lit in both
    let se = 0, sr = 0, count = 0, sum1 = 0, sum2 = 0;
    const g = [], k = [];
    for (let p = 0; p < N * N; p++) {
      const a1 = img1[4 * p + 3], a2 = img2[4 * p + 3];
      for (let c = 0; c < 3; c++) { g.push(img1[4 * p + c]); k.push(img2[4 * p + c]); }
      if (a1 < 0.5 || a2 < 0.5) continue;
      for (let c = 0; c < 3; c++) {
        const d = img1[4 * p + c] - img2[4 * p + c];
        se += d * d; sr += img2[4 * p + c] ** 2; sum1 += img1[4 * p + c]; sum2 += img2[4 * p + c];
      }
      count++;
    }
    return { material, rel_rmse: Math.sqrt(se / Math.max(sr, 1e-30)), pixels: count,
             mean_gltf: sum1 / Math.max(3 * count, 1), mean_kes: sum2 / Math.max(3 * count, 1), size: N, gltf: g, kes: k };
  }, { glb, inp: input, kesGlsl });
  results.push(result);
  }
  if (errors.length) throw new Error(errors.join('\n'));
  fs.writeFileSync(outPath, JSON.stringify(input.glbs ? { results } : results[0]));
} finally {
  await close();
}
