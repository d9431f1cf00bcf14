// render/shaders.hpp — GLSL 3.30 sources of the renderer's passes.
//
// Spheres are ray-cast impostors: one camera-facing quad per sphere, sized to
// cover the sphere's exact silhouette under perspective; the fragment shader
// intersects the eye ray with the sphere, discards misses, and writes the true
// depth of the hit (so spheres intersect each other and the walls correctly)
// and its normal for lighting. The shadow pass draws the same impostors from
// the light with an orthographic projection.
#pragma once

namespace marbles::render::shaders {

// Shared by every lit fragment shader: background gradient (also the fog
// colour of the floor), shadow lookup, and the lighting model.
inline constexpr const char* kCommon = R"(
uniform vec2 u_viewport;      // framebuffer size, pixels
uniform vec3 u_bg_top;
uniform vec3 u_bg_bottom;
uniform int u_lighting;
uniform int u_shadows;
uniform vec3 u_light_view;    // unit vector towards the light, view space
uniform vec3 u_up_view;       // world up, view space
uniform sampler2DShadow u_shadow_map;
uniform mat4 u_view_to_light; // view space -> light clip space
uniform float u_shadow_offset;// normal offset against acne, scene units
uniform float u_shadow_texel; // 1 / shadow-map size

vec3 background(vec2 frag) {
  vec2 uv = frag / u_viewport;
  vec3 c = mix(u_bg_bottom, u_bg_top, smoothstep(0.0, 1.0, uv.y));
  float r = length((uv - vec2(0.5, 0.55)) * vec2(1.0, 0.8));
  return c * (1.0 - 0.16 * smoothstep(0.3, 0.85, r));
}

float shadow_at(vec3 p_view, vec3 n_view) {
  if (u_shadows == 0) return 1.0;
  vec3 s = (u_view_to_light * vec4(p_view + n_view * u_shadow_offset, 1.0)).xyz * 0.5 + 0.5;
  float d = 0.75 * u_shadow_texel;
  float sum = texture(u_shadow_map, vec3(s.xy + vec2(-d, -d), s.z))
            + texture(u_shadow_map, vec3(s.xy + vec2( d, -d), s.z))
            + texture(u_shadow_map, vec3(s.xy + vec2(-d,  d), s.z))
            + texture(u_shadow_map, vec3(s.xy + vec2( d,  d), s.z));
  return 0.25 * sum;
}

// Lambert key light with shadow, sky/ground hemisphere fill, Blinn-Phong
// highlight; in linear light, returned as sRGB.
vec3 shade(vec3 base_srgb, vec3 n, vec3 v, float shadow, float shininess, float specular) {
  vec3 base = pow(base_srgb, vec3(2.2));
  float hemi = 0.5 + 0.5 * dot(n, u_up_view);
  vec3 ambient = mix(vec3(0.10, 0.10, 0.11), vec3(0.34, 0.36, 0.40), hemi);
  float diffuse = max(dot(n, u_light_view), 0.0) * shadow;
  vec3 h = normalize(u_light_view + v);
  float spec = pow(max(dot(n, h), 0.0), shininess) * specular * shadow;
  vec3 c = base * (ambient + vec3(1.0, 0.97, 0.92) * diffuse) + vec3(spec);
  return pow(clamp(c, 0.0, 1.0), vec3(1.0 / 2.2));
}
)";

inline constexpr const char* kBackgroundVertex = R"(
void main() {
  vec2 p = vec2(float((gl_VertexID << 1) & 2), float(gl_VertexID & 2));
  gl_Position = vec4(p * 2.0 - 1.0, 1.0, 1.0);
}
)";

inline constexpr const char* kBackgroundFragment = R"(
out vec4 o_color;
void main() { o_color = vec4(background(gl_FragCoord.xy), 1.0); }
)";

inline constexpr const char* kSphereVertex = R"(
layout(location = 0) in vec4 a_sphere;  // centre (scene frame), radius
layout(location = 1) in vec4 a_color;
uniform mat4 u_view;
uniform mat4 u_proj;
out vec3 v_pos;                  // view-space point on the quad
flat out vec4 v_sphere;          // view-space centre, radius
flat out vec3 v_color;
void main() {
  vec2 corner = vec2(float(gl_VertexID & 1), float(gl_VertexID >> 1)) * 2.0 - 1.0;
  vec3 c = (u_view * vec4(a_sphere.xyz, 1.0)).xyz;
  float r = a_sphere.w;
  float d2 = dot(c, c);
  v_sphere = vec4(c, r);
  v_color = a_color.rgb;
  if (d2 <= r * r * 1.0001) {    // the eye is inside this sphere: skip it
    v_pos = vec3(0.0);
    gl_Position = vec4(2.0, 2.0, 2.0, 1.0);
    return;
  }
  // A quad through the centre, facing the eye; the silhouette cone cuts its
  // plane in a circle of radius r / sqrt(1 - r^2/d^2).
  vec3 w = c * inversesqrt(d2);
  vec3 a = abs(w.y) < 0.99 ? vec3(0.0, 1.0, 0.0) : vec3(1.0, 0.0, 0.0);
  vec3 u = normalize(cross(a, w));
  vec3 v = cross(w, u);
  float s = r * inversesqrt(1.0 - r * r / d2);
  v_pos = c + (u * corner.x + v * corner.y) * s;
  gl_Position = u_proj * vec4(v_pos, 1.0);
}
)";

inline constexpr const char* kSphereFragment = R"(
uniform mat4 u_proj;
in vec3 v_pos;
flat in vec4 v_sphere;
flat in vec3 v_color;
out vec4 o_color;
void main() {
  vec3 dir = normalize(v_pos);
  vec3 c = v_sphere.xyz;
  float r = v_sphere.w;
  float b = dot(dir, c);
  vec3 q = c - b * dir;                 // closest approach of the ray to the centre
  float disc = r * r - dot(q, q);
  if (disc < 0.0) discard;
  vec3 hit = dir * (b - sqrt(disc));
  vec3 n = (hit - c) / r;
  vec4 clip = u_proj * vec4(hit, 1.0);
  gl_FragDepth = 0.5 * clip.z / clip.w + 0.5;
  if (u_lighting == 0) { o_color = vec4(v_color, 1.0); return; }
  o_color = vec4(shade(v_color, n, -dir, shadow_at(hit, n), 60.0, 0.30), 1.0);
}
)";

inline constexpr const char* kShadowVertex = R"(
layout(location = 0) in vec4 a_sphere;
uniform mat4 u_light_view_matrix;
uniform mat4 u_light_proj;
out vec2 v_uv;
flat out float v_radius;
void main() {
  vec2 corner = vec2(float(gl_VertexID & 1), float(gl_VertexID >> 1)) * 2.0 - 1.0;
  vec3 c = (u_light_view_matrix * vec4(a_sphere.xyz, 1.0)).xyz;
  v_uv = corner;
  v_radius = a_sphere.w;
  gl_Position = u_light_proj * vec4(c + vec3(corner * a_sphere.w, 0.0), 1.0);
}
)";

inline constexpr const char* kShadowFragment = R"(
uniform float u_depth_per_unit;   // window depth per scene unit along the light (1 / (far - near))
in vec2 v_uv;
flat in float v_radius;
void main() {
  float d2 = dot(v_uv, v_uv);
  if (d2 > 1.0) discard;
  gl_FragDepth = gl_FragCoord.z - v_radius * sqrt(1.0 - d2) * u_depth_per_unit;
}
)";

inline constexpr const char* kWallVertex = R"(
layout(location = 0) in vec3 a_pos;     // scene frame
layout(location = 1) in vec3 a_normal;  // scene frame, towards the free side
layout(location = 2) in vec2 a_grid;    // surface coordinates in grid cells
uniform mat4 u_view;
uniform mat4 u_proj;
out vec3 v_world;
out vec3 v_view;
out vec3 v_normal;
out vec2 v_grid;
void main() {
  v_world = a_pos;
  v_view = (u_view * vec4(a_pos, 1.0)).xyz;
  v_normal = mat3(u_view) * a_normal;
  v_grid = a_grid;
  gl_Position = u_proj * vec4(v_view, 1.0);
}
)";

inline constexpr const char* kWallFragment = R"(
uniform vec3 u_base;
uniform vec3 u_fade_center;
uniform vec2 u_fade;          // fade to the background between these distances; y <= 0: none
in vec3 v_world;
in vec3 v_view;
in vec3 v_normal;
in vec2 v_grid;
out vec4 o_color;
void main() {
  vec2 g = v_grid;
  float checker = mod(floor(g.x) + floor(g.y), 2.0);
  vec2 to_line = abs(fract(g - 0.5) - 0.5) / max(fwidth(g), vec2(1e-6));
  float line = 1.0 - min(min(to_line.x, to_line.y), 1.0);
  vec3 base = u_base * (1.0 - 0.05 * checker) * (1.0 - 0.22 * line);
  vec3 n = normalize(v_normal);
  if (dot(n, v_view) > 0.0) n = -n;
  vec3 col = base;
  if (u_lighting != 0) col = shade(base, n, normalize(-v_view), shadow_at(v_view, n), 24.0, 0.04);
  if (u_fade.y > 0.0)
    col = mix(col, background(gl_FragCoord.xy), smoothstep(u_fade.x, u_fade.y, length(v_world - u_fade_center)));
  o_color = vec4(col, 1.0);
}
)";

// Box edges as screen-space ribbons of constant pixel width.
inline constexpr const char* kEdgeVertex = R"(
layout(location = 0) in vec3 a_p0;
layout(location = 1) in vec3 a_p1;
uniform mat4 u_view;
uniform mat4 u_proj;
uniform vec2 u_viewport;
uniform float u_near;
uniform float u_width_px;
void main() {
  int end = gl_VertexID & 1;
  float side = (gl_VertexID >> 1) == 0 ? -1.0 : 1.0;
  vec3 a = (u_view * vec4(a_p0, 1.0)).xyz;
  vec3 b = (u_view * vec4(a_p1, 1.0)).xyz;
  float zn = -u_near;
  if (a.z > zn && b.z > zn) { gl_Position = vec4(2.0, 2.0, 2.0, 1.0); return; }
  if (a.z > zn) a = mix(a, b, (a.z - zn) / (a.z - b.z));
  if (b.z > zn) b = mix(b, a, (b.z - zn) / (b.z - a.z));
  vec4 ca = u_proj * vec4(a, 1.0);
  vec4 cb = u_proj * vec4(b, 1.0);
  vec2 sa = ca.xy / ca.w * u_viewport;
  vec2 sb = cb.xy / cb.w * u_viewport;
  vec2 d = sb - sa;
  d = dot(d, d) > 1e-12 ? normalize(d) : vec2(1.0, 0.0);
  vec4 c = end == 0 ? ca : cb;
  c.xy += vec2(-d.y, d.x) * side * u_width_px / u_viewport * c.w;
  gl_Position = c;
}
)";

inline constexpr const char* kEdgeFragment = R"(
uniform vec3 u_edge_color;
out vec4 o_color;
void main() { o_color = vec4(u_edge_color, 1.0); }
)";

}  // namespace marbles::render::shaders
