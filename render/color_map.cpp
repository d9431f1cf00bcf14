// render/color_map.cpp — colour-map tables.
//
// viridis: matplotlib's table at t = 0, 0.1, ..., 1 (every 25.5th of its 256
// entries); turbo: Google's table at entries 0, 16, ..., 240, 255. Linear
// interpolation between these keys stays within ~1/255 of the full tables.
#include "render/color_map.hpp"

#include <algorithm>
#include <cmath>
#include <iterator>

namespace marbles::render {

std::optional<ColorBy> parse_color_by(std::string_view name) {
  if (name == "speed") return ColorBy::speed;
  if (name == "id") return ColorBy::id;
  if (name == "radius") return ColorBy::radius;
  if (name == "material") return ColorBy::material;
  return std::nullopt;
}

const char* color_by_name(ColorBy c) {
  switch (c) {
    case ColorBy::speed: return "speed";
    case ColorBy::id: return "id";
    case ColorBy::radius: return "radius";
    case ColorBy::material: return "material";
  }
  return "?";
}

const char* color_by_unit(ColorBy c) {
  switch (c) {
    case ColorBy::speed: return "m/s";
    case ColorBy::radius: return "m";
    default: return "";
  }
}

bool is_categorical(ColorBy c) { return c == ColorBy::material; }

std::optional<ColorMapName> parse_color_map(std::string_view name) {
  if (name == "viridis") return ColorMapName::viridis;
  if (name == "turbo") return ColorMapName::turbo;
  return std::nullopt;
}

namespace {

struct Key {
  float t, r, g, b;
};

constexpr Key kViridis[] = {
    {0.0f, 0.267004f, 0.004874f, 0.329415f}, {0.1f, 0.282623f, 0.140926f, 0.457517f},
    {0.2f, 0.253935f, 0.265254f, 0.529983f}, {0.3f, 0.206756f, 0.371758f, 0.553117f},
    {0.4f, 0.163625f, 0.471133f, 0.558148f}, {0.5f, 0.127568f, 0.566949f, 0.550556f},
    {0.6f, 0.134692f, 0.658636f, 0.517649f}, {0.7f, 0.266941f, 0.748751f, 0.440573f},
    {0.8f, 0.477504f, 0.821444f, 0.318195f}, {0.9f, 0.741388f, 0.873449f, 0.149561f},
    {1.0f, 0.993248f, 0.906157f, 0.143936f},
};

constexpr Key kTurbo[] = {
    {0.f / 255, 0.18995f, 0.07176f, 0.23217f},   {16.f / 255, 0.25107f, 0.25237f, 0.63374f},
    {32.f / 255, 0.27628f, 0.42118f, 0.89123f},  {48.f / 255, 0.25862f, 0.57958f, 0.99876f},
    {64.f / 255, 0.15844f, 0.73551f, 0.92305f},  {80.f / 255, 0.09267f, 0.86554f, 0.76230f},
    {96.f / 255, 0.19659f, 0.94901f, 0.59466f},  {112.f / 255, 0.42778f, 0.99419f, 0.38575f},
    {128.f / 255, 0.64362f, 0.98999f, 0.23356f}, {144.f / 255, 0.80473f, 0.92452f, 0.20459f},
    {160.f / 255, 0.93301f, 0.81236f, 0.22667f}, {176.f / 255, 0.99314f, 0.67408f, 0.20348f},
    {192.f / 255, 0.98360f, 0.49291f, 0.12849f}, {208.f / 255, 0.92105f, 0.31489f, 0.05475f},
    {224.f / 255, 0.81608f, 0.18462f, 0.01809f}, {240.f / 255, 0.66449f, 0.08436f, 0.00424f},
    {255.f / 255, 0.47960f, 0.01583f, 0.01055f},
};

// Okabe & Ito (2008), "Color Universal Design", without black.
constexpr Rgb kCategories[] = {
    {0x00 / 255.f, 0x72 / 255.f, 0xB2 / 255.f},  // blue
    {0xE6 / 255.f, 0x9F / 255.f, 0x00 / 255.f},  // orange
    {0x00 / 255.f, 0x9E / 255.f, 0x73 / 255.f},  // bluish green
    {0xCC / 255.f, 0x79 / 255.f, 0xA7 / 255.f},  // reddish purple
    {0x56 / 255.f, 0xB4 / 255.f, 0xE9 / 255.f},  // sky blue
    {0xD5 / 255.f, 0x5E / 255.f, 0x00 / 255.f},  // vermillion
    {0xF0 / 255.f, 0xE4 / 255.f, 0x42 / 255.f},  // yellow
    {0x99 / 255.f, 0x99 / 255.f, 0x99 / 255.f},  // grey
};

template <std::size_t N>
Rgb interpolate(const Key (&keys)[N], double t) {
  if (!(t > 0)) t = 0;  // also maps NaN to the low end
  if (t > 1) t = 1;
  std::size_t i = 1;
  while (i + 1 < N && keys[i].t < t) ++i;
  const Key& a = keys[i - 1];
  const Key& b = keys[i];
  const float f = static_cast<float>(std::clamp((t - a.t) / (b.t - a.t), 0.0, 1.0));
  return {a.r + (b.r - a.r) * f, a.g + (b.g - a.g) * f, a.b + (b.b - a.b) * f};
}

}  // namespace

Rgb sample_color_map(ColorMapName map, double t) {
  return map == ColorMapName::turbo ? interpolate(kTurbo, t) : interpolate(kViridis, t);
}

Rgb category_color(std::uint32_t index) { return kCategories[index % std::size(kCategories)]; }

}  // namespace marbles::render
