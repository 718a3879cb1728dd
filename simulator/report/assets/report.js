// vimsim study report: table sorting and filtering, the EPOF/opacity timeline (a classic
// script: it works from the file system too). The replay (assets/replay.js, an ES module)
// uses window.vimsimTimeline to move the cursor and to hear clicks.
"use strict";

(function () {
  // ---------------------------------------------------------------- the viewings table
  const table = document.querySelector("table.sortable");
  if (table) {
    const body = table.tBodies[0];
    const heads = Array.from(table.tHead.rows[0].cells);
    heads.forEach((th, i) => th.addEventListener("click", () => {
      const asc = !th.classList.contains("asc");
      heads.forEach((h) => h.classList.remove("asc", "desc"));
      th.classList.add(asc ? "asc" : "desc");
      const rows = Array.from(body.rows);
      const key = (r) => r.cells[i].textContent.trim();
      rows.sort((a, b) => {
        const x = key(a), y = key(b), nx = Number(x), ny = Number(y);
        const c = x !== "" && y !== "" && !isNaN(nx) && !isNaN(ny) ? nx - ny : x.localeCompare(y);
        return asc ? c : -c;
      });
      rows.forEach((r) => body.appendChild(r));
    }));
    const col = (name) => heads.findIndex((h) => h.textContent === name);
    const selects = Array.from(document.querySelectorAll("[data-filter]"));
    const texts = Array.from(document.querySelectorAll("[data-filter-text]"));
    const apply = () => {
      let n = 0;
      for (const r of body.rows) {
        let ok = selects.every((s) => !s.value || r.cells[col(s.dataset.filter)].textContent === s.value);
        ok = ok && texts.every((t) => !t.value || r.cells[col(t.dataset.filterText)].textContent.includes(t.value));
        r.hidden = !ok;
        n += ok;
      }
      const shown = document.getElementById("shown");
      if (shown) shown.textContent = `${n} of ${body.rows.length} shown`;
    };
    selects.forEach((s) => s.addEventListener("change", apply));
    texts.forEach((t) => t.addEventListener("input", apply));
    apply();
  }

  // ------------------------------------------------------------------- the timeline
  const dataEl = document.getElementById("viewing-data");
  const canvas = document.getElementById("timeline");
  if (!dataEl || !canvas) return;
  const data = JSON.parse(dataEl.textContent);
  // Columns arrive as base64 float32 little-endian (frame, time_s, yaw/pitch/roll_deg, epof_dps, opacity).
  const decode = (b64) => {
    const s = atob(b64), u = new Uint8Array(s.length);
    for (let i = 0; i < s.length; i++) u[i] = s.charCodeAt(i);
    return new Float32Array(u.buffer);
  };
  for (const k of Object.keys(data.columns)) data.columns[k] = decode(data.columns[k]);
  const c = data.columns;
  const n = c.time_s.length;
  const ctx = canvas.getContext("2d");
  const pad = { l: 40, r: 40, t: 10, b: 22 };
  const t0 = n ? c.time_s[0] : 0, t1 = n ? c.time_s[n - 1] : 1;
  let emax = 1e-6;
  for (const v of c.epof_dps) if (Number.isFinite(v) && v > emax) emax = v;
  const W = canvas.width, H = canvas.height, pw = W - pad.l - pad.r, ph = H - pad.t - pad.b;
  const X = (t) => pad.l + ((t - t0) / Math.max(t1 - t0, 1e-9)) * pw;
  const listeners = [];
  let cursor = null, extra = null;
  function line(vals, scale, color) {
    ctx.strokeStyle = color; ctx.lineWidth = 1.2; ctx.beginPath();
    const step = Math.max(1, Math.floor(n / (2 * pw)));
    for (let i = 0; i < n; i += step) {
      const y = pad.t + ph - (vals[i] / scale) * ph;
      i === 0 ? ctx.moveTo(X(c.time_s[i]), y) : ctx.lineTo(X(c.time_s[i]), y);
    }
    ctx.stroke();
  }
  function draw() {
    ctx.clearRect(0, 0, W, H);
    ctx.strokeStyle = "#ccc"; ctx.strokeRect(pad.l, pad.t, pw, ph);
    ctx.fillStyle = "#333"; ctx.font = "11px sans-serif";
    ctx.fillText(emax.toFixed(1), 2, pad.t + 10); ctx.fillText("0", 2, pad.t + ph);
    ctx.fillText("1", W - pad.r + 4, pad.t + 10);
    ctx.fillText(`${t0.toFixed(1)} s`, pad.l, H - 6); ctx.fillText(`${t1.toFixed(1)} s`, W - pad.r - 30, H - 6);
    line(c.epof_dps, emax, "#1f77b4");
    line(c.opacity, 1, "#ff7f0e");
    if (extra) {
      ctx.fillStyle = "#2a2"; ctx.beginPath();
      ctx.arc(X(extra.t), pad.t + ph - (extra.epof / emax) * ph, 4, 0, 2 * Math.PI); ctx.fill();
    }
    if (cursor !== null) {
      ctx.strokeStyle = "#c00"; ctx.beginPath(); ctx.moveTo(X(cursor), pad.t); ctx.lineTo(X(cursor), pad.t + ph); ctx.stroke();
    }
  }
  canvas.addEventListener("click", (e) => {
    const r = canvas.getBoundingClientRect();
    const x = ((e.clientX - r.left) / r.width) * W;
    const t = Math.min(t1, Math.max(t0, t0 + ((x - pad.l) / pw) * (t1 - t0)));
    cursor = t; draw();
    listeners.forEach((f) => f(t));
  });
  draw();
  window.vimsimTimeline = {
    data,
    setCursor(t, live) { cursor = t; extra = live || null; draw(); },
    onSeek(f) { listeners.push(f); },
  };
  const note = document.getElementById("replay-note");
  if (note && location.protocol === "file:") {
    note.textContent = "The replay needs the report served over http (browsers treat a video as a " +
      "cross-origin WebGL texture and block the runtime's data under file://): run " +
      "`vimsim report OUTDIR --serve` and open the address it prints.";
  }
})();
