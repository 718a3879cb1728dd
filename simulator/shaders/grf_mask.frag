#version 430 core
// Granulated rest frame: coverage (blocked fraction, 0..1) of the world-fixed grains on
// the sphere, as an equirect image (rendered once per GRF, then mipmapped and sampled by
// eye.frag). Conventions as eye.frag / simulator/sphere/geometry.py: texel (col x, row y), row 0
// = lat +pi/2 (texture row 0 is written from GL row 0, so the image needs no flip here:
// y = gl_FragCoord.y - 0.5 indexes texture rows the way eye.frag's t does).
//
// Grains come from simulator.grf.GrainBuckets in storage buffers: latitude bands of
// u_cell radians from the south pole, each cut into equal longitude cells; a cell lists
// every grain whose disc (grown by the antialiasing reach) reaches into it.

uniform vec2 u_size;               // mask size, texels (W, H = W / 2)
uniform float u_cell;              // latitude band height, radians
uniform int u_n_bands;
layout(std430, binding = 0) readonly buffer Bands { ivec2 bands[]; };   // first cell, n cells
layout(std430, binding = 1) readonly buffer Cells { int cell_start[]; };
layout(std430, binding = 2) readonly buffer Grains { vec4 grains[]; };  // xyz world, chord radius

out float coverage;

const float PI = 3.14159265358979;

void main() {
    float lon = gl_FragCoord.x / u_size.x * 2.0 * PI - PI;
    float lat = 0.5 * PI - gl_FragCoord.y / u_size.y * PI;
    vec3 p = vec3(cos(lat) * sin(lon), sin(lat), cos(lat) * cos(lon));
    // Box filter one texel row (pi / H rad) wide across each disc edge.
    float footprint = PI / u_size.y;
    int band = clamp(int(floor((lat + 0.5 * PI) / u_cell)), 0, u_n_bands - 1);
    ivec2 bl = bands[band];
    int c = bl.x + min(int(floor((lon + PI) / (2.0 * PI) * float(bl.y))), bl.y - 1);
    float trans = 1.0;
    for (int k = cell_start[c]; k < cell_start[c + 1]; ++k) {
        vec4 g = grains[k];
        // Chord length ~ angle (relative error < 1e-4 at 2 deg); g.w: chord radius.
        float cov = clamp((g.w - length(p - g.xyz)) / footprint + 0.5, 0.0, 1.0);
        trans *= 1.0 - cov;                                 // union of overlapping discs
    }
    coverage = 1.0 - trans;
}
