// render/image.cpp — PNG through libpng (see image.hpp for why not VTK).
#include "render/image.hpp"

#include <cerrno>
#include <csetjmp>
#include <cstdio>
#include <cstring>
#include <string>

#include "core/error.hpp"
#include "render/atomic_file.hpp"

#if defined(MARBLES_HAVE_PNG)
#include <png.h>
#endif

namespace marbles::render {

namespace fs = std::filesystem;

#if defined(MARBLES_HAVE_PNG)

bool png_available() { return true; }

namespace {

struct FileCloser {
  std::FILE* f;
  ~FileCloser() {
    if (f) std::fclose(f);
  }
};

[[noreturn]] void png_fail(png_structp png, png_const_charp message) {
  auto* text = static_cast<std::string*>(png_get_error_ptr(png));
  if (text) *text = message;
  png_longjmp(png, 1);
}

}  // namespace

void write_png(const fs::path& path, const Image& image) {
  if (image.width <= 0 || image.height <= 0 || image.rgb.size() != std::size_t(image.width) * image.height * 3)
    throw RuntimeFailure("write_png: " + path.string() + ": image has inconsistent size");
  const fs::path tmp = temp_path_beside(path);
  std::FILE* f = std::fopen(tmp.c_str(), "wb");
  if (!f) throw RuntimeFailure(cannot_create(tmp, errno));

  std::string error;
  png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, &error, png_fail, nullptr);
  png_infop info = png ? png_create_info_struct(png) : nullptr;
  volatile bool ok = png && info;
  if (ok && setjmp(png_jmpbuf(png)) == 0) {
    png_init_io(png, f);
    png_set_compression_level(png, 3);
    png_set_filter(png, PNG_FILTER_TYPE_BASE, PNG_FILTER_SUB | PNG_FILTER_UP);
    png_set_IHDR(png, info, image.width, image.height, 8, PNG_COLOR_TYPE_RGB, PNG_INTERLACE_NONE,
                 PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
    png_write_info(png, info);
    for (int y = 0; y < image.height; ++y) png_write_row(png, image.pixel(0, y));
    png_write_end(png, nullptr);
  } else {
    ok = false;
  }
  png_destroy_write_struct(png ? &png : nullptr, info ? &info : nullptr);
  const bool closed = std::fclose(f) == 0;
  if (!ok || !closed) {
    std::error_code ec;
    fs::remove(tmp, ec);
    throw RuntimeFailure("cannot write PNG " + path.string() + ": " + (error.empty() ? std::strerror(errno) : error));
  }
  commit_file(tmp, path, ends_with(std::string_view("IEND\xae\x42\x60\x82", 8)));
}

Image read_png(const fs::path& path) {
  FileCloser file{std::fopen(path.c_str(), "rb")};
  if (!file.f) throw RuntimeFailure("cannot open " + path.string() + ": " + std::strerror(errno));
  std::string error;
  png_structp png = png_create_read_struct(PNG_LIBPNG_VER_STRING, &error, png_fail, nullptr);
  png_infop info = png ? png_create_info_struct(png) : nullptr;
  Image image;
  volatile bool ok = png && info;
  if (ok && setjmp(png_jmpbuf(png)) == 0) {
    png_init_io(png, file.f);
    png_read_info(png, info);
    png_set_expand(png);
    png_set_strip_16(png);
    png_set_strip_alpha(png);
    png_set_gray_to_rgb(png);
    png_read_update_info(png, info);
    image = Image(static_cast<int>(png_get_image_width(png, info)), static_cast<int>(png_get_image_height(png, info)));
    std::vector<png_bytep> rows(image.height);
    for (int y = 0; y < image.height; ++y) rows[y] = image.pixel(0, y);
    png_read_image(png, rows.data());
    png_read_end(png, nullptr);
  } else {
    ok = false;
  }
  png_destroy_read_struct(png ? &png : nullptr, info ? &info : nullptr, nullptr);
  if (!ok) throw RuntimeFailure("cannot read PNG " + path.string() + ": " + error);
  return image;
}

#else  // !MARBLES_HAVE_PNG

bool png_available() { return false; }

void write_png(const fs::path& path, const Image&) {
  throw RuntimeFailure("cannot write " + path.string() + ": marbles was built without libpng (install libpng-dev)");
}

Image read_png(const fs::path& path) {
  throw RuntimeFailure("cannot read " + path.string() + ": marbles was built without libpng (install libpng-dev)");
}

#endif

}  // namespace marbles::render
