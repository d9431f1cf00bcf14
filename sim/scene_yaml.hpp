// sim/scene_yaml.hpp — reading validated values out of a yaml-cpp tree.
//
// Private to the scene loader (sim/scene.cpp; sim/study.cpp reads numbers
// with its parse_double): nothing outside sim/ includes yaml-cpp. A Field is a node plus the dotted key that leads to it
// ("materials.glass.restitution", "particles[2].random.count") and the file
// it came from, so that every check can throw an InputError that reads
// `file:line:column: key: message` with the node's own position.
// MapFields checks a map's keys against the allowed ones once (unknown keys
// with a suggestion, duplicates, non-scalar keys) and then hands out fields.
// Nodes put in by `--set` overrides (Origins) report the override instead of
// a file line.
#pragma once

#include <array>
#include <cmath>
#include <cstdint>
#include <initializer_list>
#include <optional>
#include <string>
#include <string_view>
#include <unordered_map>
#include <unordered_set>
#include <utility>
#include <vector>

#include <yaml-cpp/yaml.h>

#include "core/error.hpp"
#include "core/vec3.hpp"

namespace marbles::scene::detail {

// Position of a yaml-cpp mark as 1-based line and column (0 when unknown).
SourceLocation location_of(const std::string& file, const YAML::Mark& mark);

// A YAML text read event by event, for what yaml-cpp takes without a word
// but a scene must not hold: `problem` is the first, in the first document,
// of a tag (`!foo 2500`, `!!str 5`: the reader keeps the value and drops
// the tag's meaning) and a quoted value never closed (the reader takes
// `"abc` as a whole value where a line break ends the text). `documents`
// counts the documents, up to the limit asked (yaml-cpp 0.7 reads empty
// documents forever after a leading ','), and `second` is where the second
// begins. Quotes are looked for only in UTF-8 text (`utf8`), where a
// mark's position is a byte's (past a byte order mark).
struct YamlScan {
  struct Problem {
    YAML::Mark mark;
    std::string key;  // dotted, as a Field's
    std::string what;
  };
  std::size_t documents = 0;
  YAML::Mark second;
  std::optional<Problem> problem;
};
YamlScan scan_yaml(const std::string& text, std::size_t limit, bool utf8);

// The closest candidate by edit distance, or empty when none is close enough
// to be a likely typo.
std::string nearest_name(std::string_view word, const std::vector<std::string>& candidates);

// " (did you mean 'x'?)" when one candidate is close, else "; expected one of: a, b, c".
std::string suggestion(std::string_view word, const std::vector<std::string>& candidates);

// Parses the whole of `text` (blanks around it, a leading '+' allowed) as a
// double, as the scene's numbers are read: false on any leftover character.
bool parse_double(std::string_view text, double& value);

// What keeps a number read from input out of the run's precision ("" where
// it fits): not finite in `real`, or non-zero and below the smallest normal;
// with `bound`, the bound it passed. The scene's numbers (Field::number) and
// a CSV's rows share the rule.
std::string real_range_problem(double value, bool bound);

// [x, y, z] as written (Field::triple) in the run's precision: Field::vec3's value.
inline Vec3 vec3_of(const std::array<double, 3>& xyz) { return {real(xyz[0]), real(xyz[1]), real(xyz[2])}; }

// The nodes that `--set` overrides put into a tree, each with the text of its
// override ("--set time.dt=-1"); and, for the scene's fingerprint
// (Scene::fingerprint), how the reader took the tree's values.
class Origins {
 public:
  void add(const YAML::Node& node, const std::string& text);
  // The override that put `node` in (the latest when several did), or nullptr.
  const std::string* find(const YAML::Node& node) const;
  // The latest override whose path is `key` or lies below it
  // ("particles[0]": --set particles[0].list.radius=1e38), or nullptr: what
  // a check of the whole (a block's masses) names when a part was overridden.
  const std::string* find_under(const std::string& key) const;

  // The scalar `text` at `key` read as `value` (a typed read's one spelling:
  // "n:0.0005", "i:12", "b:1"), or, with `value` empty, as a name: a key
  // read as a name, or from two texts, keeps its text. Kept as hashes (a
  // scene of 10^6 inline numbers holds 10^6 of them).
  void took(const std::string& key, const std::string& text, const std::string& value) const;
  // The hash of what the scalar `text` at `key` was taken for, or 0 (its text stands).
  std::uint64_t taken(const std::string& key, const std::string& text) const;
  // `copy` stands where `original` stood (an override's path, copied so that
  // a node shared through an alias keeps its other places): it is placed
  // where the original was in the file.
  void copied(const YAML::Node& copy, const YAML::Node& original);
  // Where the file had the node `copied` stands for, or nullptr.
  const YAML::Mark* mark_of(const YAML::Node& node) const;

  // A map whose order the reader keeps (the materials': their numbering),
  // said by its reader.
  void ordered(const std::string& key) const { m_ordered.insert(key); }
  bool is_ordered(const std::string& key) const { return m_ordered.count(key) > 0; }

 private:
  std::vector<std::pair<YAML::Node, std::string>> m_nodes;
  std::vector<std::pair<YAML::Node, YAML::Mark>> m_marks;
  struct Taken {
    std::uint64_t text = 0, value = 0;  // value 0: the text stands
  };
  mutable std::unordered_map<std::uint64_t, Taken> m_taken;  // by the key's hash
  mutable std::unordered_set<std::string> m_ordered;
};

class Field {
 public:
  Field(YAML::Node node, std::string key, const std::string& file, const Origins* origins = nullptr);
  // A node inside `parent` (an item or a map value): the same file, unless an
  // override put the node (or one above it) in; then the override's text.
  Field(YAML::Node node, std::string key, const Field& parent);
  // `fallback` is where to point when the node is null: yaml-cpp marks an
  // empty value (`key:` and nothing) at the next token, often lines below.
  Field(YAML::Node node, std::string key, const Field& parent, const YAML::Mark& fallback);

  const YAML::Node& node() const { return m_node; }
  const std::string& key() const { return m_key; }
  const std::string& file() const { return m_file; }
  bool from_override() const { return m_from_override; }
  const Origins* origins() const { return m_origins; }
  // file:line:column, or the override's text without a line.
  SourceLocation where() const;

  [[noreturn]] void fail(const std::string& message) const;

  bool is_map() const { return m_node.IsMap(); }
  bool is_sequence() const { return m_node.IsSequence(); }
  bool is_scalar() const { return m_node.IsScalar(); }

  // What the node is, for "expected X, got <description>".
  std::string description() const;

  // Checked conversions; each throws at this node on failure.
  double number() const;                        // finite
  double positive() const;                      // > 0
  double non_negative() const;                  // >= 0
  double within(double lo, double hi) const;    // [lo, hi]
  long long integer() const;                    // exact integer (1e5 is accepted)
  int integer_at_least(long long lo, long long hi = 1'000'000'000) const;
  std::uint64_t seed() const;                   // integer >= 0
  std::string word() const;                     // a scalar (string)
  bool boolean() const;                         // true/false (also yes/no, on/off)
  Vec3 vec3() const;                            // [x, y, z], finite
  std::array<double, 3> triple() const;         // vec3() as written, in double
  void expect_map() const;
  void expect_sequence() const;

  // Elements of a sequence, keyed "key[i]".
  std::vector<Field> items() const;

 private:
  double finite_number() const;  // number() without the fingerprint's record
  double parsed_number() const;  // a finite double, the precision not asked
  double in_precision(double value) const;  // `value`, refused where the run's precision cannot hold it
  double taken(double value) const;         // in_precision, and the fingerprint's record
  void took(const std::string& value) const;  // Origins::took of this scalar

  YAML::Node m_node;
  std::string m_key;
  std::string m_file;
  YAML::Mark m_mark;
  const Origins* m_origins = nullptr;
  bool m_from_override = false;
};

class MapFields {
 public:
  // `allowed` empty: any key (a map of user names such as `materials`).
  MapFields(const Field& map, std::initializer_list<const char*> allowed);
  MapFields(const Field& map, const std::vector<std::string>& allowed);

  const Field& self() const { return m_self; }
  bool has(const char* name) const;
  std::optional<Field> optional(const char* name) const;
  Field required(const char* name) const;
  // The entries in file order: key text, key location and the value.
  struct Entry {
    std::string name;
    SourceLocation name_where;
    Field value;
  };
  const std::vector<Entry>& entries() const { return m_entries; }

 private:
  void read(const std::vector<std::string>& allowed);

  Field m_self;
  std::vector<Entry> m_entries;
  std::unordered_map<std::string, std::size_t> m_index;  // name -> entry: duplicates found in O(1)
};

}  // namespace marbles::scene::detail
