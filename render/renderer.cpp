// render/renderer.cpp — the passes of one frame:
//
//   1. per-sphere instance data (centre relative to the scene centre, radius,
//      colour from the colour map), uploaded once;
//   2. shadow pass: sphere impostors into a depth texture, orthographic from
//      the light;
//   3. main pass at `supersample` x the final size: background gradient,
//      walls (floor planes with a grid fading into the background; the inside
//      faces of boxes that face the camera), box edges, sphere impostors;
//   4. box-filter down in linear light, flip to top-first rows;
//   5. colour legend and time label on the CPU.
//
// Positions are shifted to the scene centre before they become floats, so a
// scene far from the origin renders as well as one around it.
#include "render/renderer.hpp"


#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <limits>
#include <string>
#include <vector>

#include "core/error.hpp"
#include "render/occlusion.hpp"
#include "render/osmesa_context.hpp"
#include "render/overlay.hpp"

#if defined(MARBLES_HAVE_OSMESA)
#include "render/gl.hpp"
#include "render/shaders.hpp"
#include "render/d3.hpp"
#endif

namespace marbles::render {

Walls walls_at(const Walls& walls, double time) {
  Walls w = walls;
  const real t = static_cast<real>(time);
  for (PlaneWall& p : w.planes) p.point += p.velocity * t;
  for (BoxWall& b : w.boxes) b.lo += b.velocity * t, b.hi += b.velocity * t;
  for (SphereWall& sp : w.spheres) sp.centre += sp.velocity * t;
  return w;
}

void ColorRange::add(const ColorRange& o) {
  lo = std::min(lo, o.lo);
  hi = std::max(hi, o.hi);
}

namespace {

double color_value(const Snapshot& s, ColorBy by, std::size_t i) {
  switch (by) {
    case ColorBy::speed: return length(s.velocity[i]);
    case ColorBy::id: return s.id[i];
    case ColorBy::radius: return s.radius[i];
    case ColorBy::material: return s.material[i];
  }
  return 0;
}

}  // namespace

bool has_color_data(const Snapshot& s, ColorBy by) {
  const std::size_t n = s.size();
  switch (by) {
    case ColorBy::speed: return s.velocity.size() == n;
    case ColorBy::id: return s.id.size() == n;
    case ColorBy::radius: return s.radius.size() == n;
    case ColorBy::material: return s.material.size() == n;
  }
  return false;
}

const char* color_data_name(ColorBy by) { return by == ColorBy::speed ? "velocity" : color_by_name(by); }

ColorRange data_range(const Snapshot& s, ColorBy by) {
  if (s.size() == 0 || !has_color_data(s, by)) return {0, 1};
  ColorRange r{1e300, -1e300};
  for (std::size_t i = 0; i < s.size(); ++i) {
    const double v = color_value(s, by, i);
    if (!std::isfinite(v)) continue;
    r.lo = std::min(r.lo, v);
    r.hi = std::max(r.hi, v);
  }
  if (r.lo > r.hi) return {0, 1};
  return r;
}

#if defined(MARBLES_HAVE_OSMESA)

bool renderer_available() { return true; }

namespace {

// ---- small double-precision 3-D math for the camera and light -------------

D3 any_perpendicular(D3 n) {
  const D3 a = std::abs(n.x) < 0.9 ? D3{1, 0, 0} : D3{0, 1, 0};
  return normalize(cross(n, a));
}

// Column-major 4x4, as OpenGL wants it: m[column * 4 + row].
struct M4 {
  std::array<double, 16> m{};
  static M4 identity() {
    M4 r;
    r.m[0] = r.m[5] = r.m[10] = r.m[15] = 1;
    return r;
  }
  double& at(int row, int col) { return m[col * 4 + row]; }
  double at(int row, int col) const { return m[col * 4 + row]; }
  std::array<float, 16> f() const {
    std::array<float, 16> r;
    for (int i = 0; i < 16; ++i) r[i] = static_cast<float>(m[i]);
    return r;
  }
};

M4 operator*(const M4& a, const M4& b) {
  M4 r;
  for (int i = 0; i < 4; ++i)
    for (int j = 0; j < 4; ++j) {
      double s = 0;
      for (int k = 0; k < 4; ++k) s += a.at(i, k) * b.at(k, j);
      r.at(i, j) = s;
    }
  return r;
}

D3 transform_point(const M4& a, D3 p) {
  return {a.at(0, 0) * p.x + a.at(0, 1) * p.y + a.at(0, 2) * p.z + a.at(0, 3),
          a.at(1, 0) * p.x + a.at(1, 1) * p.y + a.at(1, 2) * p.z + a.at(1, 3),
          a.at(2, 0) * p.x + a.at(2, 1) * p.y + a.at(2, 2) * p.z + a.at(2, 3)};
}

D3 transform_direction(const M4& a, D3 d) {
  return {a.at(0, 0) * d.x + a.at(0, 1) * d.y + a.at(0, 2) * d.z, a.at(1, 0) * d.x + a.at(1, 1) * d.y + a.at(1, 2) * d.z,
          a.at(2, 0) * d.x + a.at(2, 1) * d.y + a.at(2, 2) * d.z};
}

// Right-handed view matrix: the eye looks down -z with y up.
M4 look_at(D3 eye, D3 target, D3 up) {
  const D3 f = normalize(target - eye);
  D3 s = cross(f, up);
  if (norm(s) < 1e-9) s = cross(f, any_perpendicular(f));
  s = normalize(s);
  const D3 u = cross(s, f);
  M4 r = M4::identity();
  r.at(0, 0) = s.x, r.at(0, 1) = s.y, r.at(0, 2) = s.z, r.at(0, 3) = -dot(s, eye);
  r.at(1, 0) = u.x, r.at(1, 1) = u.y, r.at(1, 2) = u.z, r.at(1, 3) = -dot(u, eye);
  r.at(2, 0) = -f.x, r.at(2, 1) = -f.y, r.at(2, 2) = -f.z, r.at(2, 3) = dot(f, eye);
  return r;
}

// Inverse of a rotation + translation.
M4 inverse_rigid(const M4& a) {
  M4 r = M4::identity();
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) r.at(i, j) = a.at(j, i);
  for (int i = 0; i < 3; ++i) r.at(i, 3) = -(r.at(i, 0) * a.at(0, 3) + r.at(i, 1) * a.at(1, 3) + r.at(i, 2) * a.at(2, 3));
  return r;
}

M4 perspective(double fovy_rad, double aspect, double n, double f) {
  const double t = 1 / std::tan(0.5 * fovy_rad);
  M4 r;
  r.at(0, 0) = t / aspect;
  r.at(1, 1) = t;
  r.at(2, 2) = -(f + n) / (f - n);
  r.at(2, 3) = -2 * f * n / (f - n);
  r.at(3, 2) = -1;
  return r;
}

M4 ortho(double l, double rt, double b, double t, double n, double f) {
  M4 r = M4::identity();
  r.at(0, 0) = 2 / (rt - l), r.at(0, 3) = -(rt + l) / (rt - l);
  r.at(1, 1) = 2 / (t - b), r.at(1, 3) = -(t + b) / (t - b);
  r.at(2, 2) = -2 / (f - n), r.at(2, 3) = -(f + n) / (f - n);
  return r;
}

// A "nice" grid spacing (1, 2 or 5 x 10^k) close to `x`.
double nice_step(double x) {
  if (!(x > 0)) return 1;
  const double p = std::pow(10.0, std::floor(std::log10(x)));
  const double m = x / p;
  return (m < 1.5 ? 1 : m < 3.5 ? 2 : m < 7.5 ? 5 : 10) * p;
}

// ---- GL helpers -----------------------------------------------------------

GLuint compile(GLenum type, const std::string& source, const char* name) {
  GLuint shader = glCreateShader(type);
  const char* text = source.c_str();
  glShaderSource(shader, 1, &text, nullptr);
  glCompileShader(shader);
  GLint ok = 0;
  glGetShaderiv(shader, GL_COMPILE_STATUS, &ok);
  if (!ok) {
    char log[4096] = {};
    glGetShaderInfoLog(shader, sizeof log, nullptr, log);
    glDeleteShader(shader);
    throw RuntimeFailure(std::string("renderer: shader '") + name + "' does not compile: " + log);
  }
  return shader;
}

GLuint link(const char* vertex, const char* fragment, const char* name) {
  const std::string header = "#version 330 core\n";
  GLuint vs = compile(GL_VERTEX_SHADER, header + vertex, name);
  GLuint fs = compile(GL_FRAGMENT_SHADER, header + shaders::kCommon + fragment, name);
  GLuint program = glCreateProgram();
  glAttachShader(program, vs);
  glAttachShader(program, fs);
  glLinkProgram(program);
  glDeleteShader(vs);
  glDeleteShader(fs);
  GLint ok = 0;
  glGetProgramiv(program, GL_LINK_STATUS, &ok);
  if (!ok) {
    char log[4096] = {};
    glGetProgramInfoLog(program, sizeof log, nullptr, log);
    glDeleteProgram(program);
    throw RuntimeFailure(std::string("renderer: program '") + name + "' does not link: " + log);
  }
  return program;
}

struct Uniforms {
  GLuint program;
  GLint at(const char* name) const { return glGetUniformLocation(program, name); }
  void set(const char* name, const M4& m) const {
    const auto f = m.f();
    glUniformMatrix4fv(at(name), 1, GL_FALSE, f.data());
  }
  void set(const char* name, D3 v) const { glUniform3f(at(name), float(v.x), float(v.y), float(v.z)); }
  void set(const char* name, float x) const { glUniform1f(at(name), x); }
  void set(const char* name, float x, float y) const { glUniform2f(at(name), x, y); }
  void set(const char* name, int x) const { glUniform1i(at(name), x); }
};

void check_gl(const char* where) {
  const GLenum e = glGetError();
  if (e != GL_NO_ERROR) throw RuntimeFailure(std::string("renderer: OpenGL error 0x") + std::to_string(e) + " in " + where);
}

constexpr int kShadowMapSize = 2048;
constexpr D3 kBackgroundTop{0.86, 0.89, 0.93};
constexpr D3 kBackgroundBottom{0.50, 0.55, 0.62};
constexpr D3 kFloorColor{0.80, 0.79, 0.76};
constexpr D3 kBoxColor{0.78, 0.81, 0.86};
constexpr D3 kEdgeColor{0.22, 0.25, 0.30};
constexpr D3 kNoDataColor{0.75, 0.30, 0.25};

// sRGB byte <-> linear light, for the anti-aliasing filter.
struct SrgbTables {
  float to_linear[256];
  std::uint8_t to_srgb[4096];
  SrgbTables() {
    for (int i = 0; i < 256; ++i) to_linear[i] = static_cast<float>(std::pow(i / 255.0, 2.2));
    for (int i = 0; i < 4096; ++i)
      to_srgb[i] = static_cast<std::uint8_t>(std::lround(255 * std::pow((i + 0.5) / 4096.0, 1 / 2.2)));
  }
};

}  // namespace

struct Renderer::Impl {
  RenderOptions options;
  int ss = 2;
  OsmesaContext context;
  GLuint background = 0, sphere = 0, shadow = 0, wall = 0, edge = 0;
  GLuint empty_vao = 0, sphere_vao = 0, shadow_vao = 0, wall_vao = 0, edge_vao = 0;
  GLuint sphere_vbo = 0, color_vbo = 0, shadow_vbo = 0, wall_vbo = 0, edge_vbo = 0;
  FrameStats stats;
  GLuint shadow_fbo = 0, shadow_texture = 0;
  SrgbTables srgb;

  explicit Impl(RenderOptions o)
      : options(std::move(o)),
        ss(std::clamp(options.supersample, 1, 4)),
        context(options.width * ss, options.height * ss) {
    background = link(shaders::kBackgroundVertex, shaders::kBackgroundFragment, "background");
    sphere = link(shaders::kSphereVertex, shaders::kSphereFragment, "sphere");
    shadow = link(shaders::kShadowVertex, shaders::kShadowFragment, "shadow");
    wall = link(shaders::kWallVertex, shaders::kWallFragment, "wall");
    edge = link(shaders::kEdgeVertex, shaders::kEdgeFragment, "edge");

    glGenVertexArrays(1, &empty_vao);

    glGenVertexArrays(1, &sphere_vao);
    glBindVertexArray(sphere_vao);
    glGenBuffers(1, &sphere_vbo);
    glBindBuffer(GL_ARRAY_BUFFER, sphere_vbo);
    glEnableVertexAttribArray(0);
    glVertexAttribPointer(0, 4, GL_FLOAT, GL_FALSE, 16, nullptr);
    glVertexAttribDivisor(0, 1);
    glGenBuffers(1, &color_vbo);
    glBindBuffer(GL_ARRAY_BUFFER, color_vbo);
    glEnableVertexAttribArray(1);
    glVertexAttribPointer(1, 4, GL_UNSIGNED_BYTE, GL_TRUE, 4, nullptr);
    glVertexAttribDivisor(1, 1);

    glGenVertexArrays(1, &shadow_vao);
    glBindVertexArray(shadow_vao);
    glGenBuffers(1, &shadow_vbo);
    glBindBuffer(GL_ARRAY_BUFFER, shadow_vbo);
    glEnableVertexAttribArray(0);
    glVertexAttribPointer(0, 4, GL_FLOAT, GL_FALSE, 16, nullptr);
    glVertexAttribDivisor(0, 1);

    glGenVertexArrays(1, &wall_vao);
    glBindVertexArray(wall_vao);
    glGenBuffers(1, &wall_vbo);
    glBindBuffer(GL_ARRAY_BUFFER, wall_vbo);
    for (GLuint loc : {0u, 1u, 2u}) glEnableVertexAttribArray(loc);
    glVertexAttribPointer(0, 3, GL_FLOAT, GL_FALSE, 32, nullptr);
    glVertexAttribPointer(1, 3, GL_FLOAT, GL_FALSE, 32, reinterpret_cast<void*>(12));
    glVertexAttribPointer(2, 2, GL_FLOAT, GL_FALSE, 32, reinterpret_cast<void*>(24));

    glGenVertexArrays(1, &edge_vao);
    glBindVertexArray(edge_vao);
    glGenBuffers(1, &edge_vbo);
    glBindBuffer(GL_ARRAY_BUFFER, edge_vbo);
    glEnableVertexAttribArray(0);
    glVertexAttribPointer(0, 3, GL_FLOAT, GL_FALSE, 24, nullptr);
    glVertexAttribDivisor(0, 1);
    glEnableVertexAttribArray(1);
    glVertexAttribPointer(1, 3, GL_FLOAT, GL_FALSE, 24, reinterpret_cast<void*>(12));
    glVertexAttribDivisor(1, 1);
    glBindVertexArray(0);

    glGenTextures(1, &shadow_texture);
    glBindTexture(GL_TEXTURE_2D, shadow_texture);
    glTexImage2D(GL_TEXTURE_2D, 0, GL_DEPTH_COMPONENT24, kShadowMapSize, kShadowMapSize, 0, GL_DEPTH_COMPONENT,
                 GL_FLOAT, nullptr);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_LINEAR);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_LINEAR);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_S, GL_CLAMP_TO_BORDER);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_T, GL_CLAMP_TO_BORDER);
    const float lit[4] = {1, 1, 1, 1};
    glTexParameterfv(GL_TEXTURE_2D, GL_TEXTURE_BORDER_COLOR, lit);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_COMPARE_MODE, GL_COMPARE_REF_TO_TEXTURE);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_COMPARE_FUNC, GL_LEQUAL);
    glGenFramebuffers(1, &shadow_fbo);
    glBindFramebuffer(GL_FRAMEBUFFER, shadow_fbo);
    glFramebufferTexture2D(GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, GL_TEXTURE_2D, shadow_texture, 0);
    glDrawBuffer(GL_NONE);
    glReadBuffer(GL_NONE);
    if (glCheckFramebufferStatus(GL_FRAMEBUFFER) != GL_FRAMEBUFFER_COMPLETE)
      throw RuntimeFailure("renderer: the shadow-map framebuffer is incomplete");
    glBindFramebuffer(GL_FRAMEBUFFER, 0);
    check_gl("setup");
  }

  ~Impl() {
    context.make_current();
    for (GLuint p : {background, sphere, shadow, wall, edge}) glDeleteProgram(p);
    const GLuint vaos[] = {empty_vao, sphere_vao, shadow_vao, wall_vao, edge_vao};
    glDeleteVertexArrays(5, vaos);
    const GLuint vbos[] = {sphere_vbo, color_vbo, shadow_vbo, wall_vbo, edge_vbo};
    glDeleteBuffers(5, vbos);
    glDeleteFramebuffers(1, &shadow_fbo);
    glDeleteTextures(1, &shadow_texture);
  }

  Image render(const Snapshot& s, const Walls& walls, const Camera& camera, ColorRange range);
};

Image Renderer::Impl::render(const Snapshot& s, const Walls& walls, const Camera& camera, ColorRange range) {
  const std::size_t n = s.size();
  if (s.radius.size() != n)
    throw RuntimeFailure("renderer: the snapshot has " + std::to_string(s.radius.size()) + " radii for " +
                         std::to_string(n) + " spheres");
  context.make_current();
  stats = FrameStats{};
  const int fw = options.width * ss, fh = options.height * ss;

  // ---- scene frame, camera ------------------------------------------------
  const Bounds bounds = scene_bounds(s, walls);
  const D3 origin{bounds.center(0), bounds.center(1), bounds.center(2)};
  const double scene_r = std::max(bounds.radius(), 1e-9);
  const D3 eye = d3(camera.position) - origin;
  D3 target = d3(camera.look_at) - origin;
  if (norm(target - eye) < 1e-12 * scene_r) target = eye + D3{0, 1, 0};
  const D3 up = normalize(d3(camera.up));
  const M4 view = look_at(eye, target, up);
  const D3 forward = normalize(target - eye);
  const D3 right = normalize(norm(cross(forward, up)) > 1e-9 ? cross(forward, up) : any_perpendicular(forward));

  // ---- spheres (and sphere obstacles) in the scene frame; the near limit ----
  const std::size_t n_all = n + walls.spheres.size();
  std::vector<D3> centers(n_all);
  std::vector<double> radii(n_all);
  for (std::size_t i = 0; i < n; ++i) centers[i] = d3(s.position[i]) - origin, radii[i] = s.radius[i];
  for (std::size_t j = 0; j < walls.spheres.size(); ++j)
    centers[n + j] = d3(walls.spheres[j].centre) - origin, radii[n + j] = walls.spheres[j].radius;
  double near_sphere = 1e300;
  for (std::size_t i = 0; i < n_all; ++i) {
    const double depth = dot(centers[i] - eye, forward) - radii[i];
    if (depth > 0) near_sphere = std::min(near_sphere, depth);
  }

  // ---- wall geometry ----------------------------------------------------------
  // Each wall becomes triangles (position, normal, grid coordinates). Only the
  // surfaces seen from their free side are kept: the floor, the far faces of a
  // box, the far half of a drum, the near half of a post; a container never
  // hides what it holds. Edges (box edges, cylinder rims) are drawn as lines.
  struct WallDraw {
    GLint first = 0;
    GLsizei count = 0;
    D3 base, fade_center;
    float fade0 = 0, fade1 = 0;
    bool offset = false;  // pulled forward a little: wins over a coplanar floor
  };
  struct Segment {
    D3 a, b;
  };
  std::vector<float> wall_vertices;  // 8 floats per vertex
  std::vector<WallDraw> wall_draws;
  std::vector<Segment> edges;
  std::vector<D3> far_points;  // for the depth range
  auto vertex = [&](D3 p, D3 nrm, double gu, double gv) {
    for (double v : {p.x, p.y, p.z, nrm.x, nrm.y, nrm.z, gu, gv}) wall_vertices.push_back(float(v));
    far_points.push_back(p);
  };
  // Planar quad a, b, c, d (in order around it), grid from g0 along t1, t2.
  auto quad = [&](D3 a, D3 b, D3 c, D3 d, D3 nrm, D3 g0, D3 t1, D3 t2, double cell) {
    for (D3 p : {a, b, c, a, c, d}) vertex(p, nrm, dot(p - g0, t1) / cell, dot(p - g0, t2) / cell);
  };
  auto begin_draw = [&](D3 base, bool offset) {
    WallDraw d;
    d.first = GLint(wall_vertices.size() / 8);
    d.base = base;
    d.offset = offset;
    wall_draws.push_back(d);
  };
  auto end_draw = [&] {
    WallDraw& d = wall_draws.back();
    d.count = GLsizei(wall_vertices.size() / 8) - d.first;
    if (d.count == 0) wall_draws.pop_back();
  };
  const double patch = 3.0 * scene_r;
  for (const PlaneWall& plane : walls.planes) {
    const D3 nrm = normalize(d3(plane.normal));
    const D3 q = d3(plane.point) - origin;
    const D3 c = dot(q, nrm) * nrm;  // the scene centre (origin) dropped onto the plane
    const D3 t1 = any_perpendicular(nrm), t2 = cross(nrm, t1);
    begin_draw(kFloorColor, false);
    wall_draws.back().fade_center = c;
    wall_draws.back().fade0 = float(1.1 * scene_r);
    wall_draws.back().fade1 = float(patch);
    quad(c - patch * t1 - patch * t2, c + patch * t1 - patch * t2, c + patch * t1 + patch * t2,
         c - patch * t1 + patch * t2, nrm, q, t1, t2, nice_step(scene_r / 3));
    end_draw();
  }
  for (const BoxWall& box : walls.boxes) {
    const D3 lo = d3(box.lo) - origin, hi = d3(box.hi) - origin;
    const double cell = nice_step(std::max({hi.x - lo.x, hi.y - lo.y, hi.z - lo.z}) / 8);
    auto corner = [&](int i) { return D3{i & 1 ? hi.x : lo.x, i & 2 ? hi.y : lo.y, i & 4 ? hi.z : lo.z}; };
    auto unit = [](int axis) { return D3{axis == 0 ? 1.0 : 0.0, axis == 1 ? 1.0 : 0.0, axis == 2 ? 1.0 : 0.0}; };
    begin_draw(kBoxColor, true);
    for (int axis = 0; axis < 3; ++axis)
      for (int side = 0; side < 2; ++side) {
        const D3 inward = (side == 0 ? 1.0 : -1.0) * unit(axis);
        if (dot(eye - (side == 0 ? lo : hi), inward) <= 0) continue;  // seen from outside
        const int a1 = (axis + 1) % 3, a2 = (axis + 2) % 3, bit = side << axis;
        quad(corner(bit), corner(bit | (1 << a1)), corner(bit | (1 << a1) | (1 << a2)), corner(bit | (1 << a2)),
             inward, lo, unit(a1), unit(a2), cell);
      }
    end_draw();
    for (int i = 0; i < 8; ++i)
      for (int axis = 0; axis < 3; ++axis)
        if (!(i & (1 << axis))) edges.push_back({corner(i), corner(i | (1 << axis))});
  }
  for (const CylinderWall& cyl : walls.cylinders) {
    constexpr int kSegments = 96;
    constexpr double kTwoPi = 6.283185307179586;
    const D3 axis = normalize(d3(cyl.axis)), base = d3(cyl.base) - origin;
    const double radius = cyl.radius;
    double h0 = 0, h1 = cyl.length;
    if (!(cyl.length > 0)) {  // infinite: the stretch beside the scene
      const double mid = dot(-1.0 * base, axis);
      h0 = mid - 1.5 * scene_r, h1 = mid + 1.5 * scene_r;
    }
    const D3 e1 = any_perpendicular(axis), e2 = cross(axis, e1);
    auto radial = [&](double a) { return std::cos(a) * e1 + std::sin(a) * e2; };
    const double cell = nice_step(std::max(radius, h1 - h0) / 8);
    const double spin = double(cyl.angular_velocity) * s.time;  // the grid turns with a spinning drum
    begin_draw(kBoxColor, true);
    for (int k = 0; k < kSegments; ++k) {
      const double a0 = kTwoPi * k / kSegments, a1 = kTwoPi * (k + 1) / kSegments;
      const double side = cyl.inside ? -1.0 : 1.0;  // free side: inwards for a drum, outwards for a post
      const D3 mid = base + 0.5 * (h0 + h1) * axis + radius * radial(0.5 * (a0 + a1));
      if (dot(eye - mid, side * radial(0.5 * (a0 + a1))) <= 0) continue;
      const D3 p00 = base + h0 * axis + radius * radial(a0), p01 = base + h0 * axis + radius * radial(a1);
      const D3 p11 = base + h1 * axis + radius * radial(a1), p10 = base + h1 * axis + radius * radial(a0);
      const double u0 = h0 / cell, u1 = h1 / cell, v0 = (a0 + spin) * radius / cell, v1 = (a1 + spin) * radius / cell;
      vertex(p00, side * radial(a0), u0, v0), vertex(p01, side * radial(a1), u0, v1), vertex(p11, side * radial(a1), u1, v1);
      vertex(p00, side * radial(a0), u0, v0), vertex(p11, side * radial(a1), u1, v1), vertex(p10, side * radial(a0), u1, v0);
    }
    if (!cyl.inside && cyl.length > 0) {  // the end caps of a post
      for (int end = 0; end < 2; ++end) {
        const D3 n = (end ? 1.0 : -1.0) * axis, c = base + (end ? h1 : h0) * axis;
        if (dot(eye - c, n) <= 0) continue;
        for (int k = 0; k < kSegments; ++k) {
          const D3 r0 = c + radius * radial(kTwoPi * k / kSegments), r1 = c + radius * radial(kTwoPi * (k + 1) / kSegments);
          for (D3 p : {c, r0, r1}) vertex(p, n, dot(p - c, e1) / cell, dot(p - c, e2) / cell);
        }
      }
    }
    end_draw();
    if (cyl.length > 0)
      for (double h : {h0, h1})
        for (int k = 0; k < kSegments; ++k)
          edges.push_back({base + h * axis + radius * radial(kTwoPi * k / kSegments),
                           base + h * axis + radius * radial(kTwoPi * (k + 1) / kSegments)});
  }

  // ---- depth range ----------------------------------------------------------
  double far_depth = 0, near_depth = near_sphere;
  for (int i = 0; i < 8; ++i) {
    const D3 c{(i & 1 ? bounds.hi[0] : bounds.lo[0]) - origin.x, (i & 2 ? bounds.hi[1] : bounds.lo[1]) - origin.y,
               (i & 4 ? bounds.hi[2] : bounds.lo[2]) - origin.z};
    far_points.push_back(c);
  }
  for (const D3& p : far_points) {
    const double d = dot(p - eye, forward);
    far_depth = std::max(far_depth, d);
    if (d > 0) near_depth = std::min(near_depth, d);
  }
  far_depth = std::max(far_depth * 1.01, 1e-6);
  const double near_plane = std::clamp(0.9 * near_depth, far_depth * 1e-5, far_depth * 0.5);
  const double aspect = double(options.width) / options.height;
  const double fov = std::clamp(camera.fov, 1.0, 170.0) * 3.14159265358979323846 / 180;
  const M4 proj = perspective(fov, aspect, near_plane, far_depth);

  // ---- main-pass instances: the spheres that may be visible, coloured ---------
  const bool have_color = has_color_data(s, options.color_by);
  const bool categorical = is_categorical(options.color_by);
  const double span = range.hi - range.lo;
  std::vector<std::uint32_t> shown;
  {
    const double f_px = 0.5 * fh / std::tan(0.5 * fov);
    std::vector<ProjectedSphere> projected(n_all);
    for (std::size_t i = 0; i < n_all; ++i) {
      const D3 c = transform_point(view, centers[i]);
      const double depth = -c.z, r = radii[i];
      ProjectedSphere& q = projected[i];
      q.depth = float(depth);
      q.radius = float(r);
      if (depth - r <= near_plane) {  // reaches the near plane: always drawn
        q.x = 0.5f * fw, q.y = 0.5f * fh, q.outer = 1e30f;
        continue;
      }
      q.x = float(0.5 * fw + f_px * c.x / depth);
      q.y = float(0.5 * fh + f_px * c.y / depth);
      q.inner = float(f_px * r / depth);
      q.outer = float(f_px * r * (1 + (std::abs(c.x) + std::abs(c.y)) / depth) / (depth - r) + 1);
    }
    if (options.cull_hidden) {
      shown = visible_spheres(projected, fw, fh, float(2 * ss), float(near_plane));
    } else {
      shown.resize(n_all);
      for (std::size_t i = 0; i < n_all; ++i) shown[i] = std::uint32_t(i);
    }
  }
  std::vector<float> sphere_data(4 * shown.size());
  std::vector<std::uint8_t> colors(4 * shown.size());
  for (std::size_t k = 0; k < shown.size(); ++k) {
    const std::size_t i = shown[k];
    sphere_data[4 * k + 0] = float(centers[i].x), sphere_data[4 * k + 1] = float(centers[i].y);
    sphere_data[4 * k + 2] = float(centers[i].z), sphere_data[4 * k + 3] = float(radii[i]);
    Rgb c{float(kNoDataColor.x), float(kNoDataColor.y), float(kNoDataColor.z)};
    if (i >= n) {
      c = Rgb{float(kBoxColor.x), float(kBoxColor.y), float(kBoxColor.z)};
    } else if (have_color) {
      const double v = color_value(s, options.color_by, i);
      if (categorical)
        c = category_color(static_cast<std::uint32_t>(v));
      else
        c = sample_color_map(options.color_map, span > 0 ? (v - range.lo) / span : 0.0);
    }
    colors[4 * k + 0] = static_cast<std::uint8_t>(std::lround(std::clamp(c.r, 0.f, 1.f) * 255));
    colors[4 * k + 1] = static_cast<std::uint8_t>(std::lround(std::clamp(c.g, 0.f, 1.f) * 255));
    colors[4 * k + 2] = static_cast<std::uint8_t>(std::lround(std::clamp(c.b, 0.f, 1.f) * 255));
    colors[4 * k + 3] = 255;
  }
  glBindBuffer(GL_ARRAY_BUFFER, sphere_vbo);
  glBufferData(GL_ARRAY_BUFFER, GLsizeiptr(sphere_data.size() * sizeof(float)), sphere_data.data(), GL_STREAM_DRAW);
  glBindBuffer(GL_ARRAY_BUFFER, color_vbo);
  glBufferData(GL_ARRAY_BUFFER, GLsizeiptr(colors.size()), colors.data(), GL_STREAM_DRAW);
  stats.spheres_drawn = shown.size();

  // ---- light ----------------------------------------------------------------
  // From above, behind the viewer's left shoulder: shadows fall away from the
  // camera and to the right, where they show.
  const D3 horizontal_forward = normalize(forward - dot(forward, up) * up);
  const D3 to_light = normalize(up - 0.45 * horizontal_forward - 0.35 * right);
  const bool use_shadows = options.lighting && options.shadows && n_all > 0;
  std::size_t shadow_casters = 0;
  const M4 light_view = look_at(D3{} + 2 * scene_r * to_light, D3{}, any_perpendicular(to_light));
  M4 light_proj = M4::identity();
  double depth_per_unit = 0, texel_world = 0;
  {
    Bounds lb;  // light-space bounds of casters and where their shadows land
    auto add_light_point = [&](D3 p) {
      const D3 q = transform_point(light_view, p);
      lb.add(q.x, q.y, q.z);
    };
    for (int i = 0; i < 8; ++i) {
      const D3 c{(i & 1 ? bounds.hi[0] : bounds.lo[0]) - origin.x, (i & 2 ? bounds.hi[1] : bounds.lo[1]) - origin.y,
                 (i & 4 ? bounds.hi[2] : bounds.lo[2]) - origin.z};
      add_light_point(c);
    }
    const double pad = 0.02 * scene_r;
    const double l = lb.lo[0] - pad, r = lb.hi[0] + pad, b = lb.lo[1] - pad, t = lb.hi[1] + pad;
    const double zn = -lb.hi[2] - pad, zf = -lb.lo[2] + pad;
    // Square, so that a sphere's shadow-map image is a circle.
    const double half = 0.5 * std::max(r - l, t - b), cx = 0.5 * (l + r), cy = 0.5 * (b + t);
    light_proj = ortho(cx - half, cx + half, cy - half, cy + half, zn, zf);
    depth_per_unit = 1 / (zf - zn);
    texel_world = 2 * half / kShadowMapSize;
    if (use_shadows) {
      const double scale = kShadowMapSize / (2 * half);
      std::vector<ProjectedSphere> projected(n_all);
      for (std::size_t i = 0; i < n_all; ++i) {
        const D3 c = transform_point(light_view, centers[i]);
        ProjectedSphere& q = projected[i];
        q.x = float((c.x - (cx - half)) * scale), q.y = float((c.y - (cy - half)) * scale);
        q.depth = float(-c.z), q.radius = float(radii[i]);
        q.inner = float(radii[i] * scale), q.outer = q.inner + 1;
      }
      std::vector<std::uint32_t> casters;
      if (options.cull_hidden) {
        casters = visible_spheres(projected, kShadowMapSize, kShadowMapSize, 4, -std::numeric_limits<float>::infinity());
      } else {
        casters.resize(n_all);
        for (std::size_t i = 0; i < n_all; ++i) casters[i] = std::uint32_t(i);
      }
      std::vector<float> data(4 * casters.size());
      for (std::size_t k = 0; k < casters.size(); ++k) {
        const std::size_t i = casters[k];
        data[4 * k + 0] = float(centers[i].x), data[4 * k + 1] = float(centers[i].y);
        data[4 * k + 2] = float(centers[i].z), data[4 * k + 3] = float(radii[i]);
      }
      glBindBuffer(GL_ARRAY_BUFFER, shadow_vbo);
      glBufferData(GL_ARRAY_BUFFER, GLsizeiptr(data.size() * sizeof(float)), data.data(), GL_STREAM_DRAW);
      shadow_casters = casters.size();
      stats.shadow_casters = casters.size();
    }
  }

  if (use_shadows) {
    glBindFramebuffer(GL_FRAMEBUFFER, shadow_fbo);
    glViewport(0, 0, kShadowMapSize, kShadowMapSize);
    glEnable(GL_DEPTH_TEST);
    glDepthFunc(GL_LESS);
    glDepthMask(GL_TRUE);
    glClear(GL_DEPTH_BUFFER_BIT);
    glUseProgram(shadow);
    const Uniforms u{shadow};
    u.set("u_light_view_matrix", light_view);
    u.set("u_light_proj", light_proj);
    u.set("u_depth_per_unit", float(depth_per_unit));
    glBindVertexArray(shadow_vao);
    glDrawArraysInstanced(GL_TRIANGLE_STRIP, 0, 4, GLsizei(shadow_casters));
    glBindFramebuffer(GL_FRAMEBUFFER, 0);
  }

  // ---- main pass --------------------------------------------------------------
  glViewport(0, 0, fw, fh);
  glClearColor(0, 0, 0, 1);
  glDepthMask(GL_TRUE);
  glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
  glActiveTexture(GL_TEXTURE0);
  glBindTexture(GL_TEXTURE_2D, shadow_texture);

  const M4 view_to_light = light_proj * light_view * inverse_rigid(view);
  auto set_common = [&](GLuint program) {
    glUseProgram(program);
    const Uniforms u{program};
    u.set("u_viewport", float(fw), float(fh));
    u.set("u_bg_top", kBackgroundTop);
    u.set("u_bg_bottom", kBackgroundBottom);
    u.set("u_lighting", options.lighting ? 1 : 0);
    u.set("u_shadows", use_shadows ? 1 : 0);
    u.set("u_light_view", normalize(transform_direction(view, to_light)));
    u.set("u_up_view", normalize(transform_direction(view, up)));
    u.set("u_shadow_map", 0);
    u.set("u_view_to_light", view_to_light);
    u.set("u_shadow_offset", float(1.5 * texel_world));
    u.set("u_shadow_texel", float(1.0 / kShadowMapSize));
    u.set("u_view", view);
    u.set("u_proj", proj);
    return u;
  };

  glDisable(GL_DEPTH_TEST);
  glDepthMask(GL_FALSE);
  set_common(background);
  glBindVertexArray(empty_vao);
  glDrawArrays(GL_TRIANGLES, 0, 3);

  glEnable(GL_DEPTH_TEST);
  glDepthFunc(GL_LESS);
  glDepthMask(GL_TRUE);
  if (!wall_draws.empty()) {
    const Uniforms u = set_common(wall);
    glBindBuffer(GL_ARRAY_BUFFER, wall_vbo);
    glBufferData(GL_ARRAY_BUFFER, GLsizeiptr(wall_vertices.size() * sizeof(float)), wall_vertices.data(),
                 GL_STREAM_DRAW);
    glBindVertexArray(wall_vao);
    glPolygonOffset(-1, -2);
    for (const WallDraw& d : wall_draws) {
      u.set("u_base", d.base);
      u.set("u_fade_center", d.fade_center);
      u.set("u_fade", d.fade0, d.fade1);
      if (d.offset) glEnable(GL_POLYGON_OFFSET_FILL);
      glDrawArrays(GL_TRIANGLES, d.first, d.count);
      glDisable(GL_POLYGON_OFFSET_FILL);
    }
  }
  if (!edges.empty()) {
    std::vector<float> data;
    for (const Segment& e : edges)
      for (D3 p : {e.a, e.b}) data.push_back(float(p.x)), data.push_back(float(p.y)), data.push_back(float(p.z));
    const Uniforms u = set_common(edge);
    u.set("u_near", float(near_plane));
    u.set("u_width_px", float(1.6 * ss));
    u.set("u_edge_color", kEdgeColor);
    glBindBuffer(GL_ARRAY_BUFFER, edge_vbo);
    glBufferData(GL_ARRAY_BUFFER, GLsizeiptr(data.size() * sizeof(float)), data.data(), GL_STREAM_DRAW);
    glBindVertexArray(edge_vao);
    glEnable(GL_POLYGON_OFFSET_FILL);
    glPolygonOffset(-1, -4);
    glDrawArraysInstanced(GL_TRIANGLE_STRIP, 0, 4, GLsizei(edges.size()));
    glDisable(GL_POLYGON_OFFSET_FILL);
  }
  if (!shown.empty()) {
    set_common(sphere);
    glBindVertexArray(sphere_vao);
    glDrawArraysInstanced(GL_TRIANGLE_STRIP, 0, 4, GLsizei(shown.size()));
  }
  glBindVertexArray(0);
  glFinish();
  check_gl("frame");

  // ---- resolve: box filter in linear light, top row first ---------------------
  Image image(options.width, options.height);
  const std::uint8_t* src = context.pixels();
  const float inv = 1.0f / float(ss * ss);
  for (int y = 0; y < options.height; ++y) {
    const int sy0 = (options.height - 1 - y) * ss;  // OSMesa rows are bottom first
    std::uint8_t* out = image.pixel(0, y);
    for (int x = 0; x < options.width; ++x) {
      for (int c = 0; c < 3; ++c) {
        const std::uint8_t first = src[(std::size_t(sy0) * fw + x * ss) * 4 + c];
        bool uniform = true;
        float sum = 0;
        for (int j = 0; j < ss; ++j)
          for (int i = 0; i < ss; ++i) {
            const std::uint8_t v = src[(std::size_t(sy0 + j) * fw + x * ss + i) * 4 + c];
            uniform &= v == first;
            sum += srgb.to_linear[v];
          }
        out[3 * x + c] = uniform ? first : srgb.to_srgb[std::min(4095, int(sum * inv * 4096))];
      }
    }
  }

  // ---- annotations ------------------------------------------------------------
  if (options.overlay) {
    draw_time_label(image, s.time);
    if (have_color && n > 0) {
      ColorLegend legend{options.color_by, options.color_map, range.lo, range.hi, {}, options.material_names};
      if (categorical) {
        std::vector<bool> seen;
        for (std::uint32_t m : s.material) {
          if (m >= 64) continue;
          if (seen.size() <= m) seen.resize(m + 1);
          seen[m] = true;
        }
        for (std::uint32_t m = 0; m < seen.size(); ++m)
          if (seen[m]) legend.categories.push_back(m);
      }
      draw_color_legend(image, legend);
    }
  }
  return image;
}

Renderer::Renderer(RenderOptions options) {
  if (options.width < 16 || options.height < 16)
    throw RuntimeFailure("renderer: image size " + std::to_string(options.width) + "x" +
                         std::to_string(options.height) + " is too small (at least 16x16)");
  m_impl = std::make_unique<Impl>(std::move(options));
}

Renderer::~Renderer() = default;

Image Renderer::render(const Snapshot& s, const Walls& walls) {
  const RenderOptions& o = m_impl->options;
  const Camera camera = o.camera ? *o.camera : default_camera(scene_bounds(s, walls), o.width, o.height);
  ColorRange range = data_range(s, o.color_by);
  if (o.color_min) range.lo = *o.color_min;
  if (o.color_max) range.hi = *o.color_max;
  return m_impl->render(s, walls, camera, range);
}

Image Renderer::render(const Snapshot& s, const Walls& walls, const Camera& camera, ColorRange range) {
  return m_impl->render(s, walls, camera, range);
}

const RenderOptions& Renderer::options() const { return m_impl->options; }

std::string Renderer::gl_description() const { return m_impl->context.description(); }

FrameStats Renderer::last_frame_stats() const { return m_impl->stats; }

#else  // !MARBLES_HAVE_OSMESA

bool renderer_available() { return false; }

struct Renderer::Impl {
  RenderOptions options;
};

Renderer::Renderer(RenderOptions) {
  throw RuntimeFailure("marbles was built without OSMesa (libosmesa6-dev): images and movies are not available");
}
Renderer::~Renderer() = default;
Image Renderer::render(const Snapshot&, const Walls&) { return {}; }
Image Renderer::render(const Snapshot&, const Walls&, const Camera&, ColorRange) { return {}; }
const RenderOptions& Renderer::options() const { return m_impl->options; }
std::string Renderer::gl_description() const { return {}; }
FrameStats Renderer::last_frame_stats() const { return {}; }

#endif

}  // namespace marbles::render
