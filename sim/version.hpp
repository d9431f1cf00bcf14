// sim/version.hpp — the program's version and the commit it was built from
// (MARBLES_GIT_COMMIT, written at every build by scripts/commit.cmake;
// "unknown" outside a git checkout, "-dirty" with uncommitted changes).
#pragma once

#include "marbles_commit.h"

namespace marbles {

inline constexpr const char* kMarblesVersion = "0.1";
inline constexpr const char* kMarblesCommit = MARBLES_GIT_COMMIT;

}  // namespace marbles
