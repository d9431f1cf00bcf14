// sim/scene_yaml.cpp — checked conversions from yaml-cpp nodes (see scene_yaml.hpp).
//
// Numbers are parsed from the scalar text with std::from_chars rather than
// yaml-cpp's stream conversion, so that YAML's .nan/.inf spellings, trailing
// garbage and out-of-range values each get their own message, and the
// message can quote the value exactly as it was written.
#include "sim/scene_yaml.hpp"

#include <algorithm>
#include <charconv>
#include <cstdlib>
#include <cmath>
#include <limits>
#include <sstream>

#include <yaml-cpp/eventhandler.h>

#include "core/format.hpp"
#include "core/hash.hpp"

namespace marbles::scene::detail {

SourceLocation location_of(const std::string& file, const YAML::Mark& mark) {
  SourceLocation where;
  where.file = file;
  where.line = mark.line >= 0 ? mark.line + 1 : 0;
  where.column = (mark.line >= 0 && mark.column >= 0) ? mark.column + 1 : 0;
  return where;
}

namespace {

// The events of a YAML text, as scan_yaml reads them, with the dotted key
// of each node ("materials.glass.density", "particles[2]"; a map's key
// takes its map's).
class ScanHandler : public YAML::EventHandler {
 public:
  ScanHandler(const std::string& text, bool utf8, YamlScan& scan) : m_text(text), m_utf8(utf8), m_scan(scan) {}

  void OnDocumentStart(const YAML::Mark& mark) override {
    if (++m_scan.documents == 2) m_scan.second = mark;
    m_levels.clear();
  }
  void OnDocumentEnd() override {}
  void OnNull(const YAML::Mark&, YAML::anchor_t) override { after(nullptr); }
  void OnAlias(const YAML::Mark&, YAML::anchor_t) override { after(nullptr); }
  void OnScalar(const YAML::Mark& mark, const std::string& tag, YAML::anchor_t, const std::string& value) override {
    tagged(mark, tag);
    if (tag == "!" && m_utf8) quoted(mark);
    after(&value);
  }
  void OnSequenceStart(const YAML::Mark& mark, const std::string& tag, YAML::anchor_t,
                       YAML::EmitterStyle::value) override {
    tagged(mark, tag);
    m_levels.push_back({false});
  }
  void OnSequenceEnd() override { end(); }
  void OnMapStart(const YAML::Mark& mark, const std::string& tag, YAML::anchor_t, YAML::EmitterStyle::value) override {
    tagged(mark, tag);
    m_levels.push_back({true});
  }
  void OnMapEnd() override { end(); }

 private:
  struct Level {
    bool map;
    bool key_next = true;
    std::string last = {};  // a map's last key
    std::size_t index = 0;  // a sequence's next item
  };

  // The key of the node that starts now (made only for a problem: a scene
  // of 10^6 inline positions starts 10^6 sequences).
  std::string here() const {
    std::string key;
    for (const Level& level : m_levels) {
      if (level.map && level.key_next) break;  // a key: its map's (only the innermost level waits for one)
      key += level.map ? (key.empty() ? "" : ".") + printable(level.last) : "[" + std::to_string(level.index) + "]";
    }
    return key;
  }
  // A node has ended: the next is its map's value or key, or its sequence's next item.
  void after(const std::string* scalar) {
    if (m_levels.empty()) return;
    Level& level = m_levels.back();
    if (!level.map) {
      ++level.index;
      return;
    }
    if (level.key_next) level.last = scalar ? *scalar : "?";
    level.key_next = !level.key_next;
  }
  void end() {
    if (!m_levels.empty()) m_levels.pop_back();
    after(nullptr);
  }
  void found(const YAML::Mark& mark, std::string what) {
    if (m_scan.documents == 1 && !m_scan.problem) m_scan.problem = YamlScan::Problem{mark, here(), std::move(what)};
  }
  // "?" is no tag, "!" a quoted value's (or the bare `!`, which asks for nothing).
  void tagged(const YAML::Mark& mark, const std::string& tag) {
    if (tag == "?" || tag == "!") return;
    static constexpr std::string_view core = "tag:yaml.org,2002:";
    const std::string said = tag.starts_with(core) ? "!!" + tag.substr(core.size()) : tag;
    found(mark, "a YAML tag ('" + printable(said) + "'): a scene's values take none (remove it)");
  }
  // The value at the mark, where it is quoted, must close its quote before
  // the text ends (in double quotes a backslash escapes the next byte, in
  // single quotes a doubled quote is one).
  void quoted(const YAML::Mark& mark) {
    if (mark.pos < 0) return;
    std::size_t start = (m_text.starts_with("\xef\xbb\xbf") ? 3 : 0) + static_cast<std::size_t>(mark.pos);
    if (start >= m_text.size()) return;
    // The mark stands before the node's properties: an anchor (`&a "x`) or a bare `!`.
    while (start < m_text.size() && (m_text[start] == '&' || m_text[start] == '!')) {
      while (start < m_text.size() && m_text[start] != ' ' && m_text[start] != '\t' && m_text[start] != '\n')
        ++start;
      while (start < m_text.size() && (m_text[start] == ' ' || m_text[start] == '\t')) ++start;
    }
    if (start >= m_text.size()) return;
    const char quote = m_text[start];
    if (quote != '"' && quote != '\'') return;  // a block scalar's `|` or `>`
    for (std::size_t k = start + 1; k < m_text.size(); ++k) {
      if (quote == '"' && m_text[k] == '\\') {
        ++k;
      } else if (m_text[k] == quote) {
        if (quote == '"' || k + 1 == m_text.size() || m_text[k + 1] != '\'') return;
        ++k;
      }
    }
    found(mark, std::string("a quoted value never closed (its ") + quote + " is missing)");
  }

  const std::string& m_text;
  bool m_utf8;
  YamlScan& m_scan;
  std::vector<Level> m_levels;
};

char lower(char c) { return (c >= 'A' && c <= 'Z') ? char(c - 'A' + 'a') : c; }

std::size_t edit_distance(std::string_view a, std::string_view b) {
  std::vector<std::size_t> row(b.size() + 1);
  for (std::size_t j = 0; j <= b.size(); ++j) row[j] = j;
  for (std::size_t i = 1; i <= a.size(); ++i) {
    std::size_t diagonal = row[0];
    row[0] = i;
    for (std::size_t j = 1; j <= b.size(); ++j) {
      const std::size_t above = row[j];
      const std::size_t substitute = diagonal + (lower(a[i - 1]) == lower(b[j - 1]) ? 0 : 1);
      row[j] = std::min({above + 1, row[j - 1] + 1, substitute});
      diagonal = above;
    }
  }
  return row[b.size()];
}

std::string join_key(const std::string& parent, const std::string& name) {
  return parent.empty() ? name : parent + "." + name;
}

std::string_view trimmed(std::string_view s) {
  while (!s.empty() && (s.front() == ' ' || s.front() == '\t')) s.remove_prefix(1);
  while (!s.empty() && (s.back() == ' ' || s.back() == '\t')) s.remove_suffix(1);
  return s;
}

bool is_yaml_non_finite(std::string_view s) {
  std::string t;
  for (char c : s) t += lower(c);
  return t == ".nan" || t == ".inf" || t == "+.inf" || t == "-.inf";
}

template <typename Int>
bool parse_integer(std::string_view text, Int& value) {
  std::string_view s = trimmed(text);
  if (!s.empty() && s.front() == '+') s.remove_prefix(1);
  if (s.empty()) return false;
  const auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), value);
  return ec == std::errc() && end == s.data() + s.size();
}

}  // namespace

YamlScan scan_yaml(const std::string& text, std::size_t limit, bool utf8) {
  YamlScan scan;
  std::istringstream in(text);
  YAML::Parser parser(in);
  ScanHandler handler(text, utf8, scan);
  while (scan.documents < limit && parser.HandleNextDocument(handler)) {
  }
  return scan;
}

bool parse_double(std::string_view text, double& value) {
  std::string_view s = trimmed(text);
  if (!s.empty() && s.front() == '+') s.remove_prefix(1);
  if (s.empty()) return false;
  const auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), value);
  if (ec == std::errc::result_out_of_range) {
    // A number past double's range either way: its value rounded as strtod
    // rounds it (+-inf past the top, a subnormal below), with its sign. One
    // that rounds to 0 is kept off zero (the smallest subnormal), so that the
    // range check refuses it as too small: 1e-400 was taken as 0.
    if (end != s.data() + s.size()) return false;
    value = std::strtod(std::string(s).c_str(), nullptr);
    if (value == 0) value = std::copysign(std::numeric_limits<double>::denorm_min(), value);
    return true;
  }
  return ec == std::errc() && end == s.data() + s.size();
}

std::string nearest_name(std::string_view word, const std::vector<std::string>& candidates) {
  std::string best;
  std::size_t best_distance = std::numeric_limits<std::size_t>::max();
  for (const std::string& c : candidates) {
    const std::size_t d = edit_distance(word, c);
    if (d < best_distance) {
      best_distance = d;
      best = c;
    }
  }
  const std::size_t limit = std::max<std::size_t>(1, std::min(word.size(), best.size()) / 3);
  if (best.empty() || best_distance > limit || best_distance >= word.size()) return {};
  return best;
}

std::string suggestion(std::string_view word, const std::vector<std::string>& candidates) {
  const std::string near = nearest_name(word, candidates);
  if (!near.empty()) return " (did you mean '" + near + "'?)";
  std::string out = "; expected one of: ";
  for (std::size_t i = 0; i < candidates.size(); ++i) out += (i ? ", " : "") + candidates[i];
  return out;
}

// --- Origins ---------------------------------------------------------------

void Origins::add(const YAML::Node& node, const std::string& text) { m_nodes.emplace_back(node, text); }

const std::string* Origins::find(const YAML::Node& node) const {
  for (auto it = m_nodes.rbegin(); it != m_nodes.rend(); ++it)
    if (it->first.is(node)) return &it->second;
  return nullptr;
}

const std::string* Origins::find_under(const std::string& key) const {
  for (auto it = m_nodes.rbegin(); it != m_nodes.rend(); ++it) {
    std::string_view path = it->second;  // "--set KEY.PATH=VALUE"
    if (!path.starts_with("--set ")) continue;
    path.remove_prefix(6);
    path = path.substr(0, path.find('='));
    if (path.starts_with(key) && (path.size() == key.size() || path[key.size()] == '.' || path[key.size()] == '['))
      return &it->second;
  }
  return nullptr;
}

void Origins::copied(const YAML::Node& copy, const YAML::Node& original) {
  const YAML::Mark* earlier = mark_of(original);  // a copy of a copy
  m_marks.emplace_back(copy, earlier ? *earlier : original.Mark());
}

const YAML::Mark* Origins::mark_of(const YAML::Node& node) const {
  for (auto it = m_marks.rbegin(); it != m_marks.rend(); ++it)
    if (it->first.is(node)) return &it->second;
  return nullptr;
}

void Origins::took(const std::string& key, const std::string& text, const std::string& value) const {
  const std::uint64_t text_hash = fnv1a(text.data(), text.size());
  const std::uint64_t value_hash = value.empty() ? 0 : std::max<std::uint64_t>(1, fnv1a(value.data(), value.size()));
  const auto [at, added] = m_taken.try_emplace(fnv1a(key.data(), key.size()), Taken{text_hash, value_hash});
  if (!added && (at->second.text != text_hash || at->second.value != value_hash)) at->second.value = 0;
}

std::uint64_t Origins::taken(const std::string& key, const std::string& text) const {
  const auto at = m_taken.find(fnv1a(key.data(), key.size()));
  return at != m_taken.end() && at->second.text == fnv1a(text.data(), text.size()) ? at->second.value : 0;
}

// --- Field -----------------------------------------------------------------

Field::Field(YAML::Node node, std::string key, const std::string& file, const Origins* origins)
    : m_node(std::move(node)), m_key(std::move(key)), m_file(file), m_mark(m_node.Mark()), m_origins(origins) {
  if (const YAML::Mark* mark = m_origins ? m_origins->mark_of(m_node) : nullptr) m_mark = *mark;
}

Field::Field(YAML::Node node, std::string key, const Field& parent)
    : Field(std::move(node), std::move(key), parent.m_file, parent.m_origins) {
  m_from_override = parent.m_from_override;
  if (const std::string* text = m_origins ? m_origins->find(m_node) : nullptr) {
    m_file = *text;
    m_from_override = true;
  }
}

Field::Field(YAML::Node node, std::string key, const Field& parent, const YAML::Mark& fallback)
    : Field(std::move(node), std::move(key), parent) {
  if (m_node.IsNull()) m_mark = fallback;
}

SourceLocation Field::where() const {
  return m_from_override ? SourceLocation{m_file, 0, 0} : location_of(m_file, m_mark);
}

void Field::fail(const std::string& message) const { throw InputError(where(), m_key, message); }

std::string Field::description() const {
  switch (m_node.Type()) {
    case YAML::NodeType::Map: return "a map";
    case YAML::NodeType::Sequence: return "a sequence";
    case YAML::NodeType::Scalar: return "'" + m_node.Scalar() + "'";
    default: return "nothing (null)";
  }
}

void Field::took(const std::string& value) const {
  if (m_origins && is_scalar()) m_origins->took(m_key, m_node.Scalar(), value);
}

double Field::number() const { return taken(parsed_number()); }

double Field::finite_number() const { return in_precision(parsed_number()); }

double Field::parsed_number() const {
  if (!is_scalar()) fail("expected a number, got " + description());
  const std::string& text = m_node.Scalar();
  if (is_yaml_non_finite(text)) fail("must be a finite number, got " + text);
  double value = 0;
  if (!parse_double(text, value)) fail("expected a number, got " + description());
  if (!std::isfinite(value)) fail("must be a finite number, got " + text);
  return value;
}

// Every value reaches the step as `real`: it must stay finite, and a
// non-zero one non-zero, in the precision of the run.
double Field::in_precision(double value) const {
  if (const std::string problem = real_range_problem(value, true); !problem.empty())
    fail(problem + ", got " + m_node.Scalar());
  return value;
}

double Field::taken(double value) const {
  in_precision(value);
  took("n:" + shortest(value));
  return value;
}

std::string real_range_problem(double value, bool bound) {
  const std::string precision = " for " + std::string(kRealName) + " precision";
  if (!std::isfinite(static_cast<real>(value)))
    return "out of range" + precision +
           (bound ? " (largest " + shortest(std::numeric_limits<real>::max()) + ")" : std::string());
  if (value != 0 && !(std::abs(static_cast<real>(value)) >= std::numeric_limits<real>::min()))
    return "too small" + precision +
           (bound ? " (smallest " + shortest(std::numeric_limits<real>::min()) + ")" : std::string());
  return "";
}

// The key's own bounds before the precision's: a restitution of -1e-300
// is outside [0, 1], not "too small for float precision".
double Field::positive() const {
  const double v = parsed_number();
  if (!(v > 0)) fail("must be > 0, got " + m_node.Scalar());
  return taken(v);
}

double Field::non_negative() const {
  const double v = parsed_number();
  if (!(v >= 0)) fail("must be >= 0, got " + m_node.Scalar());
  return taken(v);
}

double Field::within(double lo, double hi) const {
  const double v = parsed_number();
  if (!(v >= lo && v <= hi))
    fail("must be within [" + shortest(lo) + ", " + shortest(hi) + "], got " + m_node.Scalar());
  return taken(v);
}

long long Field::integer() const {
  if (!is_scalar()) fail("expected an integer, got " + description());
  long long value = 0;
  if (!parse_integer(m_node.Scalar(), value)) {
    const double d = finite_number();  // reports non-numbers and non-finite values
    if (d != std::floor(d)) fail("expected an integer, got " + m_node.Scalar());
    // A whole number past long long's range (written out, or as 1e20): the
    // nearest end, for the caller's bounds to name ("must be <= ...").
    constexpr double kTop = 9223372036854775808.0;  // 2^63
    value = d >= kTop ? std::numeric_limits<long long>::max()
            : d <= -kTop ? std::numeric_limits<long long>::min()
                         : static_cast<long long>(d);
  }
  took("i:" + std::to_string(value));
  return value;
}

int Field::integer_at_least(long long lo, long long hi) const {
  const long long v = integer();
  if (v < lo) fail("must be >= " + std::to_string(lo) + ", got " + m_node.Scalar());
  if (v > hi) fail("must be <= " + std::to_string(hi) + ", got " + m_node.Scalar());
  return static_cast<int>(v);
}

std::uint64_t Field::seed() const {
  if (!is_scalar()) fail("expected an integer, got " + description());
  std::uint64_t value = 0;
  if (!parse_integer(m_node.Scalar(), value)) {
    const double d = finite_number();
    if (d != std::floor(d)) fail("expected an integer, got " + m_node.Scalar());
    if (d < 0) fail("must be >= 0, got " + m_node.Scalar());
    if (d >= 18446744073709551616.0) fail("must be <= 18446744073709551615, got " + m_node.Scalar());  // 2^64
    value = static_cast<std::uint64_t>(d);  // whole and below 2^64: exact
  }
  took("u:" + std::to_string(value));
  return value;
}

std::string Field::word() const {
  if (!is_scalar()) fail("expected a name, got " + description());
  took("");  // a name is its text
  return m_node.Scalar();
}

bool Field::boolean() const {
  if (is_scalar()) {
    std::string t;
    for (char c : m_node.Scalar()) t += lower(c);
    const bool yes = t == "true" || t == "yes" || t == "on";
    if (yes || t == "false" || t == "no" || t == "off") {
      took(yes ? "b:1" : "b:0");
      return yes;
    }
  }
  fail("expected true or false, got " + description());
}

Vec3 Field::vec3() const { return vec3_of(triple()); }

std::array<double, 3> Field::triple() const {
  if (!is_sequence()) fail("expected [x, y, z], got " + description());
  if (m_node.size() != 3)
    fail("expected [x, y, z], got a sequence of " + std::to_string(m_node.size()));
  const std::vector<Field> item = items();
  const std::array<double, 3> xyz{item[0].number(), item[1].number(), item[2].number()};
  const Vec3 v{real(xyz[0]), real(xyz[1]), real(xyz[2])};
  // The step squares vectors (speeds into energies, gaps into distances):
  // one whose square overflows the run's precision would turn into inf there.
  if (square_overflows(v))
    fail("too large for " + std::string(kRealName) + " precision: its squared length overflows (largest " +
         shortest(std::sqrt(std::numeric_limits<real>::max() / 3)) + " a component is safe)");
  return xyz;
}

void Field::expect_map() const {
  if (!is_map()) fail("expected a map, got " + description());
}

void Field::expect_sequence() const {
  if (!is_sequence()) fail("expected a sequence, got " + description());
}

std::vector<Field> Field::items() const {
  expect_sequence();
  std::vector<Field> out;
  out.reserve(m_node.size());
  for (std::size_t i = 0; i < m_node.size(); ++i)
    out.emplace_back(m_node[i], m_key + "[" + std::to_string(i) + "]", *this);
  return out;
}

// --- MapFields -------------------------------------------------------------

MapFields::MapFields(const Field& map, std::initializer_list<const char*> allowed) : m_self(map) {
  std::vector<std::string> names;
  for (const char* a : allowed) names.emplace_back(a);
  read(names);
}

MapFields::MapFields(const Field& map, const std::vector<std::string>& allowed) : m_self(map) {
  read(allowed);
}

void MapFields::read(const std::vector<std::string>& allowed) {
  m_self.expect_map();
  for (auto it = m_self.node().begin(); it != m_self.node().end(); ++it) {
    const YAML::Node key = it->first;
    if (!key.IsScalar())
      Field(key, m_self.key(), m_self).fail("expected a key name, got " + Field(key, "", "").description());
    const std::string name = key.Scalar();
    const Field value(it->second, join_key(m_self.key(), name), m_self, key.Mark());
    const SourceLocation key_where =
        value.from_override() ? value.where() : location_of(m_self.file(), key.Mark());
    // Where there is no line to point at (a scene from a dict), the key names itself.
    if (!allowed.empty() && std::find(allowed.begin(), allowed.end(), name) == allowed.end())
      throw InputError(key_where, key_where.line > 0 || value.from_override() ? m_self.key() : value.key(),
                       "unknown key '" + name + "'" + suggestion(name, allowed));
    if (const auto first = m_index.find(name); first != m_index.end()) {
      // A line to point at in a file; in an override's value or a dict, none.
      const int line = m_entries[first->second].name_where.line;
      throw InputError(key_where, m_self.key(),
                       "duplicate key '" + name + "'" +
                           (line > 0 ? " (first given at line " + std::to_string(line) + ")" : std::string()));
    }
    m_index.emplace(name, m_entries.size());
    m_entries.push_back({name, key_where, value});
  }
}

bool MapFields::has(const char* name) const {
  return std::any_of(m_entries.begin(), m_entries.end(), [&](const Entry& e) { return e.name == name; });
}

std::optional<Field> MapFields::optional(const char* name) const {
  for (const Entry& e : m_entries)
    if (e.name == name) return e.value;
  return std::nullopt;
}

Field MapFields::required(const char* name) const {
  if (auto f = optional(name)) return *f;
  m_self.fail(std::string("missing required key '") + name + "'");
}

}  // namespace marbles::scene::detail
