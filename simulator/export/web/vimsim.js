// vimsim export: vimsim.js, the EPOF runtime for web players (ES module, no dependencies).
// Written by `vimsim export GRID.npz -o DIR --format web`; docs/web.md in vimsim.
//
//   import { loadExport } from "./vimsim.js";
//   const rt = await loadExport("./");                 // DIR/vimsim_web.json and its .bin files
//   const epof = rt.epof(videoTimeS, yawDeg, pitchDeg, rollDeg);   // deg/s, as `vimsim epof`
//   const op = rt.opacity(epof);                      // GRF opacity 0..1 (the linear rule)
//   const ease = rt.createEasing();                   // once; then per video frame:
//   const shown = ease.step(op);                      // the exported rule (default: comfort)
//   const grains = rt.grains;                          // the renderer's grain layout
//
// Conventions, exactly as vimsim: angles in degrees; yaw + turns right, pitch + looks up,
// roll + tilts the head right ear down, applied yaw, then pitch, then roll (intrinsic);
// world +x right, +y up, +z forward (the centre of the equirect frame). A time is seconds
// from the video start; it shows frame floor(time * fps + 1e-6), clamped to the export.
// Paper mode reads the overlap table vimsim computed (vimsim_overlaps.bin: the table of
// simulator.epof.overlaps.ViewportOverlaps) and interpolates it as vimsim does; sphere mode
// integrates the field over the viewport as simulator.epof.exact.ViewportQuery (weights per
// 0.5 deg bin of pitch, roll and yaw within a cell, cached).

export const FORMAT = "vimsim-epof";
export const FRAME_EPS = 1e-6;
const MAGIC = "VIMSIMEP";
const D2R = Math.PI / 180;

/** Round half to even (Python's round, numpy's rint). */
export function roundEven(x) {
  const r = Math.round(x);
  return Math.abs(x % 1) === 0.5 && r % 2 !== 0 ? r - 1 : r;
}

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

/** Parse vimsim_epof.bin: {header, values (Uint16Array of binary16 or Float32Array, C order,
 * views of the buffer: no copy)}. Throws Error naming the problem. */
export function parseEpofBinary(buffer, name = "vimsim_epof.bin") {
  const b = new Uint8Array(buffer);
  if (b.length < 16 || String.fromCharCode(...b.subarray(0, 8)) !== MAGIC)
    throw new Error(`${name}: not a vimsim export (no VIMSIMEP signature)`);
  const dv = new DataView(buffer);
  const version = dv.getUint32(8, true), hlen = dv.getUint32(12, true);
  if (16 + hlen > b.length) throw new Error(`${name}: truncated header`);
  const header = JSON.parse(new TextDecoder().decode(b.subarray(16, 16 + hlen)));
  if (header.format !== FORMAT || header.version !== version)
    throw new Error(`${name}: export format ${header.format} version ${version} is not readable here`);
  const d = header.data, n = d.shape.reduce((x, y) => x * y, 1), off = d.offset;
  const size = d.dtype === "float16" ? 2 : 4;
  if (off + n * size !== b.length) throw new Error(`${name}: truncated or padded data`);
  // Little-endian typed arrays (every browser's platform); offset is a multiple of 16.
  const values = d.dtype === "float16" ? new Uint16Array(buffer, off, n) : new Float32Array(buffer, off, n);
  return { header, values };
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
  /** Advance dt seconds towards opacity x (render frames of any length). */
  update(x, dt) {
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

// ------------------------------------------------------------------ grains

const mul32 = (a, b) => Math.imul(a, b) >>> 0;

/** numpy.random.SeedSequence(seed).generate_state(4, uint64) for an integer seed >= 0,
 * as BigInts (numpy/random/bit_generator.pyx: hashmix, mix, pool of 4 words). */
function seedSequenceState(seed) {
  const INIT_A = 0x43b0d7e5, MULT_A = 0x931e8875, INIT_B = 0x8b51f9dd, MULT_B = 0x58f38ded;
  const MIX_L = 0xca01f9dd, MIX_R = 0x4973f715;
  const entropy = [];
  let x = BigInt(seed);
  do { entropy.push(Number(x & 0xffffffffn)); x >>= 32n; } while (x > 0n);
  let hc = INIT_A;
  const hashmix = (v) => {
    v = (v ^ hc) >>> 0; hc = mul32(hc, MULT_A); v = mul32(v, hc);
    return (v ^ (v >>> 16)) >>> 0;
  };
  const mix = (a, b) => { const r = (mul32(MIX_L, a) - mul32(MIX_R, b)) >>> 0; return (r ^ (r >>> 16)) >>> 0; };
  const pool = [0, 1, 2, 3].map((i) => hashmix(i < entropy.length ? entropy[i] : 0));
  for (let s = 0; s < 4; s++) for (let d = 0; d < 4; d++) if (s !== d) pool[d] = mix(pool[d], hashmix(pool[s]));
  for (let s = 4; s < entropy.length; s++) for (let d = 0; d < 4; d++) pool[d] = mix(pool[d], hashmix(entropy[s]));
  let hb = INIT_B;
  const words = [];
  for (let i = 0; i < 8; i++) {
    let v = (pool[i % 4] ^ hb) >>> 0; hb = mul32(hb, MULT_B); v = mul32(v, hb);
    words.push((v ^ (v >>> 16)) >>> 0);
  }
  return [0, 1, 2, 3].map((k) => (BigInt(words[2 * k + 1]) << 32n) | BigInt(words[2 * k]));
}

/** numpy's PCG64 (XSL-RR 128/64) seeded as numpy.random.default_rng(seed) seeds it. */
export class Pcg64 {
  constructor(seed) {
    const v = seedSequenceState(seed), M = (1n << 128n) - 1n;
    this.mult = (2549297995355413924n << 64n) + 4865540595714422341n;
    this.M = M;
    this.inc = ((((v[2] << 64n) | v[3]) << 1n) | 1n) & M;
    this.state = 0n;
    this.step();
    this.state = (this.state + ((v[0] << 64n) | v[1])) & M;
    this.step();
  }
  step() { this.state = (this.state * this.mult + this.inc) & this.M; }
  nextU64() {
    this.step();
    const s = this.state, x = ((s >> 64n) ^ s) & 0xffffffffffffffffn, rot = s >> 122n;
    return ((x >> rot) | (x << ((64n - rot) & 63n))) & 0xffffffffffffffffn;
  }
  /** A double in [0, 1): (next64 >> 11) * 2^-53, as numpy's random(). */
  nextDouble() { return Number(this.nextU64() >> 11n) * (1 / 9007199254740992); }
  /** n draws of uniform(low, high): low + (high - low) * random(). */
  uniform(low, high, n) {
    const out = new Float64Array(n);
    for (let i = 0; i < n; i++) out[i] = low + (high - low) * this.nextDouble();
    return out;
  }
}

/** The renderer's grain layout (simulator.mitigation.grf.GrainField): world unit centres
 * (Float64Array n*3, +x right, +y up, +z forward), the grain angular radius and the cutout. */
export class GrainLayout {
  constructor(config, centres) {
    this.config = config; // grain_deg, density, inner_deg, outer_deg, seed, count
    this.centres = centres;
    this.count = centres.length / 3;
    this.radiusRad = (config.grain_deg * D2R) / 2;
  }
  /** The layout from the seed, as simulator.mitigation.grf.GrainField.from_config: grain_count
   * grains, z = uniform(-1, 1), lon = uniform(-pi, pi) from numpy.random.default_rng(seed),
   * centre (sqrt(1 - z^2) sin lon, z, sqrt(1 - z^2) cos lon). config: grain_deg, density,
   * inner_deg, outer_deg, seed. */
  static fromSeed(config) {
    const n = GrainLayout.grainCount(config.grain_deg, config.density);
    const rng = new Pcg64(config.seed);
    const z = rng.uniform(-1, 1, n), lon = rng.uniform(-Math.PI, Math.PI, n);
    const c = new Float64Array(3 * n);
    for (let i = 0; i < n; i++) {
      const s = Math.sqrt(1 - z[i] * z[i]);
      c[3 * i] = s * Math.sin(lon[i]); c[3 * i + 1] = z[i]; c[3 * i + 2] = s * Math.cos(lon[i]);
    }
    const g = new GrainLayout({ ...config, count: n }, c);
    g.draws = { z, lon };
    return g;
  }
  /** grf.grain_count: grains whose union blocks `density` of the sphere. */
  static grainCount(grainDeg, density) {
    const a = 2 * Math.PI * (1 - Math.cos((grainDeg * D2R) / 2)), p = a / (4 * Math.PI);
    return Math.max(1, roundEven(Math.log1p(-density) / Math.log1p(-p)));
  }
  /** Cutout alpha at an eccentricity (degrees): 0 inside inner_deg, 1 beyond outer_deg. */
  cutout(eccDeg) {
    const { inner_deg: a, outer_deg: b } = this.config;
    return Math.min(1, Math.max(0, (eccDeg - a) / (b - a)));
  }
  /** Coverage (0..1, the union of the discs) as a width x width/2 equirect, row 0 north,
   * the image vimsim's shaders/grf_mask.frag renders: per texel centre p,
   * cov_k = clamp((chord - |p - c_k|) / (pi / height) + 1/2, 0, 1), coverage 1 - prod(1 - cov_k). */
  coverageMask(width) {
    const W = width, H = width / 2, trans = new Float32Array(W * H).fill(1);
    const fp = Math.PI / H, chord = 2 * Math.sin(this.radiusRad / 2);
    const reach = this.radiusRad + fp;
    const cosLat = new Float64Array(H), sinLat = new Float64Array(H);
    for (let y = 0; y < H; y++) { const lat = Math.PI / 2 - ((y + 0.5) / H) * Math.PI; cosLat[y] = Math.cos(lat); sinLat[y] = Math.sin(lat); }
    const cosLon = new Float64Array(W), sinLon = new Float64Array(W);
    for (let x = 0; x < W; x++) { const lon = ((x + 0.5) / W) * 2 * Math.PI - Math.PI; cosLon[x] = Math.cos(lon); sinLon[x] = Math.sin(lon); }
    const C = this.centres;
    for (let g = 0; g < this.count; g++) {
      const gx = C[3 * g], gy = C[3 * g + 1], gz = C[3 * g + 2];
      const lat = Math.asin(Math.max(-1, Math.min(1, gy))), lon = Math.atan2(gx, gz);
      const y0 = Math.max(0, Math.floor(((Math.PI / 2 - lat - reach) / Math.PI) * H));
      const y1 = Math.min(H - 1, Math.ceil(((Math.PI / 2 - lat + reach) / Math.PI) * H));
      const cl = Math.cos(lat), polar = Math.abs(lat) + reach >= Math.PI / 2 - 1e-9;
      const dlon = polar ? Math.PI : Math.asin(Math.min(1, Math.sin(reach) / Math.max(cl, 1e-12)));
      const xa = polar ? 0 : Math.floor(((lon - dlon + Math.PI) / (2 * Math.PI)) * W) - 1;
      const xb = polar ? W - 1 : Math.ceil(((lon + dlon + Math.PI) / (2 * Math.PI)) * W) + 1;
      for (let y = y0; y <= y1; y++) {
        const row = y * W, cy = cosLat[y], py = sinLat[y] - gy;
        for (let xx = xa; xx <= xb; xx++) {
          const x = ((xx % W) + W) % W;
          const dx = cy * sinLon[x] - gx, dz = cy * cosLon[x] - gz;
          const cov = (chord - Math.sqrt(dx * dx + py * py + dz * dz)) / fp + 0.5;
          if (cov <= 0) continue;
          trans[row + x] *= 1 - Math.min(1, cov);
        }
      }
    }
    const out = new Uint8Array(W * H);
    for (let i = 0; i < W * H; i++) out[i] = Math.round((1 - trans[i]) * 255);
    return out;
  }
}

// ----------------------------------------------------------------- runtime

/** EPOF (deg/s) and GRF opacity of a viewport at a video time, from a vimsim export. */
export class VimsimEpof {
  constructor(manifest, epofBin, overlapsBin = null, grainsBin = null) {
    const { header, values } = parseEpofBinary(epofBin);
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
    this.grains = null;
    if (grainsBin && manifest.grains) this.grains = new GrainLayout(manifest.grains, new Float64Array(grainsBin, 16));
  }
  /** Video frame shown at a time (s from the video start), clamped to the exported frames. */
  frameAt(timeS) {
    const f = Math.floor(timeS * this.fps + FRAME_EPS), s = this.startFrame;
    return Math.min(Math.max(f, s), s + this.frameCount - 1);
  }
  /** EPOF (deg/s) of the viewport (degrees) at a video time (s). */
  epof(timeS, yawDeg, pitchDeg, rollDeg = 0) {
    return this.epofAtFrame(this.frameAt(timeS), yawDeg, pitchDeg, rollDeg);
  }
  /** EPOF (deg/s) at a video frame number (startFrame .. startFrame + frameCount - 1). */
  epofAtFrame(frame, yawDeg, pitchDeg, rollDeg = 0) {
    const row = Math.min(Math.max(frame - this.startFrame, 0), this.frameCount - 1);
    if (![yawDeg, pitchDeg, rollDeg].every(Number.isFinite)) throw new Error("orientation must be finite degrees");
    return this.model.query(this.frameRow(row), 0, yawDeg, pitchDeg, rollDeg);
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
  /** GRF opacity 0..1 of an EPOF (deg/s): linear between the exported thresholds, clamped. */
  opacity(epofDps) {
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
  const [epof, ov, gr] = await Promise.all([
    fetchBuffer(dir + manifest.data),
    manifest.overlaps ? fetchBuffer(dir + manifest.overlaps.file) : null,
    manifest.grains ? fetchBuffer(dir + manifest.grains.file) : null,
  ]);
  return new VimsimEpof(manifest, epof, ov, gr);
}
