// The authors' Unity runtime rule (vimsim --preset cao2021-code) as an ES module, written from its
// description in vimsim's docs/parity.md; vimsim's Python (simulator/mitigation/cao2021.py) and
// C# (VimsimCao2021.cs) give the same numbers (tests: 1e-7).
//
// Data: a folder in the authors' layout (vimsim export --format cao-csv): one CSV per window,
// horizontal_<yaw>_vertical_<pitch>.csv (degrees), a header line ",0" then "frame,value" rows in
// window px/frame, and percentileData.csv (low and high px/frame).
//
// At video frame k (0-based), head yaw / pitch in degrees (yaw + right, pitch + up): each angle
// wrapped to (-180, 180]; yaw candidates ceil(yaw/s)*s and floor(yaw/s)*s, each above 180-s moved
// by -360 or below -(180-s) by +360; pitch candidates ceil/floor(pitch/sp)*sp; in each axis the
// smaller plain absolute difference wins (a tie: ceil); pitch clamped to the rows. The window's
// list is the number after the comma of every non-empty line, header ",0" included; the flow is
// list[k-1] (row k-2), 0 for k < 1 and beyond the list. Opacity = clamp((flow-lo)/(hi-lo), 0, 1).

export const CAO_LOW_PX = 0.18;
export const CAO_HIGH_PX = 53.73;

/** Their reader: the number after the comma of every non-empty line (as float32). */
export function readList(text) {
  const out = [];
  for (const raw of text.split("\n")) {
    const line = raw.trim();
    if (line.length === 0) continue;
    out.push(Math.fround(parseFloat(line.slice(line.indexOf(",") + 1))));
  }
  return Float32Array.from(out);
}

/** A window's file name: centres as "-180", "7.5", never "-0". */
export function windowFileName(yawDeg, pitchDeg) {
  const t = (d) => (d === 0 ? "0" : String(d));
  return `horizontal_${t(yawDeg)}_vertical_${t(pitchDeg)}.csv`;
}

function wrap180(a) {
  let w = (a + 180.0) % 360.0;
  if (w < 0) w += 360.0;
  w -= 180.0;
  return w === -180.0 ? 180.0 : w;
}

/** [yawCentre, pitchCentre] (degrees) of the window their runtime reads for a pose. */
export function nearestCentre(yawDeg, pitchDeg, yawStep = 15, pitchStep = 15, pitchMin = -90, pitchMax = 90) {
  const yaw = wrap180(yawDeg), pitch = wrap180(pitchDeg), edge = 180.0 - yawStep;
  const move = (c) => (c > edge ? c - 360.0 : c < -edge ? c + 360.0 : c);
  const up = move(Math.ceil(yaw / yawStep) * yawStep), dn = move(Math.floor(yaw / yawStep) * yawStep);
  const yc = Math.abs(yaw - up) <= Math.abs(yaw - dn) ? up : dn;
  const pu = Math.ceil(pitch / pitchStep) * pitchStep, pd = Math.floor(pitch / pitchStep) * pitchStep;
  const pc = Math.abs(pitch - pu) <= Math.abs(pitch - pd) ? pu : pd;
  return [yc, Math.min(Math.max(pc, pitchMin), pitchMax)];
}

export class Cao2021Runtime {
  /** files: {name: text} of the folder (window CSVs; percentileData.csv optional). */
  constructor(files) {
    this.lists = new Map();
    const yaws = new Set(), pitches = new Set();
    const re = /^horizontal_(-?\d+(?:\.\d+)?)_vertical_(-?\d+(?:\.\d+)?)\.csv$/;
    for (const [name, text] of Object.entries(files)) {
      const m = re.exec(name);
      if (!m) continue;
      yaws.add(parseFloat(m[1]));
      pitches.add(parseFloat(m[2]));
      this.lists.set(name, readList(text));
    }
    if (this.lists.size === 0) throw new Error("no window CSVs");
    const p = [...pitches].sort((a, b) => a - b);
    this.yawStep = 360.0 / yaws.size;
    this.pitchStep = p.length > 1 ? p[1] - p[0] : 15.0;
    this.pitchMin = p[0];
    this.pitchMax = p[p.length - 1];
    this.lowPx = CAO_LOW_PX;
    this.highPx = CAO_HIGH_PX;
    const pct = files["percentileData.csv"];
    if (pct !== undefined) {
      const v = pct.split("\n").map((s) => s.trim()).filter((s) => s.length > 0).map(parseFloat);
      [this.lowPx, this.highPx] = v;
    }
    if (!(this.highPx > this.lowPx)) throw new Error("percentileData: low must be below high");
  }

  /** Window px/frame their runtime uses at video frame k (0-based). */
  flow(frame, yawDeg, pitchDeg) {
    const [yc, pc] = nearestCentre(yawDeg, pitchDeg, this.yawStep, this.pitchStep, this.pitchMin, this.pitchMax);
    const list = this.lists.get(windowFileName(yc, pc));
    if (list === undefined) throw new Error(`no window file ${windowFileName(yc, pc)}`);
    const i = frame - 1;
    return i < 0 || i >= list.length ? 0.0 : list[i];
  }

  opacity(frame, yawDeg, pitchDeg) {
    const o = (this.flow(frame, yawDeg, pitchDeg) - this.lowPx) / (this.highPx - this.lowPx);
    return o < 0 ? 0 : o > 1 ? 1 : o;
  }
}
