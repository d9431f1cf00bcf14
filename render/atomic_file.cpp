// render/atomic_file.cpp — see atomic_file.hpp.
#include "render/atomic_file.hpp"

#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <string>

#include "core/error.hpp"

namespace marbles::render {

namespace fs = std::filesystem;

fs::path temp_path_beside(const fs::path& final_path) {
  static std::atomic<unsigned> counter{0};
  const std::string name = "." + final_path.filename().string() + ".tmp-" + std::to_string(::getpid()) + "-" +
                           std::to_string(counter++);
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
