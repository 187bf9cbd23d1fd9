import { defineConfig } from 'vite';

// Deterministic build: fixed file names (no content hashes), relative base, no
// source maps, so `make test-web` can diff a rebuild against the committed bundle
// in src/kesbrdf/viewer/static/.
export default defineConfig({
  base: './',
  // `npm run dev`: forward the JSON API to a running `kesbrdf view --port 8765`
  // and serve ../src/kesbrdf/shaders/kes_brdf.glsl, the model's GLSL shared with the Python export
  server: { proxy: { '/api': process.env.KESBRDF_API ?? 'http://127.0.0.1:8765' }, fs: { allow: ['..'] } },
  build: {
    outDir: 'dist',
    sourcemap: false,
    chunkSizeWarningLimit: 2000,
    assetsInlineLimit: 0,
    modulePreload: { polyfill: false },
    rolldownOptions: {
      output: {
        entryFileNames: 'assets/[name].js',
        chunkFileNames: 'assets/[name].js',
        assetFileNames: 'assets/[name][extname]',
      },
    },
  },
});
