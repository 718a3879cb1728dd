#version 430 core
// Full-screen pass: one triangle from gl_VertexID, no vertex buffer.
// Vertices (-1,-1), (3,-1), (-1,3) cover the viewport; the fragment shader works from
// gl_FragCoord, so nothing is passed on.
void main() {
    vec2 p = vec2(float((gl_VertexID & 1) << 2) - 1.0, float((gl_VertexID & 2) << 1) - 1.0);
    gl_Position = vec4(p, 0.0, 1.0);
}
