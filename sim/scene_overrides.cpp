// sim/scene_overrides.cpp — `--set` overrides on a YAML tree (see scene_overrides.hpp).
//
// yaml-cpp nodes are handles with value semantics on assignment: `a = b`
// replaces the node `a` refers to inside its tree, while `a.reset(b)` only
// makes the handle refer elsewhere. Walking down therefore uses reset().
#include "sim/scene_overrides.hpp"

#include <algorithm>
#include <charconv>

#include <yaml-cpp/depthguard.h>

#include "core/format.hpp"

namespace marbles::scene::detail {

namespace {

// One step of a key path: a map key, or (name empty) a sequence index.
struct Step {
  std::string name;
  std::size_t index = 0;
};

[[noreturn]] void fail(const std::string& label, const std::string& key, const std::string& message) {
  throw InputError(SourceLocation{label, 0, 0}, key, message);
}

// "a.b[2].c" → a, b, [2], c.
std::vector<Step> parse_path(const std::string& path, const std::string& label) {
  constexpr auto npos = std::string::npos;
  std::vector<Step> steps;
  for (std::size_t at = 0;;) {
    const std::size_t end = std::min(path.find_first_of(".[]", at), path.size());
    if (end == at) fail(label, "", "expected a key name at character " + std::to_string(at + 1) + " of '" + path + "'");
    steps.push_back({path.substr(at, end - at)});
    at = end;
    while (at < path.size() && path[at] == '[') {
      const std::size_t close = path.find(']', at);
      std::size_t index = 0;
      const char* first = path.data() + at + 1;
      const char* last = path.data() + (close == npos ? path.size() : close);
      const auto [ptr, ec] = std::from_chars(first, last, index);
      if (close == npos || first == last || ec != std::errc() || ptr != last)
        fail(label, "", "expected an index such as [0] after '" + path.substr(0, at) + "'");
      steps.push_back({"", index});
      at = close + 1;
    }
    if (at == path.size()) return steps;
    if (path[at] != '.')
      fail(label, "", "unexpected '" + path.substr(at, 1) + "' at character " + std::to_string(at + 1) + " of '" +
                          path + "'");
    ++at;
  }
}

std::string description(const YAML::Node& node) { return Field(node, "", "").description(); }

std::string item_text(std::size_t index) { return std::string(1, '[').append(std::to_string(index)).append("]"); }

// The child of `node` at `step`, created as a map when it is a missing key
// and not the last step (`last`: the caller assigns it).
YAML::Node child(YAML::Node node, const Step& step, bool last, std::string& key, const std::string& label,
                 Origins& origins) {
  if (step.name.empty()) {
    if (!node.IsSequence())
      fail(label, key, "cannot take item " + item_text(step.index) + ": expected a sequence, got " + description(node));
    if (step.index >= node.size())
      fail(label, key, "has " + std::to_string(node.size()) + " item(s); " + item_text(step.index) + " is past the end");
    key += item_text(step.index);
    return node[step.index];
  }
  if (node.IsNull()) {
    node = YAML::Node(YAML::NodeType::Map);
    origins.add(node, label);
  }
  if (!node.IsMap()) fail(label, key, "cannot hold key '" + step.name + "': expected a map, got " + description(node));
  key += (key.empty() ? "" : ".") + step.name;
  YAML::Node next = node[step.name];
  if (!next.IsDefined() && !last) {
    next = YAML::Node(YAML::NodeType::Map);
    origins.add(next, label);
  }
  return next;
}

void add_subtree(const YAML::Node& node, const std::string& label, Origins& origins) {
  origins.add(node, label);
  if (node.IsSequence())
    for (const YAML::Node& item : node) add_subtree(item, label, origins);
  if (node.IsMap())
    for (const auto& entry : node) {
      origins.add(entry.first, label);
      add_subtree(entry.second, label, origins);
    }
}

void apply_override(YAML::Node root, const std::string& text, Origins& origins) {
  // The override as its errors name it: printable (its bytes past ASCII kept
  // where it is UTF-8), and cut after 200 bytes, before a character's
  // continuation bytes (a value nested 600 deep was echoed whole).
  const std::size_t not_utf8 = first_non_utf8(text);
  std::size_t cut = std::min<std::size_t>(text.size(), 200);
  while (cut < text.size() && cut > 0 && (static_cast<unsigned char>(text[cut]) & 0xc0) == 0x80) --cut;
  const std::string label =
      "--set " + printable(cut < text.size() ? text.substr(0, cut) + "..." : text, not_utf8 != std::string::npos);
  const std::size_t equals = text.find('=');
  if (equals == std::string::npos || equals == 0) fail(label, "", "expected key.path=value, e.g. time.dt=5e-4");
  const std::vector<Step> steps = parse_path(text.substr(0, equals), label);
  if (not_utf8 != std::string::npos)
    fail(label, "", not_utf8_text(text, not_utf8) + " at byte " + std::to_string(not_utf8 + 1));
  YAML::Node value;
  try {
    value = YAML::Load(text.substr(equals + 1));
  } catch (const YAML::DeepRecursion& e) {  // yaml-cpp's own message for it is "bad file", as for a scene file
    fail(label, "", "the value is nested deeper than the YAML reader follows (" + std::to_string(e.depth()) +
                        " levels)");
  } catch (const YAML::Exception& e) {  // its message quotes the offending byte, which may be any
    fail(label, "", "the value is not valid YAML: " + printable(e.msg));
  }
  YAML::Node node = root;
  std::string key;
  std::vector<YAML::Node> parents;  // the node before each step
  for (std::size_t k = 0; k < steps.size(); ++k) {
    parents.push_back(node);
    YAML::Node next = child(node, steps[k], k + 1 == steps.size(), key, label, origins);
    node.reset(next);
  }
  node = value;
  origins.add(value, label);
  // A merge key in the value moves the nodes under it into the map that
  // holds it (read_scene resolves them after the overrides): each names the
  // override, not the place in the override's text as if in the file.
  if (text.find("<<") != std::string::npos) add_subtree(value, label, origins);
  // An item of a vector (gravity[2], positions[0][1]) changes the vector,
  // which is read and checked whole: a problem with it names the override.
  // Only sequences of scalars: a list of maps (particles, walls) keeps its
  // other items' places in the file.
  for (std::size_t k = steps.size(); k-- > 0 && steps[k].name.empty();) {
    const YAML::Node& vector = parents[k];
    const bool scalars =
        std::all_of(vector.begin(), vector.end(), [](const YAML::Node& item) { return item.IsScalar(); });
    if (scalars) origins.add(vector, label);
  }
}

}  // namespace

bool reads_as_itself(const std::string& value) {
  try {
    const YAML::Node node = YAML::Load(value);
    return node.IsScalar() && node.Tag() == "?" && node.Scalar() == value;
  } catch (const YAML::Exception&) {
    return false;
  }
}

void apply_overrides(YAML::Node root, const std::vector<std::string>& overrides, Origins& origins) {
  for (const std::string& text : overrides) apply_override(root, text, origins);
}

}  // namespace marbles::scene::detail
