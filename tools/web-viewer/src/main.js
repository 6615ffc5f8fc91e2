// nasset web viewer: three.js rasterises the fallback mesh into a G-buffer (object-space position, shading
// frame, light visibility from a shadow map per pixel), onnxruntime-web (WASM) runs the asset's portable graph on the
// covered pixels, and the linear radiance is shown with exposure and the reference renderer's tone curve.
// Nothing of the kind's encodings (triplanes, Fourier features, MLPs) is written here: the graph holds them.
// docs/web-viewer.md describes the shading per kind and the test hooks (window.nassetViewer).
import * as THREE from "three";
import { OrbitControls } from "three/addons/controls/OrbitControls.js";
import * as ort from "onnxruntime-web/wasm";

const ROWS_PER_RUN = 8192; // rows per session.run: bounded memory, and the page stays responsive between runs
const LEVELS = [4, 2, 1]; // progressive refinement: image size divisors, coarse first

const $ = (id) => document.getElementById(id);
// the portable graph's outputs the shading reads, per kind (spec/format.md#portable-evaluation-graphs)
const OUTPUTS = { rna: ["unshadowed", "shadowed"], neupress: ["transport"], "8dna": ["albedo"] };

function fail(text) {
  $("message").textContent = text;
  $("message").style.display = "block";
  $("canvas").style.display = "none";
  $("status").textContent = "";
  if (window.nassetViewer) window.nassetViewer.error = text;
  throw new Error(text);
}

// wasm-feature-detect's SIMD probe module (i8x16.splat + popcnt)
const SIMD_PROBE = new Uint8Array([0, 97, 115, 109, 1, 0, 0, 0, 1, 5, 1, 96, 0, 1, 123, 3, 2, 1, 0, 10, 10, 1, 8, 0, 65, 0, 253, 15, 253, 98, 11]);

function checkBrowser() {
  if (typeof WebAssembly !== "object" || !WebAssembly.validate(SIMD_PROBE)) {
    fail("This browser lacks WebAssembly SIMD, which onnxruntime-web needs to evaluate the asset's networks. " +
         "Use a current Chrome, Edge, Firefox or Safari.");
  }
  const gl = document.createElement("canvas").getContext("webgl2");
  if (!gl) fail("This browser has no WebGL 2 (disabled, or no GPU driver): the viewer cannot rasterise the asset.");
  if (!gl.getExtension("EXT_color_buffer_float")) fail("WebGL 2 without EXT_color_buffer_float: the viewer needs float render targets.");
}

async function fetchOk(url, what) {
  let r;
  try {
    r = await fetch(url);
  } catch (e) {
    fail(`Cannot load ${what} (${url}): ${e.message}`);
  }
  if (!r.ok) fail(`Cannot load ${what} (${url}): HTTP ${r.status}. Export an asset with: nasset web A.usdc -o DIR --serve`);
  return r;
}

async function loadAsset(base) {
  const r = await fetchOk(new URL("asset.json", base), "the asset description asset.json");
  let doc;
  try {
    doc = await r.json();
  } catch (e) {
    fail(`asset.json is not JSON (${e.message}): this folder was not written by nasset web.`);
  }
  if (doc.format !== "nasset-web/1" || !doc.kind || !doc.mesh) fail("asset.json is not a nasset web export (format nasset-web/1).");
  if (!Object.hasOwn(OUTPUTS, doc.kind)) fail(`This viewer does not know the asset kind ${JSON.stringify(doc.kind)} (it shows ${Object.keys(OUTPUTS).join(", ")}).`);
  if (!doc.graphs || Object.keys(doc.graphs).length === 0) {
    fail(`The asset ${doc.metadata?.file ?? ""} has no portable evaluation graph. Add it with:\n` +
         "  nasset optimize A.usdc -o A_portable.usdc --portable\nthen export again with nasset web.");
  }
  const mesh = await (await fetchOk(new URL(doc.mesh.file, base), "the mesh")).arrayBuffer();
  const v = doc.mesh.vertices, f = doc.mesh.triangles;
  if (mesh.byteLength !== 24 * v + 12 * f) fail(`mesh.bin has ${mesh.byteLength} bytes, expected ${24 * v + 12 * f}.`);
  const pos = new Float32Array(mesh, 0, 3 * v), frame = new Float32Array(mesh, 12 * v, 3 * v);
  const idx = new Uint32Array(mesh, 24 * v, 3 * f);
  const [name, graph] = Object.entries(doc.graphs)[0];
  const missing = OUTPUTS[doc.kind].filter((o) => !Object.hasOwn(graph.outputs ?? {}, o));
  if (missing.length) fail(`The portable graph ${name} lacks the output(s) ${missing.join(", ")} a ${doc.kind} asset's graph has.`);
  const model = await (await fetchOk(new URL(graph.file, base), `the portable graph ${name}`)).arrayBuffer();
  return { doc, pos, frame, idx, graph, model };
}

function buildGeometry(pos, frame, idx) {
  // non-indexed, so each corner also carries its triangle's geometric normal (the self-shadow test)
  const n = idx.length;
  const p = new Float32Array(3 * n), fr = new Float32Array(3 * n), ng = new Float32Array(3 * n);
  for (let t = 0; t < n; t += 3) {
    const a = 3 * idx[t], b = 3 * idx[t + 1], c = 3 * idx[t + 2];
    const e1 = [pos[b] - pos[a], pos[b + 1] - pos[a + 1], pos[b + 2] - pos[a + 2]];
    const e2 = [pos[c] - pos[a], pos[c + 1] - pos[a + 1], pos[c + 2] - pos[a + 2]];
    const g = [e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]];
    for (let k = 0; k < 3; k++) {
      const s = 3 * idx[t + k], d = 3 * (t + k);
      for (let j = 0; j < 3; j++) {
        p[d + j] = pos[s + j];
        fr[d + j] = frame[s + j];
        ng[d + j] = g[j];
      }
    }
  }
  const geo = new THREE.BufferGeometry();
  geo.setAttribute("position", new THREE.BufferAttribute(p, 3));
  geo.setAttribute("frame", new THREE.BufferAttribute(fr, 3));
  geo.setAttribute("ng", new THREE.BufferAttribute(ng, 3));
  geo.computeBoundingSphere();
  return geo;
}

const GBUFFER_VS = `precision highp float;
in vec3 position; in vec3 frame; in vec3 ng;
uniform mat4 modelViewMatrix; uniform mat4 projectionMatrix;
out vec3 vPos; out vec3 vFrame; out vec3 vNg;
void main() { vPos = position; vFrame = frame; vNg = ng; gl_Position = projectionMatrix * modelViewMatrix * vec4(position, 1.0); }`;
// pass 0: position, alpha 1 = covered; pass 1: frame, alpha 2 where the light reaches the point (the face looks
// towards it and the shadow map holds nothing nearer the light), else 1
const GBUFFER_FS = `precision highp float;
in vec3 vPos; in vec3 vFrame; in vec3 vNg;
uniform int pass; uniform vec3 lightDir; uniform sampler2D shadowMap; uniform mat4 lightViewProj; uniform float texelDepth;
out vec4 color;
void main() {
  if (pass == 0) { color = vec4(vPos, 1.0); return; }
  float l = length(vFrame), g = length(vNg);
  float c = g > 0.0 ? dot(vNg, lightDir) / g : 0.0;
  vec4 lp = lightViewProj * vec4(vPos, 1.0);
  vec3 s = lp.xyz / lp.w * 0.5 + 0.5;
  float slope = sqrt(max(1.0 - c * c, 0.0)) / max(c, 0.1); // tan of the angle to the light, capped
  bool blocked = s.z - texelDepth * (2.0 + 2.0 * slope) > texture(shadowMap, s.xy).r;
  color = vec4(l > 1e-20 ? vFrame / l : vec3(0.0, 0.0, 1.0), (c > 0.0 && !blocked) ? 2.0 : 1.0);
}`;
// depth of the nearest surface seen from the light (orthographic, along -lightDir)
const SHADOW_FS = `precision highp float;
out vec4 color;
void main() { color = vec4(gl_FragCoord.z, 0.0, 0.0, 1.0); }`;
const SHADOW_MAP_SIZE = 1024;
// the reference renderer's PNG curve (nasset_sdk.images.tonemap): ACES fit of 0.6 x, then sRGB
const DISPLAY_FS = `precision highp float;
in vec2 uv; uniform sampler2D radiance; uniform float exposure; uniform vec3 background;
out vec4 color;
vec3 srgb(vec3 y) { return mix(12.92 * y, 1.055 * pow(y, vec3(1.0 / 2.4)) - 0.055, step(vec3(0.0031308), y)); }
void main() {
  vec4 r = texture(radiance, uv);
  if (r.a <= 0.0) { color = vec4(background, 1.0); return; }
  vec3 x = max(r.rgb, 0.0) * exp2(exposure) * 0.6;
  vec3 y = clamp((x * (2.51 * x + 0.03)) / (x * (2.43 * x + 0.59) + 0.14), 0.0, 1.0);
  color = vec4(srgb(y), 1.0);
}`;
const DISPLAY_VS = `precision highp float;
in vec3 position; out vec2 uv;
void main() { uv = position.xy * 0.5 + 0.5; gl_Position = vec4(position.xy, 0.0, 1.0); }`;

function hexColor(hex) {
  const v = parseInt(hex.slice(1), 16);
  return [(v >> 16 & 255) / 255, (v >> 8 & 255) / 255, (v & 255) / 255].map((c) => (c <= 0.04045 ? c / 12.92 : ((c + 0.055) / 1.055) ** 2.4));
}

function lightFromAngles(azDeg, elDeg) {
  const az = azDeg * Math.PI / 180, el = elDeg * Math.PI / 180;
  return [Math.cos(el) * Math.sin(az), Math.sin(el), Math.cos(el) * Math.cos(az)];
}

class Viewer {
  constructor(asset, session) {
    this.asset = asset;
    this.session = session;
    this.kind = asset.doc.kind;
    this.canvas = $("canvas");
    this.width = this.canvas.width;
    this.height = this.canvas.height;
    this.renderer = new THREE.WebGLRenderer({ canvas: this.canvas, antialias: false, preserveDrawingBuffer: true });
    this.renderer.outputColorSpace = THREE.LinearSRGBColorSpace;
    this.renderer.setPixelRatio(1);
    this.renderer.setSize(this.width, this.height, false);
    this.scene = new THREE.Scene();
    this.gmat = new THREE.RawShaderMaterial({
      vertexShader: GBUFFER_VS, fragmentShader: GBUFFER_FS, glslVersion: THREE.GLSL3, side: THREE.DoubleSide,
      uniforms: { pass: { value: 0 }, lightDir: { value: new THREE.Vector3(0, 1, 0) }, shadowMap: { value: null },
                  lightViewProj: { value: new THREE.Matrix4() }, texelDepth: { value: 0 } },
    });
    this.shadowMat = new THREE.RawShaderMaterial({ vertexShader: GBUFFER_VS, fragmentShader: SHADOW_FS, glslVersion: THREE.GLSL3,
                                                   side: THREE.DoubleSide });
    this.shadowRT = new THREE.WebGLRenderTarget(SHADOW_MAP_SIZE, SHADOW_MAP_SIZE, {
      type: THREE.FloatType, format: THREE.RGBAFormat, minFilter: THREE.NearestFilter, magFilter: THREE.NearestFilter, depthBuffer: true });
    this.scene.add(new THREE.Mesh(buildGeometry(asset.pos, asset.frame, asset.idx), this.gmat));
    const b = asset.doc.mesh.bounds;
    this.center = new THREE.Vector3(...b.min).add(new THREE.Vector3(...b.max)).multiplyScalar(0.5);
    this.radius = Math.max(1e-6, 0.5 * new THREE.Vector3(...b.max).sub(new THREE.Vector3(...b.min)).length());
    this.camera = new THREE.PerspectiveCamera(30, this.width / this.height, this.radius * 0.01, this.radius * 100);
    const dist = this.radius / Math.sin(15 * Math.PI / 180) * 1.1;
    this.camera.position.copy(this.center).add(new THREE.Vector3(0, 0.35, 1).normalize().multiplyScalar(dist));
    this.camera.lookAt(this.center);
    this.controls = new OrbitControls(this.camera, this.canvas);
    this.controls.target.copy(this.center);
    this.controls.update();
    this.controls.addEventListener("change", () => this.restart());
    this.dispScene = new THREE.Scene();
    this.dispMat = new THREE.RawShaderMaterial({
      vertexShader: DISPLAY_VS, fragmentShader: DISPLAY_FS, glslVersion: THREE.GLSL3, depthTest: false,
      uniforms: { radiance: { value: null }, exposure: { value: 0 }, background: { value: new THREE.Vector3(0.12, 0.12, 0.12) } },
    });
    const tri = new THREE.BufferGeometry();
    tri.setAttribute("position", new THREE.BufferAttribute(new Float32Array([-1, -1, 0, 3, -1, 0, -1, 3, 0]), 3));
    const quad = new THREE.Mesh(tri, this.dispMat);
    quad.frustumCulled = false;
    this.dispScene.add(quad);
    this.dispCam = new THREE.OrthographicCamera(-1, 1, 1, -1, 0, 1);
    this.settings = { light: lightFromAngles(30, 40), irradiance: Math.PI, color: [1, 1, 1], ambient: 0.05, exposure: 0,
                      fallback: false, samples: 8 }; // samples: jittered full-resolution passes averaged while idle
    this.generation = 0;
    this.stats = {};
    this.targets = new Map();
  }

  setCamera({ eye, target, fovDeg }) {
    if (fovDeg) this.camera.fov = fovDeg;
    this.camera.position.set(...eye);
    this.controls.target.set(...target);
    this.camera.lookAt(this.controls.target);
    this.camera.updateProjectionMatrix();
    this.controls.update();
    this.restart();
  }

  set(changes) {
    if (changes.light) {
      const l = Math.hypot(...changes.light);
      if (!(l > 0) || !Number.isFinite(l)) throw new Error(`light direction ${changes.light} must be finite and nonzero`);
      changes = { ...changes, light: changes.light.map((c) => c / l) };
    }
    Object.assign(this.settings, changes);
    if ("exposure" in changes && Object.keys(changes).length === 1) this.display(); // tone mapping only: no re-evaluation
    else this.restart();
  }

  restart() {
    this.generation++;
    if (!this.loop) {
      this.loop = this.refine()
        .catch((e) => { try { fail(`Shading stopped: ${e.message}`); } catch { /* shown on the page */ } })
        .finally(() => { this.loop = null; });
    }
  }

  // G-buffer at w x h with a sub-pixel jitter (in pixels); returns [position, frame] as Float32Array RGBA rows, bottom-up
  gbuffer(w, h, jx, jy) {
    const key = `${w}x${h}`; // one float target per refinement level, kept across frames
    if (!this.targets.has(key)) {
      this.targets.set(key, new THREE.WebGLRenderTarget(w, h, { type: THREE.FloatType, format: THREE.RGBAFormat,
                                                                minFilter: THREE.NearestFilter, magFilter: THREE.NearestFilter, depthBuffer: true }));
    }
    const rt = this.targets.get(key);
    this.camera.setViewOffset(w, h, jx, jy, w, h);
    this.camera.updateProjectionMatrix();
    this.gmat.uniforms.lightDir.value.set(...this.settings.light);
    this.shadowPass();
    const out = [];
    this.renderer.setRenderTarget(rt);
    this.renderer.setClearColor(0x000000, 0);
    for (const pass of [0, 1]) {
      this.gmat.uniforms.pass.value = pass;
      this.renderer.clear();
      this.renderer.render(this.scene, this.camera);
      const buf = new Float32Array(4 * w * h);
      this.renderer.readRenderTargetPixels(rt, 0, 0, w, h, buf);
      out.push(buf);
    }
    this.renderer.setRenderTarget(null);
    this.camera.clearViewOffset();
    this.camera.updateProjectionMatrix();
    return out;
  }

  // shadow map of the current light: an orthographic view along -lightDir framing the bounding sphere
  shadowPass() {
    const key = this.settings.light.join(","); // the map depends on the light direction only
    if (key === this.shadowKey) return;
    this.shadowKey = key;
    const r = this.radius, L = new THREE.Vector3(...this.settings.light);
    const cam = new THREE.OrthographicCamera(-r, r, r, -r, 0.5 * r, 3.5 * r);
    cam.position.copy(this.center).addScaledVector(L, 2 * r);
    cam.up.set(Math.abs(L.y) < 0.9 ? 0 : 1, Math.abs(L.y) < 0.9 ? 1 : 0, 0);
    cam.lookAt(this.center);
    cam.updateMatrixWorld();
    this.renderer.setRenderTarget(this.shadowRT);
    this.renderer.setClearColor(0xffffff, 1);
    this.renderer.clear();
    this.scene.overrideMaterial = this.shadowMat;
    this.renderer.render(this.scene, cam);
    this.scene.overrideMaterial = null;
    const u = this.gmat.uniforms;
    u.shadowMap.value = this.shadowRT.texture;
    u.lightViewProj.value.multiplyMatrices(cam.projectionMatrix, cam.matrixWorldInverse);
    u.texelDepth.value = (2 * r / SHADOW_MAP_SIZE) / (3 * r); // one texel's width in depth units at slope 1
  }

  // linear radiance RGBA [h w 4] (alpha = coverage) of one pass; null when a newer view superseded it
  async shade(w, h, jx, jy, gen) {
    const t0 = performance.now();
    const [gpos, gframe] = this.gbuffer(w, h, jx, jy);
    const pass = { width: w, height: h, gbufferMs: performance.now() - t0, graphMs: 0 };
    const pix = [];
    for (let i = 0; i < w * h; i++) if (gpos[4 * i + 3] > 0) pix.push(i);
    const s = this.settings, eye = this.camera.position, fb = this.asset.doc.fallbackColor;
    const L = s.light, E = s.color.map((c) => c * s.irradiance);
    const amb = fb.map((c) => c * s.ambient);
    const img = new Float32Array(4 * w * h);
    const inputs = this.asset.graph.inputs;
    if (jx === 0 && jy === 0) this.lastGbuffer = { w, h, pix, gpos, gframe, eye: [eye.x, eye.y, eye.z], light: L };
    for (let start = 0; start < pix.length; start += ROWS_PER_RUN) {
      const rows = pix.slice(start, start + ROWS_PER_RUN), n = rows.length;
      const q = { x: new Float32Array(3 * n), frame: new Float32Array(3 * n), wo: new Float32Array(3 * n),
                  wi: new Float32Array(3 * n), h: new Float32Array(n) };
      for (let r = 0; r < n; r++) {
        const i = 4 * rows[r];
        const x = [gpos[i], gpos[i + 1], gpos[i + 2]];
        const d = [eye.x - x[0], eye.y - x[1], eye.z - x[2]], l = Math.hypot(...d) || 1;
        for (let k = 0; k < 3; k++) {
          q.x[3 * r + k] = x[k];
          q.frame[3 * r + k] = gframe[i + k];
          q.wo[3 * r + k] = d[k] / l;
          q.wi[3 * r + k] = L[k];
        }
      }
      let y = null;
      if (!s.fallback) {
        const feeds = {};
        for (const [name, width] of Object.entries(inputs)) feeds[name] = new ort.Tensor("float32", q[name], [n, width]);
        const tg = performance.now();
        y = await this.session.run(feeds);
        pass.graphMs += performance.now() - tg;
        if (gen !== this.generation) return null;
      }
      for (let r = 0; r < n; r++) {
        const i = 4 * rows[r], lit = gframe[i + 3] > 1.5;
        const fr = [gframe[i], gframe[i + 1], gframe[i + 2]];
        let rgb;
        if (s.fallback) { // Lambertian fallback material: rho / pi E max(n.wi, 0), zero where the face looks away
          const c = lit ? Math.max(0, fr[0] * L[0] + fr[1] * L[1] + fr[2] * L[2]) / Math.PI : 0;
          rgb = [0, 1, 2].map((k) => fb[k] * E[k] * c);
        } else if (this.kind === "rna") {
          const t = lit ? y.unshadowed.data : y.shadowed.data;
          rgb = [0, 1, 2].map((k) => t[3 * r + k] * E[k]);
        } else if (this.kind === "neupress") {
          rgb = [0, 1, 2].map((k) => y.transport.data[3 * r + k] * E[k]);
        } else { // 8dna: far-field albedo only (unitless colour)
          rgb = [0, 1, 2].map((k) => y.albedo.data[3 * r + k]);
        }
        for (let k = 0; k < 3; k++) img[i + k] = (Number.isFinite(rgb[k]) ? rgb[k] : 0) + amb[k];
        img[i + 3] = 1;
      }
      await new Promise((res) => setTimeout(res, 0));
      if (gen !== this.generation) return null;
    }
    this.stats.lastPass = { ...pass, pixels: pix.length, totalMs: performance.now() - t0 };
    return img;
  }

  async refine() {
    while (true) {
      const gen = this.generation, t0 = performance.now();
      let done = true;
      for (const f of LEVELS) {
        const w = Math.max(1, Math.round(this.width / f)), h = Math.max(1, Math.round(this.height / f));
        const ts = performance.now();
        const img = await this.shade(w, h, 0, 0, gen);
        if (!img) { done = false; break; }
        this.stats[`level${f}Ms`] = performance.now() - ts;
        this.show(img, w, h);
        this.accum = f === 1 ? img.slice() : null;
        this.samples = f === 1 ? 1 : 0;
      }
      if (done) {
        this.stats.fullFrameMs = performance.now() - t0;
        for (let k = 1; k < this.settings.samples; k++) {
          const jx = ((k * 0.618034) % 1) - 0.5, jy = ((k * 0.754878) % 1) - 0.5; // R2 sequence offsets
          const img = await this.shade(this.width, this.height, jx, jy, gen);
          if (!img) { done = false; break; }
          for (let i = 0; i < img.length; i++) this.accum[i] += img[i];
          this.samples++;
          const avg = this.accum.map((v) => v / this.samples);
          this.show(avg, this.width, this.height);
        }
      }
      if (done && gen === this.generation) {
        $("status").textContent = `${this.width}x${this.height}, ${this.samples} sample(s) per pixel; first full frame ` +
                                  `${this.stats.fullFrameMs.toFixed(0)} ms`;
        return;
      }
    }
  }

  show(img, w, h) {
    if (this.tex) this.tex.dispose();
    this.tex = new THREE.DataTexture(img, w, h, THREE.RGBAFormat, THREE.FloatType);
    this.tex.minFilter = this.tex.magFilter = THREE.NearestFilter;
    this.tex.needsUpdate = true;
    this.current = { img, w, h };
    this.display();
  }

  display() {
    if (!this.tex) return;
    this.dispMat.uniforms.radiance.value = this.tex;
    this.dispMat.uniforms.exposure.value = this.settings.exposure;
    this.renderer.setRenderTarget(null);
    this.renderer.render(this.dispScene, this.dispCam);
  }

  // the G-buffer of the latest unjittered pass, per covered pixel (index into linear()'s rows, top-down):
  // {pixel: [n], x, frame: [n 3], lit: [n] 0/1, eye: [3], wi: [3]}; w_o is normalize(eye - x)
  queries() {
    const { w, h, pix, gpos, gframe, eye, light } = this.lastGbuffer;
    const out = { pixel: [], x: [], frame: [], lit: [], eye, wi: light };
    for (const i of pix) {
      out.pixel.push((h - 1 - Math.floor(i / w)) * w + (i % w));
      out.x.push([gpos[4 * i], gpos[4 * i + 1], gpos[4 * i + 2]]);
      out.frame.push([gframe[4 * i], gframe[4 * i + 1], gframe[4 * i + 2]]);
      out.lit.push(gframe[4 * i + 3] > 1.5 ? 1 : 0);
    }
    return out;
  }

  // linear radiance of the latest image, rows top-down: {width, height, rgb: [h w 3] array, mask: [h w] 0/1}
  linear() {
    const { img, w, h } = this.current;
    const rgb = new Array(3 * w * h), mask = new Array(w * h);
    for (let y = 0; y < h; y++) {
      for (let x = 0; x < w; x++) {
        const src = 4 * ((h - 1 - y) * w + x), dst = y * w + x;
        for (let k = 0; k < 3; k++) rgb[3 * dst + k] = img[src + k];
        mask[dst] = img[src + 3] > 0 ? 1 : 0;
      }
    }
    return { width: w, height: h, rgb, mask };
  }
}

function accuracyLines(prov) {
  // figures a bake records (spec/bake.md#psnr, spec/accuracy.md): held-out PSNR, its noise ceiling, energy ratio
  const acc = prov?.validation?.accuracy;
  if (!acc) return ["accuracy: none recorded (not a bake, or an older one)"];
  const f = (v, d = 2) => (typeof v === "number" ? v.toFixed(d) : "?");
  const lines = [`held-out PSNR: ${f(acc.psnr_db)} dB (noise-corrected ${f(acc.psnr_corrected_db)} dB; reference ceiling ${f(acc.ceiling_db)} dB)`];
  if (acc.energy_ratio) lines.push(`energy ratio (RGB): ${acc.energy_ratio.map((v) => f(v, 3)).join(", ")}`);
  if (acc.claimed_psnr) lines.push(`claimed: ${acc.claimed_psnr}`);
  return lines;
}

function showMetadata(doc) {
  const m = doc.metadata ?? {};
  const lines = [`kind: ${doc.kind} (${doc.variant})`, `file: ${m.file ?? "?"} (${((m.fileBytes ?? 0) / 1024).toFixed(0)} KiB)`,
                 `spec: ${m.specVersion ?? "?"}`, `mesh: ${doc.mesh.vertices} vertices, ${doc.mesh.triangles} triangles`];
  if (m.totals) lines.push(`tensors ${(m.totals.tensorBytes / 1024).toFixed(0)} KiB, networks ${(m.totals.networkBytes / 1024).toFixed(0)} KiB, ` +
                           `${m.totals.parameters} parameters`);
  lines.push(`components: ${Object.keys(m.components ?? {}).join(", ")}`);
  const prov = m.provenance ?? {};
  lines.push(`made by: ${prov.generator ?? "?"}${prov.source?.scene ? ` from ${prov.source.scene.split("/").pop()}` : ""}`, "");
  lines.push(...accuracyLines(prov));
  if (doc.kind === "8dna") lines.push("", "8dna: the viewer shows the far-field albedo only (the spline flow is not in the portable graph).");
  if (doc.kind === "neupress") lines.push("", "neupress: subsurface transport only (the analytic boundary reflection is not in the portable graph).");
  if (doc.variant === "fiber") lines.push("", "fibres: tubes around the curves, h = 0 (the fibre centre) at every pixel.");
  $("meta").textContent = lines.join("\n");
  const details = document.createElement("details"), summary = document.createElement("summary"), pre = document.createElement("pre");
  summary.textContent = "provenance (all recorded fields)";
  pre.textContent = JSON.stringify(prov, null, 1);
  details.append(summary, pre);
  $("meta").append(details);
}

function bindControls(v, doc) {
  const light = () => v.set({ light: lightFromAngles(+$("lightAz").value, +$("lightEl").value) });
  $("lightAz").oninput = light;
  $("lightEl").oninput = light;
  $("lightE").oninput = () => v.set({ irradiance: +$("lightE").value });
  $("lightColor").oninput = () => v.set({ color: hexColor($("lightColor").value) });
  $("ambient").oninput = () => v.set({ ambient: +$("ambient").value });
  $("exposure").oninput = () => v.set({ exposure: +$("exposure").value });
  $("fallback").onchange = () => v.set({ fallback: $("fallback").checked });
  const channels = doc.channels ?? [];
  $("channel").max = Math.max(0, channels.length - 1);
  const channel = () => {
    const on = $("channelOn").checked && channels.length > 0;
    $("channelImg").style.display = on ? "block" : "none";
    if (on) $("channelImg").src = channels[Math.min(channels.length - 1, Math.max(0, +$("channel").value))];
  };
  $("channelOn").disabled = channels.length === 0;
  $("channelOn").onchange = channel;
  $("channel").oninput = channel;
  let drag = null; // Shift + drag: the light follows the pointer
  v.canvas.addEventListener("pointerdown", (e) => {
    if (!e.shiftKey) return;
    drag = { x: e.clientX, y: e.clientY, az: +$("lightAz").value, el: +$("lightEl").value };
    v.controls.enabled = false;
  });
  window.addEventListener("pointermove", (e) => {
    if (!drag) return;
    $("lightAz").value = String(((drag.az + (e.clientX - drag.x) * 0.5 + 540) % 360) - 180);
    $("lightEl").value = String(Math.max(-90, Math.min(90, drag.el - (e.clientY - drag.y) * 0.5)));
    light();
  });
  window.addEventListener("pointerup", () => { drag = null; v.controls.enabled = true; });
}

async function main() {
  window.nassetViewer = { error: null };
  let resolveReady;
  window.nassetViewer.ready = new Promise((res) => { resolveReady = res; });
  checkBrowser();
  const params = new URLSearchParams(location.search);
  const size = parseInt(params.get("size") ?? "", 10); // ?size=N: an N x N image (tests; default 512)
  if (size > 0 && size <= 4096) $("canvas").width = $("canvas").height = size;
  const base = new URL(params.get("asset") ?? "./", location.href);
  const asset = await loadAsset(base.href.endsWith("/") ? base : new URL(base.href + "/"));
  // one thread: onnxruntime-web's worker threads would need a cross-origin isolated page and a worker script
  // apart from the page bundle; plain static hosting works as is
  ort.env.wasm.numThreads = 1;
  ort.env.wasm.wasmPaths = { wasm: new URL("ort-wasm-simd-threaded.wasm", document.baseURI).href };
  let session;
  try {
    session = await ort.InferenceSession.create(asset.model, { executionProviders: ["wasm"] });
  } catch (e) {
    fail(`onnxruntime-web could not load the portable graph: ${e.message}`);
  }
  showMetadata(asset.doc);
  const v = new Viewer(asset, session);
  bindControls(v, asset.doc);
  Object.assign(window.nassetViewer, {
    viewer: v,
    setCamera: (c) => v.setCamera(c),
    set: (s) => v.set(s),
    // wait until refinement has finished (all levels and jittered passes of the current view)
    idle: async () => { while (v.loop) await v.loop; return v.stats; },
    linear: () => v.linear(),
    queries: () => v.queries(),
  });
  v.restart();
  resolveReady(true);
}

main().catch((e) => {
  if (!$("message").textContent) {
    try { fail(`The viewer stopped: ${e.message}`); } catch { /* shown */ }
  }
});
