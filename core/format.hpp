// core/format.hpp — numbers as text for output files.
//
//   shortest(v)      the shortest text that reads back as exactly v
//                    (std::to_chars): 0.1, 1e-07, 2.5; a float's, read as a
//                    double and rounded to a float (as the scene reader does)
//   significant(v, n) v to n significant digits (%g): messages
//   time_text(t)     the shortest text within 1e-13 of t relative: a frame
//                    time k dt written as 0.03, not 0.030000000000000002,
//                    and 10 or 120, not 1e+01 or 1.2e+02
#pragma once

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <string_view>

namespace marbles {

inline std::string shortest(double v) {
  if (!std::isfinite(v)) return std::isnan(v) ? "nan" : (v > 0 ? "inf" : "-inf");
  char text[32];
  const auto result = std::to_chars(text, text + sizeof text, v);
  return std::string(text, result.ptr);
}

// A float's shortest digits read as a double and rounded to a float could
// in principle land on its neighbour: then the double's digits.
inline std::string shortest(float v) {
  if (!std::isfinite(v)) return shortest(static_cast<double>(v));
  char text[32];
  const auto result = std::to_chars(text, text + sizeof text, v);
  std::string s(text, result.ptr);
  if (static_cast<float>(std::strtod(s.c_str(), nullptr)) != v) return shortest(static_cast<double>(v));
  return s;
}

inline std::string significant(double v, int digits) {
  char text[40];
  std::snprintf(text, sizeof text, "%.*g", digits, v);
  return text;
}

// Text quoted from input in a message, its control bytes (a NUL would end
// the message where it is printed) as \xNN; with `ascii`, every byte past
// ASCII too (a binary file's), else those kept (UTF-8 text).
inline std::string printable(std::string_view text, bool ascii = true) {
  std::string out;
  for (const unsigned char c : text) {
    if (c >= 0x20 && c != 0x7f && (c < 0x80 || !ascii)) {
      out += char(c);
    } else {
      char hex[8];
      std::snprintf(hex, sizeof hex, "\\x%02x", c);
      out += hex;
    }
  }
  return out;
}

// The offset of the first byte of `text` that does not begin a whole UTF-8
// character (an overlong form, a surrogate or past U+10FFFF), else npos.
inline std::size_t first_non_utf8(std::string_view text) {
  std::size_t i = 0;
  while (i < text.size()) {
    const unsigned char c = text[i];
    int more = 0;                        // bytes that follow
    unsigned char lo = 0x80, hi = 0xbf;  // the second byte's range
    if (c < 0x80) more = 0;
    else if (c >= 0xc2 && c <= 0xdf) more = 1;
    else if (c >= 0xe0 && c <= 0xef) more = 2, lo = c == 0xe0 ? 0xa0 : 0x80, hi = c == 0xed ? 0x9f : 0xbf;
    else if (c >= 0xf0 && c <= 0xf4) more = 3, lo = c == 0xf0 ? 0x90 : 0x80, hi = c == 0xf4 ? 0x8f : 0xbf;
    else return i;
    if (i + more >= text.size()) return i;  // cut short
    for (int k = 1; k <= more; ++k) {
      const unsigned char b = text[i + k];
      if (k == 1 ? (b < lo || b > hi) : (b < 0x80 || b > 0xbf)) return i;
    }
    i += 1 + more;
  }
  return std::string_view::npos;
}

// A path in a message, in one line: its control bytes as \xNN, and every
// byte past ASCII too where it is no UTF-8 text (a name in Latin-1).
inline std::string printable_path(std::string_view path) {
  return printable(path, first_non_utf8(path) != std::string_view::npos);
}

// "not UTF-8 text: \xNN": a refusal's words for the byte at `at`
// (first_non_utf8), its place the caller's.
inline std::string not_utf8_text(std::string_view text, std::size_t at) {
  return "not UTF-8 text: " + printable(text.substr(at, 1));
}

// A size in bytes for messages: three significant digits in GB, MB, kB or
// bytes ("1.23 GB", "640 bytes").
inline std::string bytes_text(double bytes) {
  if (bytes >= 1e9) return significant(bytes / 1e9, 3) + " GB";
  if (bytes >= 1e6) return significant(bytes / 1e6, 3) + " MB";
  if (bytes >= 1e3) return significant(bytes / 1e3, 3) + " kB";
  return significant(bytes, 3) + " bytes";
}

inline std::string time_text(double t) {
  if (!std::isfinite(t)) return shortest(t);
  char text[40];
  for (int digits = 1; digits <= 17; ++digits) {
    std::snprintf(text, sizeof text, "%.*g", digits, t);
    if (std::fabs(std::strtod(text, nullptr) - t) <= 1e-13 * std::fabs(t)) {
      const char* e = std::strchr(text, 'e');
      if (!e) return text;
      // "1e+01" or "1.2e+02" where "10" or "120" says the same digits in
      // fewer characters: the shorter (a tie, the plain one).
      const int exponent = std::atoi(e + 1);
      char plain[400];
      std::snprintf(plain, sizeof plain, "%.*f", std::max(0, digits - 1 - exponent), t);
      return std::strlen(plain) <= std::strlen(text) ? plain : text;
    }
  }
  return shortest(t);
}

}  // namespace marbles
