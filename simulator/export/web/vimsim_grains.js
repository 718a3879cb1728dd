// vimsim export: vimsim_grains.js, the grain layout of the mitigation (ES module, no dependencies).
// Written by `vimsim export GRID.npz -o DIR --format web` and by `vimsim report`; docs/web.md.
// vimsim.js re-exports it: a loaded export's `rt.grains` is the layout stored in
// vimsim_epof.bin (GrainLayout.fromExport); GrainLayout.fromSeed draws the same layout from
// the seed (numpy's default_rng ported: SeedSequence, PCG64), for a layout without an export.

const D2R = Math.PI / 180;

/** Round half to even (Python's round, numpy's rint). */
export function roundEven(x) {
  const r = Math.round(x);
  return Math.abs(x % 1) === 0.5 && r % 2 !== 0 ? r - 1 : r;
}

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
  /** The layout stored in an export (format 3 on): the header's grf settings and its grains
   * section (Float32Array, n_grains x 3 unit vectors), widened to float64. */
  static fromExport(header, floats) {
    const g = header.grf;
    const config = { grain_deg: g.grain_deg, density: g.density, inner_deg: g.inner_deg,
      outer_deg: g.outer_deg, seed: g.seed, count: g.n_grains };
    return new GrainLayout(config, Float64Array.from(floats));
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
