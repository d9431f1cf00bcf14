// render/renderer.hpp — draws a snapshot of the spheres, and the walls that
// hold them, into an image, off-screen on the CPU (OSMesa / llvmpipe).
//
// How (details in docs/rendering.md): each sphere is one instanced quad
// facing the camera; its fragment shader intersects the view ray with the
// exact sphere, so silhouettes, normals and depth are exact at any
// resolution, for 4 vertices per sphere. Spheres that are certainly hidden
// are culled on the CPU first (occlusion.hpp). A shadow map (same impostor trick,
// seen from the light) gives contact shadows on the floor and walls; a
// supersampled frame is box-filtered down for anti-aliasing; the colour bar and
// time label are drawn on the CPU with a built-in bitmap font.
#pragma once

#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "core/walls.hpp"
#include "render/camera.hpp"
#include "render/color_map.hpp"
#include "render/image.hpp"
#include "render/snapshot.hpp"

namespace marbles::render {

/// What a frame looks like. The defaults give the production look.
struct RenderOptions {
  int width = 1280, height = 720;  ///< pixels of the final image, each >= 16
  /// nullopt: frame the whole scene (see default_camera); FrameOutput and
  /// render_output_dir choose that view once and keep it for every frame.
  std::optional<Camera> camera;
  ColorBy color_by = ColorBy::speed;
  ColorMapName color_map = ColorMapName::viridis;
  /// Fixed ends of the colour scale for continuous quantities; nullopt = from data.
  std::optional<double> color_min, color_max;
  bool lighting = true;  ///< false: flat, unlit colours (exactly the colour map; for tests and diagnostics)
  bool shadows = true;   ///< cast shadows from a light above the camera (only with lighting)
  bool overlay = true;   ///< colour bar and simulated-time label
  /// Legend labels of colour-by-material, by material id (the id where missing).
  std::vector<std::string> material_names;
  int supersample = 2;   ///< samples per pixel along each axis, 1..4 (anti-aliasing; cost ~ square)
  /// Skip spheres that are off screen or certainly hidden behind nearer ones
  /// before drawing (see occlusion.hpp); the picture is the same either way.
  bool cull_hidden = true;
};

/// What the last frame drew (for benchmarks and tests).
struct FrameStats {
  std::size_t spheres_drawn = 0;   ///< main pass, after culling
  std::size_t shadow_casters = 0;  ///< shadow pass, after culling (0 without shadows)
};

/// The two ends of the colour scale.
struct ColorRange {
  double lo = 0, hi = 1;
  void add(const ColorRange& o);
};

/// Smallest and largest value of the colouring quantity in `snapshot`
/// ({0, 1} when the snapshot lacks it or is empty).
ColorRange data_range(const Snapshot& snapshot, ColorBy by);
// Whether the snapshot carries the array `by` colours by, and its name in
// the frames (speed's is velocity).
bool has_color_data(const Snapshot& snapshot, ColorBy by);
const char* color_data_name(ColorBy by);

/// The walls where they are at `time` (s) when each moves with its constant
/// velocity from its given position at time 0 (what the narrow phase does).
/// The renderer draws the walls it is given where they are (a wall frame of
/// a run is already at its time; FrameOutput moves the scene's walls with
/// this); a spinning drum's grid turns by angular_velocity * snapshot.time.
Walls walls_at(const Walls& walls, double time);

/// True when this build can render (it was built with OSMesa).
bool renderer_available();

/// An off-screen OpenGL 3.3-core context and the sphere renderer on it. One
/// Renderer draws frames of one size; it is not thread-safe, but several may
/// exist.
class Renderer {
 public:
  /// Creates the context. Throws marbles::RuntimeFailure when built without
  /// OSMesa, when the context cannot be created, or when a shader fails.
  explicit Renderer(RenderOptions options);
  ~Renderer();
  Renderer(const Renderer&) = delete;
  Renderer& operator=(const Renderer&) = delete;

  /// Renders with the options' camera (or the default view of this snapshot)
  /// and colour range (or this snapshot's range).
  Image render(const Snapshot& snapshot, const Walls& walls);

  /// Renders with an explicit camera and colour range.
  Image render(const Snapshot& snapshot, const Walls& walls, const Camera& camera, ColorRange range);

  const RenderOptions& options() const;
  /// The OpenGL renderer and version strings, e.g. "llvmpipe (LLVM 15.0.6, 256 bits), OpenGL 4.5 (Core Profile) Mesa 22.3.6".
  std::string gl_description() const;
  FrameStats last_frame_stats() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> m_impl;
};

}  // namespace marbles::render
