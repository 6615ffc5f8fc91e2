// Minimal non-Python host: runs one ONNX model with onnxruntime-web's WASM backend (the runtime a
// browser viewer uses) on float32 inputs read from raw little-endian files, and writes the outputs.
//
//   node host.mjs JOB.json
//
// JOB.json: {"model": "graph.onnx", "inputs": {"x": {"file": "x.bin", "shape": [N, 3]}, ...},
//            "outputDir": "out"}  (paths relative to JOB.json's folder)
// Writes outputDir/<output name>.bin (float32 little-endian) and outputDir/outputs.json
// ({"<name>": [N, w], ...}). Exits non-zero on any failure.
import { readFileSync, writeFileSync, mkdirSync, renameSync } from "node:fs";
import { dirname, resolve, join } from "node:path";
import * as ort from "onnxruntime-web";

const jobPath = resolve(process.argv[2] ?? "");
const base = dirname(jobPath);
const job = JSON.parse(readFileSync(jobPath, "utf8"));
ort.env.wasm.numThreads = 1; // no worker threads: deterministic, and nothing to spawn in a test

function readF32(path, shape) {
  const buf = readFileSync(resolve(base, path));
  const n = shape.reduce((a, b) => a * b, 1);
  if (buf.byteLength !== 4 * n) throw new Error(`${path}: ${buf.byteLength} bytes, expected ${4 * n} for ${shape}`);
  return new Float32Array(buf.buffer.slice(buf.byteOffset, buf.byteOffset + buf.byteLength));
}

function writeAtomic(path, data) {
  const tmp = `${path}.tmp-${process.pid}`;
  writeFileSync(tmp, data);
  renameSync(tmp, path);
}

const session = await ort.InferenceSession.create(readFileSync(resolve(base, job.model)), { executionProviders: ["wasm"] });
const feeds = {};
for (const [name, spec] of Object.entries(job.inputs)) {
  feeds[name] = new ort.Tensor("float32", readF32(spec.file, spec.shape), spec.shape);
}
const results = await session.run(feeds);
const outDir = resolve(base, job.outputDir);
mkdirSync(outDir, { recursive: true });
const shapes = {};
for (const name of session.outputNames) {
  const t = results[name];
  writeAtomic(join(outDir, `${name}.bin`), Buffer.from(t.data.buffer, t.data.byteOffset, t.data.byteLength));
  shapes[name] = t.dims;
}
writeAtomic(join(outDir, "outputs.json"), JSON.stringify(shapes));
