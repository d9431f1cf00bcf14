// render/atomic_file.cpp — see atomic_file.hpp.
#include "render/atomic_file.hpp"

#include <signal.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <string>

#include "core/error.hpp"
#include "core/files.hpp"

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

std::string cannot_create(const fs::path& tmp, int error) {
  std::string said = "cannot create " + tmp.string() + ": " + std::strerror(error);
  if (error != ENOENT) return said;
  // The outermost folder of the path that is not there (the nearest one
  // above it is).
  std::error_code ec;
  fs::path gone = fs::absolute(tmp, ec).parent_path();  // a run's folder is often relative ("out/demo")
  if (ec || fs::exists(gone, ec) || ec) return said;
  while (gone.has_relative_path() && gone.parent_path() != gone && !fs::exists(gone.parent_path(), ec) && !ec)
    gone = gone.parent_path();
  return said + " (the folder " + gone.string() + " is gone: moved or removed while this wrote into it)";
}

CompleteCheck has_size(std::uintmax_t bytes) {
  return [bytes](const fs::path& p) {
    std::error_code ec;
    return fs::file_size(p, ec) == bytes && !ec;
  };
}

CompleteCheck ends_with(std::string_view tail) {
  return [tail = std::string(tail)](const fs::path& p) {
    std::ifstream in(p, std::ios::binary);
    in.seekg(0, std::ios::end);
    const std::streamoff size = in.tellg();
    if (!in || size < 0) return false;  // unreadable: not a finished file
    const std::streamoff span = std::min<std::streamoff>(size, static_cast<std::streamoff>(tail.size()) + 16);
    std::string end(static_cast<std::size_t>(span), '\0');
    in.seekg(size - span);
    in.read(end.data(), span);
    while (!end.empty() && (end.back() == '\n' || end.back() == ' ' || end.back() == '\r')) end.pop_back();
    return in.good() && end.size() >= tail.size() && end.compare(end.size() - tail.size(), tail.size(), tail) == 0;
  };
}

CompleteCheck mp4_has_index() {
  return [](const fs::path& p) {
    std::ifstream in(p, std::ios::binary);
    std::error_code ec;
    const std::uintmax_t size = fs::file_size(p, ec);
    // Every top-level box whole, the last ending at the file's end: with
    // +faststart the index comes before the media data (mdat), so an index
    // that fits said nothing of a movie cut short after it.
    std::uintmax_t at = 0;
    bool index = false;
    unsigned char h[16];
    while (!ec && at + 8 <= size && in.seekg(static_cast<std::streamoff>(at)) && in.read(reinterpret_cast<char*>(h), 8)) {
      std::uintmax_t box = (std::uintmax_t(h[0]) << 24) | (h[1] << 16) | (h[2] << 8) | h[3];
      if (box == 1 && in.read(reinterpret_cast<char*>(h + 8), 8)) {  // 64-bit size
        box = 0;
        for (int k = 8; k < 16; ++k) box = (box << 8) | h[k];
      } else if (box == 0) {
        box = size - at;  // to the end of the file
      }
      if (box < 8 || box > size - at) return false;
      index = index || std::string(reinterpret_cast<char*>(h + 4), 4) == "moov";
      at += box;
    }
    return !ec && index && at == size;
  };
}

namespace {

// What commit_file checks before its rename (the fault hook, completeness,
// nothing but a plain file under the name); on failure removes `tmp` and
// throws.
void check_before_rename(const fs::path& tmp, const fs::path& final_path, const CompleteCheck& complete) {
  std::error_code ec;
  if (const char* fault = std::getenv("MARBLES_FAULT_TRUNCATE");
      fault != nullptr && *fault != '\0' && final_path.filename().string().find(fault) != std::string::npos)
    fs::resize_file(tmp, fs::file_size(tmp, ec) / 2, ec);
  if (complete && !complete(tmp)) {
    fs::remove(tmp, ec);
    throw RuntimeFailure("cannot write " + final_path.string() +
                         ": the file was left incomplete (disk full?); nothing was written under its name");
  }
  // A device, pipe, socket or folder under the name is not replaced (the
  // rename would put a file in place of /dev/full when run as root). A link
  // is replaced itself, its target left alone, as before.
  if (const char* what = not_a_plain_file(final_path.string(), /*follow_links=*/false)) {
    fs::remove(tmp, ec);
    throw RuntimeFailure("cannot write " + final_path.string() + ": it is " + what +
                         ", not a file; nothing was replaced");
  }
}

void rename_over(const fs::path& tmp, const fs::path& final_path) {
  std::error_code ec;
  fs::rename(tmp, final_path, ec);
  if (ec) {
    const std::string why = ec.message();  // before the clean-up reuses ec
    fs::remove(tmp, ec);
    throw RuntimeFailure("cannot rename " + tmp.string() + " to " + final_path.string() + ": " + why);
  }
}

}  // namespace

void commit_file(const fs::path& tmp, const fs::path& final_path, const CompleteCheck& complete) {
  check_before_rename(tmp, final_path, complete);
  rename_over(tmp, final_path);
}

namespace {

// The writer's process of a name temp_path_beside gives (`.NAME.tmp-PID-K`,
// or a movie's `.NAME.tmp-PID-K.log` beside it), else 0: any other file,
// a user's `.notes.tmp-1` among them, is none of ours.
long temporary_writer(const std::string& name) {
  const std::size_t tag = name.rfind(".tmp-");
  if (name.size() < 2 || name[0] != '.' || tag == std::string::npos || tag < 2) return 0;
  std::string_view rest = std::string_view(name).substr(tag + 5);
  if (rest.ends_with(".log")) rest.remove_suffix(4);
  const std::size_t dash = rest.find('-');
  if (dash == std::string_view::npos || !whole_number(rest.substr(dash + 1))) return 0;
  const auto pid = whole_number(rest.substr(0, dash));
  return pid ? static_cast<long>(*pid) : 0;
}

}  // namespace

std::size_t remove_stale_temporaries(const fs::path& dir) {
  std::size_t removed = 0;
  std::error_code ec;
  for (fs::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
    const long pid = temporary_writer(it->path().filename().string());
    const bool writer_gone = pid > 0 && ::kill(static_cast<pid_t>(pid), 0) != 0 && errno == ESRCH;
    if (!writer_gone) continue;
    std::error_code remove_ec;
    if (fs::remove(it->path(), remove_ec)) ++removed;
  }
  return removed;
}

namespace {

// `contents` under a fresh temporary name beside `path`; that name.
fs::path write_temporary(const fs::path& path, std::string_view contents) {
  const fs::path tmp = temp_path_beside(path);
  std::FILE* f = std::fopen(tmp.c_str(), "wb");
  if (!f) throw RuntimeFailure(cannot_create(tmp, errno));
  const bool written = std::fwrite(contents.data(), 1, contents.size(), f) == contents.size();
  const bool closed = std::fclose(f) == 0;
  if (!written || !closed) {
    const int error = errno;
    std::error_code ec;
    fs::remove(tmp, ec);
    throw RuntimeFailure("cannot write " + tmp.string() + ": " + std::strerror(error));
  }
  return tmp;
}

}  // namespace

void write_file_atomic(const fs::path& path, std::string_view contents) {
  commit_file(write_temporary(path, contents), path, has_size(contents.size()));
}

void write_files_atomic(const std::vector<std::pair<fs::path, std::string_view>>& files) {
  // Every file written and checked before the first rename; only a rename
  // itself failing (within one folder, after every check) can part them.
  std::vector<fs::path> temps;
  const auto drop = [&temps] {
    std::error_code ec;
    for (const fs::path& t : temps) fs::remove(t, ec);
  };
  try {
    for (const auto& [path, contents] : files) temps.push_back(write_temporary(path, contents));
    for (std::size_t k = 0; k < files.size(); ++k) check_before_rename(temps[k], files[k].first, has_size(files[k].second.size()));
  } catch (...) {
    drop();
    throw;
  }
  for (std::size_t k = 0; k < files.size(); ++k) {
    try {
      rename_over(temps[k], files[k].first);
    } catch (...) {
      std::error_code ec;
      for (std::size_t j = k + 1; j < temps.size(); ++j) fs::remove(temps[j], ec);
      throw;
    }
  }
}

}  // namespace marbles::render
