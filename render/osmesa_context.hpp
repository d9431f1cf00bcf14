// render/osmesa_context.hpp — an off-screen OpenGL context that Mesa runs on
// the CPU (llvmpipe), rendering into memory we own. No display, no GPU.
//
// Only render/ .cpp files include this; nothing here exposes GL or OSMesa
// headers.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

struct osmesa_context;

namespace marbles::render {

class OsmesaContext {
 public:
  /// Creates an OpenGL >= 3.3 core-profile context drawing into a width x
  /// height RGBA buffer with a 24-bit depth buffer. Throws
  /// marbles::RuntimeFailure when OSMesa is missing or refuses.
  OsmesaContext(int width, int height);
  ~OsmesaContext();
  OsmesaContext(const OsmesaContext&) = delete;
  OsmesaContext& operator=(const OsmesaContext&) = delete;

  /// Binds the context and its buffer to the calling thread.
  void make_current();
  /// The colour buffer, RGBA bytes, bottom row first; valid after glFinish().
  const std::uint8_t* pixels() const { return m_buffer.data(); }
  int width() const { return m_width; }
  int height() const { return m_height; }
  /// GL_RENDERER and GL_VERSION, for logs and benchmarks.
  std::string description() const { return m_description; }

 private:
  osmesa_context* m_context = nullptr;
  std::vector<std::uint8_t> m_buffer;
  int m_width = 0, m_height = 0;
  std::string m_description;
};

}  // namespace marbles::render
