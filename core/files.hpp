#pragma once
// not_a_plain_file(path): what a path names when it is not a plain file.
// folder_problem(path): why a command cannot write into that folder.
// whole_number(text), folders_of_ended_processes(dir, prefix): the
// PREFIX-PID folders (a study's staging, a run's earlier output set aside)
// whose process no longer runs. copy_plain_file(from, to, ec): a copy that says
// why it failed.
//
// The scene, its CSV blocks and checkpoints are each read more than once (the
// scene for its precision, its hash and its text), so a pipe would give its
// bytes to the first read only, and opening a pipe that has no writer waits
// for one. Such paths are refused up front, by what they are.

#include <fcntl.h>
#include <signal.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstdint>
#include <filesystem>
#include <limits>
#include <optional>
#include <string>
#include <string_view>
#include <system_error>
#include <vector>

#include "core/format.hpp"

namespace marbles {

// Why `path` cannot be an output folder (empty: it can): it must be one,
// or nothing yet (made then, with the folders above it that are not there:
// the nearest one there must be a folder). A link to nothing names nothing
// that could be made.
inline std::string folder_problem(const std::string& path) {
  std::error_code ec;
  const auto status = std::filesystem::status(path, ec);
  if (std::filesystem::exists(status) && !std::filesystem::is_directory(status))
    return "'" + printable_path(path) + "' exists and is not a folder";
  if (!std::filesystem::exists(status) && std::filesystem::is_symlink(std::filesystem::symlink_status(path, ec)))
    return "'" + printable_path(path) +
           "' is a link to nothing (a link whose target is gone): no folder can be made there";
  for (std::filesystem::path above = std::filesystem::path(path).parent_path(); !above.empty();
       above = above.parent_path()) {
    const auto there = std::filesystem::status(above, ec);
    if (std::filesystem::exists(there)) {
      if (!std::filesystem::is_directory(there))
        return "'" + printable_path(path) + "' cannot be made: '" + printable_path(above.string()) + "' is not a folder";
      break;
    }
    if (above == above.parent_path()) break;  // a root that cannot be read
  }
  return {};
}

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

// A file name's whole number: 1 to 18 digits, nothing else.
inline std::optional<std::uint64_t> whole_number(std::string_view text) {
  if (text.empty() || text.size() > 18 || text.find_first_not_of("0123456789") != std::string_view::npos)
    return std::nullopt;
  return std::stoull(std::string(text));
}

// The folders PREFIX-PID (or PREFIX-PID.N) in `dir` whose process has
// ended (this process's own and a running one's are not among them).
inline std::vector<std::filesystem::path> folders_of_ended_processes(const std::filesystem::path& dir,
                                                                     std::string_view prefix) {
  std::error_code ec;
  std::vector<std::filesystem::path> ended;
  for (std::filesystem::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
    const std::string name = it->path().filename().string();
    const std::string_view rest = name.starts_with(prefix) ? std::string_view(name).substr(prefix.size()) : "";
    const std::size_t dot = rest.find('.');  // PID.N: N whole too
    const auto pid = dot == std::string_view::npos || whole_number(rest.substr(dot + 1))
                         ? whole_number(rest.substr(0, dot))
                         : std::nullopt;
    if (pid && *pid != static_cast<std::uint64_t>(getpid()) && *pid <= std::numeric_limits<pid_t>::max() &&
        ::kill(static_cast<pid_t>(*pid), 0) != 0 && errno == ESRCH && it->is_directory(ec))
      ended.push_back(it->path());
  }
  return ended;
}

// Copies the plain file `from` to `to` (replaced where it is there; with
// from's permission bits; anything but a plain file `from` is refused,
// without waiting on a pipe), setting `ec` to the error that stopped it:
// std::filesystem::copy_file reports a full disk as "Input/output error"
// (libstdc++ takes a short copy for EIO; ENOSPC underneath). On failure
// what was made of `to` is removed (where it is a plain file).
inline void copy_plain_file(const std::filesystem::path& from, const std::filesystem::path& to, std::error_code& ec) {
  ec.clear();
  const int in = ::open(from.c_str(), O_RDONLY | O_CLOEXEC | O_NONBLOCK);  // a pipe put there does not wait
  if (in < 0) {
    ec.assign(errno, std::generic_category());
    return;
  }
  struct stat st {};
  int out = -1;
  if (::fstat(in, &st) != 0)
    ec.assign(errno, std::generic_category());
  else if (!S_ISREG(st.st_mode))
    ec = std::make_error_code(std::errc::invalid_argument);  // not a plain file
  else if ((out = ::open(to.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0600)) < 0 ||
           ::fchmod(out, st.st_mode & 07777) != 0)  // the source's bits, whatever the umask or an earlier file's
    ec.assign(errno, std::generic_category());
  char buffer[1 << 16];
  while (!ec) {
    const ssize_t got = ::read(in, buffer, sizeof buffer);
    if (got < 0 && errno == EINTR) continue;
    if (got < 0) ec.assign(errno, std::generic_category());
    if (got <= 0) break;
    for (ssize_t done = 0; done < got && !ec;) {
      const ssize_t put = ::write(out, buffer + done, static_cast<std::size_t>(got - done));
      if (put < 0 && errno != EINTR) ec.assign(errno, std::generic_category());
      if (put == 0) ec = std::make_error_code(std::errc::io_error);  // no progress: not a loop for ever
      if (put > 0) done += put;
    }
  }
  struct stat made {};
  const bool plain = out >= 0 && ::fstat(out, &made) == 0 && S_ISREG(made.st_mode);  // not a device's node
  if (out >= 0 && ::close(out) != 0 && !ec) ec.assign(errno, std::generic_category());  // a delayed write's error
  ::close(in);
  if (ec && plain) ::unlink(to.c_str());
}

}  // namespace marbles
