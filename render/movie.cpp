// render/movie.cpp — see movie.hpp.
//
// Writing to a pipe whose reader has died raises SIGPIPE, which would kill the
// simulation; writes therefore run with SIGPIPE blocked in this thread and a
// pending one is consumed, so a dead ffmpeg becomes an error message instead.
#include "render/movie.hpp"

#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <fstream>
#include <sstream>
#include <string_view>

#include "core/error.hpp"
#include "render/atomic_file.hpp"

namespace marbles::render {

namespace fs = std::filesystem;

namespace {

std::string shell_quote(const std::string& s) {
  std::string out = "'";
  for (char c : s) {
    if (c == '\'') out += "'\\''";
    else out += c;
  }
  return out + "'";
}

// Runs fwrite with SIGPIPE blocked; returns whether everything was written.
bool write_all(std::FILE* pipe, const void* data, std::size_t size) {
  sigset_t block, old;
  sigemptyset(&block);
  sigaddset(&block, SIGPIPE);
  pthread_sigmask(SIG_BLOCK, &block, &old);
  const bool ok = std::fwrite(data, 1, size, pipe) == size && std::fflush(pipe) == 0;
  if (!ok) {
    const timespec zero{0, 0};
    while (sigtimedwait(&block, nullptr, &zero) > 0) {
    }
  }
  pthread_sigmask(SIG_SETMASK, &old, nullptr);
  return ok;
}

int close_pipe(std::FILE* pipe) {
  sigset_t block, old;
  sigemptyset(&block);
  sigaddset(&block, SIGPIPE);
  pthread_sigmask(SIG_BLOCK, &block, &old);
  const int status = pclose(pipe);
  const timespec zero{0, 0};
  while (sigtimedwait(&block, nullptr, &zero) > 0) {
  }
  pthread_sigmask(SIG_SETMASK, &old, nullptr);
  return status;
}

}  // namespace

bool ffmpeg_available() {
  const char* path = std::getenv("PATH");
  if (!path) return false;
  std::string_view rest(path);
  while (!rest.empty()) {
    const auto colon = rest.find(':');
    const std::string dir(rest.substr(0, colon));
    rest = colon == std::string_view::npos ? std::string_view() : rest.substr(colon + 1);
    const std::string candidate = (dir.empty() ? "." : dir) + "/ffmpeg";
    if (::access(candidate.c_str(), X_OK) == 0) return true;
  }
  return false;
}

MovieWriter::MovieWriter(fs::path path, int width, int height, double fps, int crf)
    : m_path(std::move(path)), m_width(width), m_height(height), m_fps(fps > 0 ? fps : 30), m_crf(crf) {
  if (!ffmpeg_available())
    throw RuntimeFailure("ffmpeg is not on PATH: no movie is made (install ffmpeg; the PNG frames are still written)");
  m_tmp = temp_path_beside(m_path);
  m_log = m_tmp;
  m_log += ".log";
}

MovieWriter::~MovieWriter() {
  if (m_pipe) close_pipe(m_pipe);
  if (!m_finished) {
    std::error_code ec;
    fs::remove(m_tmp, ec);
    fs::remove(m_log, ec);
  }
}

void MovieWriter::start() {
  char rate[32];
  std::snprintf(rate, sizeof rate, "%.6g", m_fps);
  const std::string command = "ffmpeg -hide_banner -loglevel error -nostdin -y -f rawvideo -pix_fmt rgb24 -s " +
                              std::to_string(m_width) + "x" + std::to_string(m_height) + " -framerate " + rate +
                              " -i - -vf " + shell_quote("pad=ceil(iw/2)*2:ceil(ih/2)*2") +
                              " -c:v libx264 -preset medium -crf " + std::to_string(m_crf) +
                              " -pix_fmt yuv420p -movflags +faststart -f mp4 " + shell_quote(m_tmp.string()) +
                              " 2> " + shell_quote(m_log.string());
  m_pipe = popen(command.c_str(), "w");
  if (!m_pipe) throw RuntimeFailure(std::string("cannot start ffmpeg: ") + std::strerror(errno));
}

std::string MovieWriter::ffmpeg_log_tail() const {
  std::ifstream in(m_log);
  std::stringstream text;
  text << in.rdbuf();
  std::string s = text.str();
  while (!s.empty() && (s.back() == '\n' || s.back() == '\r')) s.pop_back();
  if (s.size() > 600) s = "..." + s.substr(s.size() - 600);
  return s.empty() ? "(no message)" : s;
}

void MovieWriter::add(const Image& frame) {
  if (m_finished) throw RuntimeFailure("movie " + m_path.string() + ": frame added after finish()");
  if (frame.width != m_width || frame.height != m_height)
    throw RuntimeFailure("movie " + m_path.string() + ": frame is " + std::to_string(frame.width) + "x" +
                         std::to_string(frame.height) + ", the movie is " + std::to_string(m_width) + "x" +
                         std::to_string(m_height));
  if (!m_pipe) start();
  if (!write_all(m_pipe, frame.rgb.data(), frame.rgb.size())) {
    close_pipe(m_pipe);
    m_pipe = nullptr;
    throw RuntimeFailure("ffmpeg stopped while writing " + m_path.string() + ": " + ffmpeg_log_tail());
  }
  ++m_frames;
}

void MovieWriter::finish() {
  if (m_finished) return;
  m_finished = true;
  std::error_code ec;
  if (!m_pipe) {
    fs::remove(m_log, ec);
    return;  // no frames: no movie
  }
  const int status = close_pipe(m_pipe);
  m_pipe = nullptr;
  if (status == -1 || !WIFEXITED(status) || WEXITSTATUS(status) != 0) {
    const std::string tail = ffmpeg_log_tail();
    fs::remove(m_tmp, ec);
    fs::remove(m_log, ec);
    throw RuntimeFailure("ffmpeg failed to write " + m_path.string() + ": " + tail);
  }
  fs::remove(m_log, ec);
  commit_file(m_tmp, m_path, mp4_has_index());
}

}  // namespace marbles::render
