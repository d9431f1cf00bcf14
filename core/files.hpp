#pragma once
// not_a_plain_file(path): what a path names when it is not a plain file.
//
// The scene, its CSV blocks and checkpoints are each read more than once (the
// scene for its precision, its hash and its text), so a pipe would give its
// bytes to the first read only, and opening a pipe that has no writer waits
// for one. Such paths are refused up front, by what they are.

#include <filesystem>
#include <string>

namespace marbles {

// "a folder", "a pipe", "a socket" or "a device"; nullptr for a plain file
// or a path naming nothing (opening it then says why). A link is followed,
// or with `follow_links` false taken as itself (nullptr: a name a rename
// may replace, its target left alone).
inline const char* not_a_plain_file(const std::string& path, bool follow_links = true) {
  std::error_code ec;
  switch ((follow_links ? std::filesystem::status(path, ec) : std::filesystem::symlink_status(path, ec)).type()) {
    case std::filesystem::file_type::directory: return "a folder";
    case std::filesystem::file_type::fifo: return "a pipe";
    case std::filesystem::file_type::socket: return "a socket";
    case std::filesystem::file_type::block:
    case std::filesystem::file_type::character: return "a device";
    default: return nullptr;
  }
}

}  // namespace marbles
