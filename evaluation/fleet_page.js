// The script of the fleet page (eosp/evaluation/fleet_report.py): canvases drawn from one JSON block.
//
// Plain browser JavaScript, no library: a Gantt chart and a map on canvases (tens of thousands of bars and points
// draw in milliseconds, where SVG would take seconds), hover by binary search in each satellite's observations and
// by nearest target, and a task table rendered a page at a time.  window.fleetPage exposes what was drawn (counts)
// and the pixel position of any observation, so that a test can point the mouse at a known bar.
(function () {
'use strict';
const T0 = performance.now();
const D = JSON.parse(document.getElementById('fleet-data').textContent);
const NS = D.sats.length, NT = D.tasks.id.length, H = D.seconds;
const t0 = Date.parse(D.start);
const tip = document.getElementById('tip');
const page = {drawn: {}, ready: false};
window.fleetPage = page;
// times: UTC for aeossp fleets; seconds since 0 h (shown as h:mm:ss) when the fleet has no dates (ONERA)
const pad = x => String(x).padStart(2, '0');
const rel = t => { const s = Math.round(t); return Math.floor(s / 3600) + ':' + pad(Math.floor(s / 60) % 60) + ':' + pad(s % 60); };
const fmt = D.relative ? (t => rel(t) + ' (since 0 h)') : (t => new Date(t0 + Math.round(t * 1000)).toISOString()
    .replace('T', ' ').replace(/\.\d+Z$/, '').replace('Z', '') + ' UTC');
const hms = t => D.relative ? rel(t) : fmt(t).slice(11, 19);
const hm = t => D.relative ? rel(t).slice(0, -3) : fmt(t).slice(11, 16);
const win = t => (H > 86400 && !D.relative) ? fmt(t).slice(5, 19) : hms(t);  // date too when the horizon is longer than a day
const num = (x, d) => (x === null || x === undefined) ? '-' : (+x).toFixed(d);
const esc = s => String(s).replace(/[&<>"']/g, c => ({'&': '&amp;', '<': '&lt;', '>': '&gt;', '"': '&quot;',
  "'": '&#39;'}[c]));
let V = 0;  // the schedule drawn

// ------------------------------------------------------------------ per view: observations by satellite, status
function prepare(vd) {
  const by = Array.from({length: NS}, () => []);
  const served = new Int32Array(NT).fill(-1);
  for (let i = 0; i < vd.st.length; i++) {
    const k = vd.sat[i], t = vd.task[i];
    if (k >= 0) by[k].push(i);
    if (t >= 0 && (served[t] < 0 || vd.en[i] < vd.en[served[t]])) served[t] = i;
  }
  if (vd.credit) for (let t = 0; t < NT; t++) if (!vd.credit[t]) served[t] = -1;  // observed, but worth nothing yet
  vd.dlBy = Array.from({length: NS}, () => []);
  if (vd.dl) vd.dl.sat.forEach((k, j) => { if (k >= 0) vd.dlBy[k].push(j); });
  for (const l of by) l.sort((a, b) => vd.st[a] - vd.st[b]);
  vd.by = by; vd.served = served;
}
D.views.forEach(prepare);

const R = D.reasons;
const reasonOf = new Map();
if (R) R.task.forEach((t, i) => reasonOf.set(t, i));
function reasonText(t) {
  if (V !== 0) return 'reasons are given for ' + D.views[0].label;
  if (!R) return 'no reasons (see the notes above)';
  const i = reasonOf.get(t);
  if (i === undefined) return '';
  const k = R.kind[i], tk = D.tasks;
  const where = R.sat[i] >= 0 ? D.sats[R.sat[i]] + ' at ' + fmt(R.st[i]) : '';
  switch (k) {
    case 0: return 'sensor mismatch: no satellite carries its sensor (' + tk.sensor[t] + ')';
    case 1: return 'no opportunity: no ' + tk.sensor[t] + ' satellite sees it within its window and off-nadir limit';
    case 2: return 'insertable as it is (' + where + '): value left on the table (weight ' + tk.w[t] + ')';
    case 3: return 'energy: fits in time (' + where + ') but the battery would go below zero';
    case 4: return 'blocked (' + where + '): removing ' + R.blk[i].map(b => tk.id[b]).join(', ') +
                   (R.blk[i].length > 1 ? ' together' : '') + ' would free it';
    default: return 'blocked: no removal of up to 3 neighbouring observations frees any of its ' + R.cand[i] +
                    ' opportunities';
  }
}
function statusText(t) {
  const vd = D.views[V], i = vd.served[t];
  return i < 0 ? 'missed' : 'observed by ' + D.sats[vd.sat[i]] + ' at ' + fmt(vd.st[i]);
}

// ------------------------------------------------------------------ Gantt
const G = document.getElementById('gantt');
const LEFT = 92, TOP = 30, ROWH = NS > 60 ? 14 : 28;
let GW = 0, PW = 0;
let VA = 0, VB = H;  // the time range shown (drag across the chart to zoom, double-click to see the horizon)
const gx = t => LEFT + (t - VA) / (VB - VA) * PW;
const tx = x => VA + (x - LEFT) / PW * (VB - VA);
const STEPS = [60, 300, 600, 1800, 3600, 3 * 3600, 6 * 3600, 86400];
function drawGantt() {
  const vd = D.views[V];
  GW = Math.max(900, G.parentElement.clientWidth || 1200); PW = GW - LEFT - 12;
  G.width = GW; G.height = TOP + NS * ROWH + 6;
  const c = G.getContext('2d');
  c.fillStyle = '#fff'; c.fillRect(0, 0, G.width, G.height);
  const n = {bars: 0, slews: 0, downloads: 0, eclipses: 0, violations: 0, battery_points: 0};
  c.font = '11px sans-serif'; c.fillStyle = '#333'; c.textBaseline = 'middle';
  // time ticks: about 12 to 24 over the range shown
  const span = VB - VA, step = STEPS.find(s => span / s <= 24) || 86400;
  const first = Math.ceil((t0 / 1000 + VA) / step) * step - t0 / 1000;
  c.strokeStyle = '#eee';
  for (let t = first; t <= VB; t += step) {
    const x = gx(t);
    c.beginPath(); c.moveTo(x, TOP - 4); c.lineTo(x, G.height); c.stroke();
    c.fillStyle = '#333'; c.fillText(span > 86400 && !D.relative ? fmt(t).slice(5, 16) : hm(t), x - 14, 12);
  }
  c.fillStyle = '#fff'; c.fillRect(0, 0, LEFT - 2, TOP - 2);
  c.fillStyle = '#333'; c.fillText(D.relative ? 'since 0 h' : fmt(VA).slice(0, 10) + ' UTC', 4, 12);
  for (let k = 0; k < NS; k++) { c.fillText(D.sats[k], 4, TOP + k * ROWH + ROWH / 2); }
  c.save(); c.beginPath(); c.rect(LEFT, 0, PW, G.height); c.clip();
  for (let k = 0; k < NS; k++) {
    const y = TOP + k * ROWH;
    c.fillStyle = '#fffbe6'; c.fillRect(LEFT, y + 1, PW, ROWH - 2);
    if (D.eclipses) {
      c.fillStyle = '#d9d9d9';
      const e = D.eclipses[k];
      for (let j = 0; j < e[0].length; j++) { c.fillRect(gx(e[0][j]), y + 1, Math.max(1, gx(e[1][j]) - gx(e[0][j])), ROWH - 2); n.eclipses++; }
    }
    const obs = vd.by[k];
    if (vd.slew) {
      c.fillStyle = '#ff9f1c';
      for (const i of obs) {
        const s = vd.slew[i]; if (s === null) continue;
        c.fillRect(gx(s), y + ROWH * 0.62, Math.max(1, gx(vd.st[i]) - gx(s)), ROWH * 0.22); n.slews++;
      }
    }
    if (vd.dl) {  // downloads, with the transition before each
      for (const j of vd.dlBy[k]) {
        const s = vd.dl.slew[j];
        if (s !== null) { c.fillStyle = '#ff9f1c'; c.fillRect(gx(s), y + ROWH * 0.62, Math.max(1, gx(vd.dl.st[j]) - gx(s)), ROWH * 0.22); n.slews++; }
        c.fillStyle = '#9467bd'; c.fillRect(gx(vd.dl.st[j]), y + ROWH * 0.18, Math.max(1.5, gx(vd.dl.en[j]) - gx(vd.dl.st[j])), ROWH * 0.44);
        n.downloads++;
      }
    }
    c.fillStyle = '#1f77b4';
    for (const i of obs) { c.fillRect(gx(vd.st[i]), y + ROWH * 0.18, Math.max(1.5, gx(vd.en[i]) - gx(vd.st[i])), ROWH * 0.44); n.bars++; }
    if (vd.battery) {
      const b = vd.battery[k], cap = D.capacity[k] || 1;
      c.strokeStyle = '#2ca02c'; c.lineWidth = 1; c.beginPath();
      for (let j = 0; j < b[0].length; j++) {
        const yy = y + ROWH - 1 - Math.max(0, Math.min(1, b[1][j] / cap)) * (ROWH - 2);
        if (j) c.lineTo(gx(b[0][j]), yy); else c.moveTo(gx(b[0][j]), yy);
      }
      c.stroke(); n.battery_points += b[0].length;
    }
    c.strokeStyle = '#f0f0f0'; c.beginPath(); c.moveTo(LEFT, y + ROWH); c.lineTo(LEFT + PW, y + ROWH); c.stroke();
  }
  if (vd.viol) {
    c.strokeStyle = '#e00000'; c.fillStyle = '#e00000'; c.lineWidth = 2;
    for (const [k, t] of vd.viol) {
      if (k < 0 || t === null) continue;
      const x = gx(t), y = TOP + k * ROWH;
      c.beginPath(); c.moveTo(x, y); c.lineTo(x, y + ROWH); c.stroke();
      c.beginPath(); c.moveTo(x - 5, y); c.lineTo(x + 5, y); c.lineTo(x, y + 7); c.fill(); n.violations++;
    }
    c.lineWidth = 1;
  }
  c.restore();
  page.drawn.gantt = n;
  G.dataset.bars = n.bars; G.dataset.violations = n.violations;
}
function bsearch(a, f) { let lo = 0, hi = a.length; while (lo < hi) { const m = (lo + hi) >> 1; if (f(a[m])) hi = m; else lo = m + 1; } return lo; }
function ganttHover(mx, my) {
  const vd = D.views[V], k = Math.floor((my - TOP) / ROWH);
  if (k < 0 || k >= NS || mx < LEFT) return null;
  const t = tx(mx), tol = 3 / PW * (VB - VA), sat = D.sats[k];
  if (vd.viol) for (const [kk, tv, text] of vd.viol) if (kk === k && tv !== null && Math.abs(tv - t) <= tol * 2) return 'violation: ' + text;
  if (vd.dl) for (const q of vd.dlBy[k]) if (vd.dl.st[q] - tol <= t && t <= vd.dl.en[q] + tol)
    return sat + ': download ' + vd.dl.id[q] + '\n' + fmt(vd.dl.st[q]) + ' to ' + fmt(vd.dl.en[q]) + ', ' +
      (vd.dl.en[q] - vd.dl.st[q]).toFixed(1) + ' s';
  const obs = vd.by[k];
  const j = bsearch(obs, i => vd.en[i] >= t - tol);
  for (let q = j; q < obs.length && vd.st[obs[q]] <= t + tol; q++) {
    const i = obs[q], ti = vd.task[i], tk = D.tasks;
    return sat + ': task ' + (ti >= 0 ? tk.id[ti] : '?') + (ti >= 0 ? ' (weight ' + tk.w[ti] + ')' : '') +
      '\n' + fmt(vd.st[i]) + ' to ' + fmt(vd.en[i]) + ', ' + (vd.en[i] - vd.st[i]).toFixed(1) + ' s' +
      (vd.slew && vd.slew[i] !== null ? '\nslew and settling ' + (vd.st[i] - vd.slew[i]).toFixed(1) + ' s before it' : '');
  }
  if (vd.slew) for (let q = Math.max(0, j - 1); q < Math.min(obs.length, j + 2); q++) {
    const i = obs[q]; if (vd.slew[i] !== null && vd.slew[i] <= t && t <= vd.st[i])
      return sat + ': slew and settling to task ' + D.tasks.id[vd.task[i]] + ', ' + (vd.st[i] - vd.slew[i]).toFixed(1) + ' s';
  }
  let s = sat + ' at ' + fmt(t);
  if (D.eclipses) {
    const e = D.eclipses[k]; let dark = false;
    for (let q = 0; q < e[0].length; q++) if (e[0][q] <= t && t < e[1][q]) { dark = true; s += '\neclipse ' + hms(e[0][q]) + ' to ' + hms(e[1][q]); }
    if (!dark) s += '\nsunlit';
  }
  if (vd.battery) {
    const b = vd.battery[k]; const q = Math.min(b[0].length - 1, bsearch(b[0], x => x >= t));
    s += '\nbattery about ' + num(b[1][q], 2) + ' of ' + D.capacity[k] + ' Wh';
  }
  return s;
}
page.barAt = function (i) {  // the viewport position of the middle of observation i of the drawn schedule
  const vd = D.views[V], r = G.getBoundingClientRect(), k = vd.sat[i];
  return {x: r.left + (gx(vd.st[i]) + gx(vd.en[i])) / 2, y: r.top + TOP + k * ROWH + ROWH * 0.4};
};
page.violationAt = function (j) {  // the viewport position of the mark of violation j of the drawn schedule
  const [k, t] = D.views[V].viol[j], r = G.getBoundingClientRect();
  return {x: r.left + gx(t), y: r.top + TOP + k * ROWH + ROWH / 2};
};

// ------------------------------------------------------------------ map
const M = document.getElementById('map');
const west = D.map.west;
const wl = lon => lon < west ? lon + 360 : lon;
let MX = null;
function drawMap() {
  const vd = D.views[V];
  const w = Math.max(700, M.parentElement.clientWidth || 1200);
  let [x0, x1] = D.map.x, [y0, y1] = D.map.y;
  let h = w * (y1 - y0) / (x1 - x0);
  // equal scales on both axes: a range too tall for the page is widened in longitude, one too flat in latitude
  if (h > 760) { const need = (y1 - y0) * w / 760, m = (x0 + x1) / 2; h = 760; x0 = m - need / 2; x1 = m + need / 2; }
  if (h < 320) { const need = (y1 - y0) * 320 / h, m = (y0 + y1) / 2; h = 320; y0 = m - need / 2; y1 = m + need / 2; }
  M.width = w; M.height = Math.round(h);
  const X = lon => (lon - x0) / (x1 - x0) * w, Y = lat => (y1 - lat) / (y1 - y0) * h;
  MX = {X, Y};
  const c = M.getContext('2d');
  c.fillStyle = '#f4f8fb'; c.fillRect(0, 0, w, h);
  c.strokeStyle = '#8a8a8a'; c.lineWidth = 0.8;
  const [cl, ca] = D.coast;
  for (const shift of [0, 360]) {
    c.beginPath(); let pen = false;
    for (let i = 0; i < cl.length; i++) {
      if (cl[i] === null) { pen = false; continue; }
      const x = X(cl[i] + shift), y = Y(ca[i]);
      if (pen) c.lineTo(x, y); else { c.moveTo(x, y); pen = true; }
    }
    c.stroke();
  }
  const n = {tracks: 0, track_points: 0, points: 0, observed: 0, missed: 0};
  if (D.tracks) {
    c.lineWidth = 1;
    D.tracks.forEach(([la, lo], k) => {
      c.strokeStyle = 'hsla(' + Math.round(k * 137.5 % 360) + ',60%,40%,' + (NS > 40 ? 0.12 : 0.45) + ')'; c.beginPath();
      let prev = null;
      for (let i = 0; i < la.length; i++) {
        const l = wl(lo[i]);
        if (prev === null || Math.abs(l - prev) > 180) c.moveTo(X(l), Y(la[i])); else c.lineTo(X(l), Y(la[i]));
        prev = l;
      }
      c.stroke(); n.tracks++; n.track_points += la.length;
    });
  }
  const r = NT > 5000 ? 1.6 : 3.2, tk = D.tasks;
  for (const pass of [0, 1]) {  // missed under observed
    c.fillStyle = pass ? '#2ca02c' : '#d62728';
    for (let t = 0; t < NT; t++) {
      if ((vd.served[t] >= 0) !== !!pass) continue;
      c.beginPath(); c.arc(X(wl(tk.lon[t])), Y(tk.lat[t]), r, 0, 6.2832); c.fill();
      n.points++; if (pass) n.observed++; else n.missed++;
    }
  }
  page.drawn.map = n;
}
function mapHover(mx, my) {
  if (!MX) return null;
  let best = -1, bd = 49;
  const tk = D.tasks;
  for (let t = 0; t < NT; t++) {
    const dx = MX.X(wl(tk.lon[t])) - mx, dy = MX.Y(tk.lat[t]) - my, d = dx * dx + dy * dy;
    if (d < bd) { bd = d; best = t; }
  }
  if (best < 0) return null;
  const st = statusText(best);
  return 'task ' + tk.id[best] + ' (weight ' + tk.w[best] + ', ' + tk.lat[best] + ', ' + tk.lon[best] + ')\n' +
    'window ' + fmt(tk.rel[best]) + ' to ' + fmt(tk.due[best]) + '\n' + st + (st === 'missed' ? ': ' + reasonText(best) : '');
}
page.taskAt = function (t) {
  const r = M.getBoundingClientRect();
  return {x: r.left + MX.X(wl(D.tasks.lon[t])), y: r.top + MX.Y(D.tasks.lat[t])};
};

// ------------------------------------------------------------------ tooltips
function hook(el, f) {
  el.addEventListener('mousemove', e => {
    const r = el.getBoundingClientRect(), s = f(e.clientX - r.left, e.clientY - r.top);
    if (!s) { tip.style.display = 'none'; return; }
    tip.textContent = s; tip.style.display = 'block';
    tip.style.left = Math.min(e.clientX + 14, window.innerWidth - 540) + 'px'; tip.style.top = (e.clientY + 14) + 'px';
  });
  el.addEventListener('mouseleave', () => { tip.style.display = 'none'; });
}
hook(G, ganttHover); hook(M, mapHover);
page.zoom = function (a, b) {  // show [a, b] seconds (clamped to the horizon, at least a minute); no args: all
  if (a === undefined) { VA = 0; VB = H; } else {
    a = Math.max(0, Math.min(a, b)); b = Math.min(H, Math.max(a + 60, b));
    VA = a; VB = b;
  }
  drawGantt(); return [VA, VB];
};
page.view = () => [VA, VB];
let drag = null;
G.addEventListener('mousedown', e => { const r = G.getBoundingClientRect(); if (e.clientX - r.left >= LEFT) drag = e.clientX - r.left; });
G.addEventListener('mouseup', e => {
  const r = G.getBoundingClientRect(), x = e.clientX - r.left;
  if (drag !== null && Math.abs(x - drag) > 5) page.zoom(tx(Math.min(x, drag)), tx(Math.max(x, drag)));
  drag = null;
});
G.addEventListener('dblclick', () => page.zoom());

// ------------------------------------------------------------------ task table
const PAGE = 200;
let sortKey = 'w', sortDir = -1, pageNo = 0;
const body = document.querySelector('#tasks tbody');
function keyOf(t, k) {
  const tk = D.tasks;
  if (k === 'id') return tk.id[t];
  if (k === 'w') return tk.w[t];
  if (k === 'rel') return tk.rel[t];
  if (k === 'status') return D.views[V].served[t] < 0 ? 'missed' : statusText(t);
  const i = reasonOf.get(t); return (V === 0 && R && i !== undefined) ? R.kind[i] : -1;
}
function drawTable() {
  const only = document.getElementById('only-missed').checked, vd = D.views[V], tk = D.tasks;
  let rows = [];
  for (let t = 0; t < NT; t++) if (!only || vd.served[t] < 0) rows.push(t);
  const keys = new Map(rows.map(t => [t, keyOf(t, sortKey)]));
  rows.sort((a, b) => { const x = keys.get(a), y = keys.get(b); return (x < y ? -1 : x > y ? 1 : a - b) * sortDir; });
  const pages = Math.max(1, Math.ceil(rows.length / PAGE));
  pageNo = Math.min(pageNo, pages - 1);
  const part = rows.slice(pageNo * PAGE, (pageNo + 1) * PAGE);
  body.innerHTML = part.map(t => {
    const missed = vd.served[t] < 0, i = reasonOf.get(t);
    const kind = (missed && V === 0 && R && i !== undefined) ? R.kinds[R.kind[i]] : '';
    return "<tr data-task='" + esc(tk.id[t]) + "' data-status='" + (missed ? 'missed' : 'observed') +
      "' data-kind='" + esc(kind) + "'><td>" + esc(tk.id[t]) + '</td><td>' + tk.w[t] + '</td><td>' +
      win(tk.rel[t]) + ' to ' + win(tk.due[t]) + '</td><td' + (missed ? " class='bad status'" : " class='status'") +
      '>' + esc(statusText(t)) + "</td><td class='reason'>" + (missed ? esc(reasonText(t)) : '') + '</td></tr>';
  }).join('');
  const pg = document.getElementById('pager');
  pg.innerHTML = 'rows ' + (rows.length ? pageNo * PAGE + 1 : 0) + ' to ' + (pageNo * PAGE + part.length) + ' of ' +
    rows.length + (pages > 1 ? " <button id='prev'>previous</button> <button id='next'>next</button>" : '');
  if (pages > 1) {
    document.getElementById('prev').onclick = () => { pageNo = Math.max(0, pageNo - 1); drawTable(); };
    document.getElementById('next').onclick = () => { pageNo = Math.min(pages - 1, pageNo + 1); drawTable(); };
  }
  document.getElementById('tasks-section').dataset.rows = rows.length;
}
document.querySelectorAll('#tasks th.sort').forEach(th => th.addEventListener('click', () => {
  const k = th.dataset.k; sortDir = (k === sortKey) ? -sortDir : 1; sortKey = k; pageNo = 0; drawTable();
}));
document.getElementById('only-missed').addEventListener('change', () => { pageNo = 0; drawTable(); });

// ------------------------------------------------------------------ summaries and differences
function drawSummaries() {
  const vd = D.views[V], tk = D.tasks;
  const busy = new Float64Array(NS), slew = new Float64Array(NS), wsum = new Float64Array(NS), cnt = new Int32Array(NS);
  for (let i = 0; i < vd.st.length; i++) {
    const k = vd.sat[i]; if (k < 0) continue;
    cnt[k]++; busy[k] += vd.en[i] - vd.st[i];
    if (vd.slew && vd.slew[i] !== null) slew[k] += vd.st[i] - vd.slew[i];
    if (vd.task[i] >= 0 && vd.served[vd.task[i]] === i) wsum[k] += tk.w[vd.task[i]];
  }
  let s = '<thead><tr><th>satellite</th><th>sensor</th><th>observations</th><th>weight observed</th><th>observing %</th>' +
    '<th>slewing %</th><th>lowest charge (Wh)</th><th>capacity (Wh)</th><th>in eclipse %</th></tr></thead><tbody>';
  for (let k = 0; k < NS; k++) {
    let dark = 0;
    if (D.eclipses) { const e = D.eclipses[k]; for (let q = 0; q < e[0].length; q++) dark += e[1][q] - e[0][q]; }
    s += "<tr data-sat='" + esc(D.sats[k]) + "'><td>" + esc(D.sats[k]) + '</td><td>' + esc(D.sensor[k]) + '</td><td>' +
      cnt[k] + '</td><td>' + +wsum[k].toFixed(4) + '</td><td>' + (100 * busy[k] / H).toFixed(2) + '</td><td>' +
      (vd.slew ? (100 * slew[k] / H).toFixed(2) : '-') + '</td><td>' + (vd.low ? num(vd.low[k], 2) : '-') + '</td><td>' +
      (D.capacity ? D.capacity[k] : '-') + '</td><td>' + (D.eclipses ? (100 * dark / H).toFixed(1) : '-') + '</td></tr>';
  }
  document.getElementById('per-sat').innerHTML = s + '</tbody>';
  const grp = D.groups ? D.groups.of : tk.w;  // per weight, or per group (ONERA: request kind)
  const ws = [...new Set(grp)].sort((a, b) => D.groups ? (a < b ? -1 : 1) : b - a), kinds = R ? R.kinds : [];
  let w = '<thead><tr><th>' + (D.groups ? esc(D.groups.name) : 'weight') + '</th><th>tasks</th><th>observed</th><th>missed</th>' +
    kinds.map(k => '<th>' + esc(k) + '</th>').join('') + '</tr></thead><tbody>';
  for (const x of ws) {
    let n = 0, o = 0; const byKind = new Array(kinds.length).fill(0);
    for (let t = 0; t < NT; t++) if (grp[t] === x) {
      n++; if (vd.served[t] >= 0) o++;
      else if (V === 0 && R) { const i = reasonOf.get(t); if (i !== undefined) byKind[R.kind[i]]++; }
    }
    w += "<tr data-weight='" + x + "'><td>" + x + '</td><td>' + n + '</td><td>' + o + '</td><td>' + (n - o) + '</td>' +
      byKind.map(v => '<td>' + (V === 0 ? v : '-') + '</td>').join('') + '</tr>';
  }
  document.getElementById('per-weight').innerHTML = w + '</tbody>';
  if (D.groups) document.getElementById('weight-section').previousElementSibling.textContent = 'Per ' + D.groups.name;
}
function drawDiff() {
  if (D.views.length < 2) return;
  const a = D.views[0], tk = D.tasks;
  let s = '<h2>What differs from ' + esc(a.label) + '</h2>';
  for (const b of D.views.slice(1)) {
    const onlyA = [], onlyB = [];
    for (let t = 0; t < NT; t++) {
      if (a.served[t] >= 0 && b.served[t] < 0) onlyA.push(t);
      if (b.served[t] >= 0 && a.served[t] < 0) onlyB.push(t);
    }
    const w = l => +l.reduce((x, t) => x + tk.w[t], 0).toFixed(4);
    const list = l => l.slice(0, 60).map(t => esc(tk.id[t])).join(', ') + (l.length > 60 ? ', ...' : '');
    let sats = [];
    for (let k = 0; k < NS; k++) { const d = b.by[k].length - a.by[k].length; if (d) sats.push(esc(D.sats[k]) + ' ' + (d > 0 ? '+' : '') + d); }
    s += "<div class='diffrow' data-b='" + esc(b.label) + "' data-only-a='" + onlyA.length + "' data-only-b='" + onlyB.length + "'>" +
      '<p><b>' + esc(b.label) + '</b>: ' + onlyA.length + ' task(s) only ' + esc(a.label) + ' observes (weight ' + w(onlyA) +
      '): ' + list(onlyA) + '<br>' + onlyB.length + ' task(s) only ' + esc(b.label) + ' observes (weight ' + w(onlyB) + '): ' +
      list(onlyB) + '<br>observations per satellite, ' + esc(b.label) + ' minus ' + esc(a.label) + ': ' +
      (sats.length ? sats.slice(0, 200).join(', ') : 'the same') + '</p></div>';
  }
  document.getElementById('diff').innerHTML = s;
}

// ------------------------------------------------------------------ wiring
const sel = document.getElementById('view');
sel.innerHTML = D.views.map((v, i) => "<option value='" + i + "'>" + esc(v.label) + '</option>').join('');
function drawAll() { drawGantt(); drawMap(); drawTable(); drawSummaries(); }
sel.addEventListener('change', () => { V = +sel.value; drawAll(); });
drawDiff(); drawAll();
page.ready = true; page.renderMs = performance.now() - T0;
document.body.dataset.ready = '1';
})();
