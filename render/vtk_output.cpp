// render/vtk_output.cpp — see vtk_output.hpp.
#include "render/vtk_output.hpp"

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <initializer_list>
#include <limits>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <sstream>
#include <string_view>
#include <type_traits>

#include "core/error.hpp"
#include "core/files.hpp"
#include "core/format.hpp"
#include "render/atomic_file.hpp"

#if defined(MARBLES_HAVE_ZLIB)
#include <zlib.h>
#endif

namespace marbles::render {

namespace fs = std::filesystem;

static_assert(sizeof(Vec3) == 3 * sizeof(real), "Vec3 must be three packed reals");

std::optional<PointField> parse_point_field(std::string_view name) {
  if (name == "radius") return PointField::radius;
  if (name == "velocity") return PointField::velocity;
  if (name == "angular_velocity") return PointField::angular_velocity;
  if (name == "id") return PointField::id;
  if (name == "material") return PointField::material;
  if (name == "speed") return PointField::speed;
  if (name == "contacts") return PointField::contacts;
  return std::nullopt;
}

const char* point_field_name(PointField f) {
  switch (f) {
    case PointField::radius: return "radius";
    case PointField::velocity: return "velocity";
    case PointField::angular_velocity: return "angular_velocity";
    case PointField::id: return "id";
    case PointField::material: return "material";
    case PointField::speed: return "speed";
    case PointField::contacts: return "contacts";
  }
  return "?";
}

std::vector<PointField> parse_point_fields(const std::vector<std::string>& names) {
  std::vector<PointField> fields;
  for (const std::string& name : names) {
    const auto f = parse_point_field(name);
    if (!f)
      throw InputError({}, "output.fields",
                       "unknown field '" + name + "' (expected radius, velocity, angular_velocity, id, material, speed, contacts)");
    if (std::find(fields.begin(), fields.end(), *f) == fields.end()) fields.push_back(*f);
  }
  return fields;
}

namespace {

// The time a frame's TimeValue holds: the number its .pvd line (and
// thermo.csv's row) spells, so the three match exactly (175 steps of 1 ms
// are 0.17500000000000002 s, listed as 0.175).
double listed_time(double time) { return std::strtod(time_text(time).c_str(), nullptr); }

// One file's line of a .pvd.
std::string dataset_line(double time, const std::string& file) {
  return "    <DataSet timestep=\"" + time_text(time) + "\" group=\"\" part=\"0\" file=\"" + file + "\"/>\n";
}

// A .pvd around its files' lines (kept as text: a run of 10^4 frames formatted
// every time in each rewrite spent most of its time writing numbers).
std::string pvd_text(std::string_view lines) {
  constexpr std::string_view head =
      "<?xml version=\"1.0\"?>\n"
      "<VTKFile type=\"Collection\" version=\"0.1\" byte_order=\"LittleEndian\">\n"
      "  <Collection>\n";
  constexpr std::string_view tail = "  </Collection>\n</VTKFile>\n";
  std::string out;
  out.reserve(head.size() + lines.size() + tail.size());
  out.append(head).append(lines).append(tail);
  return out;
}

// XML scanned by hand: a regular expression over an attribute tens of
// kilobytes long recurses once a character in libstdc++ and overflows the
// stack, and a run's files are read back (render, a resume) as they lie.
bool is_name_char(char c) { return std::isalpha(static_cast<unsigned char>(c)) != 0 || c == '_'; }
bool is_space(char c) { return c == ' ' || c == '\t' || c == '\n' || c == '\r' || c == '\f' || c == '\v'; }

// f(name, value) for each `name = "value"` in `text` (name: letters and _;
// with `single`, 'value' too), in order; anything else is passed over.
template <class F>
void for_each_attribute(std::string_view text, bool single, F&& f) {
  std::size_t i = 0;
  while (i < text.size()) {
    if (!is_name_char(text[i])) {
      ++i;
      continue;
    }
    std::size_t j = i;
    while (j < text.size() && is_name_char(text[j])) ++j;
    std::size_t k = j;
    while (k < text.size() && is_space(text[k])) ++k;
    if (k < text.size() && text[k] == '=') {
      ++k;
      while (k < text.size() && is_space(text[k])) ++k;
      if (k < text.size() && (text[k] == '"' || (single && text[k] == '\''))) {
        const std::size_t close = text.find(text[k], k + 1);
        if (close != std::string_view::npos) {
          f(text.substr(i, j - i), text.substr(k + 1, close - k - 1));
          i = close + 1;
          continue;
        }
      }
    }
    i = j;
  }
}

// f(closing, name, attributes) for each tag `<name ...>` or `</name ...>`
// in `text` (name: letters), in order.
template <class F>
void for_each_tag(std::string_view text, F&& f) {
  std::size_t i = 0;
  while ((i = text.find('<', i)) != std::string_view::npos) {
    std::size_t j = i + 1;
    const bool closing = j < text.size() && text[j] == '/';
    if (closing) ++j;
    std::size_t k = j;
    while (k < text.size() && std::isalpha(static_cast<unsigned char>(text[k])) != 0) ++k;
    if (k == j) {
      ++i;
      continue;
    }
    const std::size_t end = text.find('>', k);
    if (end == std::string_view::npos) return;
    f(closing, text.substr(j, k - j), text.substr(k, end - k));
    i = end + 1;
  }
}

}  // namespace

void require_plain_file(const fs::path& path) {
  // A run's outputs are plain files; a device or pipe named in their place
  // (a .pvd edited, a link) would be read without end or wait for a writer.
  if (const char* what = not_a_plain_file(path.string()))
    throw InputError(SourceLocation{path.string(), 0, 0}, "",
                     std::string("is ") + what + ", not a run's output file (render reads plain files only)");
}

void require_whole_vtk(const fs::path& path, const std::string& why) {
  require_plain_file(path);
  if (!std::ifstream(path, std::ios::binary)) throw RuntimeFailure("cannot read " + path.string() + ": " + std::strerror(errno));
  if (!ends_with("</VTKFile>")(path))
    throw InputError(SourceLocation{path.string(), 0, 0}, "",
                     "is cut short or damaged: it does not end with </VTKFile> (" + why + ")");
}

std::vector<SeriesEntry> read_pvd(const fs::path& pvd_path) {
  require_plain_file(pvd_path);
  std::ifstream in(pvd_path, std::ios::binary);
  if (!in) {
    if (!fs::exists(pvd_path)) throw InputError(SourceLocation{pvd_path.string(), 0, 0}, "", "no such file");
    throw RuntimeFailure("cannot read " + pvd_path.string());
  }
  std::stringstream buffer;
  buffer << in.rdbuf();
  const std::string text = buffer.str();
  // Cut short (a copy that stopped, a disk that filled): the frames it no
  // longer names would be taken for gone, and their images removed.
  const std::size_t collection_end = text.rfind("</Collection>");
  if (collection_end == std::string::npos || text.find("</VTKFile>", collection_end) == std::string::npos ||
      text.find("<DataSet", collection_end) != std::string::npos)
    throw InputError(SourceLocation{pvd_path.string(), 0, 0}, "",
                     "is cut short or damaged: it does not end with </Collection></VTKFile> (marbles run writes it "
                     "whole: run again, or resume the run from a checkpoint)");

  std::vector<SeriesEntry> entries;
  std::optional<double> last_time;  // the last entry's that gave one
  for_each_tag(text, [&](bool closing, std::string_view name, std::string_view attrs) {
    if (closing || name != "DataSet") return;
    std::optional<double> time;
    std::string file;
    for_each_attribute(attrs, true, [&](std::string_view key, std::string_view value) {
      if (key == "timestep") {
        // A time a run writes: a finite number, the whole attribute.
        const std::string v(value);
        char* end = nullptr;
        const double t = std::strtod(v.c_str(), &end);
        if (v.empty() || end != v.c_str() + v.size() || !std::isfinite(t))
          throw InputError(SourceLocation{pvd_path.string(), 0, 0}, "",
                           "a DataSet's timestep \"" + v + "\" is not a finite number");
        time = t;
      } else if (key == "file") {
        file = value;
      }
    });
    if (file.empty()) return;
    // In time order, as a run lists them (the movie and its frame rate follow the list).
    if (time && last_time && !(*time > *last_time))
      throw InputError(SourceLocation{pvd_path.string(), 0, 0}, "",
                       "frame " + std::to_string(entries.size()) + "'s timestep " + shortest(*time) +
                           " is not after the one before it, " + shortest(*last_time) +
                           ": a run lists its frames in time order (a series edited, or mixed with another run's?)");
    if (time) last_time = time;
    const fs::path p(file);
    entries.push_back({time.value_or(double(entries.size())), p.is_absolute() ? p : pvd_path.parent_path() / p});
  });
  if (entries.empty()) throw InputError(SourceLocation{pvd_path.string(), 0, 0}, "", "lists no frames");
  return entries;
}

std::string numbered_vtp(const char* prefix, std::size_t index) {
  char name[48];
  std::snprintf(name, sizeof name, "%s_%06zu.vtp", prefix, index);
  return name;
}

bool vtk_compressed() {
#if defined(MARBLES_HAVE_ZLIB)
  return true;
#else
  return false;
#endif
}

namespace {

constexpr std::size_t kBlockBytes = 32768;  // VTK's default compression block

// The appended-data section of a VTK XML file: each array is a header of
// UInt64 words followed by its bytes. Compressed (zlib): [blocks, block
// size, last block size, compressed size of each block], then the blocks;
// raw: [byte count], then the bytes.
class AppendedData {
 public:
  // Appends `bytes` bytes at `data`; returns the array's offset attribute.
  std::size_t add(const void* data, std::size_t bytes) {
    const std::size_t offset = m_bytes.size();
    const auto* in = static_cast<const unsigned char*>(data);
#if defined(MARBLES_HAVE_ZLIB)
    const std::size_t blocks = (bytes + kBlockBytes - 1) / kBlockBytes;
    std::vector<std::uint64_t> header{blocks, kBlockBytes, blocks == 0 ? 0 : bytes - (blocks - 1) * kBlockBytes};
    std::string compressed;
    for (std::size_t b = 0; b < blocks; ++b) {
      const std::size_t size = std::min(kBlockBytes, bytes - b * kBlockBytes);
      uLongf out_size = compressBound(static_cast<uLong>(size));
      std::string block(out_size, '\0');
      if (compress2(reinterpret_cast<Bytef*>(block.data()), &out_size, in + b * kBlockBytes, static_cast<uLong>(size),
                    Z_BEST_SPEED) != Z_OK)
        throw RuntimeFailure("VTK output: zlib could not compress a block");
      header.push_back(out_size);
      compressed.append(block.data(), out_size);
    }
    m_bytes.append(reinterpret_cast<const char*>(header.data()), header.size() * sizeof(std::uint64_t));
    m_bytes += compressed;
#else
    const std::uint64_t count = bytes;
    m_bytes.append(reinterpret_cast<const char*>(&count), sizeof count);
    m_bytes.append(reinterpret_cast<const char*>(in), bytes);
#endif
    return offset;
  }
  const std::string& bytes() const { return m_bytes; }

 private:
  std::string m_bytes;
};

template <typename T>
constexpr const char* vtk_type() {
  if constexpr (std::is_same_v<T, float>) return "Float32";
  else if constexpr (std::is_same_v<T, double>) return "Float64";
  else if constexpr (std::is_same_v<T, std::uint32_t>) return "UInt32";
  else if constexpr (std::is_same_v<T, std::uint64_t>) return "UInt64";
  else return "Int64";
}

// One <DataArray .../> of `tuples` x `components` values of T.
template <typename T>
std::string data_array(AppendedData& data, const char* name, int components, const T* values, std::size_t tuples,
                       const char* indent) {
  const std::size_t offset = data.add(values, tuples * std::size_t(components) * sizeof(T));
  std::string tag = std::string(indent) + "<DataArray type=\"" + vtk_type<T>() + "\" Name=\"" + name + "\"";
  if (components != 1) tag += " NumberOfComponents=\"" + std::to_string(components) + "\"";
  tag += " NumberOfTuples=\"" + std::to_string(tuples) + "\" format=\"appended\" offset=\"" + std::to_string(offset) +
         "\"/>\n";
  return tag;
}

// A field-data string array: each string's bytes and a terminating NUL.
std::string string_array(AppendedData& data, const char* name, const std::vector<std::string>& strings) {
  std::string bytes;
  for (const std::string& s : strings) bytes.append(s).push_back('\0');
  const std::size_t offset = data.add(bytes.data(), bytes.size());
  return std::string("      <Array type=\"String\" Name=\"") + name + "\" NumberOfTuples=\"" +
         std::to_string(strings.size()) + "\" format=\"appended\" offset=\"" + std::to_string(offset) + "\"/>\n";
}

void check_length(const char* name, std::size_t have, std::size_t n) {
  if (have != n)
    throw RuntimeFailure(std::string("VTK output: field '") + name + "' has " + std::to_string(have) +
                         " values for " + std::to_string(n) + " spheres");
}

// A VTK XML poly data file under construction: field data, points, one
// kind of cell (vertices or lines), point and cell data; every array in the
// appended section.
class PolyDataFile {
 public:
  template <typename T>
  void field(const char* name, const T& value) {
    m_field += data_array(m_data, name, 1, &value, 1, "      ");
  }
  template <typename T>
  void field_array(const char* name, int components, const T* values, std::size_t tuples) {
    if (tuples > 0) m_field += data_array(m_data, name, components, values, tuples, "      ");
  }
  void field_strings(const char* name, const std::vector<std::string>& strings) {
    if (!strings.empty()) m_field += string_array(m_data, name, strings);
  }
  void metadata(const FrameMetadata& m) {
    field_strings("material_names", m.material_names);
    field_strings("units", {"length m", "time s", "mass kg", "velocity m/s", "angular_velocity rad/s", "force N"});
    if (!m.producer.empty()) field_strings("producer", {m.producer});
  }
  void points(const Vec3* p, std::size_t n) {
    m_points = n;
    m_point_xyz = data_array(m_data, "Points", 3, &p->x, n, "        ");
  }
  template <typename T>
  void point_array(const char* name, int components, const T* values) {
    m_point += data_array(m_data, name, components, values, m_points, "        ");
  }
  template <typename T>
  void cell_array(const char* name, int components, const T* values, std::size_t cells) {
    m_cell += data_array(m_data, name, components, values, cells, "        ");
  }
  // `cells` cells of `per_cell` consecutive points each: "Verts" or "Lines".
  void cells(const char* kind, std::size_t cells, std::size_t per_cell) {
    std::vector<std::int64_t> ends(cells);
    for (std::size_t c = 0; c < cells; ++c) ends[c] = std::int64_t((c + 1) * per_cell);
    this->cells(kind, ends);
  }
  // Cells of varying size, their points consecutive: `ends` are the cells' end offsets.
  void cells(const char* kind, const std::vector<std::int64_t>& ends) {
    m_kind = kind;
    m_cells = ends.size();
    std::vector<std::int64_t> connectivity(ends.empty() ? 0 : std::size_t(ends.back()));
    for (std::size_t i = 0; i < connectivity.size(); ++i) connectivity[i] = std::int64_t(i);
    m_topology = data_array(m_data, "connectivity", 1, connectivity.data(), connectivity.size(), "        ") +
                 data_array(m_data, "offsets", 1, ends.data(), ends.size(), "        ");
  }
  void active_scalars(const char* name) { m_scalars = name; }

  std::string text() const {
    std::string xml = "<?xml version=\"1.0\"?>\n<VTKFile type=\"PolyData\" version=\"1.0\" byte_order=\"LittleEndian\" "
                      "header_type=\"UInt64\"";
    if (vtk_compressed()) xml += " compressor=\"vtkZLibDataCompressor\"";
    const std::string verts = m_kind == "Verts" ? std::to_string(m_cells) : "0";
    const std::string lines = m_kind == "Lines" ? std::to_string(m_cells) : "0";
    const std::string polys = m_kind == "Polys" ? std::to_string(m_cells) : "0";
    xml += ">\n  <PolyData>\n    <FieldData>\n" + m_field + "    </FieldData>\n    <Piece NumberOfPoints=\"" +
           std::to_string(m_points) + "\" NumberOfVerts=\"" + verts + "\" NumberOfLines=\"" + lines +
           "\" NumberOfStrips=\"0\" NumberOfPolys=\"" + polys + "\">\n";
    xml += "      <PointData" + (m_scalars.empty() ? std::string() : " Scalars=\"" + m_scalars + "\"") + ">\n" + m_point +
           "      </PointData>\n";
    if (!m_cell.empty()) xml += "      <CellData>\n" + m_cell + "      </CellData>\n";
    xml += "      <Points>\n" + m_point_xyz + "      </Points>\n";
    if (!m_kind.empty()) xml += "      <" + m_kind + ">\n" + m_topology + "      </" + m_kind + ">\n";
    xml += "    </Piece>\n  </PolyData>\n  <AppendedData encoding=\"raw\">\n   _";
    xml += m_data.bytes();
    xml += "\n  </AppendedData>\n</VTKFile>\n";
    return xml;
  }

 private:
  AppendedData m_data;
  std::string m_field, m_point, m_cell, m_point_xyz, m_topology, m_kind, m_scalars;
  std::size_t m_points = 0, m_cells = 0;
};

}  // namespace

// --- a series: numbered files and their .pvd ---------------------------------

fs::path Series::next_path() const { return m_dir / m_folder / numbered_vtp(m_prefix.c_str(), m_count); }

fs::path Series::add(double time, const std::string& file_text) {
  const fs::path path = next_path();
  if (!m_folder_made) {  // on the first file of this process (a resumed run may adopt earlier ones)
    m_folder_made = true;
    std::error_code ec;
    fs::create_directories(m_dir / m_folder, ec);
    if (ec) throw RuntimeFailure("cannot create " + (m_dir / m_folder).string() + ": " + ec.message());
  }
  // The file and the series that lists it are written together: where
  // either cannot be, neither is, and the series stays as it was. Where the
  // .pvd is not due, the file alone (listed at the .pvd's next write).
  const std::size_t before = m_lines.size();
  m_lines += dataset_line(time, m_folder + "/" + numbered_vtp(m_prefix.c_str(), m_count));
  try {
    if (!m_in_steps || m_relisting.due(m_lines.size())) {
      const std::string pvd = pvd_text(m_lines);
      write_files_atomic({{path, file_text}, {pvd_path(), pvd}});
      m_relisting.written(m_lines.size());
    } else {
      write_file_atomic(path, file_text);
    }
  } catch (...) {
    m_lines.resize(before);
    throw;
  }
  ++m_listed;
  ++m_count;
  return path;
}

void Series::adopt(double time, const fs::path& from) {
  const std::string file = m_folder + "/" + numbered_vtp(m_prefix.c_str(), m_count++);
  std::error_code ec;
  if (!fs::exists(m_dir / file, ec)) {
    // In neither folder (a run that wrote no frames, or a checkpoint away
    // from its run's folder): numbered, but not listed.
    // (Whole: the resume holds every file it copies to require_whole_vtk
    // before it writes anything, sim/run.cpp check_frames_beside.)
    if (from.empty() || !fs::is_regular_file(from / file, ec)) return;
    fs::create_directories(m_dir / m_folder, ec);
    if (ec) throw RuntimeFailure("cannot create " + (m_dir / m_folder).string() + ": " + ec.message());
    // Copied under a temporary name and renamed, as every output is written.
    const fs::path to = m_dir / file, part = temp_path_beside(to);
    copy_plain_file(from / file, part, ec);
    if (!ec) fs::rename(part, to, ec);
    if (ec) {
      std::error_code ignored;
      fs::remove(part, ignored);
      throw RuntimeFailure("cannot copy " + (from / file).string() + " to " + to.string() + ": " + ec.message());
    }
  }
  m_lines += dataset_line(time, file);
  ++m_listed;
}

void Series::write_pvd() {
  if (m_listed > 0) write_file_atomic(pvd_path(), pvd_text(m_lines));
  m_relisting.written(m_lines.size());
}

Series::~Series() {
  try {
    flush();
  } catch (...) {  // a run that fails or stops: its earlier .pvd stands, naming files that are there
  }
}

// --- spheres ------------------------------------------------------------------

VtkSeriesWriter::VtkSeriesWriter(fs::path dir, std::vector<PointField> fields, FrameMetadata metadata)
    : m_series(dir, "frames", "frame", "series.pvd"), m_fields(std::move(fields)), m_metadata(std::move(metadata)) {
  std::error_code ec;
  fs::create_directories(dir / "frames", ec);
  if (ec) throw RuntimeFailure("cannot create " + (dir / "frames").string() + ": " + ec.message());
}

void VtkSeriesWriter::adopt(double time, const fs::path& from) { m_series.adopt(time, from); }

fs::path VtkSeriesWriter::write(const Snapshot& s) {
  const std::size_t n = s.size();
  PolyDataFile file;
  file.field("TimeValue", listed_time(s.time));
  file.field("step", std::uint64_t(s.step));
  file.metadata(m_metadata);
  file.points(s.position.data(), n);
  for (PointField f : m_fields) {
    const char* name = point_field_name(f);
    switch (f) {
      case PointField::radius:
        check_length(name, s.radius.size(), n);
        file.point_array(name, 1, s.radius.data());
        break;
      case PointField::velocity:
        check_length(name, s.velocity.size(), n);
        file.point_array(name, 3, &s.velocity.data()->x);
        break;
      case PointField::angular_velocity:
        check_length(name, s.angular_velocity.size(), n);
        file.point_array(name, 3, &s.angular_velocity.data()->x);
        break;
      case PointField::id:
        check_length(name, s.id.size(), n);
        file.point_array(name, 1, s.id.data());
        break;
      case PointField::material:
        check_length(name, s.material.size(), n);
        file.point_array(name, 1, s.material.data());
        break;
      case PointField::speed: {
        check_length("velocity (for speed)", s.velocity.size(), n);
        std::vector<real> speed(n);
        for (std::size_t i = 0; i < n; ++i) speed[i] = length(s.velocity[i]);
        file.point_array(name, 1, speed.data());
        break;
      }
      case PointField::contacts:
        check_length(name, s.contacts.size(), n);
        file.point_array(name, 1, s.contacts.data());
        break;
    }
  }
  if (!m_fields.empty() && m_fields.front() == PointField::radius) file.active_scalars("radius");
  file.cells("Verts", n, 1);  // one vertex cell per sphere
  return m_series.add(s.time, file.text());
}

// --- contacts -----------------------------------------------------------------

ContactSeriesWriter::ContactSeriesWriter(fs::path dir, FrameMetadata metadata)
    : m_series(std::move(dir), "contacts", "contacts", "contacts.pvd"), m_metadata(std::move(metadata)) {}

void ContactSeriesWriter::adopt(double time, const fs::path& from) { m_series.adopt(time, from); }

fs::path ContactSeriesWriter::write(const ContactSnapshot& c) {
  const std::size_t n = c.a.size();
  for (const std::size_t size : {c.b.size(), c.sphere_a.size(), c.sphere_b.size(), c.normal_force.size(),
                                 c.tangential_force.size(), c.overlap.size(), c.material_a.size(),
                                 c.material_b.size()})
    if (size != n) throw RuntimeFailure("contact output: arrays of different lengths");
  std::vector<Vec3> points(2 * n);
  std::vector<std::array<double, 3>> force(n);
  std::vector<std::uint32_t> wall(n);
  for (std::size_t k = 0; k < n; ++k) {
    points[2 * k] = c.a[k];
    points[2 * k + 1] = c.b[k];
    for (int d = 0; d < 3; ++d) force[k][d] = double(c.normal[k][d]) * c.normal_force[k] + c.tangential_force[k][d];
    wall[k] = c.wall[k];
  }
  PolyDataFile file;
  file.field("TimeValue", listed_time(c.time));
  file.field("step", std::uint64_t(c.step));
  file.metadata(m_metadata);
  file.points(points.data(), points.size());
  file.cells("Lines", n, 2);
  file.cell_array("normal_force", 1, c.normal_force.data(), n);
  file.cell_array("tangential_force", 3, n ? c.tangential_force[0].data() : nullptr, n);
  file.cell_array("force", 3, n ? force[0].data() : nullptr, n);
  file.cell_array("normal", 3, &c.normal.data()->x, n);
  file.cell_array("overlap", 1, c.overlap.data(), n);
  file.cell_array("sphere_a", 1, c.sphere_a.data(), n);
  file.cell_array("sphere_b", 1, c.sphere_b.data(), n);
  file.cell_array("material_a", 1, c.material_a.data(), n);
  file.cell_array("material_b", 1, c.material_b.data(), n);
  file.cell_array("wall", 1, wall.data(), n);
  return m_series.add(c.time, file.text());
}

// --- walls ------------------------------------------------------------------

namespace {

// Wall surfaces as polygons: quads (planes, box faces, cylinder and sphere
// bands), each cell tagged with its wall and material.
struct WallMesh {
  std::vector<Vec3> points;
  std::vector<std::int64_t> ends;
  std::vector<std::uint32_t> wall, material;
  void quad(const Vec3& a, const Vec3& b, const Vec3& c, const Vec3& d, std::uint32_t w, std::uint32_t m) {
    for (const Vec3& p : {a, b, c, d}) points.push_back(p);
    ends.push_back(std::int64_t(points.size()));
    wall.push_back(w);
    material.push_back(m);
  }
};

Vec3 perpendicular(const Vec3& a) {
  const Vec3 t = std::fabs(a.x) < real(0.9) ? Vec3(1, 0, 0) : Vec3(0, 1, 0);
  const Vec3 c = cross(a, t);
  return c / length(c);
}

constexpr int kSegments = 48;  // around cylinders and spheres

}  // namespace

WallSeriesWriter::WallSeriesWriter(fs::path dir, const Vec3& lo, const Vec3& hi, FrameMetadata metadata)
    : m_series(std::move(dir), "walls", "walls", "walls.pvd"), m_lo(lo), m_hi(hi), m_metadata(std::move(metadata)) {}

void WallSeriesWriter::adopt(double time, const fs::path& from) { m_series.adopt(time, from); }

fs::path WallSeriesWriter::write(const Walls& walls, double time, std::uint64_t step) {
  const Vec3 centre = (m_lo + m_hi) * real(0.5);
  const real size = std::max(real(0.6) * length(m_hi - m_lo), real(1e-3));  // half the side of a plane's square
  WallMesh mesh;
  std::vector<double> planes, boxes, cylinders, spheres;  // the parameters, to read the walls back
  auto push = [](std::vector<double>& out, std::initializer_list<double> values) {
    out.insert(out.end(), values.begin(), values.end());
  };
  for (const PlaneWall& p : walls.planes) {
    const Vec3 c = centre - p.normal * dot(centre - p.point, p.normal);
    const Vec3 u = perpendicular(p.normal) * size, v = cross(p.normal, perpendicular(p.normal)) * size;
    mesh.quad(c - u - v, c + u - v, c + u + v, c - u + v, p.index, p.material);
    push(planes, {p.point.x, p.point.y, p.point.z, p.normal.x, p.normal.y, p.normal.z, p.velocity.x, p.velocity.y,
                  p.velocity.z, double(p.material)});
  }
  for (const BoxWall& b : walls.boxes) {
    const Vec3 l = b.lo, h = b.hi;
    const Vec3 c[8] = {{l.x, l.y, l.z}, {h.x, l.y, l.z}, {h.x, h.y, l.z}, {l.x, h.y, l.z},
                       {l.x, l.y, h.z}, {h.x, l.y, h.z}, {h.x, h.y, h.z}, {l.x, h.y, h.z}};
    const int faces[6][4] = {{0, 3, 2, 1}, {4, 5, 6, 7}, {0, 1, 5, 4}, {2, 3, 7, 6}, {1, 2, 6, 5}, {0, 4, 7, 3}};
    for (const auto& f : faces) mesh.quad(c[f[0]], c[f[1]], c[f[2]], c[f[3]], b.index, b.material);
    push(boxes, {l.x, l.y, l.z, h.x, h.y, h.z, b.velocity.x, b.velocity.y, b.velocity.z, double(b.material)});
  }
  for (const CylinderWall& c : walls.cylinders) {
    Vec3 base = c.base;
    real len = c.length;
    if (len <= 0) {  // infinite: drawn across the scene
      len = 2 * size;
      base = c.base + c.axis * (dot(centre - c.base, c.axis) - size);
    }
    const Vec3 u = perpendicular(c.axis), v = cross(c.axis, u);
    for (int k = 0; k < kSegments; ++k) {
      const double a0 = 2 * M_PI * k / kSegments, a1 = 2 * M_PI * (k + 1) / kSegments;
      const Vec3 r0 = (u * real(std::cos(a0)) + v * real(std::sin(a0))) * c.radius;
      const Vec3 r1 = (u * real(std::cos(a1)) + v * real(std::sin(a1))) * c.radius;
      mesh.quad(base + r0, base + r1, base + r1 + c.axis * len, base + r0 + c.axis * len, c.index, c.material);
    }
    push(cylinders, {c.base.x, c.base.y, c.base.z, c.axis.x, c.axis.y, c.axis.z, c.radius, c.length,
                     c.inside ? 1.0 : 0.0, c.angular_velocity, double(c.material)});
  }
  for (const SphereWall& s : walls.spheres) {
    auto at = [&](int i, int j) {
      const double theta = M_PI * i / (kSegments / 2), phi = 2 * M_PI * j / kSegments;
      return s.centre + Vec3(real(std::sin(theta) * std::cos(phi)), real(std::sin(theta) * std::sin(phi)),
                             real(std::cos(theta))) * s.radius;
    };
    for (int i = 0; i < kSegments / 2; ++i)
      for (int j = 0; j < kSegments; ++j)
        mesh.quad(at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1), s.index, s.material);
    push(spheres, {s.centre.x, s.centre.y, s.centre.z, s.radius, s.velocity.x, s.velocity.y, s.velocity.z,
                   double(s.material)});
  }
  PolyDataFile file;
  file.field("TimeValue", listed_time(time));
  file.field("step", step);
  file.metadata(m_metadata);
  file.field_array("planes", 10, planes.data(), planes.size() / 10);
  file.field_array("boxes", 10, boxes.data(), boxes.size() / 10);
  file.field_array("cylinders", 11, cylinders.data(), cylinders.size() / 11);
  file.field_array("spheres", 8, spheres.data(), spheres.size() / 8);
  file.points(mesh.points.data(), mesh.points.size());
  file.cells("Polys", mesh.ends);
  file.cell_array("wall", 1, mesh.wall.data(), mesh.wall.size());
  file.cell_array("material", 1, mesh.material.data(), mesh.material.size());
  return m_series.add(time, file.text());
}

Walls read_walls_vtp(const fs::path& path) {
  const VtpArrays file = read_vtp_arrays(path);
  auto rows = [&](const char* name, int components) {
    std::vector<std::vector<double>> out;
    const auto it = file.arrays.find(std::string("FieldData/") + name);
    if (it == file.arrays.end()) return out;
    if (it->second.components != components || it->second.values.size() % std::size_t(components) != 0)
      throw InputError(SourceLocation{path.string(), 0, 0}, "",
                       "'" + std::string(name) + "' is not rows of " + std::to_string(components));
    for (std::size_t k = 0; k < it->second.values.size(); k += std::size_t(components))
      out.emplace_back(it->second.values.begin() + long(k), it->second.values.begin() + long(k) + components);
    return out;
  };
  auto vec = [](const std::vector<double>& r, int at) { return Vec3(real(r[at]), real(r[at + 1]), real(r[at + 2])); };
  Walls w;
  for (const auto& r : rows("planes", 10))
    w.planes.push_back({vec(r, 0), vec(r, 3), std::uint32_t(r[9]), vec(r, 6)});
  for (const auto& r : rows("boxes", 10)) w.boxes.push_back({vec(r, 0), vec(r, 3), std::uint32_t(r[9]), vec(r, 6)});
  for (const auto& r : rows("cylinders", 11))
    w.cylinders.push_back({vec(r, 0), vec(r, 3), real(r[6]), real(r[7]), r[8] != 0, real(r[9]), std::uint32_t(r[10])});
  for (const auto& r : rows("spheres", 8))
    w.spheres.push_back({vec(r, 0), real(r[3]), std::uint32_t(r[7]), vec(r, 4)});
  return w;
}

// --- reading ----------------------------------------------------------------

namespace {

// The attributes of one XML tag, e.g. type="Float32" Name="radius".
std::vector<std::pair<std::string, std::string>> attributes_of(std::string_view tag) {
  std::vector<std::pair<std::string, std::string>> out;
  for_each_attribute(tag, false, [&](std::string_view k, std::string_view v) { out.emplace_back(k, v); });
  return out;
}

std::string attribute(const std::vector<std::pair<std::string, std::string>>& attrs, const std::string& key) {
  for (const auto& [k, v] : attrs)
    if (k == key) return v;
  return {};
}

struct ArrayTag {
  std::string section;  // FieldData, PointData, Points, Verts
  std::string name, type;
  int components = 1;
  std::size_t offset = 0;
};

class AppendedReader {
 public:
  AppendedReader(const fs::path& path, std::string_view bytes, bool compressed, bool header64)
      : m_path(path), m_bytes(bytes), m_compressed(compressed), m_header64(header64) {}

  // The decoded bytes of the array at `offset`.
  std::string read(std::size_t offset) const {
    std::size_t at = offset;
    auto word = [&]() -> std::uint64_t {
      const std::size_t size = m_header64 ? 8 : 4;
      if (at + size > m_bytes.size()) fail();
      std::uint64_t v = 0;
      if (m_header64) std::memcpy(&v, m_bytes.data() + at, 8);
      else {
        std::uint32_t w = 0;
        std::memcpy(&w, m_bytes.data() + at, 4);
        v = w;
      }
      at += size;
      return v;
    };
    if (!m_compressed) {
      const std::uint64_t count = word();
      if (count > m_bytes.size() - at) fail();
      return std::string(m_bytes.substr(at, count));
    }
    const std::uint64_t blocks = word(), block_size = word(), last_size = word();
    if (blocks > m_bytes.size()) fail();
    std::vector<std::uint64_t> sizes(blocks);
    for (auto& s : sizes) s = word();
    std::string out;
#if defined(MARBLES_HAVE_ZLIB)
    for (std::uint64_t b = 0; b < blocks; ++b) {
      const std::uint64_t raw = (b + 1 == blocks && last_size != 0) ? last_size : block_size;
      if (sizes[b] > m_bytes.size() - at || raw > (std::uint64_t(1) << 31)) fail();
      std::string block(raw, '\0');
      uLongf got = static_cast<uLongf>(raw);
      if (uncompress(reinterpret_cast<Bytef*>(block.data()), &got, reinterpret_cast<const Bytef*>(m_bytes.data() + at),
                     static_cast<uLong>(sizes[b])) != Z_OK || got != raw)
        fail();
      out += block;
      at += sizes[b];
    }
#else
    (void)block_size;
    (void)last_size;
    if (blocks > 0)
      throw RuntimeFailure("cannot read " + m_path.string() + ": it is zlib-compressed and this build has no zlib");
#endif
    return out;
  }

 private:
  [[noreturn]] void fail() const {
    throw InputError(SourceLocation{m_path.string(), 0, 0}, "", "its appended data is truncated or damaged");
  }
  fs::path m_path;
  std::string_view m_bytes;
  bool m_compressed, m_header64;
};

template <typename T>
std::vector<double> as_doubles(const std::string& bytes) {
  std::vector<double> out(bytes.size() / sizeof(T));
  for (std::size_t i = 0; i < out.size(); ++i) {
    T v;
    std::memcpy(&v, bytes.data() + i * sizeof(T), sizeof(T));
    out[i] = static_cast<double>(v);
  }
  return out;
}

std::vector<double> decode_numbers(const fs::path& path, const ArrayTag& tag, const std::string& bytes) {
  if (tag.type == "Float32") return as_doubles<float>(bytes);
  if (tag.type == "Float64") return as_doubles<double>(bytes);
  if (tag.type == "UInt32") return as_doubles<std::uint32_t>(bytes);
  if (tag.type == "Int32") return as_doubles<std::int32_t>(bytes);
  if (tag.type == "UInt64") return as_doubles<std::uint64_t>(bytes);
  if (tag.type == "Int64") return as_doubles<std::int64_t>(bytes);
  throw InputError(SourceLocation{path.string(), 0, 0}, "",
                   "array '" + tag.name + "' has the unsupported type " + tag.type);
}

}  // namespace

VtpArrays read_vtp_arrays(const fs::path& vtp_path) {
  require_plain_file(vtp_path);
  std::ifstream in(vtp_path, std::ios::binary);
  if (!in) {
    if (!fs::exists(vtp_path)) throw InputError(SourceLocation{vtp_path.string(), 0, 0}, "", "no such file");
    throw RuntimeFailure("cannot read " + vtp_path.string());
  }
  std::stringstream buffer;
  buffer << in.rdbuf();
  const std::string text = buffer.str();
  const auto bad = [&](const std::string& why) { return InputError(SourceLocation{vtp_path.string(), 0, 0}, "", why); };

  const std::size_t appended = text.find("<AppendedData");
  const std::string head = text.substr(0, appended);
  const std::size_t root = head.find("<VTKFile");
  if (root == std::string::npos || head.find("type=\"PolyData\"") == std::string::npos)
    throw bad("not a VTK poly data file");
  const auto root_attrs = attributes_of(head.substr(root, head.find('>', root) - root));
  if (attribute(root_attrs, "byte_order") != "LittleEndian") throw bad("not little-endian");
  const bool compressed = !attribute(root_attrs, "compressor").empty();
  if (compressed && attribute(root_attrs, "compressor") != "vtkZLibDataCompressor")
    throw bad("compressed with " + attribute(root_attrs, "compressor") + " (only zlib is read)");
  const bool header64 = attribute(root_attrs, "header_type") == "UInt64";

  // The arrays, with the section each sits in.
  std::vector<ArrayTag> tags;
  std::string section;
  std::size_t points = 0;
  for_each_tag(head, [&](bool closing, std::string_view name, std::string_view tag_attrs) {
    const auto attrs = attributes_of(tag_attrs);
    if (name == "FieldData" || name == "PointData" || name == "Points" || name == "Verts" || name == "CellData" ||
        name == "Lines" || name == "Polys" || name == "Strips") {
      section = closing ? std::string() : std::string(name);
    } else if (name == "Piece" && !closing) {
      points = std::strtoull(attribute(attrs, "NumberOfPoints").c_str(), nullptr, 10);
    } else if ((name == "DataArray" || name == "Array") && !closing) {
      if (attribute(attrs, "format") != "appended")
        throw bad("array '" + attribute(attrs, "Name") + "' is not in appended format (marbles writes and reads that)");
      ArrayTag tag;
      tag.section = section;
      tag.name = attribute(attrs, "Name");
      tag.type = attribute(attrs, "type");
      const std::string components = attribute(attrs, "NumberOfComponents");
      tag.components = components.empty() ? 1 : std::atoi(components.c_str());
      tag.offset = std::strtoull(attribute(attrs, "offset").c_str(), nullptr, 10);
      tags.push_back(tag);
    }
  });
  if (appended == std::string::npos) throw bad("no appended data");
  const std::size_t underscore = text.find('_', text.find('>', appended));
  if (underscore == std::string::npos) throw bad("no appended data");
  const AppendedReader data(vtp_path, std::string_view(text).substr(underscore + 1), compressed, header64);

  VtpArrays out;
  out.points = points;
  for (const ArrayTag& tag : tags) {
    if (tag.type == "String") continue;
    out.arrays[tag.section + "/" + tag.name] = {tag.components, decode_numbers(vtp_path, tag, data.read(tag.offset))};
  }
  return out;
}

Snapshot read_vtp(const fs::path& vtp_path) {
  const VtpArrays file = read_vtp_arrays(vtp_path);
  const std::size_t points = file.points;
  Snapshot s;
  // An array absent is null; one of another shape than the frame's points
  // (a value short, a velocity of one component) is refused, where it was
  // taken as absent ("has no radius array", a velocity dropped).
  auto find = [&](const std::string& key, int components) -> const std::vector<double>* {
    const auto it = file.arrays.find(key);
    if (it == file.arrays.end()) return nullptr;
    if (it->second.components != components || it->second.values.size() != points * std::size_t(components))
      throw InputError(SourceLocation{vtp_path.string(), 0, 0}, "",
                       key + ": " + std::to_string(it->second.values.size()) + " values of " +
                           std::to_string(it->second.components) + " component(s), not the frame's " +
                           std::to_string(points) + " points of " + std::to_string(components));
    return &it->second.values;
  };
  // Values a run writes: finite and within the precision (a sphere's size
  // above zero, its numbers whole); any other is a damaged or foreign file,
  // refused naming the array and the point rather than drawn as it falls.
  const double most = std::numeric_limits<real>::max();
  auto refuse = [&](const std::string& key, std::size_t i, double value, const char* rule) {
    throw InputError(SourceLocation{vtp_path.string(), 0, 0}, "",
                     key + ": point " + std::to_string(i) + " holds " + significant(value, 9) + ", not " + rule);
  };
  auto vectors = [&](const std::string& key, std::vector<Vec3>& out) {
    if (const auto* v = find(key, 3)) {
      out.resize(points);
      for (std::size_t k = 0; k < 3 * points; ++k)
        if (!(std::fabs((*v)[k]) <= most))
          refuse(key, k / 3, (*v)[k], sizeof(real) == 4 ? "a finite number within float precision (render reads in float)"
                                                       : "a finite number within double precision");
      for (std::size_t i = 0; i < points; ++i) out[i] = Vec3(real((*v)[3 * i]), real((*v)[3 * i + 1]), real((*v)[3 * i + 2]));
    }
  };
  auto scalars = [&](const std::string& key, auto& out) {
    using T = std::decay_t<decltype(out[0])>;
    if (const auto* v = find(key, 1)) {
      out.resize(points);
      for (std::size_t i = 0; i < points; ++i) {
        const double x = (*v)[i];
        if constexpr (std::is_integral_v<T>) {
          if (!(x >= 0 && x <= double(std::numeric_limits<T>::max()) && x == std::floor(x)))
            refuse(key, i, x, "a whole number in range");
        } else if (!(x > 0 && x <= most)) {
          refuse(key, i, x, "a finite number above zero");
        }
        out[i] = static_cast<T>(x);
      }
    }
  };
  if (!find("Points/Points", 3) && points > 0)
    throw InputError(SourceLocation{vtp_path.string(), 0, 0}, "",
                     "its points are not " + std::to_string(points) + " triples");
  vectors("Points/Points", s.position);
  scalars("PointData/radius", s.radius);
  vectors("PointData/velocity", s.velocity);
  vectors("PointData/angular_velocity", s.angular_velocity);
  scalars("PointData/id", s.id);
  scalars("PointData/material", s.material);
  scalars("PointData/contacts", s.contacts);
  if (const auto it = file.arrays.find("FieldData/TimeValue"); it != file.arrays.end() && !it->second.values.empty()) {
    s.time = it->second.values[0];
    if (!std::isfinite(s.time)) refuse("FieldData/TimeValue", 0, s.time, "a finite number");
  }
  if (const auto it = file.arrays.find("FieldData/step"); it != file.arrays.end() && !it->second.values.empty()) {
    const double step = it->second.values[0];
    if (!(step >= 0 && step < 1.8e19 && step == std::floor(step))) refuse("FieldData/step", 0, step, "a whole number in range");
    s.step = static_cast<std::uint64_t>(step);
  }
  return s;
}

}  // namespace marbles::render
