#version 430 core
// yuv420p chroma planes (U at location 0, V at location 1; R8, half the eye's width and
// height) from the eye image (eye.frag's RGBA8 colour, texel row 0 = image row 0, the
// top): the mean of the 2 x 2 pixels each chroma sample covers, BT.601 limited range as
// eye.frag's luma: U = 128 + 224 (B - Y') / 1.772, V = 128 + 224 (R - Y') / 1.402 with
// Y' = 0.299 R + 0.587 G + 0.114 B (R, G, B in 0..1), the conversion swscale applies to
// rgb24 -> yuv420p without a colour space. Chroma row 0 is the top, like every image here.

uniform sampler2D u_rgb;           // eye image, RGBA8

layout(location = 0) out float out_u;
layout(location = 1) out float out_v;

void main() {
    ivec2 p = 2 * ivec2(gl_FragCoord.xy);    // top-left pixel of the 2 x 2 block
    vec3 c = 0.25 * (texelFetch(u_rgb, p, 0).rgb + texelFetch(u_rgb, p + ivec2(1, 0), 0).rgb
                     + texelFetch(u_rgb, p + ivec2(0, 1), 0).rgb
                     + texelFetch(u_rgb, p + ivec2(1, 1), 0).rgb);
    float y = dot(c, vec3(0.299, 0.587, 0.114));
    out_u = (128.0 + 224.0 * (c.b - y) / 1.772) / 255.0;
    out_v = (128.0 + 224.0 * (c.r - y) / 1.402) / 255.0;
}
