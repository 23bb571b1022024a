// Builds the console into tpr-web's --console-dir (CMake passes --outDir).
// Everything is bundled: no CDN at run time.
import { defineConfig } from 'vite';

export default defineConfig({
  base: '/',
  build: {
    target: 'es2020',
    chunkSizeWarningLimit: 1024,
    sourcemap: false,
  },
});
