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
// Frames are VTK XML poly data written here (no VTK library: see
// docs/vtk-output.md), arrays in appended raw-binary mode, zlib-compressed
// in 32 KiB blocks with UInt64 headers (as vtkXMLPolyDataWriter writes them;
// uncompressed in a build without zlib). Field data: TimeValue, step, the
// material names, the units and the producer (marbles version and commit).
// Every file goes to a temporary name in its folder and is renamed into
// place, and the .pvd is rewritten after each frame, so an interrupted run
// leaves a valid series of complete frames. read_vtp reads these files (and
// vtkXMLPolyDataWriter's appended ones) back.
#pragma once

#include <array>
#include <filesystem>
#include <map>
#include <optional>
#include <string>
#include <string_view>
#include <cstdint>
#include <vector>

#include "core/walls.hpp"
#include "render/atomic_file.hpp"
#include "render/snapshot.hpp"

namespace marbles::render {

/// True when frames are zlib-compressed (the build has zlib).
bool vtk_compressed();

/// A series' file name: PREFIX_NNNNNN.vtp (frame_000012.vtp), numbered in write order.
std::string numbered_vtp(const char* prefix, std::size_t index);

/// What every frame's field data carries besides its time and step.
struct FrameMetadata {
  std::vector<std::string> material_names;  ///< by material id
  std::string producer;                     ///< e.g. "marbles 0.1 (commit 1a2b3c)"
};

/// A per-sphere quantity written to the .vtp point data.
enum class PointField { radius, velocity, angular_velocity, id, material, speed, contacts };

/// "radius" | "velocity" | "angular_velocity" | "id" | "material" | "speed" |
/// "contacts" (the coordination number: contacts that press, walls included).
std::optional<PointField> parse_point_field(std::string_view name);
const char* point_field_name(PointField f);
/// Parses a list of names; throws marbles::InputError (key "output.fields")
/// naming an unknown entry and the accepted names. Duplicates are dropped.
std::vector<PointField> parse_point_fields(const std::vector<std::string>& names);

/// Numbered files DIR/FOLDER/PREFIX_NNNNNN.vtp listed with their times in
/// DIR/PVD, rewritten (atomically) after each file.
class Series {
 public:
  Series(std::filesystem::path dir, std::string folder, std::string prefix, std::string pvd)
      : m_dir(std::move(dir)), m_folder(std::move(folder)), m_prefix(std::move(prefix)), m_pvd(std::move(pvd)) {}
  Series(const Series&) = delete;
  Series& operator=(const Series&) = delete;
  /// Writes the .pvd where it lags behind its files (best effort).
  ~Series();
  /// Writes the next file and the .pvd; returns the file's path. With
  /// list_in_steps() the .pvd only where it is due (Relisting: at once for
  /// the first 16, then once a sixteenth of the files, or a second, is
  /// unlisted): a run, whose end, checkpoints and stops flush() it. Without
  /// (a Python simulation's frames, written as its caller goes), at every file.
  std::filesystem::path add(double time, const std::string& file_text);
  void list_in_steps() { m_in_steps = true; }
  /// Counts the next file as written at `time` (a resumed run). Where it is
  /// not in DIR but in `from` (the folder of the run that wrote it), it is
  /// copied first; where it is in neither, it keeps its number but the .pvd
  /// leaves it out, so that the .pvd names only files DIR holds.
  void adopt(double time, const std::filesystem::path& from = {});
  /// Writes the .pvd of the files listed so far (a resumed run that adds
  /// none, the end of a run, a checkpoint).
  void write_pvd();
  /// Writes the .pvd where it lags behind its files.
  void flush() {
    if (m_relisting.stale(m_lines.size())) write_pvd();
  }
  std::filesystem::path next_path() const;
  std::filesystem::path pvd_path() const { return m_dir / m_pvd; }
  std::size_t size() const { return m_listed; }

 private:
  std::filesystem::path m_dir;
  std::string m_folder, m_prefix, m_pvd;
  std::string m_lines;       // the .pvd's line of each file listed (time, file relative to m_dir)
  std::size_t m_listed = 0;  // files listed
  std::size_t m_count = 0;                                 // files numbered, listed or not
  bool m_folder_made = false;
  Relisting m_relisting;     // when the .pvd is written (m_lines' size at its last write)
  bool m_in_steps = false;   // list_in_steps(): the .pvd written where m_relisting finds it due
};

/// Writes DIR/frames/frame_NNNNNN.vtp and keeps DIR/series.pvd up to date.
class VtkSeriesWriter {
 public:
  /// Creates DIR/frames. Throws marbles::RuntimeFailure when the folder
  /// cannot be created.
  VtkSeriesWriter(std::filesystem::path dir, std::vector<PointField> fields, FrameMetadata metadata = {});

  /// Writes the next frame (numbered 0, 1, 2, ... in call order) and rewrites
  /// the .pvd; returns the frame's path. Throws marbles::RuntimeFailure when a
  /// requested field has the wrong length or on I/O errors.
  std::filesystem::path write(const Snapshot& snapshot);

  std::size_t frames() const { return m_series.size(); }
  std::filesystem::path pvd_path() const { return m_series.pvd_path(); }
  /// A resumed run: counts the next frame (as write() would name it) as
  /// already written at `time`, without writing it (Series::adopt).
  void adopt(double time, const std::filesystem::path& from = {});
  void write_pvd() { m_series.write_pvd(); }
  void flush() { m_series.flush(); }
  void list_in_steps() { m_series.list_in_steps(); }

 private:
  Series m_series;
  std::vector<PointField> m_fields;
  FrameMetadata m_metadata;
};

/// The contacts of one moment: one line cell per contact, from sphere a's
/// centre to sphere b's (or to the contact point on a wall).
struct ContactSnapshot {
  double time = 0;
  std::uint64_t step = 0;
  std::vector<Vec3> a, b;                    // line ends, m
  std::vector<Vec3> normal;                  // unit, from b towards a
  // Forces in double whatever the run's precision: impulse / substep can
  // pass float's range where the impulses do not (a dense heavy pair at a
  // short substep), and a force written inf is no force.
  std::vector<double> normal_force;                   // N, >= 0 (impulse / substep)
  std::vector<std::array<double, 3>> tangential_force;  // N (impulse / substep)
  std::vector<real> overlap;                 // m, >= 0
  std::vector<std::uint32_t> sphere_a, sphere_b;      // ids (b: the wall's index for a wall)
  std::vector<std::uint32_t> material_a, material_b;  // material ids (b: the wall's material)
  std::vector<std::uint8_t> wall;            // 1: b is a wall
};

/// Writes DIR/contacts/contacts_NNNNNN.vtp (cell data normal_force,
/// tangential_force, force, normal, overlap, sphere_a, sphere_b, material_a,
/// material_b, wall) and keeps DIR/contacts.pvd up to date.
class ContactSeriesWriter {
 public:
  ContactSeriesWriter(std::filesystem::path dir, FrameMetadata metadata = {});
  std::filesystem::path write(const ContactSnapshot& contacts);
  void adopt(double time, const std::filesystem::path& from = {});
  void write_pvd() { m_series.write_pvd(); }
  void flush() { m_series.flush(); }
  void list_in_steps() { m_series.list_in_steps(); }
  std::size_t frames() const { return m_series.size(); }

 private:
  Series m_series;
  FrameMetadata m_metadata;
};

/// Writes the walls as surfaces, DIR/walls/walls_NNNNNN.vtp (polygons with
/// cell data `wall` and `material`; planes as squares sized to the scene's
/// bounds [lo, hi], infinite cylinders across them) and keeps DIR/walls.pvd
/// up to date, so that moving walls move in ParaView. The field data also
/// holds every wall's parameters (arrays planes, boxes, cylinders, spheres),
/// which read_walls_vtp turns back into Walls for `marbles render`.
class WallSeriesWriter {
 public:
  WallSeriesWriter(std::filesystem::path dir, const Vec3& lo, const Vec3& hi, FrameMetadata metadata = {});
  std::filesystem::path write(const Walls& walls, double time, std::uint64_t step);
  void adopt(double time, const std::filesystem::path& from = {});
  void write_pvd() { m_series.write_pvd(); }
  void flush() { m_series.flush(); }
  void list_in_steps() { m_series.list_in_steps(); }
  std::size_t frames() const { return m_series.size(); }

 private:
  Series m_series;
  Vec3 m_lo, m_hi;
  FrameMetadata m_metadata;
};

/// The walls stored in a walls_NNNNNN.vtp. Throws marbles::RuntimeFailure.
Walls read_walls_vtp(const std::filesystem::path& path);

/// One entry of a .pvd collection.
struct SeriesEntry {
  double time = 0;
  std::filesystem::path path;  ///< the frame file, resolved against the .pvd's folder
};

/// The <DataSet> entries of a .pvd file, in file order. Throws
/// marbles::RuntimeFailure when the file cannot be read, InputError when it
/// is cut short, lists no entry, gives a timestep that is no finite number,
/// or one not after the timestep before it (a run lists them in time order).
std::vector<SeriesEntry> read_pvd(const std::filesystem::path& pvd_path);

/// Every numeric array of a .vtp in appended format, by "Section/Name"
/// (e.g. "PointData/radius", "CellData/normal_force", "FieldData/TimeValue",
/// "Points/Points"), as doubles. Throws marbles::RuntimeFailure.
struct VtpArrays {
  struct Array {
    int components = 1;
    std::vector<double> values;
  };
  std::size_t points = 0;
  std::map<std::string, Array> arrays;
};
VtpArrays read_vtp_arrays(const std::filesystem::path& vtp_path);

/// A VTK file a run wrote whole ends with </VTKFile>; one cut short (a copy
/// that stopped, a disk that filled) or overwritten does not, and throws
/// InputError naming it (`why`: what the caller was about to do with it).
void require_whole_vtk(const std::filesystem::path& path, const std::string& why);

/// Refuses (InputError naming the path) a path that is a folder, pipe,
/// socket or device: read_pvd, read_vtp_arrays (so read_vtp and
/// read_walls_vtp) and render read plain files only.
void require_plain_file(const std::filesystem::path& path);

/// Reads a .vtp written by VtkSeriesWriter (or any poly data with points and
/// some of the arrays radius, velocity, angular_velocity, id, material) into a
/// snapshot; missing arrays stay empty; time and step come from the field data
/// TimeValue and step when present. Throws marbles::RuntimeFailure (a file it
/// cannot read) or InputError (a path that is no plain file, or a value no
/// run writes: a position, velocity, spin or time not finite or past the
/// precision, a radius not above zero, an id, material, contact count or
/// step that is not a whole number in range).
Snapshot read_vtp(const std::filesystem::path& vtp_path);

}  // namespace marbles::render
