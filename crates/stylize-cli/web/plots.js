// stylize view: the run panel — what the run was (prompt/style, config, timings from run.json,
// task.json, config.toml) and plots of metrics.jsonl (uPlot, vendored under vendor/uplot/).
//
// The server sends metrics.jsonl as columns (api/items/ID/metrics: iterations, series by flattened
// key, skipped lines); malformed lines were skipped there and are only counted here.
import uPlot from './vendor/uplot/uPlot.esm.js';

const COLORS = ['#1f77b4', '#d62728', '#2ca02c', '#ff7f0e', '#9467bd', '#8c564b', '#e377c2', '#17becf', '#7f7f7f', '#bcbd22'];

// Which series go into which chart, in order; anything left over goes into "other".
const GROUPS = [
  { title: 'loss terms', test: (k) => k.startsWith('loss') },
  { title: 'stage-II weight', test: (k) => k === 'stage2_weight' },
  { title: 'alignment (mean cos to the style normals)', test: (k) => k === 'alignment' },
  { title: 'gradient norm ‖dL/dx‖', test: (k) => k === 'grad_norm' },
  { title: 'seconds per iteration', test: (k) => k.startsWith('seconds.') },
];

let charts = [];

function clearCharts() {
  for (const c of charts) c.destroy();
  charts = [];
}

/// Draws one chart per group present in `table` into `box`; returns the number of charts.
export function renderPlots(box, table, width) {
  clearCharts();
  box.replaceChildren();
  const keys = Object.keys(table.series || {});
  const used = new Set();
  const groups = [];
  for (const g of GROUPS) {
    const ks = keys.filter((k) => g.test(k) && !used.has(k));
    ks.forEach((k) => used.add(k));
    if (ks.length) groups.push({ title: g.title, keys: ks });
  }
  const rest = keys.filter((k) => !used.has(k));
  if (rest.length) groups.push({ title: 'other', keys: rest });
  for (const g of groups) {
    const holder = document.createElement('div');
    holder.className = 'plot';
    box.append(holder);
    const opts = {
      title: g.title,
      width,
      height: 150,
      legend: { live: true },
      cursor: { drag: { x: true, y: false } },
      scales: { x: { time: false } },
      axes: [{ label: 'iteration', size: 30, labelSize: 14 }, { size: 56 }],
      series: [
        { label: 'iteration' },
        ...g.keys.map((k, i) => ({
          label: g.title === 'seconds per iteration' ? k.slice('seconds.'.length) : k,
          stroke: COLORS[i % COLORS.length],
          width: 1.5,
          spanGaps: false,
        })),
      ],
    };
    const data = [table.iterations, ...g.keys.map((k) => table.series[k])];
    charts.push(new uPlot(opts, data, holder));
  }
  return charts.length;
}

function row(name, value) {
  const tr = document.createElement('tr');
  const th = document.createElement('th');
  th.textContent = name;
  const td = document.createElement('td');
  td.textContent = value;
  tr.append(th, td);
  return tr;
}

async function fetchText(url) {
  const r = await fetch(url);
  return r.ok ? r.text() : null;
}

function parseJson(text) {
  if (text === null) return null;
  try { return JSON.parse(text); } catch { return null; }
}

function secs(s) { return s === undefined || s === null ? '—' : `${Number(s).toFixed(2)} s`; }

/// Fills `box` with what the run was: prompt/style, status, λ, sizes, timings, warnings, and the
/// configuration (config.toml) under a disclosure. Missing or malformed files leave their rows out.
export async function renderInfo(box, item) {
  const base = `api/items/${item.id}/files/`;
  const [runText, taskText, config] = await Promise.all([
    fetchText(`${base}run.json`), fetchText(`${base}task.json`), fetchText(`${base}config.toml`),
  ]);
  const run = parseJson(runText);
  const task = parseJson(taskText);
  const fields = (run && run.task) || (task && task.identity && task.identity.fields) || {};
  const table = document.createElement('table');
  const unquote = (s) => { try { return JSON.parse(s); } catch { return s; } };
  if (fields.prompt !== undefined) table.append(row('prompt', unquote(fields.prompt)));
  if (fields.style !== undefined) table.append(row('style', fields.style));
  if (run && run.objective) table.append(row('objective', run.objective));
  table.append(row('status', item.status));
  if (run && run.mesh) table.append(row('mesh', run.mesh));
  if (run && run.vertices !== undefined) table.append(row('size', `${run.vertices} vertices, ${run.faces} faces`));
  if (run && run.lambda !== undefined && run.lambda !== null) table.append(row('λ', String(run.lambda)));
  if (run && run.iterations !== undefined) table.append(row('iterations', String(run.iterations)));
  if (run && run.seed !== undefined) table.append(row('seed', String(run.seed)));
  if (run && run.seconds) {
    table.append(row('time', Object.entries(run.seconds).map(([k, v]) => `${k} ${secs(v)}`).join(' · ')));
  }
  if (run && Array.isArray(run.warnings) && run.warnings.length) table.append(row('warnings', run.warnings.join(' · ')));
  if (runText !== null && run === null) table.append(row('run.json', 'unreadable (not JSON)'));
  const parts = [table];
  if (config !== null) {
    const details = document.createElement('details');
    const summary = document.createElement('summary');
    summary.textContent = 'configuration (config.toml)';
    const pre = document.createElement('pre');
    pre.textContent = config;
    details.append(summary, pre);
    parts.push(details);
  }
  box.replaceChildren(...parts);
}
