// render/atomic_file.cpp — see atomic_file.hpp.
#include "render/atomic_file.hpp"

#include <signal.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>

#include "core/error.hpp"

namespace marbles::render {

namespace fs = std::filesystem;

fs::path temp_path_beside(const fs::path& final_path) {
  static std::atomic<unsigned> counter{0};
  std::string name = ".";  // appended piece by piece (GCC 12 warns falsely on "." + std::string)
  name += final_path.filename().string();
  name += ".tmp-";
  name += std::to_string(::getpid());
  name += '-';
  name += std::to_string(counter++);
  return final_path.parent_path() / name;
}

void commit_file(const fs::path& tmp, const fs::path& final_path) {
  std::error_code ec;
  fs::rename(tmp, final_path, ec);
  if (ec) {
    fs::remove(tmp, ec);
    throw RuntimeFailure("cannot rename " + tmp.string() + " to " + final_path.string() + ": " + ec.message());
  }
}

std::size_t remove_stale_temporaries(const fs::path& dir) {
  std::size_t removed = 0;
  std::error_code ec;
  for (fs::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
    const std::string name = it->path().filename().string();
    const std::size_t tag = name.rfind(".tmp-");
    if (name.empty() || name[0] != '.' || tag == std::string::npos) continue;
    const long pid = std::strtol(name.c_str() + tag + 5, nullptr, 10);
    const bool writer_gone = pid > 0 && ::kill(static_cast<pid_t>(pid), 0) != 0 && errno == ESRCH;
    if (!writer_gone) continue;
    std::error_code remove_ec;
    if (fs::remove(it->path(), remove_ec)) ++removed;
  }
  return removed;
}

void write_file_atomic(const fs::path& path, std::string_view contents) {
  const fs::path tmp = temp_path_beside(path);
  std::FILE* f = std::fopen(tmp.c_str(), "wb");
  if (!f) throw RuntimeFailure("cannot create " + tmp.string() + ": " + std::strerror(errno));
  const bool written = std::fwrite(contents.data(), 1, contents.size(), f) == contents.size();
  const bool closed = std::fclose(f) == 0;
  if (!written || !closed) {
    std::error_code ec;
    fs::remove(tmp, ec);
    throw RuntimeFailure("cannot write " + tmp.string() + ": " + std::strerror(errno));
  }
  commit_file(tmp, path);
}

}  // namespace marbles::render
