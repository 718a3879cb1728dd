#version 430 core
// One eye's view of an equirectangular frame, with the granulated rest frame (GRF).
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
//   MIPMAP         u_equirect has mipmaps (some pixel minifies): choose cubic or trilinear
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

uniform sampler2D u_equirect;      // the eye's equirect frame, mipmapped, RGB8, s repeats
uniform mat3 u_head;               // head -> world rotation (geometry.head_rotation)
uniform vec2 u_tan_half;           // half width / height of the image on z = 1 (tan(fov / 2))
uniform vec2 u_tan_offset;         // its centre on z = 1: 0 for a symmetric view
uniform vec2 u_size;               // eye image size, pixels (width, height)

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
    ivec2 sz = textureSize(u_equirect, 0);
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
        vec3 row = wx.x * texelFetch(u_equirect, ivec2(c.x, ys[j]), 0).rgb
                 + wx.y * texelFetch(u_equirect, ivec2(c.y, ys[j]), 0).rgb
                 + wx.z * texelFetch(u_equirect, ivec2(c.z, ys[j]), 0).rgb
                 + wx.w * texelFetch(u_equirect, ivec2(c.w, ys[j]), 0).rgb;
        acc += wy[j] * row;
    }
    return acc;
}

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
    vec2 tsz = vec2(textureSize(u_equirect, 0));
    vec2 xy = st * tsz;                                     // continuous texel coordinates

    // Filter width from the pixel's angular footprint (radians, major axis), measured on
    // the sphere, against the equirect's angular texel size (pi / H rad per row). This is
    // seam- and pole-continuous (no texture-coordinate derivatives, which jump at the
    // +-180 deg seam and blow up in longitude near the poles, where the equirect is
    // oversampled anyway).
    vec3 ddx = dFdx(d_head), ddy = dFdy(d_head);
    float footprint_max = max(length(ddx), length(ddy));
    float rho = footprint_max / (PI / tsz.y);                // texels per pixel

#if MIPMAP
    vec3 color;
    if (rho <= 1.0) {
        color = sample_cubic(xy);                     // magnification: v360's cubic
    } else {
        color = textureLod(u_equirect, xy / tsz, log2(rho)).rgb;  // minification: trilinear mips
    }
#else
    vec3 color = sample_cubic(xy);                    // magnification everywhere
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
