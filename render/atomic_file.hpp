// render/atomic_file.hpp — write-then-rename, so that a reader (ParaView, a
// movie player, a later `marbles render`) never sees half a file.
//
// Every output file of render/ is first written under a hidden temporary name
// in the same folder (`.NAME.tmp-PID-K`) and then renamed over the final name;
// rename() within one folder is atomic on POSIX file systems.
#pragma once

#include <chrono>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace marbles::render {

/// A fresh temporary name beside `final_path` (same folder, hidden, unique per
/// process and call).
std::filesystem::path temp_path_beside(const std::filesystem::path& final_path);

/// Why the temporary `tmp` could not be made (`error`, an errno): "cannot
/// create TMP: REASON", and where a folder on its way is gone, which one (a
/// series folder moved or removed while a run writes into it).
std::string cannot_create(const std::filesystem::path& tmp, int error);

/// What a finished file of a kind looks like; a writer that reported success
/// on a full disk leaves a file that is not.
using CompleteCheck = std::function<bool(const std::filesystem::path&)>;
CompleteCheck has_size(std::uintmax_t bytes);
CompleteCheck ends_with(std::string_view tail);   // e.g. "</VTKFile>" (trailing whitespace allowed)
CompleteCheck mp4_has_index();                    // a top-level `moov` box

/// Renames `tmp` over `final_path` once `complete` (when given) accepts it.
/// On failure removes `tmp` and throws marbles::RuntimeFailure naming the
/// final path. Test hook: MARBLES_FAULT_TRUNCATE=TEXT truncates every file
/// whose final name holds TEXT to half its size first (what a full disk leaves).
void commit_file(const std::filesystem::path& tmp, const std::filesystem::path& final_path,
                 const CompleteCheck& complete = nullptr);

/// Removes the temporary files in `dir` (not below) left by processes that
/// no longer run (a `kill -9` mid-write); returns how many it removed. Only
/// names temp_path_beside gives (`.NAME.tmp-PID-K`, and a movie's log
/// `.NAME.tmp-PID-K.log`) are temporaries: any other file stays.
std::size_t remove_stale_temporaries(const std::filesystem::path& dir);

/// Writes `contents` to `path` atomically (temporary file + rename).
/// Throws marbles::RuntimeFailure on any I/O error.
void write_file_atomic(const std::filesystem::path& path, std::string_view contents);

/// Files that belong together (a frame and the series that lists it, a
/// checkpoint and its record): every one is written to its temporary first,
/// and only then are they renamed, in the order given. A failure while
/// writing (a name too long, a folder in the way, a full disk) leaves none
/// of them written and every earlier file as it was.
void write_files_atomic(const std::vector<std::pair<std::filesystem::path, std::string_view>>& files);

/// When a listing that only grows (a .pvd, thermo.csv), rewritten whole and
/// atomically, is written again. Written at every addition it costs the
/// square of its length (16 000 one-sphere frames: 56 s, most of it
/// writing three listings of a megabyte each at every frame); written once
/// its unwritten part is a sixteenth of it, or a second after its last
/// write, whichever comes first, its rewrites by the first rule cost at
/// most 17 times its length in all, and the second adds at most one rewrite
/// a second (so a listing of L bytes costs at most L bytes a second beyond
/// that); it lags by at most a sixteenth of it, and a second, behind its
/// files. Its first additions are written at once, each (a .pvd's first
/// 16, whose size is its lines'). The owner writes it whole at the end, at
/// a checkpoint and where the run stops.
class Relisting {
 public:
  using Clock = std::chrono::steady_clock;
  /// True where the listing, now `size` bytes, is to be written now.
  bool due(std::size_t size) const {
    return 16 * (size - m_written) >= size || Clock::now() - m_at >= std::chrono::seconds(1);
  }
  /// True where what it lists has grown since its last write.
  bool stale(std::size_t size) const { return size != m_written; }
  /// The listing was written at `size` bytes.
  void written(std::size_t size) {
    m_written = size;
    m_at = Clock::now();
  }

 private:
  std::size_t m_written = 0;
  Clock::time_point m_at = Clock::now();
};

}  // namespace marbles::render
