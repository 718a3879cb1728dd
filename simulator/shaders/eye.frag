#version 430 core
// One eye's view of a frame (equirect, or another input projection sampled as stored), with
// the granulated rest frame (GRF).
//
// Conventions (simulator/sphere/geometry.py): world and head frames +x right, +y up, +z forward;
// lon = atan(x, z) (+ right), lat = asin(y) (+ up); equirect column x covers [x, x+1),
// its centre x + 0.5 maps to lon = (x + 0.5) / W * 2 pi - pi; row 0 is the top (lat + pi/2).
// The texture holds the frame as uploaded: texel row 0 = image row 0 (top), so
// t = 0.5 - lat / pi. Output pixel (col i, row j), row 0 at the top of the image, is
// i + 0.5 = gl_FragCoord.x and j + 0.5 = gl_FragCoord.y: the image is drawn upside down
// in GL's terms, which is the one flip (at the framebuffer boundary): GL reads rows back
// bottom (GL row 0) first, so they come out top first, with no CPU copy.
//
// Outputs: the RGB colour (location 0, RGBA8) and its luma as yuv420p's Y plane
// (location 1, R8: BT.601 limited range, 16 + 219 (0.299 R + 0.587 G + 0.114 B), the
// conversion swscale applies to rgb24 -> yuv420p without a colour space), so that the
// encoder gets Y without a CPU conversion; chroma420.frag makes U and V.
//
// Defines injected by render.py (each 0 or 1; a branch that cannot be taken costs
// llvmpipe nearly as much as one that is, so the variants are compiled apart):
//   PROJ           the frame's projection (simulator/render/sampling.py): 0 equirect (seam
//                  wrap, pole continuation); 1 cubemap c3x2 / c6x1, 2 eac, 3 dfisheye,
//                  4 hequirect: the view ray is carried into the stored frame (the maths of
//                  simulator/sphere/projections.py, v360's faces and rotations) and the
//                  frame sampled there, each tap kept inside the ray's face or lens.
//   MIPMAP         u_frame has mipmaps (some pixel minifies): choose cubic or trilinear
//                  per pixel; 0: every pixel magnifies (render.py checks): cubic only.
//   GRF            draw the grains: the world-fixed grain coverage (an equirect texture
//                  rendered once by grf_mask.frag) is looked up along each ray, times the
//                  head-fixed cutout and the opacity.
//   GRAIN_LOD      the coverage texture has mipmaps and some pixel outside the cutout's
//                  inner radius is larger than its texels: same footprint rule as the
//                  video; 0: level 0, bilinear (what that rule gives there anyway).
//   GRAIN_PARALLAX grains at a finite distance (eye offset); 0: at infinity, the ray
//                  from the eye is the view ray and the video's lon/lat are reused.
//   LOCAL_GRF      local-grf (simulator/mitigation/kinds.py): the grain alpha follows the flow
//                  of the ray's field cell (u_cell_opacity, nearest) instead of u_opacity.
//   VIGNETTE       the head-fixed tunneling vignette: alpha linear in eccentricity,
//                  clamp((ecc - radius) / feather + 1/2, 0, 1), in u_vignette_color.

uniform sampler2D u_frame;         // the eye's frame as uploaded, RGB8 (mipmapped with MIPMAP)
uniform mat3 u_head;               // head -> world rotation (geometry.head_rotation)
uniform vec2 u_tan_half;           // half width / height of the image on z = 1 (tan(fov / 2))
uniform vec2 u_tan_offset;         // its centre on z = 1: 0 for a symmetric view
uniform vec2 u_size;               // eye image size, pixels (width, height)
#if PROJ != 0
uniform float u_texel_rad;         // the frame's largest texel, radians (the filter's scale)
#endif

layout(location = 0) out vec4 frag_color;
layout(location = 1) out float frag_luma;

const float PI = 3.14159265358979;

// ffmpeg v360's "cubic": 4-point Lagrange interpolation weights for offsets -1, 0, 1, 2.
vec4 cubic_weights(float t) {
    float t2 = t * t;
    float t3 = t2 * t;
    return vec4(-t / 3.0 + t2 / 2.0 - t3 / 6.0,
                1.0 - t / 2.0 - t2 + t3 / 2.0,
                t + t2 / 2.0 - t3 / 2.0,
                -t / 6.0 + t3 / 6.0);
}

// Bicubic (Lagrange, as v360 interp=cubic) at continuous equirect pixel coordinates xy
// (pixel centres at +0.5), for magnification: 16 texel fetches of level 0 with longitude
// wrap-around at the +-180 deg seam and continuation across the poles (a row beyond a
// pole is the mirrored row on the meridian 180 deg away, as simulator.geometry pads).
// Indices are computed once per axis (faster on llvmpipe than 9 merged bilinear taps),
// wrapped with compares, not %: llvmpipe has no vector integer division and
// scalarises it (the modulo cost more than the 16 fetches, measured).
vec3 sample_cubic(vec2 xy) {
    ivec2 sz = textureSize(u_frame, 0);
    vec2 p = xy - 0.5;
    vec2 f = floor(p);
    vec2 t = p - f;
    ivec2 b = ivec2(f);
    vec4 wx = cubic_weights(t.x);
    vec4 wy = cubic_weights(t.y);
    ivec4 xr = ivec4(b.x - 1, b.x, b.x + 1, b.x + 2);            // b.x in [-1, W - 1]
    ivec4 xs = xr + sz.x * (ivec4(lessThan(xr, ivec4(0)))          // columns, wrapped
                            - ivec4(greaterThanEqual(xr, ivec4(sz.x))));
    ivec4 xo = xs + sz.x / 2;               // the same columns on the opposite meridian
    xo -= sz.x * ivec4(greaterThanEqual(xo, ivec4(sz.x)));
    ivec4 yr = ivec4(b.y - 1, b.y, b.y + 1, b.y + 2);
    bvec4 over = bvec4(yr.x < 0 || yr.x >= sz.y, yr.y < 0 || yr.y >= sz.y,
                       yr.z < 0 || yr.z >= sz.y, yr.w < 0 || yr.w >= sz.y);
    ivec4 ys = min(max(yr, -1 - yr), 2 * sz.y - 1 - yr);   // mirror rows across each pole
    vec3 acc = vec3(0.0);
    for (int j = 0; j < 4; ++j) {
        ivec4 c = over[j] ? xo : xs;
        vec3 row = wx.x * texelFetch(u_frame, ivec2(c.x, ys[j]), 0).rgb
                 + wx.y * texelFetch(u_frame, ivec2(c.y, ys[j]), 0).rgb
                 + wx.z * texelFetch(u_frame, ivec2(c.z, ys[j]), 0).rgb
                 + wx.w * texelFetch(u_frame, ivec2(c.w, ys[j]), 0).rgb;
        acc += wy[j] * row;
    }
    return acc;
}

#if PROJ != 0
// ---- Other input projections, sampled as stored (simulator/sphere/projections.py) ----
// locate_*(d) gives the ray's continuous texel coordinates xy in the stored frame (pixel
// centres at +0.5) and the box of texels (first and last column and row, inclusive) that
// its filter may read: the ray's cube face (eac: its row of faces, pads included: v360
// writes the faces continued into them), or its lens half. xy is clamped to the centres
// of the box's edge texels (the half-texel clamp), so a face never mixes with an
// unrelated neighbour; v360 works in y DOWN, so its y is -d.y.
struct Where { vec2 xy; ivec4 box; bool covered; };

#if PROJ == 1 || PROJ == 2
uniform vec4 u_face_rect[6];   // per v360 direction (r, l, u, d, f, b): origin xy, size (texels)
uniform vec4 u_face_box[6];    // the texel box it may read: x0, y0, x1, y1
uniform vec4 u_face_rot[6];    // v360's face rotation: u' = a u + b v, v' = c u + d v

// v360's xyz_to_cube (the major axis; up/down only when |y| is strictly the largest) and
// the face layout: c3x2 / c6x1 (PROJ 1: uf -> (uf + 1) / 2) or eac (PROJ 2: equi-angular,
// uf -> 2/pi atan(uf) + 1/2).
Where locate_cube(vec3 d) {
    float x = d.x, yv = -d.y, z = d.z;
    vec3 a = abs(vec3(x, yv, z));
    int k;
    vec2 uv;
    if (a.y > a.x && a.y > a.z) {
        k = yv < 0.0 ? 2 : 3;
        uv = vec2(x, -z * sign(yv)) / a.y;
    } else if (a.x > a.z) {
        k = x > 0.0 ? 0 : 1;
        uv = vec2(-z * sign(x), yv) / a.x;
    } else {
        k = z >= 0.0 ? 4 : 5;
        uv = vec2(x * sign(z), yv) / a.z;
    }
    vec4 r = u_face_rot[k];
    uv = vec2(dot(r.xy, uv), dot(r.zw, uv));
#if PROJ == 2
    vec2 t = atan(uv) * (2.0 / PI) + 0.5;
#else
    vec2 t = 0.5 * uv + 0.5;
#endif
    vec4 rect = u_face_rect[k];
    return Where(rect.xy + rect.zw * t, ivec4(u_face_box[k]), true);
}
#define LOCATE locate_cube
#endif

#if PROJ == 3
uniform float u_lens_fov;      // dual fisheye lens FOV, radians

// Equidistant lenses side by side (H x H each): the front one (z >= 0) on the right, the
// back one on the left, mirrored; radius angle / lens FOV of the frame height.
Where locate_dfisheye(vec3 d) {
    ivec2 sz = textureSize(u_frame, 0);
    float ew = float(sz.y);
    float x = d.x, yv = -d.y;
    float hh = length(vec2(x, yv));
    float r = atan(hh, abs(d.z)) / u_lens_fov;          // 0.5 at the lens rim
    vec2 q = hh > 0.0 ? vec2(x, yv) / hh : vec2(0.0);
    vec2 p = (r * q + 0.5) * ew;
    bool front = d.z >= 0.0;
    vec2 xy = vec2(front ? ew + p.x : ew - p.x, p.y);
    ivec4 box = front ? ivec4(sz.y, 0, sz.x - 1, sz.y - 1) : ivec4(0, 0, sz.y - 1, sz.y - 1);
    return Where(xy, box, true);
}
#define LOCATE locate_dfisheye
#endif

#if PROJ == 4
// Half equirect (VR180's eye): longitude and latitude -90..90 deg; the back half uncovered.
Where locate_hequirect(vec3 d) {
    ivec2 sz = textureSize(u_frame, 0);
    float lon = atan(d.x, d.z);
    float lat = asin(clamp(d.y, -1.0, 1.0));
    vec2 xy = vec2(lon / PI + 0.5, 0.5 - lat / PI) * vec2(sz);
    return Where(xy, ivec4(0, 0, sz - 1), abs(lon) <= 0.5 * PI);
}
#define LOCATE locate_hequirect
#endif

// Bicubic (v360's Lagrange, as sample_cubic) inside a texel box: xy clamped to the centres
// of its edge texels, taps clamped to it.
vec4 keys_weights(float t) {
    const float a = -0.75;
    float t1 = t + 1.0, t2 = 1.0 - t, t3 = 2.0 - t;
    return vec4(((a * t1 - 5.0 * a) * t1 + 8.0 * a) * t1 - 4.0 * a,
                ((a + 2.0) * t - (a + 3.0)) * t * t + 1.0,
                ((a + 2.0) * t2 - (a + 3.0)) * t2 * t2 + 1.0,
                ((a * t3 - 5.0 * a) * t3 + 8.0 * a) * t3 - 4.0 * a);
}

vec3 sample_cubic_box(vec2 xy, ivec4 box) {
    xy = clamp(xy, vec2(box.xy) + 0.5, vec2(box.zw) + 0.5);
    vec2 p = xy - 0.5;
    vec2 f = floor(p);
    vec2 t = p - f;
    ivec2 b = ivec2(f);
#ifndef KEYS
#define KEYS 0
#endif
#if KEYS
    vec4 wx = keys_weights(t.x);
    vec4 wy = keys_weights(t.y);
#else
    vec4 wx = cubic_weights(t.x);
    vec4 wy = cubic_weights(t.y);
#endif
    ivec4 xs = clamp(ivec4(b.x - 1, b.x, b.x + 1, b.x + 2), box.x, box.z);
    ivec4 ys = clamp(ivec4(b.y - 1, b.y, b.y + 1, b.y + 2), box.y, box.w);
    vec3 acc = vec3(0.0);
    for (int j = 0; j < 4; ++j) {
        vec3 row = wx.x * texelFetch(u_frame, ivec2(xs.x, ys[j]), 0).rgb
                 + wx.y * texelFetch(u_frame, ivec2(xs.y, ys[j]), 0).rgb
                 + wx.z * texelFetch(u_frame, ivec2(xs.z, ys[j]), 0).rgb
                 + wx.w * texelFetch(u_frame, ivec2(xs.w, ys[j]), 0).rgb;
        acc += wy[j] * row;
    }
    return acc;
}

// Trilinear mips inside a texel box: xy kept half a texel of the coarser level inside it.
vec3 sample_mip_box(vec2 xy, ivec4 box, float lod) {
    vec2 tsz = vec2(textureSize(u_frame, 0));
    float m = 0.5 * exp2(ceil(max(lod, 0.0)));
    vec2 lo = vec2(box.xy) + m, hi = vec2(box.zw) + 1.0 - m;
    xy = clamp(xy, min(lo, hi), max(lo, hi));
    return textureLod(u_frame, xy / tsz, lod).rgb;
}
#endif

#if GRF
uniform sampler2D u_grains;        // GRF coverage on the sphere, equirect, mipmapped (grf_mask.frag)
uniform float u_opacity;           // EPOF-driven GRF opacity, 0..1
uniform vec2 u_cutout;             // inner, outer cutout radius, radians
#if GRAIN_PARALLAX
uniform vec3 u_eye_offset;         // eye position in the world frame / grain distance
#endif
#if LOCAL_GRF
uniform sampler2D u_cell_opacity;  // per-cell grain opacity, lon/lat cells (row 0 north), nearest
#endif
#endif
#if VIGNETTE
uniform vec2 u_vignette;           // aperture radius (alpha 1/2), feather width, radians
uniform vec3 u_vignette_color;     // RGB 0..1
#endif

void main() {
    // Pixel centre on the image plane z = 1 (geometry.perspective_rays).
    vec2 ij = gl_FragCoord.xy;
    vec2 uv = vec2((ij.x / u_size.x * 2.0 - 1.0) * u_tan_half.x + u_tan_offset.x,
                   (1.0 - ij.y / u_size.y * 2.0) * u_tan_half.y + u_tan_offset.y);
    vec3 d_head = normalize(vec3(uv, 1.0));
    vec3 d = u_head * d_head;

    float lon = atan(d.x, d.z);
    float lat = asin(clamp(d.y, -1.0, 1.0));
    vec2 st = vec2(lon / (2.0 * PI) + 0.5, 0.5 - lat / PI);
    vec2 tsz = vec2(textureSize(u_frame, 0));

    // Filter width from the pixel's angular footprint (radians, major axis), measured on
    // the sphere, against the frame's angular texel size (equirect: pi / H rad per row;
    // other projections: u_texel_rad, their largest texel, e.g. a cube face's centre).
    // This is seam- and pole-continuous (no texture-coordinate derivatives, which jump at
    // the +-180 deg seam and face edges and blow up in longitude near the poles, where the
    // equirect is oversampled anyway, as a cube face is towards its corners).
    vec3 ddx = dFdx(d_head), ddy = dFdy(d_head);
    float footprint_max = max(length(ddx), length(ddy));
#if PROJ == 0
    vec2 xy = st * tsz;                                     // continuous texel coordinates
    float rho = footprint_max / (PI / tsz.y);                // texels per pixel
#if MIPMAP
    vec3 color;
    if (rho <= 1.0) {
        color = sample_cubic(xy);                     // magnification: v360's cubic
    } else {
        color = textureLod(u_frame, xy / tsz, log2(rho)).rgb;  // minification: trilinear mips
    }
#else
    vec3 color = sample_cubic(xy);                    // magnification everywhere
#endif
#else
    Where w = LOCATE(d);
    float rho = footprint_max / u_texel_rad;
#if PROJ == 1
    // A cube face's texels shrink away from its centre: across the ray, as the cosine of
    // its angle to the face's axis (the ray's largest component); along it as the
    // square, which would blur more (1-2 dB further from a supersampled view, measured).
    rho /= max(max(abs(d.x), abs(d.y)), abs(d.z));
#endif
#if MIPMAP
    vec3 color = rho <= 1.0 ? sample_cubic_box(w.xy, w.box)
                            : sample_mip_box(w.xy, w.box, log2(rho));
#else
    vec3 color = sample_cubic_box(w.xy, w.box);
#endif
    color *= float(w.covered);                       // uncovered: black, as the CPU path
#endif

#if GRF
    float ecc = atan(length(d_head.xy), d_head.z);
    float cut = clamp((ecc - u_cutout.x) / (u_cutout.y - u_cutout.x), 0.0, 1.0);
#if LOCAL_GRF
    float k = cut * texture(u_cell_opacity, st).r;
#else
    float k = cut * u_opacity;
#endif
    if (k > 0.0) {
        // Ray from the eye (offset o, in grain-distance units) to the grain sphere |p| = 1.
#if GRAIN_PARALLAX
        vec3 o = u_eye_offset;
        float b = dot(o, d);
        float tt = -b + sqrt(max(b * b - dot(o, o) + 1.0, 0.0));
        vec3 p = normalize(o + tt * d);
        vec2 gst = vec2(atan(p.x, p.z) / (2.0 * PI) + 0.5, 0.5 - asin(clamp(p.y, -1.0, 1.0)) / PI);
#else
        vec2 gst = st;                                      // p = d: grains at infinity
#endif
#if GRAIN_LOD
        float grho = footprint_max / (PI / float(textureSize(u_grains, 0).y));
        float cov = textureLod(u_grains, gst, log2(max(grho, 1e-6))).r;
#else
        float cov = textureLod(u_grains, gst, 0.0).r;
#endif
        color *= 1.0 - k * cov;                             // black grains, "over"
    }
#endif
#if VIGNETTE
    float vecc = atan(length(d_head.xy), d_head.z);
    float va = u_vignette.y > 0.0 ? clamp((vecc - u_vignette.x) / u_vignette.y + 0.5, 0.0, 1.0)
                                  : float(vecc >= u_vignette.x);
    color = mix(color, u_vignette_color, va);               // head-fixed, over everything
#endif
    frag_color = vec4(color, 1.0);
    frag_luma = (16.0 + 219.0 * dot(clamp(color, 0.0, 1.0), vec3(0.299, 0.587, 0.114))) / 255.0;
}
