// Builds the web viewer's static files: bundles src/main.js (three.js, onnxruntime-web) with esbuild into
// viewer.js and copies index.html and onnxruntime-web's WASM binary next to it.
//
//   node build.mjs [OUTDIR]     (default: ../../nasset_sdk/web_viewer, the files shipped in the wheel)
//
// The output depends only on src/ and the package-lock.json versions; tests/sdk/test_web.py rebuilds into a
// temporary folder and compares with the checked-in files.
import { build } from "esbuild";
import { copyFileSync, mkdirSync, renameSync } from "node:fs";
import { dirname, join, resolve } from "node:path";
import { fileURLToPath } from "node:url";

const here = dirname(fileURLToPath(import.meta.url));
const out = resolve(process.argv[2] ?? join(here, "..", "..", "nasset_sdk", "web_viewer"));
mkdirSync(out, { recursive: true });

function copyAtomic(src, dst) {
  const tmp = `${dst}.tmp-${process.pid}`;
  copyFileSync(src, tmp);
  renameSync(tmp, dst);
}

const tmpJs = join(out, `viewer.js.tmp-${process.pid}`);
await build({
  entryPoints: [join(here, "src", "main.js")],
  bundle: true, format: "esm", minify: true, target: "es2022", legalComments: "none",
  outfile: tmpJs, logLevel: "warning",
  // onnxruntime-web's bundle names its Node.js-only modules; a browser never loads them
  external: ["node:*"],
});
renameSync(tmpJs, join(out, "viewer.js"));
copyAtomic(join(here, "src", "index.html"), join(out, "index.html"));
copyAtomic(join(here, "node_modules", "onnxruntime-web", "dist", "ort-wasm-simd-threaded.wasm"), join(out, "ort-wasm-simd-threaded.wasm"));
