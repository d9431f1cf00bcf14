// sim/scene_overrides.hpp — `--set key.path=value` applied to a scene's YAML tree.
//
// Private to the scene loader (sim/scene.cpp). The key path names a place by
// map keys and sequence indices (`particles[0].random.count`); the value is
// YAML flow text (`500`, `[0, 0, -1]`, `{density: 7800}`). Missing map keys
// are created (a null value on the way becomes a map); an index past a
// sequence's end, or a step into a scalar, is an error. Every node an
// override puts in is recorded in Origins, so that validation names the
// override ("--set time.dt=-1: time.dt: must be > 0") instead of a file line.
#pragma once

#include <string>
#include <vector>

#include <yaml-cpp/yaml.h>

#include "sim/scene_yaml.hpp"

namespace marbles::scene::detail {

// Applies the overrides in order (a later one wins over an earlier one).
// Throws InputError at `--set TEXT` for a malformed override or a path that
// does not fit the tree.
void apply_overrides(YAML::Node root, const std::vector<std::string>& overrides, Origins& origins);

// Whether `value`, as the text after an override's `=`, is read as the
// plain string `value` itself (not null, a list, a map, a quoted or cut
// text): Python's set={"name": "run #2"} quotes only what is not.
bool reads_as_itself(const std::string& value);

}  // namespace marbles::scene::detail
