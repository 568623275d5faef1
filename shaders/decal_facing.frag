#version 430 core
// Decal angle fade: per texel, how squarely the nearest surface faces the projector, from the
// surface's own derivatives (decal_project.vert places the faces, depth-tested), turned into the
// fade engines apply (full below u_cos.x's angle, none beyond u_cos.y's, smooth between).

in vec3 v_world;

uniform vec3 u_axis;   // +Z of the projector (towards it), unit
uniform vec2 u_cos;    // cos(start angle), cos(end angle)

out float fade;

void main() {
    vec3 n = cross(dFdx(v_world), dFdy(v_world));
    float len = length(n);
    float c = len > 0.0 ? abs(dot(n, u_axis)) / len : 1.0;
    fade = smoothstep(u_cos.y, u_cos.x, c);
}
