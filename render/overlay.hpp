// render/overlay.hpp — the annotations drawn over a finished frame: the
// simulated time (top left) and the colour legend (top right).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "render/color_map.hpp"
#include "render/image.hpp"

namespace marbles::render {

/// What the colour legend shows.
struct ColorLegend {
  ColorBy by = ColorBy::speed;
  ColorMapName map = ColorMapName::viridis;
  double lo = 0, hi = 1;                    ///< continuous quantities
  std::vector<std::uint32_t> categories;    ///< categorical (material): the indices present
  std::vector<std::string> category_names;  ///< labels by index (the index itself where missing)
};

/// Text for a colour-bar end: 4 significant digits, exponent form for very
/// large or small magnitudes.
std::string format_value(double value);

/// Text scale (integer pixel multiple of the 5x7 font) for an image height.
int overlay_scale(int image_height);

/// Draws "t = 1.234 s" in the top-left corner.
void draw_time_label(Image& image, double time);

/// Draws the colour bar (continuous) or the swatch list (categorical) in the
/// top-right corner, titled with the quantity and its unit.
void draw_color_legend(Image& image, const ColorLegend& legend);

}  // namespace marbles::render
