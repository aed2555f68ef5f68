// stylize view: the page. Talks to the server in crates/stylize-cli/src/view/server.rs (all URLs
// are relative to /TOKEN/). Two scenes (before = the run's rest mesh, after = the saved deformation
// re-applied at the slider's λ) share one camera, so orbiting one orbits both.
//
// URL parameters: ?item=ID (which item first), ?lambda=L (after loading, set λ to L through the
// slider's own input handler — the browser test uses it), ?strength=S (the same for the strength
// slider: the result at λ pushed S times as far, `apply --strength`). <html data-state> is "loading"
// while a request is pending and "ready" when the shown shape matches the sliders; data-lambda is
// the λ shown, data-strength its strength,
// data-intersecting-faces / data-new-intersecting-faces its self-intersection counts, data-max-safe
// the strongest safe λ up to the slider's end once the server has found it.
import * as THREE from 'three';
import { OrbitControls } from './vendor/three/OrbitControls.js';
import { renderPlots, renderInfo } from './plots.js';

const $ = (id) => document.getElementById(id);
const params = new URLSearchParams(location.search);
const ui = {
  item: $('item'), status: $('status'), lambda: $('lambda'), lambdaValue: $('lambda-value'),
  strength: $('strength'), strengthValue: $('strength-value'),
  reset: $('reset-lambda'), maxSafe: $('max-safe'), safeNote: $('safe-note'), flat: $('flat'), wire: $('wire'), layout: $('layout'), toggle: $('toggle'),
  dlObj: $('dl-obj'), dlPly: $('dl-ply'), dlGlb: $('dl-glb'), images: $('images'),
  metrics: $('metrics'), warnings: $('warnings'), left: $('label-left'), right: $('label-right'),
  canvas: $('canvas'), viewport: $('viewport'),
  replayBar: $('replay-bar'), replay: $('replay'), replayValue: $('replay-value'), replayPlay: $('replay-play'),
  replayFollow: $('replay-follow'), replayNote: $('replay-note'),
  gallery: $('gallery'), galleryButton: $('gallery-button'), filter: $('filter'), cards: $('cards'), galleryCount: $('gallery-count'),
  normals: $('normals'), look: $('look'),
  panel: $('panel'), panelToggle: $('panel-toggle'), plots: $('plots'), plotsNote: $('plots-note'), info: $('info'),
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

// Two looks. "studio": a sky/ground fill plus a head light. "reference": what the optimization's
// renderer draws (docs/renderer.md, spec §6): grey albedo 0.5, Lambert only, one light at the eye
// of power 5 without falloff, two-sided, no ambient, on white, values written as they are (linear)
// — colour = 0.5 · 5 · max(n·l, 0)/π. three.js's Lambert BRDF is albedo/π and a point light with
// decay 0 gives irradiance intensity · cos, so intensity 5 reproduces it.
function makeScene() {
  const scene = new THREE.Scene();
  const hemi = new THREE.HemisphereLight(0xffffff, 0x667080, 1.4);
  const head = new THREE.DirectionalLight(0xffffff, 1.6);
  const eye = new THREE.PointLight(0xffffff, 5, 0, 0);
  eye.visible = false;
  scene.add(hemi, head, eye);
  return { scene, hemi, head, eye };
}
const before = makeScene();
const after = makeScene();

const solid = new THREE.MeshStandardMaterial({
  color: 0x8fa9c8, roughness: 0.65, metalness: 0.0, flatShading: false,
  polygonOffset: true, polygonOffsetFactor: 1, polygonOffsetUnits: 1,
});
const solidBefore = solid.clone();
solidBefore.color.set(0xb9b3a8);
const referenceMaterial = new THREE.MeshLambertMaterial({
  side: THREE.DoubleSide, flatShading: false,
  polygonOffset: true, polygonOffsetFactor: 1, polygonOffsetUnits: 1,
});
referenceMaterial.color.setRGB(0.5, 0.5, 0.5, THREE.LinearSRGBColorSpace);
function referenceLook() { return ui.look.value === 'reference'; }
const wireMaterial = new THREE.MeshBasicMaterial({ color: 0x202020, wireframe: true, transparent: true, opacity: 0.35 });

// Self-intersecting faces of the result (drawn over it, sharing its positions): new ones (not in
// the source) red, the source's own orange. Group 0 = new, group 1 = the source's own.
const newIntersectionMaterial = new THREE.MeshBasicMaterial({
  color: 0xd62828, side: THREE.DoubleSide, polygonOffset: true, polygonOffsetFactor: -1, polygonOffsetUnits: -1,
});
const oldIntersectionMaterial = newIntersectionMaterial.clone();
oldIntersectionMaterial.color.set(0xf08c00);
let highlight = null;

// Highlights head.intersecting_faces of the result (faces in head.new_intersecting_faces red).
function showIntersections(head) {
  if (highlight) { after.scene.remove(highlight); highlight.geometry.dispose(); highlight = null; }
  const all = head.intersecting_faces || [];
  if (!resultGeometry || !resultGeometry.index || all.length === 0) return;
  const src = resultGeometry.index.array;
  const fresh = new Set(head.new_intersecting_faces || []);
  const ordered = [...all.filter((f) => fresh.has(f)), ...all.filter((f) => !fresh.has(f))];
  const index = new Uint32Array(3 * ordered.length);
  ordered.forEach((f, k) => { index[3 * k] = src[3 * f]; index[3 * k + 1] = src[3 * f + 1]; index[3 * k + 2] = src[3 * f + 2]; });
  const g = new THREE.BufferGeometry();
  g.setAttribute('position', resultGeometry.getAttribute('position'));
  g.setIndex(new THREE.BufferAttribute(index, 1));
  const nNew = ordered.filter((f) => fresh.has(f)).length;
  g.addGroup(0, 3 * nNew, 0);
  g.addGroup(3 * nNew, 3 * (ordered.length - nNew), 1);
  highlight = new THREE.Mesh(g, [newIntersectionMaterial, oldIntersectionMaterial]);
  highlight.name = 'intersections';
  after.scene.add(highlight);
}

// The strongest safe λ up to the slider's end (server: api/items/ID/max-safe), shown on the
// bar under the slider (green up to it, red beyond) and behind the "max safe λ" button.
let safe = null;   // { upper, lambda, first_unsafe, safe_again, ... } of the current item
const AUTO_MAX_SAFE_FACES = 20000;
async function loadMaxSafe() {
  const item = current;
  const upper = Number(ui.lambda.max);
  ui.safeNote.textContent = 'searching the safe λ…';
  const r = await check(await fetch(`api/items/${item.id}/max-safe?upper=${upper}`), 'max-safe');
  const j = await r.json();
  if (current !== item) return;
  safe = j;
  const pct = (100 * j.lambda / upper).toFixed(2);
  // A bar under the slider: green up to the safe λ, red beyond.
  const track = document.getElementById('safe-track');
  track.style.left = `${ui.lambda.offsetLeft}px`;
  track.style.width = `${ui.lambda.offsetWidth}px`;
  track.style.background = j.first_unsafe === null
    ? '#3a9a3a'
    : `linear-gradient(to right, #3a9a3a 0%, #3a9a3a ${pct}%, #d62828 ${pct}%, #d62828 100%)`;
  track.hidden = false;
  ui.maxSafe.hidden = false;
  ui.maxSafe.dataset.lambda = String(j.lambda);
  ui.safeNote.textContent = j.first_unsafe === null
    ? `safe up to λ = ${upper}`
    : `safe up to λ = ${fmt(j.lambda, 2)}` + (j.safe_again.length ? ' (safe again further up: not monotone)' : '');
  document.documentElement.dataset.maxSafe = String(j.lambda);
}
function clearMaxSafe() {
  safe = null;
  document.getElementById('safe-track').hidden = true;
  ui.maxSafe.hidden = true;  // shown again for runs
  ui.safeNote.textContent = '';
  delete document.documentElement.dataset.maxSafe;
}

const pointsMaterial = new THREE.PointsMaterial({ color: 0x3d5a80, size: 2, sizeAttenuation: false });

function detach(target) {
  for (const c of [...target.scene.children]) if (c.isMesh || c.isPoints || c.isLineSegments) target.scene.remove(c);
  target.mesh = null;
  target.wire = null;
}

function attach(target, geometry, material) {
  detach(target);
  if (!geometry.index) {
    // Snapshots of a run that has neither faces in snapshots.npz nor deformation.npz yet.
    target.mesh = new THREE.Points(geometry, pointsMaterial);
    target.scene.add(target.mesh);
    return;
  }
  target.material = material;
  const mesh = new THREE.Mesh(geometry, referenceLook() ? referenceMaterial : material);
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
    target.eye.position.copy(camera.position);
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

// Two views (before | after) when there is something to compare: a result or a replay.
function twoViews() { return !!current && (current.has_deformation || replay.available); }

function updateLayoutUi() {
  const run = twoViews();
  ui.toggle.hidden = layout !== 'toggle' || !run;
  ui.toggle.textContent = showing === 'after' ? 'show before' : 'show after';
  ui.left.hidden = !run;
  ui.right.hidden = layout !== 'side' || !run;
  const afterName = shownReplay !== null ? `iteration ${shownReplay}` : 'after';
  if (layout === 'toggle') {
    ui.left.textContent = showing === 'after' ? afterName : 'before';
  } else {
    ui.left.textContent = 'before';
    ui.right.textContent = afterName;
  }
  if (!run) { layout = 'toggle'; showing = 'before'; }
}

// `&strength=S` for a strength other than 1 (1: the result at λ itself, the plain request).
function strengthQuery(strength) { return strength === 1 ? '' : `&strength=${strength}`; }

function setDownloads(lambda, strength) {
  for (const [a, fmt] of [[ui.dlObj, 'obj'], [ui.dlPly, 'ply'], [ui.dlGlb, 'glb']]) {
    a.href = `api/items/${current.id}/download?lambda=${lambda}&format=${fmt}${strengthQuery(strength)}`;
  }
}

function fmt(x, digits = 3) { return x === null || x === undefined ? '—' : Number(x).toFixed(digits); }

async function loadItem(id) {
  setState('loading');
  stopPlaying();
  current = items[id];
  ui.panelToggle.hidden = current.kind !== 'run';
  if (current.kind !== 'run') ui.panel.hidden = true;
  plotsIterations = -1;
  await refreshPanel(true);
  replay = { available: false, iterations: [] };
  shownReplay = null;
  delete document.documentElement.dataset.replay;
  updateReplayUi();
  ui.status.textContent = `${current.kind} · ${current.status}`;
  ui.images.replaceChildren(...current.images.map((name) => {
    const a = document.createElement('a');
    a.href = `api/items/${current.id}/files/${encodeURIComponent(name)}`;
    a.target = '_blank';
    a.textContent = name;
    return a;
  }));
  if (current.kind === 'run' && !current.has_deformation) {
    await loadLiveRun();
    return;
  }
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
  ui.strength.parentElement.hidden = !run;
  if (run) {
    resultGeometry = new THREE.BufferGeometry();
    resultGeometry.setAttribute('position', new THREE.BufferAttribute(positions.slice(), 3));
    resultGeometry.setIndex(new THREE.BufferAttribute(index, 1));
    // Normals before the first draw: an attribute added after a geometry was first drawn is not
    // picked up by three.js's cached vertex state, and the shading would keep the first normals.
    resultGeometry.computeVertexNormals();
    attach(after, resultGeometry, solid);
    const saved = current.lambda ?? 8;
    ui.lambda.max = String(Math.min(current.lambda_max, Math.max(20, Math.ceil(2 * saved))));
    ui.lambda.value = String(saved);
    ui.strength.value = '1';
    ui.strengthValue.textContent = '1.00';
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
  ui.normals.parentElement.hidden = !run;
  await showNormals();
  if (current.kind === 'run') await refreshReplay();
  clearMaxSafe();
  if (run) {
    ui.maxSafe.hidden = false;
    await request({ kind: 'lambda', value: Number(ui.lambda.value) });
    // The search re-solves ~40 λ on the server and holds the run meanwhile (slider moves wait):
    // automatic on small meshes only, else on the button's first click.
    if (head.faces <= AUTO_MAX_SAFE_FACES) loadMaxSafe().catch((e) => { ui.safeNote.textContent = e.message; });
  } else {
    render();
    setState('ready');
  }
}

// A run without its result yet: before = its first snapshot, after = its newest (when it has
// snapshots at all; else a message, and the polling below loads it once something appears).
async function loadLiveRun() {
  for (const el of [ui.lambda.parentElement, ui.strength.parentElement, ui.reset, ui.dlObj.parentElement, ui.normals.parentElement]) el.hidden = true;
  normalsField = null;
  detach(before);
  detach(after);
  await refreshReplay();
  if (!replay.available) {
    ui.metrics.textContent = `this run has no result and no replay yet (${replay.reason}); the page picks them up when they appear`;
    ui.warnings.textContent = '';
    layout = 'toggle';
    showing = 'before';
    updateLayoutUi();
    render();
    setState('ready');
    return;
  }
  const first = await fetchSnapshot(replay.iterations[0], true);
  sourceGeometry = snapshotGeometry(first);
  resultGeometry = snapshotGeometry(first);
  attach(before, sourceGeometry, solidBefore);
  attach(after, resultGeometry, solid);
  layout = ui.layout.value;
  showing = 'after';
  updateLayoutUi();
  frame(sourceGeometry);
  const last = replay.iterations.length - 1;
  ui.replay.value = String(last);
  await request({ kind: 'replay', value: replay.iterations[last] });
}

// ---------- run panel: info and plots ----------
let plotsIterations = -1;

async function refreshPanel(force) {
  if (ui.panel.hidden || !current || current.kind !== 'run') return;
  const table = await (await check(await fetch(`api/items/${current.id}/metrics`), 'metrics')).json();
  const n = table.iterations.length;
  if (force) await renderInfo(ui.info, current);
  if (!force && n === plotsIterations) return;
  plotsIterations = n;
  const count = renderPlots(ui.plots, table, ui.panel.clientWidth - 24);
  const skipped = table.skipped ? ` · ${table.skipped} malformed line(s) skipped (the first is line ${table.first_skipped_line})` : '';
  ui.plotsNote.textContent = table.available ? `metrics.jsonl: ${n} iterations${skipped}` : 'no metrics.jsonl yet';
  document.documentElement.dataset.plots = String(count);
}

ui.panelToggle.addEventListener('click', () => {
  ui.panel.hidden = !ui.panel.hidden;
  render();
  refreshPanel(true).catch((e) => { ui.plotsNote.textContent = e.message; });
});
// A live run: new metrics lines appear.
setInterval(() => { refreshPanel(false).catch((e) => { ui.plotsNote.textContent = e.message; }); }, 5000);

// ---------- replay (snapshots.npz) ----------
let replay = { available: false, iterations: [] };
let shownReplay = null;   // iteration shown in the 'after' view, null when it shows the λ result

async function fetchSnapshot(iteration, faces) {
  const { head, buf, offset } = await fetchFramed(`api/items/${current.id}/replay/${iteration}${faces ? '?faces=1' : ''}`);
  const positions = new Float32Array(buf, offset, 3 * head.vertices).slice();
  const index = head.faces > 0 ? new Uint32Array(buf, offset + 12 * head.vertices, 3 * head.faces).slice() : null;
  return { head, positions, index };
}

function snapshotGeometry(s) {
  const g = new THREE.BufferGeometry();
  g.setAttribute('position', new THREE.BufferAttribute(s.positions.slice(), 3));
  if (s.index) {
    g.setIndex(new THREE.BufferAttribute(s.index, 1));
    g.computeVertexNormals();
  }
  return g;
}

async function fetchReplayIndex() {
  return (await check(await fetch(`api/items/${current.id}/replay`), 'replay')).json();
}

function updateReplayUi() {
  const n = replay.iterations.length;
  ui.replayBar.hidden = !current || current.kind !== 'run';
  ui.replay.disabled = !replay.available;
  ui.replayPlay.disabled = !replay.available || n < 2;
  ui.replay.max = String(Math.max(0, n - 1));
  if (!replay.available) {
    ui.replayValue.textContent = 'no replay';
    ui.replayNote.textContent = replay.reason || '';
  } else {
    ui.replayValue.textContent = shownReplay !== null
      ? `iteration ${shownReplay} / ${replay.iterations[n - 1]}`
      : `${n} snapshots (0…${replay.iterations[n - 1]})`;
    ui.replayNote.textContent = replay.faces_from ? '' : 'no faces known yet: drawn as points';
  }
}

async function refreshReplay() {
  try {
    replay = await fetchReplayIndex();
  } catch (e) {
    replay = { available: false, iterations: [], reason: e.message };
  }
  updateReplayUi();
}

async function applySnapshot(iteration) {
  // The highlighted faces belong to the λ result, not to a snapshot.
  if (highlight) highlight.visible = false;
  let s;
  try {
    s = await fetchSnapshot(iteration, false);
  } catch (e) {
    // The file changed under us (a live run rewrote it): not a page error; the poll refreshes it.
    ui.replayNote.textContent = `snapshot ${iteration}: ${e.message}`;
    return;
  }
  const attr = resultGeometry.getAttribute('position');
  if (s.head.vertices !== attr.count) {
    ui.replayNote.textContent = `snapshots hold ${s.head.vertices} vertices, the result ${attr.count}: not shown`;
    return;
  }
  attr.array.set(s.positions);
  attr.needsUpdate = true;
  if (resultGeometry.index) resultGeometry.computeVertexNormals();
  resultGeometry.computeBoundingSphere();
  shownReplay = iteration;
  document.documentElement.dataset.replay = String(iteration);
  updateReplayUi();
  updateLayoutUi();
  render();
  ui.metrics.textContent = `replay: iteration ${iteration} of ${replay.iterations[replay.iterations.length - 1]} · ${s.head.vertices} vertices` +
    (current.has_deformation ? ' · move λ to see the result again' : ` · run ${current.status}`);
  ui.warnings.textContent = '';
}

let playing = null;
function stopPlaying() {
  if (playing !== null) { clearInterval(playing); playing = null; ui.replayPlay.textContent = '▶'; }
}
ui.replayPlay.addEventListener('click', () => {
  if (playing !== null) { stopPlaying(); return; }
  ui.replay.value = '0';
  ui.replay.dispatchEvent(new Event('input'));
  ui.replayPlay.textContent = '■';
  playing = setInterval(() => {
    const k = Number(ui.replay.value) + 1;
    if (k >= replay.iterations.length) { stopPlaying(); return; }
    ui.replay.value = String(k);
    ui.replay.dispatchEvent(new Event('input'));
  }, 250);
});
ui.replay.addEventListener('input', () => {
  if (!replay.available) return;
  const it = replay.iterations[Number(ui.replay.value)];
  if (it === undefined) return;
  request({ kind: 'replay', value: it });
});

// A live run: new snapshots appear; follow the newest when the newest is shown (and 'live' is on).
async function pollReplay() {
  if (!current || current.kind !== 'run' || inflight) return;
  let fresh;
  try {
    fresh = await fetchReplayIndex();
  } catch (e) {
    ui.replayNote.textContent = `cannot reach the server: ${e.message}`;
    return;
  }
  const last = (r) => r.iterations[r.iterations.length - 1];
  if (fresh.available === replay.available && fresh.iterations.length === replay.iterations.length && last(fresh) === last(replay)) return;
  if (!current.has_deformation && !replay.available && fresh.available) {
    await loadItem(current.id);
    return;
  }
  const wasAtEnd = shownReplay !== null && shownReplay === last(replay);
  replay = fresh;
  updateReplayUi();
  if (replay.available && ui.replayFollow.checked && wasAtEnd && playing === null) {
    ui.replay.value = String(replay.iterations.length - 1);
    await request({ kind: 'replay', value: last(replay) });
  }
}
setInterval(() => { pollReplay().catch((e) => { ui.replayNote.textContent = e.message; }); }, 3000);

// Latest wins: one request in flight; a slider move during it replaces the pending value.
let pending = null;
let inflight = false;
let movedAt = 0;

async function applyResult(lambda, strength) {
  const t0 = performance.now();
  const { head, buf, offset } = await fetchFramed(`api/items/${current.id}/result?lambda=${lambda}${strengthQuery(strength)}`);
  const positions = new Float32Array(buf, offset, 3 * head.vertices);
  const attr = resultGeometry.getAttribute('position');
  attr.array.set(positions);
  attr.needsUpdate = true;
  resultGeometry.computeVertexNormals();
  resultGeometry.computeBoundingSphere();
  render();
  const ms = performance.now() - Math.min(movedAt || t0, t0);
  shownLambda = lambda;
  shownReplay = null;
  updateReplayUi();
  updateLayoutUi();
  document.documentElement.dataset.lambda = String(lambda);
  document.documentElement.dataset.strength = String(strength);
  ui.metrics.textContent =
    `λ = ${lambda}` + (strength === 1 ? '' : ` · strength ${strength}`) + ` · volume ratio ${fmt(head.volume_ratio)} · face-area ratio ${fmt(head.area_ratio_mean)} ± ${fmt(head.area_ratio_std)}` +
    ` · flipped ${fmt(100 * head.flipped_fraction, 1)}%` +
    ` · self-intersecting faces ${head.intersections ? head.intersections.faces : '—'} (${head.intersections ? head.intersections.new_faces : '—'} new)` +
    ` · ${head.vertices} vertices · updated in ${ms.toFixed(0)} ms`;
  // For scripts and the browser test: the counts of the shown result.
  document.documentElement.dataset.intersectingFaces = String(head.intersections ? head.intersections.faces : '');
  document.documentElement.dataset.newIntersectingFaces = String(head.intersections ? head.intersections.new_faces : '');
  showIntersections(head);
  render();
  ui.metrics.dataset.ms = ms.toFixed(1);
  ui.warnings.textContent = (head.warnings || []).join(' · ');
  setDownloads(lambda, strength);
}

async function request(job) {
  pending = job;
  setState('loading');
  if (inflight) return;
  inflight = true;
  try {
    while (pending !== null) {
      const j = pending;
      pending = null;
      if (j.kind === 'lambda') await applyResult(j.value, j.strength ?? 1);
      else await applySnapshot(j.value);
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
// A λ request carries the strength slider's value too.
function requestResult() {
  movedAt = performance.now();
  stopPlaying();
  return request({ kind: 'lambda', value: Number(ui.lambda.value), strength: Number(ui.strength.value) });
}
ui.lambda.addEventListener('input', () => {
  ui.lambdaValue.textContent = Number(ui.lambda.value).toFixed(1);
  requestResult();
});
ui.strength.addEventListener('input', () => {
  ui.strengthValue.textContent = Number(ui.strength.value).toFixed(2);
  requestResult();
});
// The max-safe λ and the run's λ are results at strength 1.
function resetStrength() {
  ui.strength.value = '1';
  ui.strengthValue.textContent = '1.00';
}
ui.maxSafe.addEventListener('click', async () => {
  if (!safe) {
    try { await loadMaxSafe(); } catch (e) { ui.safeNote.textContent = e.message; return; }
  }
  if (safe) {
    resetStrength();
    ui.lambda.value = String(safe.lambda);
    ui.lambda.dispatchEvent(new Event('input'));
  }
});
ui.reset.addEventListener('click', () => {
  if (current && current.lambda !== null) {
    resetStrength();
    ui.lambda.value = String(current.lambda);
    ui.lambda.dispatchEvent(new Event('input'));
  }
});
function applyLook() {
  const ref = referenceLook();
  for (const t of [before, after]) {
    t.hemi.visible = !ref;
    t.head.visible = !ref;
    t.eye.visible = ref;
    if (t.mesh && t.mesh.isMesh) t.mesh.material = ref ? referenceMaterial : t.material;
  }
  renderer.setClearColor(ref ? 0xffffff : 0xf4f5f7);
  renderer.outputColorSpace = ref ? THREE.LinearSRGBColorSpace : THREE.SRGBColorSpace;
  document.documentElement.dataset.look = ui.look.value;
  render();
}
ui.look.addEventListener('change', applyLook);

// ---------- target normals (the saved deformation's, on the source) ----------
let normalsField = null;
async function showNormals() {
  if (normalsField) {
    before.scene.remove(normalsField);
    normalsField.geometry.dispose();
    normalsField = null;
  }
  delete document.documentElement.dataset.normals;
  if (!ui.normals.checked || !current || !current.has_deformation || !sourceGeometry) { render(); return; }
  const { head, buf, offset } = await fetchFramed(`api/items/${current.id}/targets`);
  const p = sourceGeometry.getAttribute('position').array;
  const v = head.vertices;
  if (3 * v !== p.length) throw new Error(`target normals: ${v} vectors for ${p.length / 3} vertices`);
  const n = new Float32Array(buf, offset, 3 * v);
  sourceGeometry.computeBoundingSphere();
  const len = 0.06 * sourceGeometry.boundingSphere.radius;
  const seg = new Float32Array(6 * v);
  const col = new Float32Array(6 * v);
  for (let i = 0; i < v; i++) {
    for (let c = 0; c < 3; c++) {
      seg[6 * i + c] = p[3 * i + c];
      seg[6 * i + 3 + c] = p[3 * i + c] + len * n[3 * i + c];
      // Coloured by direction: |x|, |y|, |z| as red, green, blue (axis-aligned targets are pure).
      col[6 * i + c] = col[6 * i + 3 + c] = Math.abs(n[3 * i + c]);
    }
  }
  const g = new THREE.BufferGeometry();
  g.setAttribute('position', new THREE.BufferAttribute(seg, 3));
  g.setAttribute('color', new THREE.BufferAttribute(col, 3));
  normalsField = new THREE.LineSegments(g, new THREE.LineBasicMaterial({ vertexColors: true }));
  before.scene.add(normalsField);
  document.documentElement.dataset.normals = String(v);
  render();
}
ui.normals.addEventListener('change', () => { showNormals().catch((e) => console.error(e.message)); });

ui.flat.addEventListener('change', () => {
  for (const m of [solid, solidBefore, referenceMaterial]) { m.flatShading = ui.flat.checked; m.needsUpdate = true; }
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
  if (!twoViews()) return;
  if (layout !== 'toggle') { layout = 'toggle'; ui.layout.value = 'toggle'; }
  showing = showing === 'after' ? 'before' : 'after';
  updateLayoutUi();
  render();
}
ui.toggle.addEventListener('click', toggleShown);
window.addEventListener('keydown', (e) => {
  if ((e.key === 't' || e.key === 'T') && e.target.tagName !== 'INPUT') toggleShown();
});
ui.item.addEventListener('change', () => { loadItem(Number(ui.item.value)).catch((e) => { setState('error'); console.error(e.message); }); });

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

// ---------- gallery (several runs, or a batch manifest) ----------
let galleryKey = '';

function describe(it) {
  const what = it.prompt !== null && it.prompt !== undefined ? `“${it.prompt}”` : (it.style ? `style ${it.style}` : '');
  return [what, it.mesh || ''].filter(Boolean).join(' · ');
}

function buildCards() {
  ui.cards.replaceChildren(...items.map((it) => {
    const a = document.createElement('a');
    a.className = 'card';
    a.href = `?item=${it.id}`;
    a.dataset.id = String(it.id);
    a.dataset.text = [it.name, it.prompt || '', it.style || '', it.mesh || '', it.status].join(' ').toLowerCase();
    let pic;
    if (it.thumbnail) {
      pic = document.createElement('img');
      pic.loading = 'lazy';
      pic.alt = it.name;
      pic.src = `api/items/${it.id}/files/${it.thumbnail.split('/').map(encodeURIComponent).join('/')}?v=${encodeURIComponent(it.status)}`;
    } else {
      pic = document.createElement('div');
      pic.className = 'noimg';
      pic.textContent = it.kind === 'mesh' ? 'mesh' : (it.status === 'not started' ? 'not started' : 'no picture yet');
    }
    const title = document.createElement('div');
    title.className = 'title';
    title.textContent = it.row !== null && it.row !== undefined ? `#${it.row} ${it.name}` : it.name;
    const sub = document.createElement('div');
    sub.className = 'sub';
    sub.textContent = describe(it);
    const badge = document.createElement('span');
    badge.className = `badge ${it.status.replace(' ', '-')}`;
    badge.textContent = it.status;
    a.append(pic, title, sub, badge);
    a.addEventListener('click', (e) => {
      e.preventDefault();
      openItem(it.id);
    });
    return a;
  }));
  applyFilter();
}

function applyFilter() {
  const terms = ui.filter.value.toLowerCase().split(/\s+/).filter(Boolean);
  let shown = 0;
  for (const card of ui.cards.children) {
    const ok = terms.every((t) => card.dataset.text.includes(t));
    card.hidden = !ok;
    shown += ok ? 1 : 0;
  }
  ui.galleryCount.textContent = `${shown} of ${items.length} shown`;
  document.documentElement.dataset.gallery = String(shown);
}
ui.filter.addEventListener('input', applyFilter);

function showGallery() {
  stopPlaying();
  document.body.classList.add('gallery-mode');
  ui.gallery.hidden = false;
  current = null;
  buildCards();
  setState('ready');
}

function openItem(id) {
  document.body.classList.remove('gallery-mode');
  ui.gallery.hidden = true;
  ui.item.value = String(id);
  loadItem(id).catch((e) => { setState('error'); console.error(e.message); });
}
ui.galleryButton.addEventListener('click', showGallery);

// Statuses and thumbnails change while a batch runs.
async function pollGallery() {
  if (ui.gallery.hidden) return;
  const fresh = await (await check(await fetch('api/items'), 'api/items')).json();
  const key = JSON.stringify(fresh.map((it) => [it.status, it.thumbnail]));
  if (key === galleryKey) return;
  galleryKey = key;
  items = fresh;
  buildCards();
}
setInterval(() => { pollGallery().catch((e) => { ui.galleryCount.textContent = e.message; }); }, 5000);

async function main() {
  items = await (await check(await fetch('api/items'), 'api/items')).json();
  galleryKey = JSON.stringify(items.map((it) => [it.status, it.thumbnail]));
  if (params.get('panel') !== null) ui.panel.hidden = false;
  if (params.get('normals') !== null) ui.normals.checked = true;
  if (params.get('look') === 'reference') { ui.look.value = 'reference'; applyLook(); }
  ui.galleryButton.hidden = items.length < 2;
  ui.item.replaceChildren(...items.map((it) => {
    const o = document.createElement('option');
    o.value = String(it.id);
    o.textContent = `${it.name} (${it.kind})`;
    return o;
  }));
  if (items.length > 1 && params.get('item') === null) {
    if (params.get('filter') !== null) ui.filter.value = params.get('filter');
    showGallery();
    return;
  }
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
  const strength = params.get('strength');
  if (strength !== null && current.has_deformation) {
    ui.strength.value = strength;
    ui.strength.dispatchEvent(new Event('input'));
  }
  const iteration = params.get('iteration');
  if (iteration !== null && replay.available) {
    // Through the replay scrubber's own handler.
    const k = replay.iterations.indexOf(Number(iteration));
    if (k < 0) throw new Error(`no snapshot at iteration ${iteration}`);
    ui.replay.value = String(k);
    ui.replay.dispatchEvent(new Event('input'));
  }
}
main().catch((e) => { setState('error'); console.error(e.message); });
