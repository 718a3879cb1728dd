#version 430 core
// One eye's view of an equirectangular frame, with the granulated rest frame (GRF).
//
// Conventions (simulator/geometry.py): world and head frames +x right, +y up, +z forward;
// lon = atan(x, z) (+ right), lat = asin(y) (+ up); equirect column x covers [x, x+1),
// its centre x + 0.5 maps to lon = (x + 0.5) / W * 2 pi - pi; row 0 is the top (lat + pi/2).
// The texture holds the frame as uploaded: texel row 0 = image row 0 (top), so
// t = 0.5 - lat / pi. Output pixel (col i, row j), row 0 at the top of the image, is
// i + 0.5 = gl_FragCoord.x and j + 0.5 = u_size.y - gl_FragCoord.y; the readback is
// flipped once in render.py so that rows come out top first.
//
// Defines injected by render.py: GRF (0 or 1).

uniform sampler2D u_equirect;      // the eye's equirect frame, mipmapped, RGB8, s repeats
uniform mat3 u_head;               // head -> world rotation (geometry.head_rotation)
uniform vec2 u_tan_half;           // tan(hfov / 2), tan(vfov / 2)
uniform vec2 u_size;               // eye image size, pixels (width, height)

out vec4 frag_color;

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

// Texel (col, row) of level 0 with longitude wrap-around and pole continuation: a row
// beyond a pole is the mirrored row on the meridian 180 deg away.
vec3 fetch_wrapped(ivec2 p, ivec2 sz) {
    if (p.y < 0) { p.y = -1 - p.y; p.x += sz.x / 2; }
    else if (p.y >= sz.y) { p.y = 2 * sz.y - 1 - p.y; p.x += sz.x / 2; }
    p.x = ((p.x % sz.x) + sz.x) % sz.x;
    return texelFetch(u_equirect, p, 0).rgb;
}

// Bicubic (Lagrange, as v360 interp=cubic) at continuous equirect pixel coordinates xy
// (pixel centres at +0.5), for magnification.
vec3 sample_cubic(vec2 xy) {
    ivec2 sz = textureSize(u_equirect, 0);
    vec2 p = xy - 0.5;
    vec2 f = floor(p);
    vec2 t = p - f;
    ivec2 b = ivec2(f);
    vec4 wx = cubic_weights(t.x);
    vec4 wy = cubic_weights(t.y);
    vec3 acc = vec3(0.0);
    for (int j = 0; j < 4; ++j) {
        vec3 row = wx.x * fetch_wrapped(b + ivec2(-1, j - 1), sz)
                 + wx.y * fetch_wrapped(b + ivec2(0, j - 1), sz)
                 + wx.z * fetch_wrapped(b + ivec2(1, j - 1), sz)
                 + wx.w * fetch_wrapped(b + ivec2(2, j - 1), sz);
        acc += wy[j] * row;
    }
    return acc;
}

#if GRF
uniform float u_opacity;           // EPOF-driven GRF opacity, 0..1
uniform vec2 u_cutout;             // inner, outer cutout radius, radians
uniform vec3 u_eye_offset;         // eye position in the world frame / grain distance
uniform float u_cell;              // latitude band height, radians (grf.GrainBuckets)
uniform int u_n_bands;
layout(std430, binding = 0) readonly buffer Bands { ivec2 bands[]; };   // first cell, n cells
layout(std430, binding = 1) readonly buffer Cells { int cell_start[]; };
layout(std430, binding = 2) readonly buffer Grains { vec4 grains[]; };  // xyz world, radius

// Transmittance (1 - blocked fraction) of the grains along world ray p (unit), with
// antialiased edges: a box filter of angular width `footprint` across each disc edge.
float grain_transmittance(vec3 p, float footprint) {
    float lat = asin(clamp(p.y, -1.0, 1.0));
    float lon = atan(p.x, p.z);
    int band = clamp(int(floor((lat + 0.5 * PI) / u_cell)), 0, u_n_bands - 1);
    ivec2 bl = bands[band];
    int c = bl.x + min(int(floor((lon + PI) / (2.0 * PI) * float(bl.y))), bl.y - 1);
    float trans = 1.0;
    for (int k = cell_start[c]; k < cell_start[c + 1]; ++k) {
        vec4 g = grains[k];
        float dist = 2.0 * asin(min(0.5 * length(p - g.xyz), 1.0));  // exact for small angles
        float cov = clamp((g.w - dist) / footprint + 0.5, 0.0, 1.0);
        trans *= 1.0 - cov;
    }
    return trans;
}
#endif

void main() {
    // Pixel centre on the image plane z = 1 (geometry.perspective_rays).
    vec2 ij = vec2(gl_FragCoord.x, u_size.y - gl_FragCoord.y);
    vec2 uv = vec2((ij.x / u_size.x * 2.0 - 1.0) * u_tan_half.x,
                   (1.0 - ij.y / u_size.y * 2.0) * u_tan_half.y);
    vec3 d_head = normalize(vec3(uv, 1.0));
    vec3 d = u_head * d_head;

    float lon = atan(d.x, d.z);
    float lat = asin(clamp(d.y, -1.0, 1.0));
    vec2 st = vec2(lon / (2.0 * PI) + 0.5, 0.5 - lat / PI);
    vec2 tsz = vec2(textureSize(u_equirect, 0));

    // Filter width from the pixel's angular footprint (radians, major axis), measured on
    // the sphere, against the equirect's angular texel size (pi / H rad per row). This is
    // seam- and pole-continuous (no texture-coordinate derivatives, which jump at the
    // +-180 deg seam and blow up in longitude near the poles, where the equirect is
    // oversampled anyway).
    vec3 ddx = dFdx(d_head), ddy = dFdy(d_head);
    float footprint_max = max(length(ddx), length(ddy));
    float rho = footprint_max / (PI / tsz.y);                // texels per pixel

    vec3 color;
    if (rho <= 1.0) {
        color = sample_cubic(st * tsz);                     // magnification: v360's cubic
    } else {
        color = textureLod(u_equirect, st, log2(rho)).rgb;  // minification: trilinear mips
    }

#if GRF
    // Angular footprint of this pixel (radians), from the head-frame ray's derivatives.
    float footprint = sqrt(length(ddx) * length(ddy));
    float ecc = atan(length(d_head.xy), d_head.z);
    float cut = clamp((ecc - u_cutout.x) / (u_cutout.y - u_cutout.x), 0.0, 1.0);
    float k = cut * u_opacity;
    if (k > 0.0) {
        // Ray from the eye (offset o, in grain-distance units) to the grain sphere |p| = 1.
        vec3 o = u_eye_offset;
        float b = dot(o, d);
        float tt = -b + sqrt(max(b * b - dot(o, o) + 1.0, 0.0));
        vec3 p = normalize(o + tt * d);
        float alpha = k * (1.0 - grain_transmittance(p, max(footprint, 1e-6)));
        color *= 1.0 - alpha;                               // black grains, "over"
    }
#endif
    frag_color = vec4(color, 1.0);
}
