// render/walls_json.hpp — the walls of a run, saved beside its frames so that
// `marbles render OUTDIR` can draw the container afterwards.
//
// Format (DIR/walls.json), all lengths in scene units (m):
//
//   {
//     "format": "marbles-walls", "version": 1,
//     "planes":    [ {"point": [x,y,z], "normal": [x,y,z], "velocity": [x,y,z], "material": 0} ],
//     "boxes":     [ {"lo": [x,y,z], "hi": [x,y,z], "velocity": [x,y,z], "material": 0} ],
//     "cylinders": [ {"base": [x,y,z], "axis": [x,y,z], "radius": r, "length": l,
//                     "inside": true, "angular_velocity": w, "material": 0} ],
//     "spheres":   [ {"centre": [x,y,z], "radius": r, "velocity": [x,y,z], "material": 0} ]
//   }
//
// The fields mirror core/walls.hpp (length 0 = infinite cylinder). velocity,
// length, inside, angular_velocity and material may be left out (0, 0, true,
// 0, 0).
// Numbers are written with 17 significant digits (exact round trip of
// doubles). Either list may be missing or empty; unknown keys are ignored.
#pragma once

#include <filesystem>
#include <string>

#include "core/walls.hpp"

namespace marbles::render {

/// The JSON text of `walls` in the format above.
std::string walls_to_json(const Walls& walls);

/// Parses walls from JSON text; `source` names it in errors. Throws
/// marbles::InputError (with the key, e.g. "boxes[0].lo") on malformed input.
Walls walls_from_json(const std::string& text, const std::string& source = "");

/// Writes DIR/walls.json atomically (creates DIR if needed). Throws
/// marbles::RuntimeFailure on I/O errors.
void write_walls_json(const std::filesystem::path& dir, const Walls& walls);

/// Reads DIR/walls.json; returns no walls when the file does not exist.
/// Throws marbles::InputError when it exists but is malformed.
Walls read_walls_json(const std::filesystem::path& dir);

}  // namespace marbles::render
