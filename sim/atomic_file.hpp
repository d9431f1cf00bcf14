// sim/atomic_file.hpp — write a whole file under a temporary name in the same
// folder, then rename it into place, so readers never see half a file.
#pragma once

#include <string>

namespace marbles {

// Throws RuntimeFailure naming the path on any I/O error.
void write_file_atomically(const std::string& path, const std::string& contents);

}  // namespace marbles
