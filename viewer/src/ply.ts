/**
 * Minimal PLY reader for drape meshes (kesbrdf drape): vertices x, y, z with optional
 * nx, ny, nz and texture coordinates (u, v | s, t | texture_u, texture_v), faces as
 * vertex index lists (triangulated as fans). ASCII and binary little-endian.
 */
import * as THREE from 'three';

const SIZES: Record<string, number> = {
  char: 1, uchar: 1, int8: 1, uint8: 1, short: 2, ushort: 2, int16: 2, uint16: 2,
  int: 4, uint: 4, int32: 4, uint32: 4, float: 4, float32: 4, double: 8, float64: 8,
};

interface Prop {
  name: string;
  type: string;
  countType?: string;
}
interface Element {
  name: string;
  count: number;
  props: Prop[];
}

function readScalar(view: DataView, off: number, type: string): number {
  switch (type) {
    case 'char': case 'int8': return view.getInt8(off);
    case 'uchar': case 'uint8': return view.getUint8(off);
    case 'short': case 'int16': return view.getInt16(off, true);
    case 'ushort': case 'uint16': return view.getUint16(off, true);
    case 'int': case 'int32': return view.getInt32(off, true);
    case 'uint': case 'uint32': return view.getUint32(off, true);
    case 'float': case 'float32': return view.getFloat32(off, true);
    case 'double': case 'float64': return view.getFloat64(off, true);
  }
  throw new Error(`PLY: unknown property type ${type}`);
}

export function parsePLY(buffer: ArrayBuffer, name = 'mesh.ply'): THREE.BufferGeometry {
  const bytes = new Uint8Array(buffer);
  const headText = new TextDecoder('latin1').decode(bytes.subarray(0, Math.min(bytes.length, 65536)));
  const endIdx = headText.indexOf('end_header');
  if (!headText.startsWith('ply') || endIdx < 0) throw new Error(`${name}: expected a PLY file ('ply' ... 'end_header')`);
  const nl = headText.indexOf('\n', endIdx);
  const bodyStart = nl + 1;
  const lines = headText.slice(0, endIdx).split(/\r?\n/);
  let format = '';
  const elements: Element[] = [];
  for (const line of lines) {
    const w = line.trim().split(/\s+/);
    if (w[0] === 'format') format = w[1];
    else if (w[0] === 'element') elements.push({ name: w[1], count: Number(w[2]), props: [] });
    else if (w[0] === 'property' && elements.length) {
      const el = elements[elements.length - 1];
      if (w[1] === 'list') el.props.push({ name: w[4], type: w[3], countType: w[2] });
      else el.props.push({ name: w[2], type: w[1] });
    }
  }
  if (format !== 'ascii' && format !== 'binary_little_endian') throw new Error(`${name}: expected PLY format ascii or binary_little_endian, got ${format}`);
  const data: Record<string, Array<Record<string, number | number[]>>> = {};
  if (format === 'ascii') {
    const tokens = new TextDecoder().decode(bytes.subarray(bodyStart)).trim().split(/\s+/).map(Number);
    let t = 0;
    for (const el of elements) {
      const rows: Array<Record<string, number | number[]>> = [];
      for (let r = 0; r < el.count; r++) {
        const row: Record<string, number | number[]> = {};
        for (const p of el.props) {
          if (p.countType) {
            const n = tokens[t++];
            row[p.name] = tokens.slice(t, t + n);
            t += n;
          } else row[p.name] = tokens[t++];
        }
        rows.push(row);
      }
      data[el.name] = rows;
    }
  } else {
    const view = new DataView(buffer);
    let off = bodyStart;
    for (const el of elements) {
      const rows: Array<Record<string, number | number[]>> = [];
      for (let r = 0; r < el.count; r++) {
        const row: Record<string, number | number[]> = {};
        for (const p of el.props) {
          if (p.countType) {
            const n = readScalar(view, off, p.countType);
            off += SIZES[p.countType];
            const list: number[] = [];
            for (let k = 0; k < n; k++) {
              list.push(readScalar(view, off, p.type));
              off += SIZES[p.type];
            }
            row[p.name] = list;
          } else {
            row[p.name] = readScalar(view, off, p.type);
            off += SIZES[p.type];
          }
        }
        rows.push(row);
      }
      data[el.name] = rows;
    }
  }
  const verts = data.vertex ?? [];
  if (!verts.length) throw new Error(`${name}: expected vertices, got none`);
  const v0 = verts[0];
  const uName = ['u', 's', 'texture_u'].find((k) => k in v0);
  const vName = ['v', 't', 'texture_v'].find((k) => k in v0);
  if (!uName || !vName) throw new Error(`${name}: expected texture coordinates (u, v) on the vertices: the warp comes from the UVs`);
  const pos = new Float32Array(verts.length * 3);
  const uv = new Float32Array(verts.length * 2);
  verts.forEach((v, k) => {
    pos.set([v.x as number, v.y as number, v.z as number], 3 * k);
    uv.set([v[uName] as number, v[vName] as number], 2 * k);
  });
  const index: number[] = [];
  for (const f of data.face ?? []) {
    const list = (f.vertex_indices ?? f.vertex_index) as number[] | undefined;
    if (!list) continue;
    for (let k = 1; k + 1 < list.length; k++) index.push(list[0], list[k], list[k + 1]);
  }
  const geom = new THREE.BufferGeometry();
  geom.setAttribute('position', new THREE.BufferAttribute(pos, 3));
  geom.setAttribute('uv', new THREE.BufferAttribute(uv, 2));
  geom.setIndex(index);
  if ('nx' in v0) {
    const nrm = new Float32Array(verts.length * 3);
    verts.forEach((v, k) => nrm.set([v.nx as number, v.ny as number, v.nz as number], 3 * k));
    geom.setAttribute('normal', new THREE.BufferAttribute(nrm, 3));
  } else geom.computeVertexNormals();
  return geom;
}
