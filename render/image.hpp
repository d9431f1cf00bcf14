// render/image.hpp — an 8-bit RGB picture and its PNG file form.
//
// PNG goes through libpng directly rather than VTK's vtkPNGWriter: images must
// be written in builds without VTK too (VTK is optional, libpng is tiny and
// ubiquitous), and libpng lets us pick a fast compression level (frames are
// written during a run: level 3 instead of the default 6).
#pragma once

#include <cstdint>
#include <filesystem>
#include <vector>

namespace marbles::render {

/// 8-bit sRGB pixels, row-major, top row first, 3 bytes (R, G, B) per pixel.
struct Image {
  int width = 0, height = 0;
  std::vector<std::uint8_t> rgb;

  Image() = default;
  Image(int w, int h) : width(w), height(h), rgb(static_cast<std::size_t>(w) * h * 3, 0) {}
  std::uint8_t* pixel(int x, int y) { return rgb.data() + (static_cast<std::size_t>(y) * width + x) * 3; }
  const std::uint8_t* pixel(int x, int y) const {
    return rgb.data() + (static_cast<std::size_t>(y) * width + x) * 3;
  }
};

/// True when this build can write and read PNG files (libpng was found).
bool png_available();

/// Writes `image` as an 8-bit RGB PNG, atomically (temporary file + rename).
/// Throws marbles::RuntimeFailure on I/O errors or when built without libpng.
void write_png(const std::filesystem::path& path, const Image& image);

/// Reads a PNG (any bit depth / colour type; converted to 8-bit RGB, alpha
/// dropped). Throws marbles::RuntimeFailure on errors.
Image read_png(const std::filesystem::path& path);

}  // namespace marbles::render
