// render/camera.cpp — scene bounds and the default view.
#include "render/camera.hpp"


#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <string>

#include "core/error.hpp"
#include "render/d3.hpp"

namespace marbles::render {

void Bounds::add(double x, double y, double z, double pad) {
  const double p[3] = {x, y, z};
  for (int a = 0; a < 3; ++a) {
    if (!std::isfinite(p[a])) return;
  }
  for (int a = 0; a < 3; ++a) {
    lo[a] = std::min(lo[a], p[a] - pad);
    hi[a] = std::max(hi[a], p[a] + pad);
  }
}

void Bounds::add(const Bounds& o) {
  if (o.empty()) return;
  add(o.lo[0], o.lo[1], o.lo[2]);
  add(o.hi[0], o.hi[1], o.hi[2]);
}

double Bounds::radius() const {
  if (empty()) return 0;
  return 0.5 * std::sqrt(extent(0) * extent(0) + extent(1) * extent(1) + extent(2) * extent(2));
}

Bounds scene_bounds(const Snapshot& s, const Walls& walls) {
  Bounds b;
  const bool have_radius = s.radius.size() == s.position.size();
  for (std::size_t i = 0; i < s.position.size(); ++i) {
    const Vec3& p = s.position[i];
    b.add(p.x, p.y, p.z, have_radius ? double(s.radius[i]) : 0.0);
  }
  for (const BoxWall& box : walls.boxes) {
    b.add(box.lo.x, box.lo.y, box.lo.z);
    b.add(box.hi.x, box.hi.y, box.hi.z);
  }
  for (const SphereWall& sp : walls.spheres) b.add(sp.centre.x, sp.centre.y, sp.centre.z, sp.radius);
  for (const CylinderWall& c : walls.cylinders) {
    if (!(c.length > 0)) continue;  // infinite: framed by what it holds
    const Vec3 top = c.base + c.axis * (c.length / length(c.axis));
    b.add(c.base.x, c.base.y, c.base.z, c.radius);
    b.add(top.x, top.y, top.z, c.radius);
  }
  if (b.empty()) {
    for (const PlaneWall& p : walls.planes) b.add(p.point.x, p.point.y, p.point.z, 1.0);
  }
  if (b.empty()) b.add(0, 0, 0, 1.0);
  // The shadow of the bounds on each plane (the floor under the spheres).
  const Bounds inner = b;
  for (const PlaneWall& plane : walls.planes) {
    const D3 n = normalize(d3(plane.normal)), q = d3(plane.point);
    for (int corner = 0; corner < 8; ++corner) {
      const D3 c{corner & 1 ? inner.hi[0] : inner.lo[0], corner & 2 ? inner.hi[1] : inner.lo[1],
                 corner & 4 ? inner.hi[2] : inner.lo[2]};
      const D3 on_plane = c - dot(c - q, n) * n;
      b.add(on_plane.x, on_plane.y, on_plane.z);
    }
  }
  // A flat scene (all spheres in a plane, no radius) still needs some depth.
  const double r = std::max(b.radius(), 1e-9);
  for (int a = 0; a < 3; ++a) {
    if (b.extent(a) < 1e-3 * r) {
      b.lo[a] -= 5e-4 * r;
      b.hi[a] += 5e-4 * r;
    }
  }
  return b;
}

Camera default_camera(const Bounds& bounds, int width, int height, double fov, Vec3 up_in) {
  constexpr double kPi = 3.14159265358979323846;
  constexpr double kAzimuth = -110 * kPi / 180;   // from the front (-x_perp side), a little to the left
  constexpr double kElevation = 25 * kPi / 180;   // above the horizon
  constexpr double kMargin = 1.06;                 // 6 % air around the scene
  constexpr double kColorBarShare = 0.86;          // horizontal share left free of the colour bar

  const D3 up = normalize(d3(up_in));
  D3 ex = D3{1, 0, 0} - dot(D3{1, 0, 0}, up) * up;
  if (dot(ex, ex) < 1e-6) ex = D3{0, 1, 0} - dot(D3{0, 1, 0}, up) * up;
  ex = normalize(ex);
  const D3 ey = cross(up, ex);
  const D3 towards_camera = normalize(std::cos(kElevation) * (std::cos(kAzimuth) * ex + std::sin(kAzimuth) * ey) +
                                      std::sin(kElevation) * up);
  const D3 forward = -1.0 * towards_camera;
  const D3 right = normalize(cross(forward, up));
  const D3 cam_up = cross(right, forward);

  const double aspect = double(std::max(width, 1)) / double(std::max(height, 1));
  const double tan_v = std::tan(0.5 * std::clamp(fov, 1.0, 170.0) * kPi / 180);
  const double tan_h = tan_v * aspect * kColorBarShare;
  const D3 center{bounds.center(0), bounds.center(1), bounds.center(2)};

  // Distance along -forward at which every corner of the bounds is in view:
  // a corner at (x, y) across and f along the view needs |x| <= tan_h (D + f).
  double distance = 0;
  for (int corner = 0; corner < 8; ++corner) {
    const D3 c{corner & 1 ? bounds.hi[0] : bounds.lo[0], corner & 2 ? bounds.hi[1] : bounds.lo[1],
               corner & 4 ? bounds.hi[2] : bounds.lo[2]};
    const D3 d = c - center;
    const double need = std::max(std::abs(dot(d, right)) / tan_h, std::abs(dot(d, cam_up)) / tan_v) - dot(d, forward);
    distance = std::max(distance, need);
  }
  distance = std::max(distance * kMargin, 1e-6 + 1.5 * bounds.radius());

  Camera cam;
  const D3 eye = center - distance * forward;
  cam.position = Vec3(real(eye.x), real(eye.y), real(eye.z));
  cam.look_at = Vec3(real(center.x), real(center.y), real(center.z));
  cam.up = up_in;
  cam.fov = fov;
  return cam;
}

Camera parse_camera(std::string_view text, std::string_view key) {
  const std::string k(key);
  const auto fail = [&]() -> Camera {
    throw InputError({}, k, "expected x,y,z:lx,ly,lz (camera position : look-at point), got '" + std::string(text) + "'");
  };
  const auto colon = text.find(':');
  if (colon == std::string_view::npos) return fail();
  auto parse3 = [&](std::string_view part, Vec3& out) {
    double v[3];
    std::string s(part);
    const char* p = s.c_str();
    for (int i = 0; i < 3; ++i) {
      char* end = nullptr;
      v[i] = std::strtod(p, &end);
      if (end == p || !std::isfinite(v[i])) return false;
      p = end;
      if (i < 2) {
        if (*p != ',') return false;
        ++p;
      }
    }
    if (*p != '\0') return false;
    out = Vec3(real(v[0]), real(v[1]), real(v[2]));
    return true;
  };
  Camera cam;
  if (!parse3(text.substr(0, colon), cam.position) || !parse3(text.substr(colon + 1), cam.look_at)) return fail();
  if (cam.position == cam.look_at) throw InputError({}, k, "camera position and look-at point coincide");
  // The view is made from their difference and its squared length: both
  // points within the precision with room for that (as a scene's vectors).
  if (square_overflows(cam.position) || square_overflows(cam.look_at) || square_overflows(cam.look_at - cam.position))
    throw InputError({}, k, "too large for " + std::string(kRealName) + " precision: a camera point's squared length "
                            "overflows, got '" + std::string(text) + "'");
  return cam;
}

}  // namespace marbles::render
