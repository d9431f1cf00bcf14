// render/walls_json.cpp — writer and a minimal JSON reader (objects, arrays,
// numbers, strings, true/false/null) for the walls file.
#include "render/walls_json.hpp"

#include <cctype>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <map>
#include <memory>
#include <optional>
#include <sstream>
#include <vector>

#include "core/error.hpp"
#include "render/atomic_file.hpp"

namespace marbles::render {

namespace fs = std::filesystem;

namespace {

std::string number(double v) {
  char text[40];
  std::snprintf(text, sizeof text, "%.17g", v);
  return text;
}

std::string vec(const Vec3& v) {
  std::string out(1, '[');  // appended piece by piece: GCC 12 warns falsely (-Wrestrict) on "[" + std::string
  out += number(v.x);
  out += ", ";
  out += number(v.y);
  out += ", ";
  out += number(v.z);
  out += ']';
  return out;
}

// ---- a tiny JSON value and parser ------------------------------------------

struct Json {
  enum class Kind { null, boolean, number, string, array, object } kind = Kind::null;
  double number = 0;
  std::string text;
  std::vector<Json> items;
  std::map<std::string, Json> members;
  int line = 0, column = 0;
};

class Parser {
 public:
  Parser(const std::string& text, std::string source) : m_text(text), m_source(std::move(source)) {}

  Json parse_document() {
    Json v = value();
    skip_space();
    if (m_pos != m_text.size()) fail("", "unexpected text after the JSON value");
    return v;
  }

  [[noreturn]] void fail(const std::string& key, const std::string& message) const {
    throw InputError({m_source, m_line, m_column}, key, message);
  }

 private:
  const std::string& m_text;
  std::string m_source;
  std::size_t m_pos = 0;
  int m_line = 1, m_column = 1;

  char peek() const { return m_pos < m_text.size() ? m_text[m_pos] : '\0'; }
  char next() {
    const char c = peek();
    ++m_pos;
    if (c == '\n') ++m_line, m_column = 1;
    else ++m_column;
    return c;
  }
  void skip_space() {
    while (m_pos < m_text.size() && std::isspace(static_cast<unsigned char>(peek()))) next();
  }
  void expect(char c) {
    skip_space();
    if (peek() != c) fail("", std::string("expected '") + c + "'");
    next();
  }

  Json value() {
    skip_space();
    Json v;
    v.line = m_line, v.column = m_column;
    const char c = peek();
    if (c == '{') {
      v.kind = Json::Kind::object;
      next();
      skip_space();
      if (peek() == '}') return next(), v;
      for (;;) {
        skip_space();
        if (peek() != '"') fail("", "expected a key string");
        const std::string key = string_body();
        expect(':');
        v.members[key] = value();
        skip_space();
        if (peek() == ',') { next(); continue; }
        expect('}');
        return v;
      }
    }
    if (c == '[') {
      v.kind = Json::Kind::array;
      next();
      skip_space();
      if (peek() == ']') return next(), v;
      for (;;) {
        v.items.push_back(value());
        skip_space();
        if (peek() == ',') { next(); continue; }
        expect(']');
        return v;
      }
    }
    if (c == '"') {
      v.kind = Json::Kind::string;
      v.text = string_body();
      return v;
    }
    for (const char* word : {"true", "false", "null"}) {
      if (m_text.compare(m_pos, std::strlen(word), word) == 0) {
        for (std::size_t i = 0; i < std::strlen(word); ++i) next();
        v.kind = word[0] == 'n' ? Json::Kind::null : Json::Kind::boolean;
        v.number = word[0] == 't';
        return v;
      }
    }
    const char* begin = m_text.c_str() + m_pos;
    char* end = nullptr;
    v.number = std::strtod(begin, &end);
    if (end == begin) fail("", "expected a JSON value");
    for (auto k = end - begin; k > 0; --k) next();
    v.kind = Json::Kind::number;
    return v;
  }

  std::string string_body() {
    next();  // opening quote
    std::string out;
    for (;;) {
      if (m_pos >= m_text.size()) fail("", "unterminated string");
      char c = next();
      if (c == '"') return out;
      if (c == '\\') {
        c = next();
        switch (c) {
          case 'n': out += '\n'; break;
          case 't': out += '\t'; break;
          case 'u': for (int i = 0; i < 4; ++i) next(); out += '?'; break;
          default: out += c;
        }
      } else {
        out += c;
      }
    }
  }
};

[[noreturn]] void bad(const std::string& source, const Json& at, const std::string& key, const std::string& message) {
  throw InputError({source, at.line, at.column}, key, message);
}

Vec3 read_vec(const std::string& source, const Json& object, const char* name, const std::string& key) {
  auto it = object.members.find(name);
  if (it == object.members.end()) bad(source, object, key, std::string("missing \"") + name + "\"");
  const Json& a = it->second;
  if (a.kind != Json::Kind::array || a.items.size() != 3)
    bad(source, a, key + "." + name, "expected an array of 3 numbers");
  for (const Json& x : a.items)
    if (x.kind != Json::Kind::number) bad(source, x, key + "." + name, "expected a number");
  return Vec3(real(a.items[0].number), real(a.items[1].number), real(a.items[2].number));
}

Vec3 read_optional_vec(const std::string& source, const Json& object, const char* name, const std::string& key) {
  if (object.members.find(name) == object.members.end()) return {};
  return read_vec(source, object, name, key);
}

double read_number(const std::string& source, const Json& object, const char* name, const std::string& key,
                   std::optional<double> fallback = std::nullopt) {
  auto it = object.members.find(name);
  if (it == object.members.end()) {
    if (fallback) return *fallback;
    bad(source, object, key, std::string("missing \"") + name + "\"");
  }
  if (it->second.kind != Json::Kind::number) bad(source, it->second, key + "." + name, "expected a number");
  return it->second.number;
}

std::uint32_t read_material(const std::string& source, const Json& object, const std::string& key) {
  auto it = object.members.find("material");
  if (it == object.members.end()) return 0;
  if (it->second.kind != Json::Kind::number || it->second.number < 0)
    bad(source, it->second, key + ".material", "expected a non-negative integer");
  return static_cast<std::uint32_t>(it->second.number);
}

const std::vector<Json>* list(const std::string& source, const Json& root, const char* name) {
  auto it = root.members.find(name);
  if (it == root.members.end() || it->second.kind == Json::Kind::null) return nullptr;
  if (it->second.kind != Json::Kind::array) bad(source, it->second, name, "expected an array");
  return &it->second.items;
}

}  // namespace

std::string walls_to_json(const Walls& walls) {
  std::ostringstream out;
  out << "{\n  \"format\": \"marbles-walls\",\n  \"version\": 1";
  auto list = [&](const char* name, std::size_t count, auto&& item) {
    out << ",\n  \"" << name << "\": [";
    for (std::size_t i = 0; i < count; ++i) out << (i ? ",\n    {" : "\n    {") << item(i) << "}";
    out << (count ? "\n  ]" : "]");
  };
  list("planes", walls.planes.size(), [&](std::size_t i) {
    const PlaneWall& p = walls.planes[i];
    return "\"point\": " + vec(p.point) + ", \"normal\": " + vec(p.normal) + ", \"velocity\": " + vec(p.velocity) +
           ", \"material\": " + std::to_string(p.material);
  });
  list("boxes", walls.boxes.size(), [&](std::size_t i) {
    const BoxWall& b = walls.boxes[i];
    return "\"lo\": " + vec(b.lo) + ", \"hi\": " + vec(b.hi) + ", \"velocity\": " + vec(b.velocity) +
           ", \"material\": " + std::to_string(b.material);
  });
  list("cylinders", walls.cylinders.size(), [&](std::size_t i) {
    const CylinderWall& c = walls.cylinders[i];
    return "\"base\": " + vec(c.base) + ", \"axis\": " + vec(c.axis) + ", \"radius\": " + number(c.radius) +
           ", \"length\": " + number(c.length) + ", \"inside\": " + (c.inside ? "true" : "false") +
           ", \"angular_velocity\": " + number(c.angular_velocity) + ", \"material\": " + std::to_string(c.material);
  });
  list("spheres", walls.spheres.size(), [&](std::size_t i) {
    const SphereWall& sp = walls.spheres[i];
    return "\"centre\": " + vec(sp.centre) + ", \"radius\": " + number(sp.radius) + ", \"velocity\": " +
           vec(sp.velocity) + ", \"material\": " + std::to_string(sp.material);
  });
  out << "\n}\n";
  return out.str();
}

Walls walls_from_json(const std::string& text, const std::string& source) {
  Parser parser(text, source);
  const Json root = parser.parse_document();
  if (root.kind != Json::Kind::object) bad(source, root, "", "expected a JSON object");
  auto format = root.members.find("format");
  if (format != root.members.end() && format->second.text != "marbles-walls")
    bad(source, format->second, "format", "expected \"marbles-walls\"");
  Walls walls;
  if (const auto* planes = list(source, root, "planes")) {
    for (std::size_t i = 0; i < planes->size(); ++i) {
      const Json& p = (*planes)[i];
      const std::string key = "planes[" + std::to_string(i) + "]";
      if (p.kind != Json::Kind::object) bad(source, p, key, "expected an object");
      PlaneWall w;
      w.point = read_vec(source, p, "point", key);
      w.normal = read_vec(source, p, "normal", key);
      if (!(length(w.normal) > 0)) bad(source, p, key + ".normal", "must not be zero");
      w.normal = w.normal / length(w.normal);
      w.velocity = read_optional_vec(source, p, "velocity", key);
      w.material = read_material(source, p, key);
      walls.planes.push_back(w);
    }
  }
  if (const auto* boxes = list(source, root, "boxes")) {
    for (std::size_t i = 0; i < boxes->size(); ++i) {
      const Json& b = (*boxes)[i];
      const std::string key = "boxes[" + std::to_string(i) + "]";
      if (b.kind != Json::Kind::object) bad(source, b, key, "expected an object");
      BoxWall w;
      w.lo = read_vec(source, b, "lo", key);
      w.hi = read_vec(source, b, "hi", key);
      if (!(w.lo.x < w.hi.x && w.lo.y < w.hi.y && w.lo.z < w.hi.z))
        bad(source, b, key, "\"lo\" must be below \"hi\" on every axis");
      w.velocity = read_optional_vec(source, b, "velocity", key);
      w.material = read_material(source, b, key);
      walls.boxes.push_back(w);
    }
  }
  if (const auto* cylinders = list(source, root, "cylinders")) {
    for (std::size_t i = 0; i < cylinders->size(); ++i) {
      const Json& c = (*cylinders)[i];
      const std::string key = "cylinders[" + std::to_string(i) + "]";
      if (c.kind != Json::Kind::object) bad(source, c, key, "expected an object");
      CylinderWall w;
      w.base = read_vec(source, c, "base", key);
      w.axis = read_vec(source, c, "axis", key);
      if (!(length(w.axis) > 0)) bad(source, c, key + ".axis", "must not be zero");
      w.axis = w.axis / length(w.axis);
      w.radius = real(read_number(source, c, "radius", key));
      if (!(w.radius > 0)) bad(source, c, key + ".radius", "must be positive");
      w.length = real(read_number(source, c, "length", key, 0.0));
      auto inside = c.members.find("inside");
      if (inside != c.members.end()) {
        if (inside->second.kind != Json::Kind::boolean) bad(source, inside->second, key + ".inside", "expected true or false");
        w.inside = inside->second.number != 0;
      }
      w.angular_velocity = real(read_number(source, c, "angular_velocity", key, 0.0));
      w.material = read_material(source, c, key);
      walls.cylinders.push_back(w);
    }
  }
  if (const auto* spheres = list(source, root, "spheres")) {
    for (std::size_t i = 0; i < spheres->size(); ++i) {
      const Json& o = (*spheres)[i];
      const std::string key = "spheres[" + std::to_string(i) + "]";
      if (o.kind != Json::Kind::object) bad(source, o, key, "expected an object");
      SphereWall w;
      w.centre = read_vec(source, o, "centre", key);
      w.radius = real(read_number(source, o, "radius", key));
      if (!(w.radius > 0)) bad(source, o, key + ".radius", "must be positive");
      w.velocity = read_optional_vec(source, o, "velocity", key);
      w.material = read_material(source, o, key);
      walls.spheres.push_back(w);
    }
  }
  return walls;
}

void write_walls_json(const fs::path& dir, const Walls& walls) {
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) throw RuntimeFailure("cannot create " + dir.string() + ": " + ec.message());
  write_file_atomic(dir / "walls.json", walls_to_json(walls));
}

Walls read_walls_json(const fs::path& dir) {
  const fs::path path = dir / "walls.json";
  std::ifstream in(path, std::ios::binary);
  if (!in) return {};
  std::stringstream text;
  text << in.rdbuf();
  return walls_from_json(text.str(), path.string());
}

}  // namespace marbles::render
