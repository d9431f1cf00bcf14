// render/osmesa_context.cpp — see osmesa_context.hpp.
#include "render/osmesa_context.hpp"

#include <string>

#include "core/error.hpp"

#if defined(MARBLES_HAVE_OSMESA)
#include "render/gl.hpp"
#endif

namespace marbles::render {

#if defined(MARBLES_HAVE_OSMESA)

OsmesaContext::OsmesaContext(int width, int height) : m_width(width), m_height(height) {
  int max_size = 0;
  OSMesaGetIntegerv(OSMESA_MAX_WIDTH, &max_size);
  if (width <= 0 || height <= 0 || (max_size > 0 && (width > max_size || height > max_size)))
    throw RuntimeFailure("OSMesa: cannot render " + std::to_string(width) + "x" + std::to_string(height) +
                         " pixels (limit " + std::to_string(max_size) + ")");
  const int attributes[] = {OSMESA_FORMAT,        OSMESA_RGBA,         OSMESA_DEPTH_BITS,
                            24,                   OSMESA_STENCIL_BITS, 0,
                            OSMESA_ACCUM_BITS,    0,                   OSMESA_PROFILE,
                            OSMESA_CORE_PROFILE,  OSMESA_CONTEXT_MAJOR_VERSION,
                            3,                    OSMESA_CONTEXT_MINOR_VERSION,
                            3,                    0};
  m_context = OSMesaCreateContextAttribs(attributes, nullptr);
  if (!m_context)
    throw RuntimeFailure("OSMesa: cannot create an OpenGL 3.3 core-profile context (needs Mesa >= 17 with llvmpipe)");
  m_buffer.assign(static_cast<std::size_t>(width) * height * 4, 0);
  make_current();
  const auto* renderer = reinterpret_cast<const char*>(glGetString(GL_RENDERER));
  const auto* version = reinterpret_cast<const char*>(glGetString(GL_VERSION));
  m_description = std::string(renderer ? renderer : "?") + ", OpenGL " + (version ? version : "?");
}

OsmesaContext::~OsmesaContext() {
  if (m_context) OSMesaDestroyContext(m_context);
}

void OsmesaContext::make_current() {
  if (!OSMesaMakeCurrent(m_context, m_buffer.data(), GL_UNSIGNED_BYTE, m_width, m_height))
    throw RuntimeFailure("OSMesa: cannot make the context current");
}

#else

OsmesaContext::OsmesaContext(int, int) {
  throw RuntimeFailure("marbles was built without OSMesa (libosmesa6-dev): images and movies are not available");
}
OsmesaContext::~OsmesaContext() = default;
void OsmesaContext::make_current() {}

#endif

}  // namespace marbles::render
