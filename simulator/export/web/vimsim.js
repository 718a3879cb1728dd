// vimsim export: vimsim.js, the EPOF runtime for web players (ES module, no dependencies).
// Written by `vimsim export GRID.npz -o DIR --format web`; docs/web.md in vimsim.
//
//   import { loadExport } from "./vimsim.js";
//   const rt = await loadExport("./");                 // DIR/vimsim_web.json and its .bin files
//   const epof = rt.epof(videoTimeS, yawDeg, pitchDeg, rollDeg);   // deg/s, as `vimsim epof`;
//                                                     // NaN outside the exported range
//   const op = rt.opacity(epof);                      // GRF opacity 0..1 (the linear rule)
//   const ease = rt.createEasing();                   // once; then per video frame:
//   const shown = ease.step(op);                      // the exported rule (default: comfort)
//   const grains = rt.grains;                          // the grain layout stored in the file
//   const mitigation = rt.mitigation;                  // what to draw (EyeRenderer's option)
//
// Conventions, exactly as vimsim: angles in degrees; yaw + turns right, pitch + looks up,
// roll + tilts the head right ear down, applied yaw, then pitch, then roll (intrinsic);
// world +x right, +y up, +z forward (the centre of the equirect frame). A time is seconds
// from the video start; it shows frame floor(time * fps + 1e-6) (a variable-rate video: the last
// of header.frame_times_s at or before it, rt.frameTimes); the export covers the frames
// range.start_frame .. range.end_frame - 1 of a source of source.n_frames frames: rt.covers(t)
// tells, rt.epof(t, ...) is NaN outside (one console warning), as the C# runtime's Epof.
// Paper mode reads the overlap table vimsim computed (vimsim_overlaps.bin: the table of
// simulator.epof.overlaps.ViewportOverlaps) and interpolates it as vimsim does; sphere mode
// integrates the field over the viewport as simulator.epof.exact.ViewportQuery (weights per
// 0.5 deg bin of pitch, roll and yaw within a cell, cached).

export const FORMAT = "vimsim-epof";
/** The vimsim_epof.bin format read here (3: grain layout, GRF and vignette settings, source
 * length and exported range in the file; 4: a variable-rate video's frame times; 5: coverage
 * and initial orientation; older files are refused: export again). */
export const VERSION = 5;
/** The vimsim_web.json version read here. */
export const MANIFEST_VERSION = 2;
export const FRAME_EPS = 1e-6;
const MAGIC = "VIMSIMEP";
const D2R = Math.PI / 180;

import { GrainLayout, Pcg64, roundEven } from "./vimsim_grains.js";

export { GrainLayout, Pcg64, roundEven };

/** Python's a % b (the sign of the divisor). */
export function pymod(a, b) {
  const m = a % b;
  return m !== 0 && (m < 0) !== (b < 0) ? m + b : m;
}

/** Head -> world rotation R = Ry(yaw) Rx(-pitch) Rz(-roll), row-major 3x3, from degrees
 * (simulator.sphere.geometry.head_rotation). Column 2 is the view axis. */
export function headRotation(yawDeg, pitchDeg, rollDeg) {
  const a = yawDeg * D2R, b = -pitchDeg * D2R, g = -rollDeg * D2R;
  const ca = Math.cos(a), sa = Math.sin(a), cb = Math.cos(b), sb = Math.sin(b);
  const cg = Math.cos(g), sg = Math.sin(g);
  // Ry(a) Rx(b)
  const m = [ca, sa * sb, sa * cb, 0, cb, -sb, -sa, ca * sb, ca * cb];
  // (Ry Rx) Rz(g)
  return [
    m[0] * cg + m[1] * sg, -m[0] * sg + m[1] * cg, m[2],
    m[3] * cg + m[4] * sg, -m[3] * sg + m[4] * cg, m[5],
    m[6] * cg + m[7] * sg, -m[6] * sg + m[7] * cg, m[8],
  ];
}

/** yaw, pitch (in [-90, 90]), roll in degrees of a head -> world matrix (row-major). */
export function headAngles(R) {
  const pitch = Math.asin(Math.max(-1, Math.min(1, R[5]))) / D2R;
  let yaw, roll;
  if (Math.abs(R[5]) < 1 - 1e-12) {
    yaw = Math.atan2(R[2], R[8]) / D2R;
    roll = Math.atan2(-R[3], R[4]) / D2R;
  } else {
    yaw = Math.atan2(-R[6], R[0]) / D2R;
    roll = 0;
  }
  return [yaw, pitch, roll];
}

/** vimsim yaw, pitch, roll (degrees) of a head orientation given as a quaternion {x, y, z, w}
 * in a frame that looks along -z with +y up (three.js cameras, WebXR poses), the video's
 * centre placed at that frame's -z: yaw = -Y, pitch = X, roll = -Z of its YXZ Euler angles
 * (THREE.Euler order "YXZ"). */
export function anglesFromQuaternion(q) {
  const { x, y, z, w } = q;
  const ey = Math.atan2(2 * (x * z + w * y), 1 - 2 * (x * x + y * y));
  const ex = Math.asin(Math.max(-1, Math.min(1, 2 * (w * x - y * z))));
  const ez = Math.atan2(2 * (x * y + w * z), 1 - 2 * (x * x + z * z));
  return [-ey / D2R, ex / D2R, -ez / D2R];
}

function halfToFloat(h) {
  const s = h & 0x8000 ? -1 : 1, e = (h >> 10) & 0x1f, m = h & 0x3ff;
  if (e === 0) return s * m * 2 ** -24;
  if (e === 31) return m ? NaN : s * Infinity;
  return s * (1 + m / 1024) * 2 ** (e - 15);
}

let HALF = null; // binary16 -> float32 for all 65536 bit patterns

function headerError(name, field, problem) {
  return new Error(`${name}: export header field ${field}: ${problem}; export again with vimsim export`);
}

/** The header checks of simulator.export.unity.binary (check_mitigation_header, range):
 * throws Error naming the file and the field. */
function checkHeader(h, name) {
  const { grf, vignette: vig, grains: g, range: r, source } = h;
  if (!grf || !vig || !g || !Array.isArray(g.shape)) throw headerError(name, "grf/vignette/grains", "missing or malformed");
  if (!r || !source) throw headerError(name, "range/source", "missing");
  if (!(grf.density > 0 && grf.density < 1)) throw headerError(name, "grf.density", `${grf.density} is not a blocked fraction in (0, 1)`);
  if (!(grf.inner_deg >= 0 && grf.inner_deg < grf.outer_deg && grf.outer_deg <= 180))
    throw headerError(name, "grf.inner_deg/outer_deg", `cutout radii ${grf.inner_deg}, ${grf.outer_deg} are not 0 <= inner < outer <= 180`);
  if (!(grf.grain_deg > 0 && grf.grain_deg <= 30)) throw headerError(name, "grf.grain_deg", `${grf.grain_deg} is not degrees in (0, 30]`);
  if (!(vig.aperture_min_deg > 0 && vig.aperture_min_deg < 180 && vig.feather_deg >= 0 && vig.feather_deg <= 180))
    throw headerError(name, "vignette", `aperture ${vig.aperture_min_deg} / feather ${vig.feather_deg} deg out of range`);
  if (g.shape.length !== 2 || g.shape[0] !== grf.n_grains || g.shape[1] !== 3 || g.dtype !== "float32")
    throw headerError(name, "grains", `a layout of shape [${g.shape}] for grf.n_grains = ${grf.n_grains}`);
  if (!(r.start_frame === h.start_frame && r.end_frame === h.start_frame + h.n_frames))
    throw headerError(name, "range", `frames ${r.start_frame}..${r.end_frame} are not the data's ${h.start_frame} + ${h.n_frames}`);
  const ft = h.frame_times_s;
  if (ft !== undefined && !(Array.isArray(ft) && ft.length === h.n_frames && r.end_s > ft[ft.length - 1] &&
      ft.every((t, i) => Number.isFinite(t) && (i === 0 || t > ft[i - 1]))))
    throw headerError(name, "frame_times_s", `expected ${h.n_frames} increasing times before range.end_s`);
}

/** Parse vimsim_epof.bin (format 5): {header, values (Uint16Array of binary16 or Float32Array,
 * C order), grains (Float32Array, n_grains x 3)}, views of the buffer (no copy). Throws Error
 * naming the file and the problem (an older format: export again). */
export function parseEpofBinary(buffer, name = "vimsim_epof.bin") {
  const b = new Uint8Array(buffer);
  if (b.length < 16 || String.fromCharCode(...b.subarray(0, 8)) !== MAGIC)
    throw new Error(`${name}: not a vimsim export (no VIMSIMEP signature)`);
  const dv = new DataView(buffer);
  const version = dv.getUint32(8, true), hlen = dv.getUint32(12, true);
  if (version < VERSION)
    throw new Error(`${name}: export format version ${version}, made by an older vimsim (no grain layout, ` +
      `range, source length, variable-rate frame times, coverage or orientation); export again with vimsim export (version ${VERSION})`);
  if (version !== VERSION) throw new Error(`${name}: export format version ${version}; this runtime reads version ${VERSION}`);
  if (16 + hlen > b.length) throw new Error(`${name}: truncated header`);
  const header = JSON.parse(new TextDecoder().decode(b.subarray(16, 16 + hlen)));
  if (header.format !== FORMAT || header.version !== version)
    throw new Error(`${name}: export format ${header.format} version ${header.version} is not readable here`);
  checkHeader(header, name);
  const d = header.data, n = d.shape.reduce((x, y) => x * y, 1), off = d.offset;
  const size = d.dtype === "float16" ? 2 : 4, gOff = header.grains.offset, nG = header.grf.n_grains;
  if (off + n * size > gOff || gOff % 16 !== 0) throw new Error(`${name}: truncated data or misplaced grain layout`);
  if (gOff + 12 * nG !== b.length) throw new Error(`${name}: truncated or padded grain layout`);
  // Little-endian typed arrays (every browser's platform); the offsets are multiples of 16.
  const values = d.dtype === "float16" ? new Uint16Array(buffer, off, n) : new Float32Array(buffer, off, n);
  return { header, values, grains: new Float32Array(buffer, gOff, 3 * nG) };
}

function halfTable() {
  if (!HALF) {
    HALF = new Float32Array(65536);
    for (let i = 0; i < 65536; i++) HALF[i] = halfToFloat(i);
  }
  return HALF;
}

// ------------------------------------------------------------------ opacity

/** The opacity easing of vimsim's OpacityRule (causal, starts at the first value): per
 * video frame v += a (x - v), a = 1 - exp(-1 / (fps S)) (S > 0), then the change of the
 * shown value is limited to +1 / (fps easeIn) and -1 / (fps easeOut) (0 = no limit). */
export class OpacityEasing {
  constructor(smoothingS, fps, easeInS = 0, easeOutS = 0) {
    this.S = smoothingS; this.fps = fps; this.easeIn = easeInS; this.easeOut = easeOutS;
    this.reset();
  }
  reset() { this.started = false; this.smooth = 0; this.value = 0; }
  /** Advance one video frame towards opacity x; returns the eased value. */
  step(x) { return this.update(x, 1 / this.fps); }
  /** Advance dt seconds towards opacity x (render frames of any length). NaN (a time
   * outside the export) returns NaN and restarts the easing at the next number. */
  update(x, dt) {
    if (Number.isNaN(x)) { this.reset(); return NaN; }
    if (!this.started) { this.started = true; this.smooth = x; this.value = x; return x; }
    if (this.S > 0) this.smooth += (1 - Math.exp(-dt / this.S)) * (x - this.smooth);
    else this.smooth = x;
    const d = this.smooth - this.value;
    const up = this.easeIn > 0 ? dt / this.easeIn : Infinity;
    const down = this.easeOut > 0 ? dt / this.easeOut : Infinity;
    this.value += d > 0 ? Math.min(d, up) : Math.max(d, -down);
    return this.value;
  }
}

// --------------------------------------------------------------- paper mode

class PaperModel {
  constructor(header, ov, table) {
    const g = header.grid;
    this.P = g.pitch_deg.length; this.Y = g.yaw_deg.length;
    this.table = table;
    this.pitchGrid = ov.pitch_grid; this.rollGrid = ov.roll_grid;
    this.nP = ov.pitch_grid.length; this.nR = ov.roll_grid.length; this.nU = ov.n_u;
    this.step = ov.step_deg; this.yawStart = ov.yaw_start_deg;
    this.dp = this.pitchGrid[1] - this.pitchGrid[0];
    this.dr = this.rollGrid[1] - this.rollGrid[0];
    this.centres = ov.centres; // P*Y*3 window centre directions
    const nr = this.nR, nu = this.nU + 1;
    this.corner = [];
    for (const a of [0, 1]) for (const b of [0, 1]) for (const c of [0, 1]) this.corner.push(a * nr * nu + b * nu + c);
    this.ol = new Float64Array(this.P * this.Y);
    this.w32 = new Float32Array(8);
  }
  query(data, off, yaw, pitch, roll) {
    if (pitch > 90 || pitch < -90) [yaw, pitch, roll] = headAngles(headRotation(yaw, pitch, roll));
    roll = pymod(roll + 180, 360) - 180;
    const { P, Y, nP, nR, nU, table, ol, w32 } = this;
    const fp = (pitch + 90) / this.dp;
    const i0 = Math.min(Math.max(Math.floor(fp), 0), nP - 2), wp = fp - i0;
    const fr = (roll + 180) / this.dr;
    const j0 = Math.min(Math.max(Math.floor(fr), 0), nR - 2), wr = fr - j0;
    const a = (yaw - this.yawStart) / this.step, kf = Math.floor(a);
    const fu = (a - kf) * nU;
    const u0 = Math.min(Math.max(Math.floor(fu), 0), nU - 1), wu = fu - u0;
    const k = pymod(kf, Y), PY = P * Y, base = (i0 * nR + j0) * (nU + 1) + u0;
    let c = 0;
    for (const ap of [1 - wp, wp]) for (const ar of [1 - wr, wr]) for (const au of [1 - wu, wu]) w32[c++] = ap * ar * au;
    ol.fill(0);
    for (c = 0; c < 8; c++) {
      const w = w32[c];
      if (w === 0) continue;
      const o = (base + this.corner[c]) * PY;
      for (let q = 0; q < PY; q++) ol[q] += w * table[o + q];
    }
    let num = 0, den = 0;
    for (let p = 0; p < P; p++) {
      const rowOff = off + p * Y, po = p * Y;
      for (let m = 0; m < Y; m++) {
        let col = k - m; if (col < 0) col += Y;
        const w = Math.fround(ol[po + m]);
        num += w * data[rowOff + col];
        den += w;
      }
    }
    if (den > 1e-6) return num / den;
    const R = headRotation(yaw, pitch, roll); // outside every window: the nearest window
    let best = -Infinity, near = 0;
    for (let q = 0; q < PY; q++) {
      const d = R[2] * this.centres[3 * q] + R[5] * this.centres[3 * q + 1] + R[8] * this.centres[3 * q + 2];
      if (d > best) { best = d; near = q; }
    }
    return data[off + near];
  }
}

// -------------------------------------------------------------- sphere mode

class SphereModel {
  constructor(header) {
    const f = header.field, v = header.viewport;
    this.cellDeg = f.cell_deg; this.nLat = f.n_lat; this.nLon = f.n_lon;
    this.st = f.query_step_deg; this.nSub = roundEven(f.cell_deg / f.query_step_deg);
    this.cacheSize = f.cache_bins || 1024;
    const c = f.cell_deg * D2R; this.c = c;
    const lf = (v.hfov_deg / 2) * D2R, up = (v.vfov_deg / 2) * D2R;
    this.normals = [[Math.cos(lf), 0, Math.sin(lf)], [-Math.cos(lf), 0, Math.sin(lf)],
      [0, Math.cos(up), Math.sin(up)], [0, -Math.cos(up), Math.sin(up)]];
    this.radius = Math.atan(Math.hypot(Math.tan(lf), Math.tan(up))) + c;
    this.rowCl = new Float64Array(this.nLat); this.rowSl = new Float64Array(this.nLat);
    this.rowHe = new Float64Array(this.nLat); this.rowSa = new Float64Array(this.nLat);
    for (let i = 0; i < this.nLat; i++) {
      const lat = Math.PI / 2 - (i + 0.5) * c;
      this.rowCl[i] = Math.cos(lat); this.rowSl[i] = Math.sin(lat);
      this.rowHe[i] = 0.5 * c * Math.max(this.rowCl[i], Math.abs(Math.cos(lat - Math.sign(lat) * c / 2)));
      this.rowSa[i] = c * (Math.sin(lat + c / 2) - Math.sin(lat - c / 2));
    }
    this.colSin = new Float64Array(this.nLon); this.colCos = new Float64Array(this.nLon);
    for (let j = 0; j < this.nLon; j++) {
      const lon = -Math.PI + (j + 0.5) * c;
      this.colSin[j] = Math.sin(lon); this.colCos[j] = Math.cos(lon);
    }
    this.bins = new Map();
  }
  bin(ip, ir, isub) {
    const key = (ip * 4096 + ir) * 64 + isub;
    let b = this.bins.get(key);
    if (b) return b;
    const st = this.st, R = headRotation(isub * st, ip * st, ir * st);
    const nw = new Float64Array(12);
    for (let k = 0; k < 4; k++) {
      const n = this.normals[k];
      for (let i = 0; i < 3; i++) nw[3 * k + i] = R[3 * i] * n[0] + R[3 * i + 1] * n[1] + R[3 * i + 2] * n[2];
    }
    const axisLat = Math.asin(Math.max(-1, Math.min(1, R[5]))), axisLon = Math.atan2(R[2], R[8]);
    const c = this.c, nLon = this.nLon, nLat = this.nLat;
    const i0 = Math.max(0, Math.floor((Math.PI / 2 - axisLat - this.radius) / c));
    const i1 = Math.min(nLat, Math.floor((Math.PI / 2 - axisLat + this.radius) / c) + 1);
    // Per row, only the columns within the viewport's radius (+ a cell) of its axis can weigh
    // anything (every other cell lies outside a frustum plane: weight exactly 0, as in vimsim).
    const cosR = Math.cos(Math.min(Math.PI, this.radius + c));
    const sa0 = Math.sin(axisLat), ca0 = Math.cos(axisLat);
    if (!this.scratch) this.scratch = { rows: new Int32Array(nLat * nLon), cols: new Int32Array(nLat * nLon), w: new Float64Array(nLat * nLon) };
    const { rows, cols, w } = this.scratch;
    const { colSin, colCos, rowCl, rowSl, rowHe, rowSa } = this, hn = 0.5 * c;
    // Per cell and plane (n = world normal): with so, co = sin, cos of the cell's longitude,
    // cl, sl of its latitude, A = nx so + nz co: d = n . centre = cl A + ny sl, and the half
    // extent hw = |he (nx co - nz so)| + |hn (ny cl - sl A)| + 1e-9 (simulator.sphere.cells).
    let cnt = 0, wmax = 0;
    for (let i = i0; i < i1; i++) {
      const cl = rowCl[i], sl = rowSl[i], he = rowHe[i], area = rowSa[i], den = cl * ca0;
      const x = den > 1e-12 ? (cosR - sl * sa0) / den : -2;
      if (x > 1) continue;
      let jA = 0, jB = nLon - 1;
      if (x > -1) {
        const half = Math.acos(x) + c;
        jA = Math.floor((axisLon - half + Math.PI) / c); jB = Math.ceil((axisLon + half + Math.PI) / c);
        if (jB - jA + 1 >= nLon) { jA = 0; jB = nLon - 1; }
      }
      for (let jj = jA; jj <= jB; jj++) {
        const j = jj < 0 ? jj + nLon : jj >= nLon ? jj - nLon : jj, so = colSin[j], co = colCos[j];
        let cov = 1;
        for (let k = 0; k < 12; k += 3) {
          const nx = nw[k], ny = nw[k + 1], nz = nw[k + 2], A = nx * so + nz * co;
          const d = cl * A + ny * sl;
          const hw = Math.abs(he * (nx * co - nz * so)) + Math.abs(hn * (ny * cl - sl * A)) + 1e-9;
          const f = 0.5 + (0.5 * d) / hw;
          if (f <= 0) { cov = 0; break; }
          if (f < 1) cov *= f;
        }
        if (cov === 0) continue;
        const v = cov * area;
        rows[cnt] = i * nLon; cols[cnt] = j; w[cnt] = v; cnt++;
        if (v > wmax) wmax = v;
      }
    }
    let m = 0, wsum = 0;
    for (let q = 0; q < cnt; q++) {
      if (w[q] > wmax * 1e-7) { rows[m] = rows[q]; cols[m] = cols[q]; w[m] = w[q]; wsum += w[q]; m++; }
    }
    b = { rows: rows.slice(0, m), cols: cols.slice(0, m), w: w.slice(0, m), wsum };
    if (this.bins.size >= this.cacheSize) this.bins.delete(this.bins.keys().next().value);
    this.bins.set(key, b);
    return b;
  }
  query(data, off, yaw, pitch, roll) {
    const st = this.st, M = this.nLon * this.nSub;
    const y = pymod(roundEven(yaw / st), M);
    const shift = Math.floor(y / this.nSub), sub = y % this.nSub;
    const ip = roundEven(Math.max(-90, Math.min(90, pitch)) / st);
    const ir = roundEven((pymod(roll + 180, 360) - 180) / st);
    const b = this.bin(ip, ir, sub), nLon = this.nLon;
    let s = 0;
    for (let q = 0, n = b.w.length; q < n; q++) {
      let col = b.cols[q] + shift;
      if (col >= nLon) col -= nLon;
      s += data[off + b.rows[q] + col] * b.w[q];
    }
    return s / b.wsum;
  }
}

// ----------------------------------------------------------------- runtime

/** EPOF (deg/s) and GRF opacity of a viewport at a video time, from a vimsim export. */
export class VimsimEpof {
  constructor(manifest, epofBin, overlapsBin = null) {
    const { header, values, grains } = parseEpofBinary(epofBin, manifest.data || "vimsim_epof.bin");
    this.manifest = manifest;
    this.header = header;
    this.values = values; // the file's data, undecoded: memory = the file's size
    this.half = values instanceof Uint16Array ? halfTable() : null;
    this.mode = header.mode;
    this.fps = header.fps;
    this.startFrame = header.start_frame;
    this.frameCount = header.n_frames;
    this.hfovDeg = header.viewport.hfov_deg;
    this.vfovDeg = header.viewport.vfov_deg;
    const o = header.opacity;
    this.lowDps = o.low_dps; this.highDps = o.high_dps;
    // the opacity rule's name ("absolute", the default: fixed deg/s; "paper", "comfort":
    // percentiles of this video's flow) and its scale ("absolute" or "relative")
    this.opacityRule = o.name; this.opacityScale = o.scale;
    this.rowLength = header.data.shape[1] * header.data.shape[2];
    this.rowBuf = new Float32Array(this.rowLength); // the frame last queried, as float32
    this.rowOf = -1;
    if (this.mode === "paper") {
      if (!overlapsBin) throw new Error("paper mode needs vimsim_overlaps.bin");
      const ov = manifest.overlaps, n = ov.shape.reduce((x, y) => x * y, 1);
      if (overlapsBin.byteLength !== 16 + 4 * n) throw new Error("vimsim_overlaps.bin: truncated or padded");
      const table = new Float32Array(overlapsBin, 16, n);
      this.model = new PaperModel(header, ov, table);
    } else {
      this.model = new SphereModel(header);
    }
    const r = header.range, src = header.source, v = header.vignette;
    /** The exported frames (endFrame exclusive) and their times (s). */
    this.range = { startFrame: r.start_frame, endFrame: r.end_frame, startS: r.start_s, endS: r.end_s };
    /** A variable-rate video's frame times (s, one per exported frame), else null. */
    this.frameTimes = header.frame_times_s ? Float64Array.from(header.frame_times_s) : null;
    /** The source video's length (known: from the grid's meta; else the grid's end). */
    this.source = { nFrames: src.n_frames, durationS: src.duration_s, known: src.known };
    /** The file's initial orientation (yaw, pitch, roll degrees; its spherical metadata), or
     * null (C#: OrientationDeg); its head -> video rotation, `pose`: see viewAngles. */
    this.orientationDeg = src.orientation_deg ? src.orientation_deg.slice() : null;
    /** A source covering only part of the sphere (VR180): its covered cells (1/0, the data's row
     * layout) and the fade threshold; epof() is then the covered part's mean (C#: PartialCoverage). */
    this.coverMask = header.coverage ? Float32Array.from(header.coverage.cells) : null;
    this.minCoverage = header.coverage ? header.coverage.min_coverage : 0;
    this.pose = src.orientation_deg ? headRotation(...src.orientation_deg) : null;
    /** Whether epof() and viewAngles() turn head angles by it (default true: head angles as in a
     * vimsim head path; false when they already are in the video's frame: C# ApplyOrientation). */
    this.applyOrientation = true;
    /** The grain layout stored in the file (the renderer's, float32 centres). */
    this.grains = GrainLayout.fromExport(header, grains);
    /** What the overlay draws, as the export was made (EyeRenderer's `mitigation` option). */
    this.mitigation = { kind: header.mitigation, apertureMinDeg: v.aperture_min_deg,
      featherDeg: v.feather_deg, color: v.color.slice() };
    this.outOfRange = false; // the last epof() time was outside the export
    this.warned = false;
  }
  /** Video frame shown at a time (s from the video start), clamped to the exported frames. */
  frameAt(timeS) {
    const f = this.frameOf(timeS), s = this.startFrame;
    return Math.min(Math.max(f, s), s + this.frameCount - 1);
  }
  /** The video frame shown at a finite time (s): floor(t * fps + 1e-6), or for a variable-rate
   * export the last of frameTimes at or before t (tolerance 1e-6 / fps s): startFrame - 1
   * before the first, range.endFrame from range.endS on (C#: FrameOf). */
  frameOf(timeS) {
    const ft = this.frameTimes;
    if (!ft) return Math.floor(timeS * this.fps + FRAME_EPS);
    const t = timeS + FRAME_EPS / this.fps;
    if (t >= this.range.endS) return this.startFrame + this.frameCount;
    let lo = 0, hi = ft.length; // the first index with a time > t
    while (lo < hi) { const mid = (lo + hi) >> 1; if (ft[mid] <= t) lo = mid + 1; else hi = mid; }
    return this.startFrame + lo - 1;
  }
  /** The time (s) frame `frame` starts (frame / fps, or its frame_times_s entry). */
  frameTime(frame) {
    const ft = this.frameTimes;
    if (!ft) return frame / this.fps;
    return ft[Math.min(Math.max(frame - this.startFrame, 0), ft.length - 1)];
  }
  /** Whether the export has the frame shown at a time (s): range.startFrame <=
   * frameOf(t) < range.endFrame; false for NaN or infinite (C#: Covers). */
  covers(timeS) {
    return Number.isFinite(timeS) && this.coversFrame(this.frameOf(timeS));
  }
  /** Whether the export has a video frame (C#: CoversFrame). */
  coversFrame(frame) {
    return frame >= this.range.startFrame && frame < this.range.endFrame;
  }
  /** EPOF (deg/s) of the viewport (degrees) at a video time (s); NaN where the export does not
   * cover the time (covers false; `outOfRange` set, one console warning per runtime). */
  epof(timeS, yawDeg, pitchDeg, rollDeg = 0) {
    this.outOfRange = !this.covers(timeS);
    if (this.outOfRange) {
      if (!this.warned) {
        this.warned = true;
        console.warn(`vimsim: time ${timeS} s is outside the export (frames ${this.range.startFrame}..` +
          `${this.range.endFrame - 1}, ${this.range.startS}..${this.range.endS} s of a ${this.source.durationS} s ` +
          "video): EPOF and opacity are NaN there");
      }
      return NaN;
    }
    return this.epofAtFrame(this.frameAt(timeS), yawDeg, pitchDeg, rollDeg);
  }
  /** EPOF (deg/s) at a video frame number (range.startFrame .. range.endFrame - 1; RangeError
   * outside, as the C# EpofAtFrame). Head angles: turned by the file's initial orientation. */
  epofAtFrame(frame, yawDeg, pitchDeg, rollDeg = 0) {
    const row = frame - this.startFrame;
    if (!(row >= 0 && row < this.frameCount && Number.isInteger(row)))
      throw new RangeError(`frame ${frame} outside ${this.range.startFrame}..${this.range.endFrame - 1}`);
    if (![yawDeg, pitchDeg, rollDeg].every(Number.isFinite)) throw new Error("orientation must be finite degrees");
    const v = this.viewAngles(yawDeg, pitchDeg, rollDeg), e = this.model.query(this.frameRow(row), 0, ...v);
    if (!this.coverMask) return e;
    // the covered part's mean, faded where the viewer sees mostly no content (vimsim epof)
    const share = Math.max(0, Math.min(1, this.model.query(this.coverMask, 0, ...v)));
    return share > 1e-9 ? (e / share) * Math.min(1, share / this.minCoverage) : 0;
  }
  /** Covered share (0..1) of the viewport at a head pose (vimsim epof's coverage column); 1 for a
   * source covering the sphere (C#: Coverage). */
  coverage(yawDeg, pitchDeg, rollDeg = 0) {
    if (!this.coverMask) return 1;
    return Math.max(0, Math.min(1, this.model.query(this.coverMask, 0, ...this.viewAngles(yawDeg, pitchDeg, rollDeg))));
  }
  /** [yaw, pitch, roll] (degrees) of the view in the video's frame for a head pose: the head's
   * turned by the file's initial orientation (its spherical metadata: R(orientation) R(head),
   * simulator.media.spherical.view_angles_deg; C#: ViewAngles), else the head's. epof() applies
   * it; draw the video and the overlay (EyeRenderer.render) at these angles, as vimsim render. */
  viewAngles(yawDeg, pitchDeg, rollDeg = 0) {
    if (!this.pose || !this.applyOrientation) return [yawDeg, pitchDeg, rollDeg];
    const P = this.pose, H = headRotation(yawDeg, pitchDeg, rollDeg), M = new Array(9);
    for (let i = 0; i < 3; i++)
      for (let j = 0; j < 3; j++) M[3 * i + j] = P[3 * i] * H[j] + P[3 * i + 1] * H[3 + j] + P[3 * i + 2] * H[6 + j];
    return headAngles(M);
  }
  /** Row `row` of the data (one frame), decoded to float32 (kept until another is asked). */
  frameRow(row) {
    if (row !== this.rowOf) {
      const L = this.rowLength, o = row * L, v = this.values, h = this.half, out = this.rowBuf;
      if (h) for (let i = 0; i < L; i++) out[i] = h[v[o + i]];
      else out.set(v.subarray(o, o + L));
      this.rowOf = row;
    }
    return this.rowBuf;
  }
  /** Un-eased GRF opacity 0..1 of an EPOF (deg/s): linear between the exported thresholds,
   * clamped; NaN for NaN (C#: RawOpacity). */
  opacity(epofDps) {
    if (Number.isNaN(epofDps)) return NaN;
    const lo = this.lowDps, hi = this.highDps;
    if (hi > lo) return Math.min(1, Math.max(0, (epofDps - lo) / (hi - lo)));
    return epofDps > lo ? 1 : 0;
  }
  /** A stateful easing with the exported rule (smoothing, ease-in, ease-out). */
  createEasing() {
    const o = this.header.opacity;
    return new OpacityEasing(o.smoothing_s, this.fps, o.ease_in_s, o.ease_out_s);
  }
}

async function fetchBuffer(url) {
  const r = await fetch(url);
  if (!r.ok) throw new Error(`${url}: HTTP ${r.status}`);
  return r.arrayBuffer();
}

/** Load an export folder (URL ending in "/" or the URL of vimsim_web.json). */
export async function loadExport(base = "./") {
  const url = base.endsWith(".json") ? base : base + "vimsim_web.json";
  const dir = url.slice(0, url.lastIndexOf("/") + 1);
  const manifest = await (await fetch(url)).json();
  if (manifest.format !== "vimsim-web") throw new Error(`${url}: not a vimsim web export`);
  if (manifest.version !== MANIFEST_VERSION)
    throw new Error(`${url}: web export version ${manifest.version}, made by another vimsim (this runtime ` +
      `reads ${MANIFEST_VERSION}: the grain layout in vimsim_epof.bin); export again with vimsim export --format web`);
  const [epof, ov] = await Promise.all([
    fetchBuffer(dir + manifest.data),
    manifest.overlaps ? fetchBuffer(dir + manifest.overlaps.file) : null,
  ]);
  return new VimsimEpof(manifest, epof, ov);
}
