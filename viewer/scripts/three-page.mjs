// Headless Chromium with three.js loaded, shared by the scripts that render with three.js
// (gltf-render.mjs, gltf-look.mjs).  Files are served by request interception on an
// origin that never reaches the network: only viewer/node_modules is readable.
//   const { page, errors, close } = await openThreePage();
//   window.__three (three), window.__GLTFLoader (three/addons GLTFLoader) in the page.
import fs from 'node:fs';
import os from 'node:os';
import path from 'node:path';
import { fileURLToPath } from 'node:url';
import { chromium } from 'playwright-core';

const HERE = path.dirname(fileURLToPath(import.meta.url));
export const VIEWER = path.resolve(HERE, '..');
export const CHROMIUM = process.env.CHROMIUM ?? '/usr/bin/chromium';
const FLAGS = ['--no-sandbox', '--disable-background-networking', '--disable-component-update',
  '--disable-sync', '--no-first-run', '--enable-unsafe-swiftshader', '--use-angle=swiftshader'];
const ORIGIN = 'http://kesbrdf.invalid';

const PAGE = `<!doctype html><html><head><script type="importmap">
{"imports": {"three": "${ORIGIN}/three/build/three.module.js", "three/addons/": "${ORIGIN}/three/examples/jsm/"}}
</script></head><body><script type="module">
import * as THREE from 'three';
import { GLTFLoader } from 'three/addons/loaders/GLTFLoader.js';
window.__three = THREE; window.__GLTFLoader = GLTFLoader; window.__ready = true;
</script></body></html>`;

export async function openThreePage() {
  const profile = fs.mkdtempSync(path.join(os.tmpdir(), 'kesbrdf-three-'));
  const ctx = await chromium.launchPersistentContext(profile, { executablePath: CHROMIUM, headless: true, args: FLAGS });
  const close = async () => {
    await ctx.close();
    fs.rmSync(profile, { recursive: true, force: true });
  };
  try {
    const page = ctx.pages()[0] ?? (await ctx.newPage());
    const errors = [];
    page.on('pageerror', (e) => errors.push(String(e)));
    const root = path.join(VIEWER, 'node_modules');
    await page.route(`${ORIGIN}/**`, (route) => {
      const url = new URL(route.request().url());
      if (url.pathname === '/') return route.fulfill({ contentType: 'text/html', body: PAGE });
      const file = path.join(root, decodeURIComponent(url.pathname));
      if (!file.startsWith(root + path.sep) || !fs.existsSync(file)) return route.fulfill({ status: 404, body: '' });
      return route.fulfill({ contentType: 'text/javascript', body: fs.readFileSync(file) });
    });
    await page.goto(`${ORIGIN}/`);
    await page.waitForFunction(() => window.__ready === true, null, { timeout: 60000 });
    return { page, errors, close };
  } catch (e) {
    await close();
    throw e;
  }
}
