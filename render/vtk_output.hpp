// render/vtk_output.hpp — frames for ParaView: one .vtp per output time and a
// .pvd collection that lists them with their times.
//
//   DIR/frames/frame_000123.vtp  points = sphere centres, one vertex cell per
//                                sphere (so ParaView shows points; apply the
//                                "Point Gaussian" representation with
//                                radius as scale array for spheres), point
//                                arrays named after the fields; field data
//                                TimeValue (s) and step
//   DIR/series.pvd               <DataSet timestep="t" file="frames/frame_000123.vtp"/>
//
// Frames are written with vtkXMLPolyDataWriter in appended raw-binary mode,
// zlib-compressed. Every file goes to a temporary name in its folder and is
// renamed into place, and the .pvd is rewritten after each frame, so an
// interrupted run leaves a valid series of complete frames.
//
// VTK is optional: without it vtk_available() is false and the writer and
// read_vtp throw marbles::RuntimeFailure (read_pvd needs no VTK).
#pragma once

#include <filesystem>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "render/snapshot.hpp"

namespace marbles::render {

/// True when this build has VTK (can write and read .vtp).
bool vtk_available();

/// A per-sphere quantity written to the .vtp point data.
enum class PointField { radius, velocity, angular_velocity, id, material, speed };

/// "radius" | "velocity" | "angular_velocity" | "id" | "material" | "speed".
std::optional<PointField> parse_point_field(std::string_view name);
const char* point_field_name(PointField f);
/// Parses a list of names; throws marbles::InputError (key "output.fields")
/// naming an unknown entry and the accepted names. Duplicates are dropped.
std::vector<PointField> parse_point_fields(const std::vector<std::string>& names);

/// Writes DIR/frames/frame_NNNNNN.vtp and keeps DIR/series.pvd up to date.
class VtkSeriesWriter {
 public:
  /// Creates DIR/frames. Throws marbles::RuntimeFailure when built without VTK
  /// or when the folder cannot be created.
  VtkSeriesWriter(std::filesystem::path dir, std::vector<PointField> fields);

  /// Writes the next frame (numbered 0, 1, 2, ... in call order) and rewrites
  /// the .pvd; returns the frame's path. Throws marbles::RuntimeFailure when a
  /// requested field has the wrong length or on I/O errors.
  std::filesystem::path write(const Snapshot& snapshot);

  std::size_t frames() const { return m_entries.size(); }
  std::filesystem::path pvd_path() const { return m_dir / "series.pvd"; }
  /// A resumed run: counts the next frame (as write() would name it) as
  /// already written at `time`, without writing it.
  void adopt(double time);

 private:
  std::filesystem::path m_dir;
  std::vector<PointField> m_fields;
  std::vector<std::pair<double, std::string>> m_entries;  // time, file relative to m_dir
};

/// One entry of a .pvd collection.
struct SeriesEntry {
  double time = 0;
  std::filesystem::path path;  ///< the frame file, resolved against the .pvd's folder
};

/// The <DataSet> entries of a .pvd file, in file order. Throws
/// marbles::RuntimeFailure when the file cannot be read or lists no valid entry.
std::vector<SeriesEntry> read_pvd(const std::filesystem::path& pvd_path);

/// Reads a .vtp written by VtkSeriesWriter (or any poly data with points and
/// some of the arrays radius, velocity, angular_velocity, id, material) into a
/// snapshot; missing arrays stay empty; time and step come from the field data
/// TimeValue and step when present. Throws marbles::RuntimeFailure.
Snapshot read_vtp(const std::filesystem::path& vtp_path);

}  // namespace marbles::render
