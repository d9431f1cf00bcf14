// render/overlay.cpp — CPU-drawn annotations: translucent panels, the bitmap
// font, and colour-bar rows sampled straight from the colour map.
#include "render/overlay.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "render/bitmap_font.hpp"

namespace marbles::render {

namespace {

constexpr std::uint8_t kInk[3] = {28, 32, 40};
constexpr std::uint8_t kBorder[3] = {60, 64, 72};

std::uint8_t to_byte(float v) { return static_cast<std::uint8_t>(std::lround(std::clamp(v, 0.0f, 1.0f) * 255)); }

// Blends a white panel of opacity `alpha` over [x0, x1) x [y0, y1).
void draw_panel(Image& image, int x0, int y0, int x1, int y1, float alpha) {
  x0 = std::max(x0, 0), y0 = std::max(y0, 0);
  x1 = std::min(x1, image.width), y1 = std::min(y1, image.height);
  for (int y = y0; y < y1; ++y)
    for (int x = x0; x < x1; ++x) {
      std::uint8_t* p = image.pixel(x, y);
      for (int c = 0; c < 3; ++c) p[c] = static_cast<std::uint8_t>(std::lround(p[c] * (1 - alpha) + 255 * alpha));
    }
}

void fill_rect(Image& image, int x0, int y0, int x1, int y1, const std::uint8_t rgb[3]) {
  x0 = std::max(x0, 0), y0 = std::max(y0, 0);
  x1 = std::min(x1, image.width), y1 = std::min(y1, image.height);
  for (int y = y0; y < y1; ++y)
    for (int x = x0; x < x1; ++x) {
      std::uint8_t* p = image.pixel(x, y);
      p[0] = rgb[0], p[1] = rgb[1], p[2] = rgb[2];
    }
}

void frame_rect(Image& image, int x0, int y0, int x1, int y1, int t, const std::uint8_t rgb[3]) {
  fill_rect(image, x0 - t, y0 - t, x1 + t, y0, rgb);
  fill_rect(image, x0 - t, y1, x1 + t, y1 + t, rgb);
  fill_rect(image, x0 - t, y0, x0, y1, rgb);
  fill_rect(image, x1, y0, x1 + t, y1, rgb);
}

std::string legend_title(ColorBy by) {
  std::string title = color_by_name(by);
  const std::string unit = color_by_unit(by);
  if (!unit.empty()) title += " [" + unit + "]";
  return title;
}

}  // namespace

std::string format_value(double v) {
  char text[32];
  const double a = std::abs(v);
  if (v == 0) return "0";
  if (a >= 1e5 || a < 1e-3)
    std::snprintf(text, sizeof text, "%.3e", v);
  else
    std::snprintf(text, sizeof text, "%.4g", v);
  return text;
}

int overlay_scale(int image_height) { return std::max(1, static_cast<int>(std::lround(image_height / 400.0))); }

void draw_time_label(Image& image, double time) {
  const int s = overlay_scale(image.height);
  char text[64];
  std::snprintf(text, sizeof text, "t = %.3f s", time);
  const int pad = 8 * s, margin = 5 * s;
  const int w = text_width(text, s), h = kGlyphHeight * s;
  draw_panel(image, pad, pad, pad + w + 2 * margin, pad + h + 2 * margin, 0.7f);
  draw_text(image, pad + margin, pad + margin, text, s, kInk);
}

namespace {

std::string category_label(const ColorLegend& legend, std::uint32_t category) {
  if (category < legend.category_names.size() && !legend.category_names[category].empty())
    return legend.category_names[category];
  return std::to_string(category);
}

}  // namespace

void draw_color_legend(Image& image, const ColorLegend& legend) {
  const int s = overlay_scale(image.height);
  const int pad = 8 * s, margin = 5 * s, line = (kGlyphHeight + 4) * s;
  const std::string title = legend_title(legend.by);

  if (is_categorical(legend.by)) {
    const int swatch = kGlyphHeight * s;
    const std::size_t shown = std::min<std::size_t>(legend.categories.size(), 16);
    int content_w = text_width(title, s);
    for (std::size_t i = 0; i < shown; ++i)
      content_w = std::max(content_w, swatch + 4 * s + text_width(category_label(legend, legend.categories[i]), s));
    const int panel_w = content_w + 2 * margin;
    const int panel_h = line * static_cast<int>(shown + 1) + 2 * margin - 4 * s;
    const int x0 = image.width - pad - panel_w, y0 = pad;
    draw_panel(image, x0, y0, x0 + panel_w, y0 + panel_h, 0.7f);
    draw_text(image, x0 + margin, y0 + margin, title, s, kInk);
    for (std::size_t i = 0; i < shown; ++i) {
      const int y = y0 + margin + line * static_cast<int>(i + 1);
      const Rgb c = category_color(legend.categories[i]);
      const std::uint8_t rgb[3] = {to_byte(c.r), to_byte(c.g), to_byte(c.b)};
      fill_rect(image, x0 + margin, y, x0 + margin + swatch, y + swatch, rgb);
      frame_rect(image, x0 + margin, y, x0 + margin + swatch, y + swatch, 1, kBorder);
      draw_text(image, x0 + margin + swatch + 4 * s, y, category_label(legend, legend.categories[i]), s, kInk);
    }
    return;
  }

  // Title, then the bar with the maximum at its top and the minimum at its
  // bottom, each labelled to its right.
  const std::string hi_text = format_value(legend.hi), lo_text = format_value(legend.lo);
  const int bar_w = 12 * s;
  const int bar_h = std::max(40, image.height * 2 / 5);
  const int labels_w = std::max(text_width(hi_text, s), text_width(lo_text, s));
  const int content_w = std::max(text_width(title, s), bar_w + 4 * s + labels_w);
  const int panel_w = content_w + 2 * margin;
  const int panel_h = line + bar_h + 2 * margin;
  const int x0 = image.width - pad - panel_w, y0 = pad;
  draw_panel(image, x0, y0, x0 + panel_w, y0 + panel_h, 0.7f);
  draw_text(image, x0 + margin, y0 + margin, title, s, kInk);

  const int bx = x0 + margin, by = y0 + margin + line;
  for (int y = 0; y < bar_h; ++y) {
    const Rgb c = sample_color_map(legend.map, 1.0 - (y + 0.5) / bar_h);
    const std::uint8_t rgb[3] = {to_byte(c.r), to_byte(c.g), to_byte(c.b)};
    fill_rect(image, bx, by + y, bx + bar_w, by + y + 1, rgb);
  }
  frame_rect(image, bx, by, bx + bar_w, by + bar_h, 1, kBorder);
  draw_text(image, bx + bar_w + 4 * s, by, hi_text, s, kInk);
  draw_text(image, bx + bar_w + 4 * s, by + bar_h - kGlyphHeight * s, lo_text, s, kInk);
}

}  // namespace marbles::render
