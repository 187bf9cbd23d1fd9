// Render a glTF's material in three.js (GLTFLoader -> MeshPhysicalMaterial) on the look
// scene of kesbrdf.export.looks, in headless Chromium; write the linear RGB image.
//   node scripts/gltf-look.mjs IN.json
// IN.json: {"gltf": path (.gltf with embedded buffers, or .glb),
//           "objects": [{"name", "fabric": bool, "position": [...], "normal": [...], "uv": [...],
//                        "tangent": [...xyzw] (fabric only), "index": [...]}],
//           "floor_albedo": [r,g,b], "lights": [{"position": [x,y,z], "color": [r,g,b], "intensity": cd}],
//           "camera": {"origin", "target", "fov_y_deg"}, "width", "height", "supersample",
//           "output": path.f32 (float32 little-endian, H x W x 3, rows top to bottom), "info": path.json}
import fs from 'node:fs';
import { openThreePage } from './three-page.mjs';

const [inPath] = process.argv.slice(2);
const input = JSON.parse(fs.readFileSync(inPath, 'utf-8'));
const file = fs.readFileSync(input.gltf).toString('base64');

const { page, errors, close } = await openThreePage();
try {
  const result = await page.evaluate(async ({ file, inp }) => {
    const THREE = window.__three;
    const bytes = Uint8Array.from(atob(file), (c) => c.charCodeAt(0));
    const gltf = await new Promise((res, rej) => new window.__GLTFLoader().parse(bytes.buffer, '', res, rej));
    let m = null;
    gltf.scene.traverse((o) => { if (!m && o.isMesh) m = o.material; });
    if (!m) throw new Error('no mesh with a material in the glTF');
    const scene = new THREE.Scene();
    const floor = new THREE.MeshStandardMaterial({ roughness: 1, metalness: 0 });
    floor.color.setRGB(...inp.floor_albedo, THREE.LinearSRGBColorSpace);
    for (const o of inp.objects) {
      const g = new THREE.BufferGeometry();
      g.setAttribute('position', new THREE.Float32BufferAttribute(o.position, 3));
      g.setAttribute('normal', new THREE.Float32BufferAttribute(o.normal, 3));
      g.setAttribute('uv', new THREE.Float32BufferAttribute(o.uv, 2));
      if (o.tangent) g.setAttribute('tangent', new THREE.Float32BufferAttribute(o.tangent, 4));
      g.setIndex(o.index);
      scene.add(new THREE.Mesh(g, o.fabric ? m : floor));
    }
    for (const l of inp.lights) {
      const c = new THREE.Color().setRGB(...l.color, THREE.LinearSRGBColorSpace);
      const light = new THREE.PointLight(c, l.intensity, 0, 2);
      light.position.set(...l.position);
      scene.add(light);
    }
    const s = inp.supersample, W = inp.width * s, H = inp.height * s;
    const camera = new THREE.PerspectiveCamera(inp.camera.fov_y_deg, W / H, 0.01, 1000);
    camera.position.set(...inp.camera.origin);
    camera.up.set(0, 1, 0);
    camera.lookAt(new THREE.Vector3(...inp.camera.target));
    const renderer = new THREE.WebGLRenderer({ antialias: false });
    renderer.setSize(W, H);
    renderer.toneMapping = THREE.NoToneMapping;
    const target = new THREE.WebGLRenderTarget(W, H, { type: THREE.FloatType, format: THREE.RGBAFormat });
    renderer.setRenderTarget(target);
    renderer.setClearColor(0x000000, 1);
    renderer.clear();
    const t0 = performance.now();
    renderer.render(scene, camera);
    const px = new Float32Array(W * H * 4);
    renderer.readRenderTargetPixels(target, 0, 0, W, H, px);
    const ms = performance.now() - t0;
    // box-filter s x s blocks (the plugin's one-pixel box filter), rows top to bottom
    const w = inp.width, h = inp.height, out = new Array(w * h * 3).fill(0);
    for (let y = 0; y < H; y++) {
      const row = h - 1 - Math.floor(y / s);
      for (let x = 0; x < W; x++) {
        const o = 3 * (row * w + Math.floor(x / s));
        for (let c = 0; c < 3; c++) out[o + c] += px[4 * (y * W + x) + c] / (s * s);
      }
    }
    const material = {
      type: m.type, roughness: m.roughness, anisotropy: m.anisotropy, anisotropyRotation: m.anisotropyRotation,
      sheen: m.sheen, sheenRoughness: m.sheenRoughness, sheenColor: m.sheenColor.toArray(),
      specularIntensity: m.specularIntensity, specularColor: m.specularColor.toArray(), ior: m.ior,
      color: m.color.toArray(), metalness: m.metalness, side: m.side,
    };
    return { image: out, material, render_ms: ms, three: THREE.REVISION };
  }, { file, inp: input });
  if (errors.length) throw new Error(errors.join('\n'));
  fs.writeFileSync(input.output, Buffer.from(new Float32Array(result.image).buffer));
  delete result.image;
  fs.writeFileSync(input.info, JSON.stringify(result));
} finally {
  await close();
}
