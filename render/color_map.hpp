// render/color_map.hpp — what a sphere's colour says, and the maps that turn a
// number into a colour.
//
// Continuous quantities (speed, radius, id) go through a perceptually uniform
// map (viridis by default, turbo on request); materials, which are categories,
// get distinct colours from the Okabe–Ito colour-blind-safe palette.
#pragma once

#include <cstdint>
#include <optional>
#include <string_view>

namespace marbles::render {

/// The quantity that colours the spheres.
enum class ColorBy { speed, id, radius, material };

/// Parses "speed" | "id" | "radius" | "material"; nullopt otherwise.
std::optional<ColorBy> parse_color_by(std::string_view name);
const char* color_by_name(ColorBy c);
/// The unit printed on the colour bar ("m/s", "m", or "" when none).
const char* color_by_unit(ColorBy c);
/// True for quantities drawn with a categorical palette (material).
bool is_categorical(ColorBy c);

enum class ColorMapName { viridis, turbo };
std::optional<ColorMapName> parse_color_map(std::string_view name);

/// An sRGB colour, components in [0, 1].
struct Rgb {
  float r = 0, g = 0, b = 0;
};

/// The colour map at t in [0, 1] (clamped), linearly interpolated between the
/// published key colours.
Rgb sample_color_map(ColorMapName map, double t);

/// A distinct colour for category `index` (cycles after 8).
Rgb category_color(std::uint32_t index);

}  // namespace marbles::render
