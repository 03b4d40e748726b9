// The replay page of a simulated day (eosp.evaluation.replay_page): a timeline per satellite, the contacts table,
// the urgent requests.  Reads its data from the JSON block #replay-data; fetches nothing.
(function () {
  "use strict";
  const D = JSON.parse(document.getElementById("replay-data").textContent);
  const t0 = Date.parse(D.start);
  const utc = (s) => new Date(t0 + s * 1000).toISOString().replace("T", " ").slice(0, 19) + " UTC";
  const hours = (s) => (s / 3600).toFixed(2);
  const NS = "http://www.w3.org/2000/svg";
  const el = (tag, attrs, parent) => {
    const e = document.createElementNS(NS, tag);
    for (const k in attrs) e.setAttribute(k, attrs[k]);
    if (parent) parent.appendChild(e);
    return e;
  };
  const drawn = { contacts: 0, uploads: 0, acquisitions: 0, served: 0, cloudy: 0, alternates: 0 };

  // the timeline: one row per satellite
  const svg = document.getElementById("timeline");
  const left = 110, width = 1200, rowH = 16, n = D.sats.length;
  svg.setAttribute("width", left + width + 10);
  svg.setAttribute("height", n * rowH + 24);
  const x = (s) => left + (s / D.horizon) * width;
  for (let h = 0; h <= D.horizon / 3600; h += 1) {
    el("line", { x1: x(h * 3600), x2: x(h * 3600), y1: 0, y2: n * rowH, stroke: "#eee" }, svg);
    const lab = el("text", { x: x(h * 3600), y: n * rowH + 14, "font-size": 10, "text-anchor": "middle" }, svg);
    lab.textContent = h + " h";
  }
  D.sats.forEach((name, k) => {
    const y = k * rowH;
    const lab = el("text", { x: 4, y: y + 12, "font-size": 10 }, svg);
    lab.textContent = name;
    for (const [a, b] of D.contacts[k]) {
      const r = el("rect", { x: x(a), y: y + 1, width: Math.max(1, x(b) - x(a)), height: rowH - 2, fill: "#ddd" }, svg);
      el("title", {}, r).textContent = `contact ${utc(a)} to ${utc(b)}`;
      drawn.contacts++;
    }
    for (const up of D.uploads) {
      const at = up.at[k];
      if (at === null) continue;
      const m = el("path", { d: `M${x(at)},${y + 1} l4,6 l-8,0 z`, fill: "#f90", class: "upload" }, svg);
      el("title", {}, m).textContent = `plan of the call at ${utc(up.t)} uploaded at ${utc(at)}`;
      drawn.uploads++;
    }
  });
  const A = D.acq;
  for (let i = 0; i < A.sat.length; i++) {
    const y = A.sat[i] * rowH;
    const color = A.alt[i] ? "#36c" : A.ok[i] ? "#2a2" : "#d33";
    const r = el("rect", { x: x(A.start[i]), y: y + 3, width: Math.max(2, x(A.end[i]) - x(A.start[i])),
                           height: rowH - 6, fill: color, class: "acq" }, svg);
    const rep = A.report[i] === null ? "never reported" : `reported ${utc(A.report[i])}`;
    el("title", {}, r).textContent = `${D.sats[A.sat[i]]}: task ${A.task[i]} at ${utc(A.start[i])}: ` +
      `${A.ok[i] ? "served" : "found cloudy"}${A.alt[i] ? " (an alternate)" : ""}, ${rep}`;
    drawn.acquisitions++;
    if (A.ok[i]) drawn.served++; else drawn.cloudy++;
    if (A.alt[i]) drawn.alternates++;
  }

  // per contact: what was reported there, whether a plan reached the satellite
  const table = document.getElementById("contacts");
  table.innerHTML = "<tr><th class='l'>satellite</th><th class='l'>contact (UTC)</th><th>reported</th>" +
    "<th>served</th><th>found cloudy</th><th>alternates</th><th class='l'>plan uploaded</th></tr>";
  let contactRows = 0;
  D.sats.forEach((name, k) => {
    for (const [a, b] of D.contacts[k]) {
      let rep = 0, ok = 0, bad = 0, alt = 0;
      for (let i = 0; i < A.sat.length; i++) {
        if (A.sat[i] !== k || A.report[i] === null || A.report[i] < a || A.report[i] > b) continue;
        rep++; if (A.ok[i]) ok++; else bad++; if (A.alt[i]) alt++;
      }
      const ups = D.uploads.filter((u) => u.at[k] !== null && u.at[k] >= a && u.at[k] <= b);
      if (!rep && !ups.length) continue;
      const tr = table.insertRow();
      tr.className = "contact";
      tr.innerHTML = `<td class='l'>${name}</td><td class='l'>${utc(a)}</td><td>${rep}</td><td>${ok}</td>` +
        `<td>${bad}</td><td>${alt}</td><td class='l'>${ups.map((u) => "call at " + hours(u.t) + " h").join(", ")}</td>`;
      contactRows++;
    }
  });

  // urgent requests: arrival, service, or never
  const ut = document.getElementById("urgent");
  ut.innerHTML = "<tr><th class='l'>request</th><th>weight</th><th class='l'>arrived (UTC)</th>" +
    "<th class='l'>served (UTC)</th><th>hours after arrival</th><th>tries</th></tr>";
  let late = 0, never = 0;
  for (const u of D.urgent) {
    const tr = ut.insertRow();
    tr.className = "request";
    const served = u.served === null ? (u.tries ? "never (tried)" : "never (not tried)") : utc(u.served);
    if (u.served === null) never++; else late++;
    tr.innerHTML = `<td class='l'>${u.id}</td><td>${u.weight}</td><td class='l'>${utc(u.arrival)}</td>` +
      `<td class='l'>${served}</td><td>${u.served === null ? "-" : hours(u.served - u.arrival)}</td><td>${u.tries}</td>`;
  }
  const c = D.catalogue;
  document.getElementById("catalogue").textContent = `${c.served} of ${c.tasks} catalogue requests served; ` +
    `${c.tried_never_served} tried and never served (clouds).`;
  window.replay = { ready: true, drawn, contactRows, urgentServed: late, urgentNever: never };
})();
