// stylize view: the page. Talks to the server in crates/stylize-cli/src/view/server.rs (all URLs
// are relative to /TOKEN/). Two scenes (before = the run's rest mesh, after = the saved deformation
// re-applied at the slider's λ) share one camera, so orbiting one orbits both.
//
// URL parameters: ?item=ID (which item first), ?lambda=L (after loading, set λ to L through the
// slider's own input handler — the browser test uses it). <html data-state> is "loading" while a
// request is pending and "ready" when the shown shape matches the slider; data-lambda is the λ shown.
import * as THREE from 'three';
import { OrbitControls } from './vendor/three/OrbitControls.js';

const $ = (id) => document.getElementById(id);
const params = new URLSearchParams(location.search);
const ui = {
  item: $('item'), status: $('status'), lambda: $('lambda'), lambdaValue: $('lambda-value'),
  reset: $('reset-lambda'), flat: $('flat'), wire: $('wire'), layout: $('layout'), toggle: $('toggle'),
  dlObj: $('dl-obj'), dlPly: $('dl-ply'), dlGlb: $('dl-glb'), images: $('images'),
  metrics: $('metrics'), warnings: $('warnings'), left: $('label-left'), right: $('label-right'),
  canvas: $('canvas'), viewport: $('viewport'),
};

function setState(s) { document.documentElement.dataset.state = s; }

// ---------- server ----------
async function check(r, what) {
  if (!r.ok) throw new Error(`${what}: ${r.status} ${await r.text()}`);
  return r;
}

// Framed response: u32 LE header length, JSON header, zero padding to 4 bytes, payload.
async function fetchFramed(url) {
  const r = await check(await fetch(url), url);
  const buf = await r.arrayBuffer();
  const len = new DataView(buf).getUint32(0, true);
  const head = JSON.parse(new TextDecoder().decode(new Uint8Array(buf, 4, len)));
  return { head, buf, offset: 4 + Math.ceil(len / 4) * 4 };
}

// ---------- scene ----------
const renderer = new THREE.WebGLRenderer({ canvas: ui.canvas, antialias: true, preserveDrawingBuffer: true });
renderer.setPixelRatio(window.devicePixelRatio);
renderer.setClearColor(0xf4f5f7);
const camera = new THREE.PerspectiveCamera(35, 1, 0.01, 100);
const controls = new OrbitControls(camera, ui.canvas);
controls.enableDamping = false;

function makeScene() {
  const scene = new THREE.Scene();
  scene.add(new THREE.HemisphereLight(0xffffff, 0x667080, 1.4));
  const head = new THREE.DirectionalLight(0xffffff, 1.6);
  scene.add(head);
  return { scene, head };
}
const before = makeScene();
const after = makeScene();

const solid = new THREE.MeshStandardMaterial({
  color: 0x8fa9c8, roughness: 0.65, metalness: 0.0, flatShading: false,
  polygonOffset: true, polygonOffsetFactor: 1, polygonOffsetUnits: 1,
});
const solidBefore = solid.clone();
solidBefore.color.set(0xb9b3a8);
const wireMaterial = new THREE.MeshBasicMaterial({ color: 0x202020, wireframe: true, transparent: true, opacity: 0.35 });

function attach(target, geometry, material) {
  for (const c of [...target.scene.children]) if (c.isMesh) target.scene.remove(c);
  const mesh = new THREE.Mesh(geometry, material);
  const wire = new THREE.Mesh(geometry, wireMaterial);
  wire.visible = ui.wire.checked;
  target.scene.add(mesh, wire);
  target.mesh = mesh;
  target.wire = wire;
}

let layout = 'side';
let showing = 'after';

function render() {
  const w = ui.viewport.clientWidth, h = ui.viewport.clientHeight;
  if (ui.canvas.width !== Math.floor(w * renderer.getPixelRatio()) || ui.canvas.height !== Math.floor(h * renderer.getPixelRatio())) {
    renderer.setSize(w, h, false);
  }
  renderer.setScissorTest(true);
  const views = layout === 'side'
    ? [[before, 0, w / 2], [after, w / 2, w / 2]]
    : [[showing === 'before' ? before : after, 0, w]];
  for (const [target, x, vw] of views) {
    camera.aspect = vw / h;
    camera.updateProjectionMatrix();
    target.head.position.copy(camera.position);
    renderer.setViewport(x, 0, vw, h);
    renderer.setScissor(x, 0, vw, h);
    renderer.render(target.scene, camera);
  }
  renderer.setScissorTest(false);
}
controls.addEventListener('change', render);
new ResizeObserver(render).observe(ui.viewport);

function frame(geometry) {
  geometry.computeBoundingSphere();
  const r = geometry.boundingSphere.radius || 1;
  const c = geometry.boundingSphere.center;
  const fov = THREE.MathUtils.degToRad(camera.fov);
  // Fit the sphere in the narrower direction of a half-width view (side by side).
  const aspect = Math.min(1, (ui.viewport.clientWidth / 2) / Math.max(1, ui.viewport.clientHeight));
  const dist = r / Math.sin(Math.atan(Math.tan(fov / 2) * aspect)) * 1.05;
  const dir = new THREE.Vector3(0.55, 0.35, 1).normalize();
  camera.position.copy(c).addScaledVector(dir, dist);
  camera.near = dist / 100;
  camera.far = dist * 10;
  controls.target.copy(c);
  controls.update();
}

// ---------- state ----------
let items = [];
let current = null;   // ItemInfo
let sourceGeometry = null;
let resultGeometry = null;
let shownLambda = null;

function updateLayoutUi() {
  const run = current && current.has_deformation;
  ui.toggle.hidden = layout !== 'toggle' || !run;
  ui.toggle.textContent = showing === 'after' ? 'show before' : 'show after';
  ui.left.hidden = !run;
  ui.right.hidden = layout !== 'side' || !run;
  if (layout === 'toggle') {
    ui.left.textContent = showing;
  } else {
    ui.left.textContent = 'before';
  }
  if (!run) { layout = 'toggle'; showing = 'before'; }
}

function setDownloads(lambda) {
  for (const [a, fmt] of [[ui.dlObj, 'obj'], [ui.dlPly, 'ply'], [ui.dlGlb, 'glb']]) {
    a.href = `api/items/${current.id}/download?lambda=${lambda}&format=${fmt}`;
  }
}

function fmt(x, digits = 3) { return x === null || x === undefined ? '—' : Number(x).toFixed(digits); }

async function loadItem(id) {
  setState('loading');
  current = items[id];
  ui.status.textContent = `${current.kind} · ${current.status}`;
  ui.images.replaceChildren(...current.images.map((name) => {
    const a = document.createElement('a');
    a.href = `api/items/${current.id}/files/${encodeURIComponent(name)}`;
    a.target = '_blank';
    a.textContent = name;
    return a;
  }));
  const { head, buf, offset } = await fetchFramed(`api/items/${id}/source`);
  const positions = new Float32Array(buf, offset, 3 * head.vertices).slice();
  const index = new Uint32Array(buf, offset + 12 * head.vertices, 3 * head.faces).slice();
  sourceGeometry = new THREE.BufferGeometry();
  sourceGeometry.setAttribute('position', new THREE.BufferAttribute(positions, 3));
  sourceGeometry.setIndex(new THREE.BufferAttribute(index, 1));
  sourceGeometry.computeVertexNormals();
  attach(before, sourceGeometry, solidBefore);
  const run = current.has_deformation;
  for (const el of [ui.lambda, ui.reset, ui.dlObj.parentElement]) el.hidden = !run;
  ui.lambda.parentElement.hidden = !run;
  if (run) {
    resultGeometry = new THREE.BufferGeometry();
    resultGeometry.setAttribute('position', new THREE.BufferAttribute(positions.slice(), 3));
    resultGeometry.setIndex(new THREE.BufferAttribute(index, 1));
    attach(after, resultGeometry, solid);
    const saved = current.lambda ?? 8;
    ui.lambda.max = String(Math.min(current.lambda_max, Math.max(20, Math.ceil(2 * saved))));
    ui.lambda.value = String(saved);
    layout = ui.layout.value;
    showing = 'after';
  } else {
    ui.metrics.textContent = current.kind === 'run'
      ? 'this run has no result yet (deformation.npz is missing); the page reloads it when it appears'
      : `${head.vertices} vertices, ${head.faces} faces`;
    ui.warnings.textContent = '';
  }
  updateLayoutUi();
  frame(sourceGeometry);
  if (run) {
    await requestLambda(Number(ui.lambda.value));
  } else {
    render();
    setState('ready');
  }
}

// Latest wins: one request in flight; a slider move during it replaces the pending value.
let pending = null;
let inflight = false;
let movedAt = 0;

async function applyResult(lambda) {
  const t0 = performance.now();
  const { head, buf, offset } = await fetchFramed(`api/items/${current.id}/result?lambda=${lambda}`);
  const positions = new Float32Array(buf, offset, 3 * head.vertices);
  const attr = resultGeometry.getAttribute('position');
  attr.array.set(positions);
  attr.needsUpdate = true;
  resultGeometry.computeVertexNormals();
  resultGeometry.computeBoundingSphere();
  render();
  const ms = performance.now() - Math.min(movedAt || t0, t0);
  shownLambda = lambda;
  document.documentElement.dataset.lambda = String(lambda);
  ui.metrics.textContent =
    `λ = ${lambda} · volume ratio ${fmt(head.volume_ratio)} · face-area ratio ${fmt(head.area_ratio_mean)} ± ${fmt(head.area_ratio_std)}` +
    ` · flipped ${fmt(100 * head.flipped_fraction, 1)}% · ${head.vertices} vertices · updated in ${ms.toFixed(0)} ms`;
  ui.metrics.dataset.ms = ms.toFixed(1);
  ui.warnings.textContent = (head.warnings || []).join(' · ');
  setDownloads(lambda);
}

async function requestLambda(lambda) {
  pending = lambda;
  setState('loading');
  if (inflight) return;
  inflight = true;
  try {
    while (pending !== null) {
      const l = pending;
      pending = null;
      await applyResult(l);
    }
    setState('ready');
  } catch (e) {
    setState('error');
    throw e;
  } finally {
    inflight = false;
  }
}

// ---------- controls ----------
ui.lambda.addEventListener('input', () => {
  const l = Number(ui.lambda.value);
  ui.lambdaValue.textContent = l.toFixed(1);
  movedAt = performance.now();
  requestLambda(l);
});
ui.reset.addEventListener('click', () => {
  if (current && current.lambda !== null) {
    ui.lambda.value = String(current.lambda);
    ui.lambda.dispatchEvent(new Event('input'));
  }
});
ui.flat.addEventListener('change', () => {
  for (const m of [solid, solidBefore]) { m.flatShading = ui.flat.checked; m.needsUpdate = true; }
  render();
});
ui.wire.addEventListener('change', () => {
  for (const t of [before, after]) if (t.wire) t.wire.visible = ui.wire.checked;
  render();
});
ui.layout.addEventListener('change', () => {
  layout = ui.layout.value;
  updateLayoutUi();
  render();
});
function toggleShown() {
  if (!current || !current.has_deformation) return;
  if (layout !== 'toggle') { layout = 'toggle'; ui.layout.value = 'toggle'; }
  showing = showing === 'after' ? 'before' : 'after';
  updateLayoutUi();
  render();
}
ui.toggle.addEventListener('click', toggleShown);
window.addEventListener('keydown', (e) => {
  if ((e.key === 't' || e.key === 'T') && e.target.tagName !== 'INPUT') toggleShown();
});
ui.item.addEventListener('change', () => loadItem(Number(ui.item.value)));

// A run still being written: poll until its result appears.
async function pollIncomplete() {
  if (!current || current.kind !== 'run' || current.has_deformation) return;
  const fresh = await (await check(await fetch('api/items'), 'api/items')).json();
  if (fresh[current.id] && fresh[current.id].has_deformation) {
    items = fresh;
    await loadItem(current.id);
  }
}
setInterval(() => { pollIncomplete().catch((e) => console.error(e.message)); }, 3000);

async function main() {
  items = await (await check(await fetch('api/items'), 'api/items')).json();
  ui.item.replaceChildren(...items.map((it) => {
    const o = document.createElement('option');
    o.value = String(it.id);
    o.textContent = `${it.name} (${it.kind})`;
    return o;
  }));
  const first = Math.min(items.length - 1, Math.max(0, Number(params.get('item') || 0)));
  ui.item.value = String(first);
  await loadItem(first);
  ui.lambdaValue.textContent = Number(ui.lambda.value).toFixed(1);
  const wanted = params.get('lambda');
  if (wanted !== null && current.has_deformation) {
    // Through the slider's own handler, as a user would.
    ui.lambda.value = wanted;
    ui.lambda.dispatchEvent(new Event('input'));
  }
}
main().catch((e) => { setState('error'); console.error(e.message); });
