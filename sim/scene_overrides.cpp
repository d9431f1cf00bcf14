// sim/scene_overrides.cpp — `--set` overrides on a YAML tree (see scene_overrides.hpp).
//
// yaml-cpp nodes are handles with value semantics on assignment: `a = b`
// replaces the node `a` refers to inside its tree (and so every place an
// alias shares it), while `a.reset(b)` only makes the handle refer
// elsewhere. An override therefore writes into no node of the tree: it makes
// its path again as new nodes, and only the root takes the new tree.
#include "sim/scene_overrides.hpp"

#include <algorithm>
#include <charconv>
#include <unordered_set>

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

// A sequence's item at `step` (an index).
YAML::Node item(const YAML::Node& node, const Step& step, std::string& key, const std::string& label) {
  if (!node.IsDefined() || node.IsNull())  // a key the scene lacks, or gives nothing
    fail(label, key, "cannot take item " + item_text(step.index) + ": the scene has no list there");
  if (!node.IsSequence())
    fail(label, key, "cannot take item " + item_text(step.index) + ": expected a sequence, got " + description(node));
  if (step.index >= node.size())
    fail(label, key, "has " + std::to_string(node.size()) + " item(s); " + item_text(step.index) + " is past the end");
  key += item_text(step.index);
  return node[step.index];
}

// The child of `node` at `step`, created as a map when it is a missing key
// and not the last step (`last`: the caller assigns it). For a tree whose
// nodes are each in one place only (shares_nodes).
YAML::Node child_in_place(YAML::Node node, const Step& step, bool last, bool index_next, std::string& key,
                          const std::string& label, Origins& origins) {
  if (step.name.empty()) return item(node, step, key, label);
  if (node.IsNull()) {
    node = YAML::Node(YAML::NodeType::Map);
    origins.add(node, label);
  }
  if (!node.IsMap()) fail(label, key, "cannot hold key '" + step.name + "': expected a map, got " + description(node));
  key += (key.empty() ? "" : ".") + step.name;
  YAML::Node next = node[step.name];
  if (!next.IsDefined() && !last && !index_next) {  // an item of a missing list is refused by item()
    next = YAML::Node(YAML::NodeType::Map);
    origins.add(next, label);
  }
  return next;
}

// Whether a node of the tree stands in more than one place: an alias (`b:
// *a`, `friction: *d`) or a merge key's values. A file's nodes are told
// apart by where they start in its text (a key starts where its map does:
// keys are left out); nodes from an override's text may share a place with
// the file's, which only makes the answer yes where it could be no. Stops at
// the first node seen twice (an alias bomb is not expanded).
bool shares_nodes(const YAML::Node& root) {
  std::unordered_set<int> seen;
  std::vector<YAML::Node> todo{root};
  while (!todo.empty()) {
    const YAML::Node node = todo.back();
    todo.pop_back();
    if (const int at = node.Mark().pos; at >= 0 && !seen.insert(at).second) return true;
    if (node.IsSequence())
      for (const YAML::Node& item : node) todo.push_back(item);
    else if (node.IsMap())
      for (const auto& entry : node) todo.push_back(entry.second);
  }
  return false;
}

// The child of `node` at `step` as the tree has it: an undefined node for a
// missing key (or a key below a missing or null one), whose map the
// override makes.
YAML::Node child_as_is(const YAML::Node& node, const Step& step, std::string& key, const std::string& label) {
  if (step.name.empty()) return item(node, step, key, label);
  const bool absent = !node.IsDefined() || node.IsNull();
  if (!absent && !node.IsMap())
    fail(label, key, "cannot hold key '" + step.name + "': expected a map, got " + description(node));
  key += (key.empty() ? "" : ".") + step.name;
  if (absent) return YAML::Node(YAML::NodeType::Undefined);
  const YAML::Node next = node[step.name];  // a missing key's is an invalid node, whose questions throw
  return next.IsDefined() ? next : YAML::Node(YAML::NodeType::Undefined);
}

// `node` with its child at `step` replaced by `value`, as a new node: the
// tree's own node may be shared through an alias (`b: *a`, a merge key's
// values, `friction: *d`), and an override of one place must leave the
// others as the file has them. Its other children are the tree's own.
YAML::Node with_child(const YAML::Node& node, const Step& step, const YAML::Node& value, const std::string& label,
                      Origins& origins) {
  YAML::Node copy(step.name.empty() ? YAML::NodeType::Sequence : YAML::NodeType::Map);
  if (step.name.empty()) {
    for (std::size_t i = 0; i < node.size(); ++i) copy.push_back(i == step.index ? value : node[i]);
  } else {
    bool placed = false;
    if (node.IsDefined() && node.IsMap())
      for (const auto& entry : node) {
        const bool here = entry.first.IsScalar() && entry.first.Scalar() == step.name;
        copy.force_insert(entry.first, here ? value : entry.second);
        placed = placed || here;
      }
    if (!placed) copy.force_insert(step.name, value);
  }
  if (const std::string* from = node.IsDefined() ? origins.find(node) : nullptr)
    origins.add(copy, *from);  // an earlier override's node: its errors name that override
  else if (node.IsDefined() && !node.IsNull())
    origins.copied(copy, node);
  else
    origins.add(copy, label);  // a map the override made: its errors name the override
  return copy;
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

void apply_override(YAML::Node root, const std::string& text, Origins& origins, bool shared) {
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
  if (const YamlScan scan = scan_yaml(text.substr(equals + 1), 1, true); scan.problem)
    fail(label, "", scan.problem->what);
  std::vector<YAML::Node> parents(steps.size());  // the node before each step, as the override leaves it
  std::string key;
  if (!shared) {  // the value put in where the path ends
    YAML::Node node = root;
    for (std::size_t k = 0; k < steps.size(); ++k) {
      parents[k].reset(node);
      const bool last = k + 1 == steps.size();
      YAML::Node next = child_in_place(node, steps[k], last, !last && steps[k + 1].name.empty(), key, label, origins);
      node.reset(next);
    }
    node = value;
    origins.add(value, label);
  } else {
    // The nodes on the path as the tree has them (the root first), then the
    // path made again from the value up, each a new node: nothing is
    // written into a node another place shares. (Linking new nodes into
    // the tree merges yaml-cpp's node sets, a few seconds for a scene of
    // 10^6 nodes: so only where the tree shares nodes.)
    std::vector<YAML::Node> path{root};
    for (std::size_t k = 0; k + 1 < steps.size(); ++k) path.push_back(child_as_is(path.back(), steps[k], key, label));
    child_as_is(path.back(), steps.back(), key, label);  // checked: a sequence's item, or a map's key
    origins.add(value, label);
    YAML::Node made = value;
    for (std::size_t k = steps.size(); k-- > 0;) {
      made.reset(with_child(path[k], steps[k], made, label, origins));
      parents[k].reset(made);
    }
    root = made;  // the root is no other node's: its handle takes the new tree
  }
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
  if (overrides.empty()) return;
  bool shared = shares_nodes(root);
  for (const std::string& text : overrides) {
    apply_override(root, text, origins, shared);
    shared = shared || text.find('*') != std::string::npos;  // an alias in the value (or a text that may hold one)
  }
}

}  // namespace marbles::scene::detail
