// render/bitmap_font.hpp — a 5x7 pixel font for the labels drawn on frames
// (simulated time, colour-bar values). Printable ASCII only; anything else
// draws as '?'. Drawn on the CPU into the finished image, scaled by an integer
// factor so it stays crisp.
#pragma once

#include <cstdint>
#include <string_view>

#include "render/image.hpp"

namespace marbles::render {

inline constexpr int kGlyphWidth = 5;
inline constexpr int kGlyphHeight = 7;
inline constexpr int kGlyphAdvance = 6;  // width + one column of spacing

/// Whether pixel (x, y) of the glyph for `c` is set; (0, 0) is top left.
bool glyph_pixel(char c, int x, int y);

/// Width in pixels of `text` drawn at `scale` (no trailing spacing).
int text_width(std::string_view text, int scale);

/// Draws `text` with its top-left corner at (x, y); pixels outside the image
/// are clipped. `rgb` is the text colour.
void draw_text(Image& image, int x, int y, std::string_view text, int scale, const std::uint8_t rgb[3]);

}  // namespace marbles::render
