/**
 * Fig. 5: the anisotropic reflection model as a 3-D surface. x = warp, y = weft,
 * z = the mirror direction; the point at angle γ from z and azimuth φ sits at radius
 * q(φ, γ). Rotatable with the mouse (OrbitControls).
 */
import * as THREE from 'three';
import { OrbitControls } from 'three/examples/jsm/controls/OrbitControls.js';
import { lookupChannel, type KesModel } from './model';
import { sequential } from './plots';

export class SphereView {
  readonly renderer: THREE.WebGLRenderer;
  private scene = new THREE.Scene();
  private camera = new THREE.PerspectiveCamera(35, 1, 0.01, 100);
  private controls: OrbitControls;
  private mesh: THREE.Mesh | null = null;

  constructor(private canvas: HTMLCanvasElement) {
    this.renderer = new THREE.WebGLRenderer({ canvas, antialias: true, preserveDrawingBuffer: true });
    this.renderer.setClearColor(0xffffff);
    this.camera.up.set(0, 0, 1);
    this.camera.position.set(2.2, -2.6, 1.8);
    this.controls = new OrbitControls(this.camera, canvas);
    this.controls.addEventListener('change', () => this.render());
    const axes: Array<[THREE.Vector3, number, string]> = [
      [new THREE.Vector3(1, 0, 0), 0xd62728, 'warp (x)'],
      [new THREE.Vector3(0, 1, 0), 0x2ca02c, 'weft (y)'],
      [new THREE.Vector3(0, 0, 1), 0x1f77b4, 'mirror (z)'],
    ];
    for (const [dir, colour] of axes) {
      this.scene.add(new THREE.ArrowHelper(dir, new THREE.Vector3(0, 0, 0), 1.25, colour, 0.06, 0.04));
    }
    this.scene.add(new THREE.AmbientLight(0xffffff, 0.55));
    const sun = new THREE.DirectionalLight(0xffffff, 2.0);
    sun.position.set(1, -1, 2);
    this.scene.add(sun);
  }

  setModel(m: KesModel, ch: number): void {
    if (this.mesh) {
      this.scene.remove(this.mesh);
      this.mesh.geometry.dispose();
    }
    const nPhi = 96;
    const nGamma = 48;
    const gmax = Math.min(m.gammaMax, Math.PI / 2);
    const vals: number[] = [];
    let vmax = 1e-12;
    for (let j = 0; j <= nGamma; j++) {
      for (let i = 0; i <= nPhi; i++) {
        const v = Math.max(lookupChannel(m, (i / nPhi) * 2 * Math.PI, (j / nGamma) * gmax, ch), 0);
        vals.push(v);
        vmax = Math.max(vmax, v);
      }
    }
    const pos: number[] = [];
    const col: number[] = [];
    const idx: number[] = [];
    for (let j = 0; j <= nGamma; j++) {
      const g = (j / nGamma) * gmax;
      for (let i = 0; i <= nPhi; i++) {
        const phi = (i / nPhi) * 2 * Math.PI;
        const r = vals[j * (nPhi + 1) + i] / vmax; // normalised so the largest lobe radius is 1
        pos.push(r * Math.sin(g) * Math.cos(phi), r * Math.sin(g) * Math.sin(phi), r * Math.cos(g));
        const [cr, cg, cb] = sequential(0.15 + 0.85 * r);
        col.push(cr / 255, cg / 255, cb / 255);
        if (i < nPhi && j < nGamma) {
          const a = j * (nPhi + 1) + i;
          const b = a + nPhi + 1;
          idx.push(a, b, a + 1, a + 1, b, b + 1);
        }
      }
    }
    const geom = new THREE.BufferGeometry();
    geom.setAttribute('position', new THREE.Float32BufferAttribute(pos, 3));
    geom.setAttribute('color', new THREE.Float32BufferAttribute(col, 3));
    geom.setIndex(idx);
    geom.computeVertexNormals();
    const mat = new THREE.MeshLambertMaterial({ vertexColors: true, side: THREE.DoubleSide });
    this.mesh = new THREE.Mesh(geom, mat);
    this.scene.add(this.mesh);
    this.render();
  }

  resize(): void {
    const w = this.canvas.clientWidth || 480;
    const h = this.canvas.clientHeight || 480;
    this.renderer.setSize(w, h, false);
    this.camera.aspect = w / h;
    this.camera.updateProjectionMatrix();
  }

  render(): void {
    this.resize();
    this.renderer.render(this.scene, this.camera);
  }
}
