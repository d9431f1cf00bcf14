// sim/particles.cpp — the scene's particle blocks expanded into spheres.
//
// Blocks are expanded in file order; ids follow that order. Every random
// number comes from std::mt19937_64 (its output is fixed by the C++
// standard) mapped to [0, 1) by hand (top 53 bits), never through
// std::uniform_real_distribution, whose algorithm differs between standard
// libraries: a seed gives the same spheres everywhere.
//
// Random blocks use random sequential addition: draw the radii, place the
// largest first, try up to kAttemptsPerSphere uniformly drawn centres per
// sphere and keep the first that overlaps nothing placed so far. The overlap
// test looks only at the 27 cells around the candidate in a uniform grid of
// cell edge >= the largest diameter (a head/next linked list per cell), so a
// block of N spheres costs O(N · attempts) instead of O(N²). Centres and radii
// are rounded to `real` before the test, so the stored spheres are exactly
// the ones that were tested.
#include "sim/particles.hpp"

#include <algorithm>
#include <array>
#include <cctype>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <random>
#include <sstream>
#include <string>
#include <string_view>

#include "core/files.hpp"
#include "core/format.hpp"
#include "core/host_memory.hpp"
#include "sim/limits.hpp"
#include "sim/scene_yaml.hpp"
#include "sim/world.hpp"

namespace marbles::scene {

namespace {

constexpr int kAttemptsPerSphere = 1000;
constexpr double kPi = 3.14159265358979323846;

class Random {
 public:
  explicit Random(std::uint64_t seed) : m_engine(seed) {}
  double unit() { return double(m_engine() >> 11) * 0x1.0p-53; }  // [0, 1)
  double uniform(double lo, double hi) { return lo + (hi - lo) * unit(); }

 private:
  std::mt19937_64 m_engine;
};

double draw_radius(const RadiusSpec& spec, Random& rng) {
  switch (spec.kind) {
    case RadiusSpec::Kind::constant: return spec.value;
    case RadiusSpec::Kind::uniform: return rng.uniform(spec.min, spec.max);
    case RadiusSpec::Kind::log_uniform: return std::exp(rng.uniform(std::log(spec.min), std::log(spec.max)));
  }
  return spec.value;
}

double largest_radius(const RadiusSpec& spec) {
  return spec.kind == RadiusSpec::Kind::constant ? spec.value : spec.max;
}

std::string block_key(std::size_t index) { return "particles[" + std::to_string(index) + "]"; }

std::string format_fraction(double x) {
  char buffer[32];
  std::snprintf(buffer, sizeof buffer, "%.3f", x);
  return buffer;
}

void push_sphere(GeneratedParticles& out, const Vec3& position, double radius, std::uint32_t material) {
  out.position.push_back(position);
  out.radius.push_back(real(radius));
  out.velocity.push_back(Vec3{});
  out.angular_velocity.push_back(Vec3{});
  out.material.push_back(material);
  out.fixed.push_back(0);
}

// --- resource guard --------------------------------------------------------

// Memory a run needs per sphere, roughly: the world, the step's buffers and
// the broad phase's, for a pile (~6 contacts per sphere); measured peak
// resident size of `marbles run` on piles of 10^5 and 10^6 spheres, rounded up.
// A count as text: exact below 1e15, else in e-notation.
std::string format_count(double n) {
  if (n < 1e15) return std::to_string(static_cast<long long>(n));
  std::ostringstream s;
  s << n;
  return s.str();
}

constexpr double kBytesPerSphere = 120.0 * sizeof(real) + 300.0;

// --- lattice ---------------------------------------------------------------

void expand_lattice(const ParticleBlock& block, std::size_t index, std::uint32_t material, GeneratedParticles& out) {
  const double margin = largest_radius(block.radius) + block.jitter;
  std::array<long long, 3> n{};
  std::array<double, 3> start{};
  std::array<double, 3> room{};
  double total = 1;
  for (int a = 0; a < 3; ++a) {
    room[a] = block.hi_written[a] - block.lo_written[a] - 2 * margin;
    total *= std::floor(room[a] / block.spacing + 1e-9) + 1;  // in double: no cast before the cap
  }
  if (!(total <= limits().spheres))
    throw InputError(block.where, block_key(index) + ".lattice",
                     "would make " + format_count(total) + " spheres, more than the limit " +
                         format_count(limits().spheres) + "; enlarge the spacing (or --limit spheres=N)");
  check_sphere_budget(double(out.size()) + total, block.where, block_key(index) + ".lattice");
  for (int a = 0; a < 3; ++a) {
    n[a] = static_cast<long long>(std::floor(room[a] / block.spacing + 1e-9)) + 1;
    start[a] = block.lo_written[a] + margin + 0.5 * (room[a] - double(n[a] - 1) * block.spacing);  // centred in the box
  }
  Random rng(block.seed);
  out.position.reserve(out.size() + std::size_t(total));
  for (long long k = 0; k < n[2]; ++k) {
    for (long long j = 0; j < n[1]; ++j) {
      for (long long i = 0; i < n[0]; ++i) {
        double c[3] = {start[0] + double(i) * block.spacing, start[1] + double(j) * block.spacing,
                       start[2] + double(k) * block.spacing};
        if (block.jitter > 0)
          for (double& x : c) x += rng.uniform(-block.jitter, block.jitter);
        const double r = draw_radius(block.radius, rng);
        push_sphere(out, Vec3(real(c[0]), real(c[1]), real(c[2])), r, material);
      }
    }
  }
}

// --- random, non-overlapping -----------------------------------------------

class PlacementGrid {
 public:
  PlacementGrid(const Vec3& lo, const Vec3& hi, double largest_radius, std::size_t count) {
    double extent[3], volume = 1;
    for (int a = 0; a < 3; ++a) {
      m_lo[a] = lo[a];
      extent[a] = double(hi[a]) - double(lo[a]);
      volume *= extent[a];
    }
    // Cell edge >= the largest diameter, and no more cells than ~8 per sphere.
    double h = std::max(2 * largest_radius, std::cbrt(volume / double(count)));
    for (;;) {
      double cells = 1;
      for (int a = 0; a < 3; ++a) {
        m_dims[a] = int(std::clamp(std::floor(extent[a] / h), 1.0, 1.0e6));
        cells *= m_dims[a];
      }
      if (cells <= 8.0 * double(count) + 64) break;
      h *= 1.25;
    }
    for (int a = 0; a < 3; ++a) m_cell[a] = extent[a] / m_dims[a];
    m_head.assign(std::size_t(m_dims[0]) * m_dims[1] * m_dims[2], -1);
  }

  bool overlaps_any(const double c[3], double r) const {
    int lo[3], hi[3];
    for (int a = 0; a < 3; ++a) {
      const int home = cell_of(c[a], a);
      lo[a] = std::max(home - 1, 0);
      hi[a] = std::min(home + 1, m_dims[a] - 1);
    }
    for (int z = lo[2]; z <= hi[2]; ++z)
      for (int y = lo[1]; y <= hi[1]; ++y)
        for (int x = lo[0]; x <= hi[0]; ++x)
          for (int j = m_head[flat(x, y, z)]; j >= 0; j = m_next[j]) {
            const Sphere& s = m_spheres[j];
            const double dx = c[0] - s.c[0], dy = c[1] - s.c[1], dz = c[2] - s.c[2];
            const double reach = r + s.r;
            if (dx * dx + dy * dy + dz * dz < reach * reach) return true;
          }
    return false;
  }

  void insert(const double c[3], double r) {
    const std::size_t cell = flat(cell_of(c[0], 0), cell_of(c[1], 1), cell_of(c[2], 2));
    m_spheres.push_back({{c[0], c[1], c[2]}, r});
    m_next.push_back(m_head[cell]);
    m_head[cell] = int(m_spheres.size() - 1);
  }

 private:
  struct Sphere {
    double c[3];
    double r;
  };
  int cell_of(double x, int a) const { return std::clamp(int(std::floor((x - m_lo[a]) / m_cell[a])), 0, m_dims[a] - 1); }
  std::size_t flat(int x, int y, int z) const { return (std::size_t(z) * m_dims[1] + y) * m_dims[0] + x; }

  double m_lo[3]{}, m_cell[3]{};
  int m_dims[3]{};
  std::vector<int> m_head, m_next;
  std::vector<Sphere> m_spheres;
};

// Spheres [first, end) numbered again in the broad phase's order for them
// (cell_order, sim/world.hpp: rows of its cells, x, then y, then z; a cell's
// spheres in the order they had), so the bodies the step reads for the
// pairs it finds lie nearly in order in memory.
void number_by_cells(GeneratedParticles& out, std::size_t first) {
  const std::size_t n = out.size() - first;
  const std::vector<std::uint32_t> order = cell_order(out.position.data() + first, out.radius.data() + first, n);
  auto gather = [&](auto& v) {
    const auto in_order = gathered(v.data() + first, order);
    std::copy(in_order.begin(), in_order.end(), v.begin() + first);
  };
  gather(out.position);
  gather(out.velocity);
  gather(out.radius);
  gather(out.angular_velocity);
  gather(out.material);
  gather(out.fixed);
}

void expand_random(const ParticleBlock& block, std::size_t index, std::uint32_t material, GeneratedParticles& out) {
  check_sphere_budget(double(out.size()) + double(block.count), block.count_where, block_key(index) + ".random.count");
  Random rng(block.seed);
  std::vector<double> radii(block.count);
  for (double& r : radii) r = double(real(draw_radius(block.radius, rng)));
  if (block.radius.kind != RadiusSpec::Kind::constant) std::sort(radii.begin(), radii.end(), std::greater<>());
  const double r_max = *std::max_element(radii.begin(), radii.end());

  PlacementGrid grid(block.lo, block.hi, r_max, block.count);
  double box_volume = 1;
  for (int a = 0; a < 3; ++a) box_volume *= double(block.hi[a]) - double(block.lo[a]);
  out.position.reserve(out.size() + block.count);
  double placed_volume = 0;
  for (std::size_t i = 0; i < block.count; ++i) {
    const double r = radii[i];
    bool placed = false;
    for (int attempt = 0; attempt < kAttemptsPerSphere && !placed; ++attempt) {
      double c[3];
      for (int a = 0; a < 3; ++a)
        c[a] = double(real(rng.uniform(double(block.lo[a]) + r, double(block.hi[a]) - r)));
      if (grid.overlaps_any(c, r)) continue;
      grid.insert(c, r);
      push_sphere(out, Vec3(real(c[0]), real(c[1]), real(c[2])), r, material);
      placed_volume += 4.0 / 3.0 * kPi * r * r * r;
      placed = true;
    }
    if (!placed) {
      throw InputError(block.count_where, block_key(index) + ".random.count",
                       "could place only " + std::to_string(i) + " of " + std::to_string(block.count) +
                           " non-overlapping spheres in the box (volume fraction " +
                           format_fraction(placed_volume / box_volume) + ", " + std::to_string(kAttemptsPerSphere) +
                           " attempts for the next one); enlarge the box or lower the count or the radii");
    }
  }
}

// --- CSV -------------------------------------------------------------------

struct CsvSpheres {
  GeneratedParticles spheres;
  bool has_velocity = false;
  bool has_angular_velocity = false;
};

std::string_view trim(std::string_view s) {
  while (!s.empty() && (s.front() == ' ' || s.front() == '\t')) s.remove_prefix(1);
  while (!s.empty() && (s.back() == ' ' || s.back() == '\t' || s.back() == '\r')) s.remove_suffix(1);
  return s;
}

struct CsvField {
  std::string_view text;
  int column;  // 1-based
};

std::vector<CsvField> split_row(std::string_view line) {
  std::vector<CsvField> fields;
  std::size_t begin = 0;
  for (;;) {
    const std::size_t end = line.find(',', begin);
    const std::string_view raw = line.substr(begin, end == std::string_view::npos ? std::string_view::npos : end - begin);
    std::size_t lead = 0;
    while (lead < raw.size() && (raw[lead] == ' ' || raw[lead] == '\t')) ++lead;
    fields.push_back({trim(raw), int(begin + lead + 1)});
    if (end == std::string_view::npos) break;
    begin = end + 1;
  }
  return fields;
}

bool parse_number(std::string_view s, double& value) {
  if (!s.empty() && s.front() == '+') s.remove_prefix(1);
  if (s.empty()) return false;
  const auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), value);
  return ec == std::errc() && end == s.data() + s.size();
}

// A digit first, or a point, after an optional sign.
bool begins_as_number(std::string_view s) {
  if (!s.empty() && (s.front() == '+' || s.front() == '-')) s.remove_prefix(1);
  return !s.empty() && (std::isdigit(static_cast<unsigned char>(s.front())) != 0 || s.front() == '.');
}

// Columns: x y z r vx vy vz wx wy wz (indices 0..9) → position in the row, or -1.
constexpr int kColumns = 10;
const char* const kColumnNames[kColumns] = {"x", "y", "z", "r", "vx", "vy", "vz", "wx", "wy", "wz"};

constexpr std::size_t kLongestCsvLine = 1 << 20;  // bytes

CsvSpheres read_csv(const std::string& path, const SourceLocation& open_where, const std::string& open_key) {
  if (const char* what = not_a_plain_file(path))
    throw InputError(open_where, open_key, "'" + printable_path(path) + "' is " + what + ", not a CSV file of spheres");
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(open_where, open_key, "cannot open '" + printable_path(path) + "': " + std::strerror(errno));

  CsvSpheres result;
  std::array<int, kColumns> column_of{};
  std::size_t expected_fields = 0;
  int layout_line = 0;  // the line that fixed the layout (header or first row)
  bool header = false;
  // Lines are read into a bounded buffer: a row is a few dozen bytes, and a
  // stream without line ends (/dev/zero, a binary file) is refused at the
  // bound instead of filling the memory.
  std::vector<char> buffer(kLongestCsvLine + 2);  // and a '\r' before the '\n'
  int line_number = 0;
  while (in) {
    in.getline(buffer.data(), static_cast<std::streamsize>(buffer.size()));
    const bool ended = in.eof();
    if (in.bad()) throw InputError(SourceLocation{path, line_number + 1, 1}, "", "cannot be read");
    const auto too_long = [&](int line) {
      throw InputError(SourceLocation{path, line, 1}, "",
                       "a line longer than " + std::to_string(kLongestCsvLine) +
                           " bytes: not a CSV file of spheres (rows x,y,z,r[,vx,vy,vz[,wx,wy,wz]])");
    };
    if (in.fail() && !ended) too_long(line_number + 1);
    const auto got = static_cast<std::size_t>(in.gcount());
    if (ended && got == 0) break;
    ++line_number;
    std::string_view content(buffer.data(), ended ? got : got - 1);  // without its '\n'
    if (!content.empty() && content.back() == '\r') content.remove_suffix(1);
    if (content.size() > kLongestCsvLine) too_long(line_number);
    if (line_number == 1 && content.substr(0, 3) == "\xEF\xBB\xBF") content.remove_prefix(3);  // UTF-8 byte order mark
    if (const std::size_t hash = content.find('#'); hash != std::string_view::npos) content = content.substr(0, hash);
    if (trim(content).empty()) continue;
    const std::vector<CsvField> fields = split_row(content);
    // A row's bytes quoted in a message: its control bytes as \xNN.
    auto fail = [&](int column, const std::string& key, const std::string& message) -> void {
      throw InputError(SourceLocation{path, line_number, column}, key, printable(message, false));
    };

    if (layout_line == 0) {
      double probe = 0;
      // A header names its columns; a first value that begins as a number
      // does (1e400, 0x10, a number of 400 digits) is a row, and its value
      // is refused as such, not read as a column's name.
      header = !parse_number(fields[0].text, probe) && !begins_as_number(fields[0].text);
      layout_line = line_number;
      column_of.fill(-1);
      if (header) {
        for (std::size_t f = 0; f < fields.size(); ++f) {
          std::string name(fields[f].text);
          for (char& ch : name) ch = char(std::tolower(static_cast<unsigned char>(ch)));
          if (name == "radius") name = "r";
          const auto it = std::find(std::begin(kColumnNames), std::end(kColumnNames), name);
          if (it == std::end(kColumnNames))
            fail(fields[f].column, "", "unknown column '" + std::string(fields[f].text) +
                                           "' in the header; expected x, y, z, r (or radius) and optionally vx, vy, vz "
                                           "and wx, wy, wz");
          const int c = int(it - std::begin(kColumnNames));
          if (column_of[c] >= 0) fail(fields[f].column, "", "column '" + name + "' appears twice in the header");
          column_of[c] = int(f);
        }
        for (int c = 0; c < 4; ++c)
          if (column_of[c] < 0) fail(1, "", std::string("the header lacks column '") + kColumnNames[c] + "'");
        const int velocity_columns = (column_of[4] >= 0) + (column_of[5] >= 0) + (column_of[6] >= 0);
        if (velocity_columns != 0 && velocity_columns != 3)
          fail(1, "", "the header must name all of vx, vy, vz or none of them");
        const int spin_columns = (column_of[7] >= 0) + (column_of[8] >= 0) + (column_of[9] >= 0);
        if (spin_columns != 0 && spin_columns != 3)
          fail(1, "", "the header must name all of wx, wy, wz or none of them");
        expected_fields = fields.size();
        result.has_velocity = velocity_columns == 3;
        result.has_angular_velocity = spin_columns == 3;
        continue;
      }
      if (fields.size() != 4 && fields.size() != 7 && fields.size() != 10)
        fail(1, "", "expected 4, 7 or 10 comma-separated values (x,y,z,r[,vx,vy,vz[,wx,wy,wz]]), got " +
                        std::to_string(fields.size()));
      for (std::size_t f = 0; f < fields.size(); ++f) column_of[f] = int(f);
      expected_fields = fields.size();
      result.has_velocity = fields.size() >= 7;
      result.has_angular_velocity = fields.size() == 10;
    }

    if (fields.size() != expected_fields)
      fail(1, "", "expected " + std::to_string(expected_fields) + " comma-separated values (as on line " +
                      std::to_string(layout_line) + "), got " + std::to_string(fields.size()));
    double value[kColumns] = {};
    for (int c = 0; c < kColumns; ++c) {
      if (column_of[c] < 0) continue;
      const CsvField& field = fields[std::size_t(column_of[c])];
      if (!parse_number(field.text, value[c]))
        fail(field.column, kColumnNames[c], "expected a number, got '" + std::string(field.text) + "'");
      if (const std::string problem = sphere_value_problem(c, value[c]); !problem.empty())
        fail(field.column, kColumnNames[c], problem + ", got " + std::string(field.text));
    }
    for (int c : {0, 4, 7}) {  // position, velocity, spin
      if (column_of[c] < 0) continue;
      const std::string names = std::string(kColumnNames[c]) + ", " + kColumnNames[c + 1] + ", " + kColumnNames[c + 2];
      if (const std::string problem = sphere_vector_problem({real(value[c]), real(value[c + 1]), real(value[c + 2])},
                                                            names);
          !problem.empty())
        fail(fields[std::size_t(column_of[c])].column, kColumnNames[c], problem);
    }
    push_sphere(result.spheres, Vec3(real(value[0]), real(value[1]), real(value[2])), value[3], 0);
    result.spheres.velocity.back() = Vec3(real(value[4]), real(value[5]), real(value[6]));
    result.spheres.angular_velocity.back() = Vec3(real(value[7]), real(value[8]), real(value[9]));
  }
  if (result.spheres.size() == 0)
    throw InputError(SourceLocation{path, 0, 0}, "", "holds no spheres (rows x,y,z,r[,vx,vy,vz[,wx,wy,wz]])");
  return result;
}

// --- velocities ------------------------------------------------------------

void assign_velocities(const VelocitySpec& spec, GeneratedParticles& out, std::size_t first) {
  if (spec.kind == VelocitySpec::Kind::constant) {
    for (std::size_t i = first; i < out.size(); ++i) out.velocity[i] = spec.value;
  } else if (spec.kind == VelocitySpec::Kind::random) {
    Random rng(spec.seed);
    for (std::size_t i = first; i < out.size(); ++i) {
      const double vx = rng.uniform(-spec.speed, spec.speed);
      const double vy = rng.uniform(-spec.speed, spec.speed);
      const double vz = rng.uniform(-spec.speed, spec.speed);
      out.velocity[i] = Vec3(real(vx), real(vy), real(vz));
    }
  }
}

}  // namespace

std::string sphere_value_problem(int column, double value) {
  if (!std::isfinite(value)) return "must be a finite number";
  // As a scene's numbers (Field::number's rule).
  if (std::string problem = detail::real_range_problem(value, false); !problem.empty()) return problem;
  if (column == 3 && !(value > 0)) return "must be > 0";
  if (column == 3 && radius_squares_below_normal(real(value)))
    return "too small for " + std::string(kRealName) + " precision: the overlap test squares it (smallest " +
           shortest(smallest_squarable_radius()) + ")";
  return {};
}

std::string sphere_vector_problem(const Vec3& v, const std::string& names) {
  if (!square_overflows(v)) return {};
  return "too large for " + std::string(kRealName) + " precision: the squared length of (" + names + ") overflows";
}

GeneratedParticles read_spheres_csv(const std::string& path) {
  return read_csv(path, SourceLocation{path, 0, 0}, "").spheres;
}

GeneratedParticles generate_particles(const Scene& scene) {
  GeneratedParticles out;
  for (std::size_t b = 0; b < scene.particles.size(); ++b) {
    const ParticleBlock& block = scene.particles[b];
    const std::uint32_t material = scene.material_index(block.material, block.material_where, block_key(b) + ".material");
    const std::size_t first = out.size();
    bool velocities_given = false, spins_given = false;
    switch (block.kind) {
      case ParticleBlock::Kind::list:
        for (std::size_t i = 0; i < block.positions.size(); ++i)
          push_sphere(out, block.positions[i], block.radii.at(i), material);
        if (!block.velocities.empty()) {
          for (std::size_t i = 0; i < block.velocities.size(); ++i) out.velocity[first + i] = block.velocities[i];
          velocities_given = true;
        }
        break;
      case ParticleBlock::Kind::lattice: expand_lattice(block, b, material, out); break;
      case ParticleBlock::Kind::random: expand_random(block, b, material, out); break;
      case ParticleBlock::Kind::csv: {
        CsvSpheres csv = read_csv(block.csv_path, block.csv_path_where, block_key(b) + ".csv.path");
        for (std::size_t i = 0; i < csv.spheres.size(); ++i) {
          push_sphere(out, csv.spheres.position[i], csv.spheres.radius[i], material);
          out.velocity.back() = csv.spheres.velocity[i];
          out.angular_velocity.back() = csv.spheres.angular_velocity[i];
        }
        if (csv.has_velocity) {
          velocities_given = true;
          if (block.velocity.kind != VelocitySpec::Kind::zero)
            throw InputError(block.velocity_where, block_key(b) + ".velocity",
                             "'" + block.csv_path + "' gives every sphere its velocity (vx,vy,vz); give one or the other");
        }
        if (csv.has_angular_velocity) {
          spins_given = true;
          if (block.angular_velocity_given)
            throw InputError(block.angular_velocity_where, block_key(b) + ".angular_velocity",
                             "'" + block.csv_path +
                                 "' gives every sphere its angular velocity (wx,wy,wz); give one or the other");
        }
        if (block.fixed && (csv.has_velocity || csv.has_angular_velocity))
          throw InputError(block.fixed_where, block_key(b) + ".fixed",
                           "fixed spheres never move, but '" + block.csv_path + "' gives them velocities");
        break;
      }
    }
    if (block.order_cells) number_by_cells(out, first);  // before the random velocities: drawn in this order
    if (!velocities_given) assign_velocities(block.velocity, out, first);
    if (!spins_given)
      for (std::size_t i = first; i < out.size(); ++i) out.angular_velocity[i] = block.angular_velocity;
    if (block.fixed)
      for (std::size_t i = first; i < out.size(); ++i) out.fixed[i] = 1;
    out.block_end.push_back(out.size());
  }
  return out;
}

// Refuses a block that would take the scene past what memory can hold,
// before it is generated (never an out-of-memory kill half way through).
void check_sphere_budget(double total, const SourceLocation& where, const std::string& key) {
  const double available = available_memory(), fraction = limits().memory;
  const double memory = available * fraction;
  if (memory > 0 && total * kBytesPerSphere > memory)
    throw InputError(where, key,
                     "would make " + significant(total, 12) + " spheres, about " +
                         bytes_text(total * kBytesPerSphere) + " to run; the spheres may take " +
                         (fraction == 1 ? bytes_text(memory) + ", what this machine has available"
                                        : bytes_text(memory) + " (" + significant(fraction, 3) + " of the " +
                                              bytes_text(available) + " this machine has available)") +
                         " (--limit memory=F lets them take F times what is available)");
}

}  // namespace marbles::scene
