// vimsim study report: the replay of one viewing (ES module; loaded only over http).
// The study's browser copy of the video on the sphere, seen along the recorded head path
// (the viewing's EPOF CSV: one pose and opacity per frame) through the study's render
// frustum, with the mitigation drawn at the viewing's opacity (vimsim_gl.js: the renderer's
// grains, cutout and vignette). Free look: drag to look elsewhere; the EPOF and opacity are
// then computed live from the grid (vimsim.js). WebXR where the browser offers it.
// window.vimsimReplay: seek(t) (resolves when that frame is drawn), state, measure(n).

import { GrainLayout, anglesFromQuaternion, loadExport } from "./vimsim.js";
import { EyeRenderer } from "./vimsim_gl.js";

const $ = (id) => document.getElementById(id);
const note = $("replay-note");
const T = window.vimsimTimeline;
const data = T.data, c = data.columns, n = c.frame.length;

function parseColor(s) {
  s = String(s || "0,0,0").trim();
  if (s.startsWith("#")) return [1, 3, 5].map((i) => parseInt(s.slice(i, i + 2), 16) / 255);
  return s.split(",").map((v) => Number(v) / 255);
}

function eyeSize(r) {
  const m = /[?&]size=(\d+)x(\d+)/.exec(location.search);
  if (m) return [Number(m[1]), Number(m[2])];
  return r.eye_size || [960, 960];
}

async function main() {
  if (!data.media || !data.export) {
    note.textContent = "No replay: the study has no browser copy of this video or no grid.";
    return;
  }
  const rt = await loadExport(data.export);
  const r = data.render || {}, fps = rt.fps;
  // the browser copy's media time + mediaStart = the source's clock (EPOF rows, head paths):
  // a re-encoded copy starts at 0 where its source's video started later (build.py browser_copy)
  const mediaStart = data.media_start_s || 0;
  const [w, h] = eyeSize(r);
  const canvas = $("eye");
  canvas.width = w; canvas.height = h;
  const gl = canvas.getContext("webgl2", { preserveDrawingBuffer: true, antialias: false });
  if (!gl) { note.textContent = "This browser has no WebGL2: no replay."; return; }
  // This viewing's own mitigation, opacity and grains (build.py replay_settings), not the study's.
  const p = data.replay || {};
  const mitigation = p.kind ? { kind: p.kind, apertureMinDeg: p.apertureMinDeg, featherDeg: p.featherDeg, color: p.color }
    : { kind: r.grf === "off" ? "none" : (r.mitigation || "grf"), apertureMinDeg: r.aperture_min_deg ?? 60,
      featherDeg: r.feather_deg ?? 10, color: parseColor(r.vignette_color) };
  const same = (a, b) => ["grain_deg", "density", "inner_deg", "outer_deg", "seed"].every((k) => a[k] === b[k]);
  const grains = !p.grf || same(p.grf, rt.grains.config) ? rt.grains : GrainLayout.fromSeed(p.grf);
  const fixed = typeof p.opacity === "number" ? p.opacity : null;
  if (p.note) $("replay-caveat").textContent = "Note: " + p.note + ".";
  $("mitigation").textContent = mitigation.kind + (fixed === null ? "" : `, fixed opacity ${fixed}`);
  const eye = new EyeRenderer(gl, { width: w, height: h, hfovDeg: r.hfov_deg ?? rt.hfovDeg,
    vfovDeg: r.vfov_deg ?? rt.vfovDeg, grains, mitigation });
  const video = $("video");
  video.src = data.media;
  await new Promise((ok, bad) => {
    video.addEventListener("loadeddata", ok, { once: true });
    video.addEventListener("error", () => bad(new Error("the browser copy of the video did not load")), { once: true });
  });
  $("replay").hidden = false;
  const state = { t: 0, free: false, yaw: 0, pitch: 0, roll: 0, epof: NaN, opacity: NaN, drawn: 0 };
  const easing = rt.createEasing();
  const row = (t) => Math.min(Math.max(rt.frameAt(t) - c.frame[0], 0), n - 1);

  function draw(t, dt) {
    const i = row(t);
    state.t = t;
    if (!state.free) {
      state.yaw = c.yaw_deg[i]; state.pitch = c.pitch_deg[i]; state.roll = c.roll_deg[i];
      state.epof = c.epof_dps[i]; state.opacity = fixed ?? c.opacity[i];
    } else {
      state.epof = rt.epof(t, state.yaw, state.pitch, state.roll);
      const o = rt.opacity(state.epof);
      state.opacity = fixed ?? (dt > 0 ? easing.update(o, dt) : o);
    }
    eye.upload(video);
    eye.render(...rt.viewAngles(state.yaw, state.pitch, state.roll), state.opacity);
    state.drawn++;
    $("t").textContent = t.toFixed(3);
    $("frame").textContent = String(rt.frameAt(t));
    $("pose").textContent = [state.yaw, state.pitch, state.roll].map((v) => v.toFixed(1)).join(" / ");
    const outside = Number.isNaN(state.epof); // free look past the exported range: NaN
    $("epof").textContent = outside ? "- (outside the export)" : state.epof.toFixed(2);
    $("opacity").textContent = outside ? "-" : state.opacity.toFixed(3);
    T.setCursor(t, state.free ? { t, epof: state.epof } : null);
  }

  // One seek at a time: a "seeked" event answers the seek in flight, so a second seek waits
  // for it (else both would draw the first one's frame). The frame is drawn once the seek
  // is done and its frame presented (requestVideoFrameCallback: before that, a WebGL upload
  // of the video may still give the previous frame); a seek to the frame already shown
  // presents none, so that wait ends after 0.5 s.
  let seeking = Promise.resolve();
  async function seekOnce(t) {
    video.pause();
    const f = rt.frameAt(t);
    const seeked = new Promise((ok) => video.addEventListener("seeked", ok, { once: true }));
    const shown = new Promise((ok) => {
      if (video.requestVideoFrameCallback) video.requestVideoFrameCallback(() => ok());
      else ok();
    });
    // the middle of the frame (its own interval for a variable-rate video): the decoder shows frame f
    const t0 = rt.frameTime(f), t1 = f + 1 < rt.range.endFrame ? rt.frameTime(f + 1) : t0 + 1 / fps;
    video.currentTime = (t0 + t1) / 2 - mediaStart;
    await seeked;
    await Promise.race([shown, new Promise((ok) => setTimeout(ok, 500))]);
    draw(t, 0);
    return state;
  }
  function seek(t) {
    seeking = seeking.then(() => seekOnce(t));
    return seeking;
  }
  T.onSeek((t) => seek(t));

  let last = null;
  function onFrame(now, meta) {
    const t = meta.mediaTime + mediaStart;
    draw(t, last === null ? 0 : Math.max(0, t - last));
    last = t;
    if (!video.paused) video.requestVideoFrameCallback(onFrame);
  }
  $("play").addEventListener("click", () => {
    if (video.paused) { last = null; video.play(); video.requestVideoFrameCallback(onFrame); $("play").textContent = "pause"; }
    else { video.pause(); $("play").textContent = "play"; }
  });
  $("freelook").addEventListener("click", () => {
    state.free = !state.free; easing.reset();
    $("freelook").textContent = `free look: ${state.free ? "on" : "off"}`;
    $("mode").textContent = state.free ? "(live from the grid)" : "(recorded)";
    draw(state.t, 0);
  });
  let drag = null;
  canvas.addEventListener("pointerdown", (e) => { if (state.free) drag = [e.clientX, e.clientY, state.yaw, state.pitch]; });
  addEventListener("pointerup", () => { drag = null; });
  addEventListener("pointermove", (e) => {
    if (!drag) return;
    const k = (r.hfov_deg ?? 100) / canvas.getBoundingClientRect().width;
    state.yaw = drag[2] - (e.clientX - drag[0]) * k;
    state.pitch = Math.max(-90, Math.min(90, drag[3] + (e.clientY - drag[1]) * k));
    if (video.paused) draw(state.t, 0);
  });
  setupXR(rt, mitigation, grains, fixed, video, state, mediaStart);

  /** Upload (optional) + draw + a 1-pixel read, n times at the current frame: frames per second. */
  function measure(count, upload = true) {
    const px = new Uint8Array(4);
    const t0 = performance.now();
    for (let k = 0; k < count; k++) {
      if (upload) eye.upload(video);
      eye.render(...rt.viewAngles(state.yaw, state.pitch, state.roll), 0.5);
      gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, px);
    }
    return (count * 1000) / (performance.now() - t0);
  }
  window.vimsimReplay = { seek, state, measure, canvas, ready: false };
  await seek(c.time_s[0]);
  window.vimsimReplay.ready = true; // the first frame drawn: a caller's seek is not raced by it
}

async function setupXR(rt, mitigation, grains, fixed, video, state, mediaStart) {
  if (!navigator.xr || !(await navigator.xr.isSessionSupported("immersive-vr").catch(() => false))) return;
  const btn = $("xr");
  btn.hidden = false;
  btn.addEventListener("click", async () => {
    const session = await navigator.xr.requestSession("immersive-vr");
    const xc = document.createElement("canvas").getContext("webgl2", { xrCompatible: true });
    const layer = new XRWebGLLayer(session, xc);
    session.updateRenderState({ baseLayer: layer });
    const space = await session.requestReferenceSpace("local");
    const eyes = new Map();
    const onXR = (now, frame) => {
      session.requestAnimationFrame(onXR);
      const pose = frame.getViewerPose(space);
      if (!pose) return;
      xc.bindFramebuffer(xc.FRAMEBUFFER, layer.framebuffer);
      for (const view of pose.views) {
        const vp = layer.getViewport(view), P = view.projectionMatrix;
        let e = eyes.get(view.eye);
        if (!e) {
          const deg = (x) => (Math.atan(x) * 180) / Math.PI;
          const frustum = { left: deg((1 - P[8]) / P[0]), right: deg((1 + P[8]) / P[0]),
            down: deg((1 - P[9]) / P[5]), up: deg((1 + P[9]) / P[5]) };
          e = new EyeRenderer(xc, { width: vp.width, height: vp.height, frustum, grains, mitigation });
          eyes.set(view.eye, e);
        }
        const [yaw, pitch, roll] = anglesFromQuaternion(view.transform.orientation); // XR: -z forward
        const t = video.currentTime + mediaStart, ep = rt.epof(t, yaw, pitch, roll);
        e.upload(video);
        e.render(...rt.viewAngles(yaw, pitch, roll), fixed ?? rt.opacity(ep), [vp.x, vp.y]);
        state.epof = ep;
      }
    };
    session.requestAnimationFrame(onXR);
  });
}

main().catch((e) => { note.textContent = "The replay could not start: " + e.message; });
