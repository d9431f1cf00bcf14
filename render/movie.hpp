// render/movie.hpp — an H.264 movie made by piping raw frames into ffmpeg.
//
// ffmpeg runs as a child process (popen) reading raw RGB24 frames on its
// standard input and encoding with libx264 to yuv420p (the pixel format every
// player accepts; it needs even dimensions, so an odd width or height is
// padded by one pixel). The movie is written under a temporary name and
// renamed when finish() succeeds, so DIR/movie.mp4 is always complete.
#pragma once

#include <cstdio>
#include <filesystem>
#include <string>

#include "render/image.hpp"

namespace marbles::render {

/// Settings of the movie written beside the frames.
struct MovieOptions {
  bool enabled = true;  ///< false: PNG frames only
  double fps = 30;      ///< frames per second of the movie; <= 0: derive from the frame times (render_output_dir) or 30
  int crf = 20;         ///< x264 constant rate factor: 0 lossless .. 51 worst; 18-23 look good
};

/// True when an executable `ffmpeg` is on PATH.
bool ffmpeg_available();

class MovieWriter {
 public:
  /// Prepares `path` (e.g. DIR/movie.mp4); ffmpeg starts with the first frame.
  /// Throws marbles::RuntimeFailure when ffmpeg is not on PATH.
  MovieWriter(std::filesystem::path path, int width, int height, double fps, int crf = 20);
  /// Abandons an unfinished movie: stops ffmpeg, removes the temporary file.
  ~MovieWriter();
  MovieWriter(const MovieWriter&) = delete;
  MovieWriter& operator=(const MovieWriter&) = delete;

  /// Appends one frame (its size must be the movie's). Throws
  /// marbles::RuntimeFailure when ffmpeg has failed, with its last messages.
  void add(const Image& frame);
  /// Closes the stream, waits for ffmpeg, renames the file into place. Throws
  /// marbles::RuntimeFailure when ffmpeg failed. A movie without frames is
  /// not written.
  void finish();

  int frames() const { return m_frames; }
  const std::filesystem::path& path() const { return m_path; }

 private:
  void start();
  std::string ffmpeg_log_tail() const;

  std::filesystem::path m_path, m_tmp, m_log;
  int m_width, m_height;
  double m_fps;
  int m_crf;
  std::FILE* m_pipe = nullptr;
  int m_frames = 0;
  bool m_finished = false;
};

}  // namespace marbles::render
