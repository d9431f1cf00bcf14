// bench/render_bench.cpp — time to render one frame of a large pile of spheres
// off-screen (OSMesa / llvmpipe, CPU only).
//
// Scene (--layout): `pile` (default) puts N spheres (default 100,000) on a
// jittered cubic lattice filling the lower part of a box, with a floor plane
// under it; `gas` scatters them at random through the same box (about 3 %
// volume fraction: little is hidden, the worst case for occlusion culling).
// Coloured by speed; the default camera frames it. Renders a warm-up frame, then F timed frames
// (default 5) at W x H (default 1280 x 720) and reports the median, plus the
// time of writing one PNG.
//
//   render_bench [--n N] [--layout pile|gas] [--width W] [--height H] [--frames F]
//                [--supersample S] [--no-shadows] [--no-cull] [--png FILE]
//
// Prints one JSON object, then a one-line table.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <iostream>
#include <random>
#include <string>
#include <vector>

#include "core/error.hpp"
#include "render/renderer.hpp"

using namespace marbles;
using namespace marbles::render;

namespace {

double seconds(std::chrono::steady_clock::time_point a, std::chrono::steady_clock::time_point b) {
  return std::chrono::duration<double>(b - a).count();
}

}  // namespace

int main(int argc, char** argv) {
  std::size_t n = 100000;
  int width = 1280, height = 720, frames = 5, supersample = RenderOptions{}.supersample;
  bool shadows = true, cull = true;
  std::string png, layout = "pile";
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto value = [&]() -> std::string {
      if (i + 1 >= argc) {
        std::cerr << "render_bench: " << a << " needs a value\n";
        std::exit(2);
      }
      return argv[++i];
    };
    if (a == "--n") n = std::stoul(value());
    else if (a == "--layout") layout = value();
    else if (a == "--width") width = std::stoi(value());
    else if (a == "--height") height = std::stoi(value());
    else if (a == "--frames") frames = std::max(1, std::stoi(value()));
    else if (a == "--supersample") supersample = std::stoi(value());
    else if (a == "--no-shadows") shadows = false;
    else if (a == "--no-cull") cull = false;
    else if (a == "--png") png = value();
    else {
      std::cerr << "usage: render_bench [--n N] [--layout pile|gas] [--width W] [--height H] [--frames F] [--supersample S] "
                   "[--no-shadows] [--no-cull] [--png FILE]\n";
      return 2;
    }
  }

  // A pile: a jittered lattice with a 2:2:1 footprint, spacing 2.2 r.
  const double r = 0.01, spacing = 2.2 * r;
  const int nx = int(std::ceil(std::cbrt(double(n) / 1.0) * std::cbrt(2.0)));
  const int ny = nx, per_layer = nx * ny;
  std::mt19937 rng(42);
  std::uniform_real_distribution<double> jitter(-0.08 * r, 0.08 * r), vel(-1.0, 1.0);
  Snapshot s;
  s.time = 1.25;
  for (std::size_t i = 0; i < n; ++i) {
    const int layer = int(i / per_layer), k = int(i % per_layer);
    s.position.emplace_back(real((k % nx) * spacing + jitter(rng)), real((k / nx) * spacing + jitter(rng)),
                            real(r + layer * spacing + jitter(rng)));
    s.velocity.emplace_back(real(vel(rng)), real(vel(rng)), real(vel(rng) * (1 + layer)));
    s.radius.push_back(real(r * (0.9 + 0.2 * (i % 7) / 6.0)));
    s.id.push_back(std::uint32_t(i));
    s.material.push_back(0);
  }
  const int layers = int((n + per_layer - 1) / per_layer);
  if (layout == "gas") {  // same spheres, scattered through a box three times as tall
    std::uniform_real_distribution<double> ux(0, nx * spacing), uz(r, 3 * layers * spacing);
    for (Vec3& p : s.position) p = Vec3(real(ux(rng)), real(ux(rng)), real(uz(rng)));
  } else if (layout != "pile") {
    std::cerr << "render_bench: unknown layout '" << layout << "' (pile or gas)\n";
    return 2;
  }
  Walls walls;
  PlaneWall floor;
  floor.point = Vec3(0, 0, 0);
  floor.normal = Vec3(0, 0, 1);
  walls.planes.push_back(floor);
  BoxWall box;
  box.lo = Vec3(real(-spacing), real(-spacing), 0);
  box.hi = Vec3(real(nx * spacing), real(ny * spacing), real((layout == "gas" ? 3 * layers : layers + 2) * spacing));
  walls.boxes.push_back(box);

  RenderOptions options;
  options.width = width;
  options.height = height;
  options.supersample = supersample;
  options.shadows = shadows;
  options.cull_hidden = cull;
  try {
    Renderer renderer(options);
    const auto c0 = std::chrono::steady_clock::now();
    Image image = renderer.render(s, walls);  // warm-up: shader compilation, buffer allocation
    const auto c1 = std::chrono::steady_clock::now();
    std::vector<double> times;
    for (int f = 0; f < frames; ++f) {
      s.time += 0.01;
      const auto t0 = std::chrono::steady_clock::now();
      image = renderer.render(s, walls);
      times.push_back(seconds(t0, std::chrono::steady_clock::now()));
    }
    std::sort(times.begin(), times.end());
    const double median = times.size() % 2 ? times[times.size() / 2]
                                           : 0.5 * (times[times.size() / 2 - 1] + times[times.size() / 2]);
    double png_s = -1;
    if (!png.empty()) {
      const auto p0 = std::chrono::steady_clock::now();
      write_png(png, image);
      png_s = seconds(p0, std::chrono::steady_clock::now());
    }
    std::printf(
        "{\"bench\": \"render\", \"layout\": \"%s\", \"spheres\": %zu, \"width\": %d, \"height\": %d, \"supersample\": %d, "
        "\"shadows\": %s, \"frames\": %d, \"first_frame_s\": %.4f, \"median_s\": %.4f, \"min_s\": %.4f, "
        "\"max_s\": %.4f, \"png_write_s\": %.4f, \"culling\": %s, \"spheres_drawn\": %zu, \"shadow_casters\": %zu, "
        "\"gl\": \"%s\"}\n",
        layout.c_str(), n, width, height, options.supersample, shadows ? "true" : "false", frames, seconds(c0, c1), median,
        times.front(), times.back(), png_s, cull ? "true" : "false", renderer.last_frame_stats().spheres_drawn,
        renderer.last_frame_stats().shadow_casters, renderer.gl_description().c_str());
    std::printf(
        "render  %s  %zu spheres (%zu drawn)  %dx%d  ss %d  shadows %s  median %.3f s/frame  (min %.3f, max %.3f, %d "
        "frames)\n",
        layout.c_str(), n, renderer.last_frame_stats().spheres_drawn, width, height, options.supersample, shadows ? "on" : "off",
        median, times.front(), times.back(), frames);
  } catch (const RuntimeFailure& e) {
    std::cerr << "render_bench: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
