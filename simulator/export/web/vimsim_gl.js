// vimsim export: vimsim_gl.js, the eye renderer and the mitigation overlay in WebGL2 (ES module).
// Written by `vimsim export GRID.npz -o DIR --format web` and by `vimsim report`; docs/web.md.
//
//   import { EyeRenderer } from "./vimsim_gl.js";
//   const eye = new EyeRenderer(canvas.getContext("webgl2"), {
//     width: 1280, height: 720, hfovDeg: 107, vfovDeg: 70,        // or frustum {left,right,down,up}
//     grains: runtime.grains,                                     // GrainLayout or null
//     mitigation: runtime.mitigation,   // as exported; or { kind: "grf", apertureMinDeg: 60,
//                                       //   featherDeg: 10, color: [0, 0, 0] }
//     video: true });                                             // false: the overlay alone
//   eye.upload(videoElement);                                     // each new video frame
//   eye.render(yawDeg, pitchDeg, rollDeg, opacity);                 // NaN: no mitigation drawn
//
// The fragment shader is vimsim's shaders/eye.frag in GLSL ES 3.00: the pixel's view ray from
// the exact frustum, the head rotation, the equirect sampled with ffmpeg v360's 4-point
// Lagrange cubic (magnification; trilinear mipmaps where a pixel spans more than a texel row),
// world-fixed grains (their coverage mask, the image shaders/grf_mask.frag renders) times
// the head-fixed cutout and the opacity, then the tunneling vignette. With video: false it
// draws only the overlay (premultiplied alpha; blend ONE, ONE_MINUS_SRC_ALPHA over a scene).

import { headRotation } from "./vimsim.js";

const D2R = Math.PI / 180;

const VERT = `#version 300 es
void main() {
  vec2 p = vec2(float((gl_VertexID & 1) << 2) - 1.0, float((gl_VertexID & 2) << 1) - 1.0);
  gl_Position = vec4(p, 0.0, 1.0);
}`;

function fragSource(d) {
  return `#version 300 es
precision highp float;
precision highp int;
precision highp sampler2D;
#define VIDEO ${d.VIDEO}
#define MIPMAP ${d.MIPMAP}
#define GRF ${d.GRF}
#define GRAIN_LOD ${d.GRAIN_LOD}
#define VIGNETTE ${d.VIGNETTE}
uniform sampler2D u_equirect;
uniform mat3 u_head;
uniform vec2 u_tan_half;
uniform vec2 u_tan_offset;
uniform vec2 u_size;
uniform vec2 u_origin;     // the viewport's lower-left corner in the framebuffer (pixels)
out vec4 frag_color;
const float PI = 3.14159265358979;
vec4 cubic_weights(float t) {
  float t2 = t * t; float t3 = t2 * t;
  return vec4(-t / 3.0 + t2 / 2.0 - t3 / 6.0, 1.0 - t / 2.0 - t2 + t3 / 2.0,
              t + t2 / 2.0 - t3 / 2.0, -t / 6.0 + t3 / 6.0);
}
#if VIDEO
vec3 sample_cubic(vec2 xy) {
  ivec2 sz = textureSize(u_equirect, 0);
  vec2 p = xy - 0.5; vec2 f = floor(p); vec2 t = p - f; ivec2 b = ivec2(f);
  vec4 wx = cubic_weights(t.x); vec4 wy = cubic_weights(t.y);
  ivec4 xr = ivec4(b.x - 1, b.x, b.x + 1, b.x + 2);
  ivec4 xs = xr + sz.x * (ivec4(lessThan(xr, ivec4(0))) - ivec4(greaterThanEqual(xr, ivec4(sz.x))));
  ivec4 xo = xs + sz.x / 2;
  xo -= sz.x * ivec4(greaterThanEqual(xo, ivec4(sz.x)));
  ivec4 yr = ivec4(b.y - 1, b.y, b.y + 1, b.y + 2);
  bvec4 over = bvec4(yr.x < 0 || yr.x >= sz.y, yr.y < 0 || yr.y >= sz.y,
                     yr.z < 0 || yr.z >= sz.y, yr.w < 0 || yr.w >= sz.y);
  ivec4 ys = min(max(yr, -1 - yr), 2 * sz.y - 1 - yr);
  vec3 acc = vec3(0.0);
  for (int j = 0; j < 4; ++j) {
    ivec4 c = over[j] ? xo : xs;
    vec3 row = wx.x * texelFetch(u_equirect, ivec2(c.x, ys[j]), 0).rgb
             + wx.y * texelFetch(u_equirect, ivec2(c.y, ys[j]), 0).rgb
             + wx.z * texelFetch(u_equirect, ivec2(c.z, ys[j]), 0).rgb
             + wx.w * texelFetch(u_equirect, ivec2(c.w, ys[j]), 0).rgb;
    acc += wy[j] * row;
  }
  return acc;
}
#endif
#if GRF
uniform sampler2D u_grains;
uniform float u_opacity;
uniform vec2 u_cutout;
#endif
#if VIGNETTE
uniform vec2 u_vignette;
uniform vec3 u_vignette_color;
#endif
void main() {
  // Image row 0 is the top: GL's row 0 is the bottom of the canvas.
  vec2 ij = vec2(gl_FragCoord.x - u_origin.x, u_size.y - (gl_FragCoord.y - u_origin.y));
  vec2 uv = vec2((ij.x / u_size.x * 2.0 - 1.0) * u_tan_half.x + u_tan_offset.x,
                 (1.0 - ij.y / u_size.y * 2.0) * u_tan_half.y + u_tan_offset.y);
  vec3 d_head = normalize(vec3(uv, 1.0));
  vec3 d = u_head * d_head;
  float lon = atan(d.x, d.z);
  float lat = asin(clamp(d.y, -1.0, 1.0));
  vec2 st = vec2(lon / (2.0 * PI) + 0.5, 0.5 - lat / PI);
  vec3 ddx = dFdx(d_head), ddy = dFdy(d_head);
  float footprint_max = max(length(ddx), length(ddy));
#if VIDEO
  vec2 tsz = vec2(textureSize(u_equirect, 0));
  vec2 xy = st * tsz;
  float rho = footprint_max / (PI / tsz.y);
#if MIPMAP
  vec3 color = rho <= 1.0 ? sample_cubic(xy) : textureLod(u_equirect, xy / tsz, log2(rho)).rgb;
#else
  vec3 color = sample_cubic(xy);
#endif
  float alpha = 1.0;
#else
  vec3 color = vec3(0.0);   // premultiplied overlay: what is drawn, and how much it hides
  float alpha = 0.0;
#endif
#if GRF
  float ecc = atan(length(d_head.xy), d_head.z);
  float cut = clamp((ecc - u_cutout.x) / (u_cutout.y - u_cutout.x), 0.0, 1.0);
  float k = cut * u_opacity;
  if (k > 0.0) {
#if GRAIN_LOD
    float grho = footprint_max / (PI / float(textureSize(u_grains, 0).y));
    float cov = textureLod(u_grains, st, log2(max(grho, 1e-6))).r;
#else
    float cov = textureLod(u_grains, st, 0.0).r;
#endif
    color *= 1.0 - k * cov;
    alpha = 1.0 - (1.0 - alpha) * (1.0 - k * cov);
  }
#endif
#if VIGNETTE
  float vecc = atan(length(d_head.xy), d_head.z);
  float va = u_vignette.y > 0.0 ? clamp((vecc - u_vignette.x) / u_vignette.y + 0.5, 0.0, 1.0)
                                : float(vecc >= u_vignette.x);
#if VIDEO
  color = mix(color, u_vignette_color, va);
#else
  color = color * (1.0 - va) + u_vignette_color * va;
  alpha = 1.0 - (1.0 - alpha) * (1.0 - va);
#endif
#endif
  frag_color = vec4(color, alpha);
}`;
}

function compile(gl, type, src) {
  const s = gl.createShader(type);
  gl.shaderSource(s, src);
  gl.compileShader(s);
  if (!gl.getShaderParameter(s, gl.COMPILE_STATUS)) throw new Error("vimsim_gl: " + gl.getShaderInfoLog(s));
  return s;
}

/** The mitigation's vignette aperture radius (radians, alpha 1/2) at an opacity 0..1. */
export function apertureRadius(mit, frustum, opacity) {
  const t = (a) => Math.tan(a * D2R);
  const full = Math.atan(Math.hypot(Math.max(t(frustum.left), t(frustum.right)), Math.max(t(frustum.down), t(frustum.up))));
  const o = Math.min(Math.max(opacity, 0), 1);
  const r0 = full + (mit.featherDeg * D2R) / 2, r1 = (mit.apertureMinDeg * D2R) / 2;
  return r0 + (r1 - r0) * o;
}

export class EyeRenderer {
  constructor(gl, opts) {
    this.gl = gl;
    this.width = opts.width; this.height = opts.height;
    this.frustum = opts.frustum || { left: opts.hfovDeg / 2, right: opts.hfovDeg / 2, down: opts.vfovDeg / 2, up: opts.vfovDeg / 2 };
    const mit = Object.assign({ kind: "grf", apertureMinDeg: 60, featherDeg: 10, color: [0, 0, 0] }, opts.mitigation || {});
    this.mitigation = mit;
    this.video = opts.video !== false;
    const f = this.frustum, t = (a) => Math.tan(a * D2R);
    this.tanHalf = [(t(f.right) + t(f.left)) / 2, (t(f.up) + t(f.down)) / 2];
    this.tanOffset = [(t(f.right) - t(f.left)) / 2, (t(f.up) - t(f.down)) / 2];
    this.pixelAngle = Math.max((2 * this.tanHalf[0]) / this.width, (2 * this.tanHalf[1]) / this.height);
    const grains = ["grf", "grf+vignette"].includes(mit.kind) ? opts.grains : null;
    this.grains = grains || null;
    this.vignette = ["vignette", "grf+vignette"].includes(mit.kind);
    this.grainLod = false;
    if (this.grains) this.grainTex = this._grainMask();
    this.programs = {};
    this.tex = null; this.mips = false;
  }
  /** The grain coverage texture, sized as vimsim's renderer sizes it (texels no larger than
   * the eye's largest pixel, 512 .. 8192 wide), mipmapped when some pixel outside the
   * cutout's inner radius is larger than a texel row. */
  _grainMask() {
    const gl = this.gl;
    const limit = Math.min(8192, gl.getParameter(gl.MAX_TEXTURE_SIZE));
    let w = Math.ceil((2 * Math.PI) / this.pixelAngle);
    w = Math.min(Math.max(512, w + (w % 2)), limit);
    const h = w / 2;
    const reach = Math.max(this.grains.config.inner_deg - 1, 0) * D2R;
    this.grainLod = this.pixelAngle * Math.cos(reach) > (0.99 * Math.PI) / h;
    const mask = this.grains.coverageMask(w);
    const tex = gl.createTexture();
    gl.bindTexture(gl.TEXTURE_2D, tex);
    gl.pixelStorei(gl.UNPACK_ALIGNMENT, 1);
    gl.texImage2D(gl.TEXTURE_2D, 0, gl.R8, w, h, 0, gl.RED, gl.UNSIGNED_BYTE, mask);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_WRAP_S, gl.REPEAT);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_WRAP_T, gl.CLAMP_TO_EDGE);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MAG_FILTER, gl.LINEAR);
    if (this.grainLod) {
      gl.generateMipmap(gl.TEXTURE_2D);
      gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MIN_FILTER, gl.LINEAR_MIPMAP_LINEAR);
    } else {
      gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MIN_FILTER, gl.LINEAR);
    }
    this.maskSize = [w, h];
    return tex;
  }
  _program(mipmap) {
    const key = mipmap ? 1 : 0;
    if (this.programs[key]) return this.programs[key];
    const gl = this.gl;
    const d = { VIDEO: +this.video, MIPMAP: +mipmap, GRF: +!!this.grains, GRAIN_LOD: +this.grainLod, VIGNETTE: +this.vignette };
    const p = gl.createProgram();
    gl.attachShader(p, compile(gl, gl.VERTEX_SHADER, VERT));
    gl.attachShader(p, compile(gl, gl.FRAGMENT_SHADER, fragSource(d)));
    gl.linkProgram(p);
    if (!gl.getProgramParameter(p, gl.LINK_STATUS)) throw new Error("vimsim_gl: " + gl.getProgramInfoLog(p));
    const u = (n) => gl.getUniformLocation(p, n);
    const prog = { p, head: u("u_head"), opacity: u("u_opacity"), vignette: u("u_vignette"), origin: u("u_origin") };
    gl.useProgram(p);
    gl.uniform2f(u("u_tan_half"), this.tanHalf[0], this.tanHalf[1]);
    gl.uniform2f(u("u_tan_offset"), this.tanOffset[0], this.tanOffset[1]);
    gl.uniform2f(u("u_size"), this.width, this.height);
    gl.uniform1i(u("u_equirect"), 0);
    if (this.grains) {
      gl.uniform1i(u("u_grains"), 1);
      gl.uniform2f(u("u_cutout"), this.grains.config.inner_deg * D2R, this.grains.config.outer_deg * D2R);
    }
    if (this.vignette) gl.uniform3f(u("u_vignette_color"), ...this.mitigation.color);
    this.programs[key] = prog;
    return prog;
  }
  /** Upload the current equirect frame (a video element, image, canvas or ImageBitmap;
   * texel row 0 = the image's top row) at the size the browser decodes it (a video's
   * videoWidth may be its display width: anamorphic frames are uploaded as stored or
   * scaled by the browser; the equirect mapping does not depend on the texture's size),
   * mipmapped only if some pixel minifies. `height`: the frame's height if not the source's. */
  upload(source, height) {
    const gl = this.gl;
    const h = height || source.videoHeight || source.naturalHeight || source.height;
    gl.activeTexture(gl.TEXTURE0);
    if (!this.tex) {
      this.tex = gl.createTexture();
      gl.bindTexture(gl.TEXTURE_2D, this.tex);
      gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_WRAP_S, gl.REPEAT);
      gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_WRAP_T, gl.CLAMP_TO_EDGE);
      gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MAG_FILTER, gl.LINEAR);
    }
    gl.bindTexture(gl.TEXTURE_2D, this.tex);
    gl.pixelStorei(gl.UNPACK_FLIP_Y_WEBGL, false);
    gl.pixelStorei(gl.UNPACK_ALIGNMENT, 1);
    this.mips = this.pixelAngle > (0.95 * Math.PI) / h;
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MIN_FILTER, this.mips ? gl.LINEAR_MIPMAP_LINEAR : gl.LINEAR);
    // The source's own size (no width/height: WebGL2's sized form takes a sub-rectangle).
    gl.texImage2D(gl.TEXTURE_2D, 0, gl.RGBA8, gl.RGBA, gl.UNSIGNED_BYTE, source);
    if (this.mips) gl.generateMipmap(gl.TEXTURE_2D);
  }
  /** Draw the eye (or the overlay) for a head orientation (degrees) and opacity 0..1, into
   * the framebuffer bound now at viewport [x, y] (default [0, 0]; e.g. an XR view's). */
  render(yawDeg, pitchDeg, rollDeg, opacity, origin = [0, 0]) {
    const gl = this.gl;
    const prog = this._program(this.video && this.mips);
    gl.useProgram(prog.p);
    const R = headRotation(yawDeg, pitchDeg, rollDeg);
    gl.uniformMatrix3fv(prog.head, false, [R[0], R[3], R[6], R[1], R[4], R[7], R[2], R[5], R[8]]);
    const o = Number.isNaN(opacity) ? 0 : Math.min(Math.max(opacity, 0), 1); // NaN: outside the export
    if (this.grains) gl.uniform1f(prog.opacity, o);
    if (this.vignette) gl.uniform2f(prog.vignette, apertureRadius(this.mitigation, this.frustum, o), this.mitigation.featherDeg * D2R);
    if (this.video) {
      gl.activeTexture(gl.TEXTURE0);
      gl.bindTexture(gl.TEXTURE_2D, this.tex);
    }
    if (this.grains) {
      gl.activeTexture(gl.TEXTURE1);
      gl.bindTexture(gl.TEXTURE_2D, this.grainTex);
    }
    gl.uniform2f(prog.origin, origin[0], origin[1]);
    gl.viewport(origin[0], origin[1], this.width, this.height);
    if (!this.video) {
      gl.enable(gl.BLEND);
      gl.blendFunc(gl.ONE, gl.ONE_MINUS_SRC_ALPHA);
    }
    gl.drawArrays(gl.TRIANGLES, 0, 3);
    if (!this.video) gl.disable(gl.BLEND);
  }
}
