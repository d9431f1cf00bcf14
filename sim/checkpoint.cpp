#include "sim/checkpoint.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstddef>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>

#include "core/error.hpp"
#include "core/files.hpp"
#include "core/hash.hpp"
#include "render/atomic_file.hpp"
#include "sim/simulation.hpp"
#include "sim/world.hpp"

namespace marbles {

namespace {

namespace fs = std::filesystem;

constexpr char kMagic[8] = {'M', 'A', 'R', 'B', 'L', 'C', 'K', '\n'};
// Format 2 adds the cache's kept colours; format 1 (without them) still
// loads, its contacts then coloured afresh in the first substep. Format 3
// adds the step's numbering (solver.renumber), written only where the
// step has one (else format 2, which earlier builds read too); formats 1
// and 2 load with none. Format 4 adds the steps kept unswept to the running
// totals, written only where there are some (RunTotals::unswept).
constexpr std::uint32_t kFormat = 4;
// The running totals' bytes before format 4.
constexpr std::size_t kTotalsBefore4 = offsetof(RunTotals, unswept);
static_assert(sizeof(RunTotals) == kTotalsBefore4 + sizeof(double), "format 4 adds one total, at the end");
constexpr char kVersion[16] = "marbles 0.1";

class Writer {
 public:
  template <class T>
  void put(const T& v) {
    raw(&v, sizeof v);
  }
  template <class T>
  void put(const std::vector<T>& v) {
    put<std::uint64_t>(v.size());
    raw(v.data(), v.size() * sizeof(T));
  }
  // The walls field by field into zeroed records: their padding (after
  // `kind`, at the end) written as 0, not as whatever memory held, so that
  // two runs alike write the same bytes. The reader takes the records whole.
  void put(const std::vector<narrowphase::WallShape>& walls) {
    using narrowphase::WallShape;
    static_assert(sizeof(WallShape) - (offsetof(WallShape, material) + sizeof(std::uint32_t)) < alignof(WallShape),
                  "`material` is the record's last field: a field after it is written here too");
    put<std::uint64_t>(walls.size());
    for (const WallShape& w : walls) {
      char record[sizeof(WallShape)] = {};
      const auto at = [&record](std::size_t offset, const auto& v) { std::memcpy(record + offset, &v, sizeof v); };
      at(offsetof(WallShape, kind), w.kind);
      at(offsetof(WallShape, point), w.point);
      at(offsetof(WallShape, direction), w.direction);
      at(offsetof(WallShape, radius), w.radius);
      at(offsetof(WallShape, length), w.length);
      at(offsetof(WallShape, velocity), w.velocity);
      at(offsetof(WallShape, angular_velocity), w.angular_velocity);
      at(offsetof(WallShape, material), w.material);
      raw(record, sizeof record);
    }
  }
  template <class T>
  void field(const T& v) {
    put(v);
  }
  void raw(const void* p, std::size_t n) { m_bytes.append(static_cast<const char*>(p), n); }
  std::string finish() {
    put<std::uint64_t>(fnv1a(m_bytes.data(), m_bytes.size()));  // checksum of all before it
    return std::move(m_bytes);
  }

 private:
  std::string m_bytes;
};

class Reader {
 public:
  Reader(std::string bytes, std::string path) : m_bytes(std::move(bytes)), m_path(std::move(path)) {}
  template <class T>
  T get() {
    T v;
    raw(&v, sizeof v);
    return v;
  }
  template <class T>
  void get(std::vector<T>& v) {
    const auto n = get<std::uint64_t>();
    if (n > (m_bytes.size() - m_at) / std::max<std::size_t>(1, sizeof(T))) fail("is truncated or damaged");
    v.resize(n);
    raw(v.data(), n * sizeof(T));
  }
  template <class T>
  void field(T& v) {
    if constexpr (requires { v.data(); v.resize(0); }) get(v);
    else v = get<T>();
  }
  void raw(void* p, std::size_t n) {
    if (m_at + n > m_bytes.size()) fail("is truncated or damaged");
    std::memcpy(p, m_bytes.data() + m_at, n);
    m_at += n;
  }
  [[noreturn]] void fail(const std::string& what) const {
    throw InputError(SourceLocation{m_path, 0, 0}, "--restart", "the checkpoint " + what);
  }
  const std::string& bytes() const { return m_bytes; }
  std::size_t at() const { return m_at; }

 private:
  std::string m_bytes;
  std::string m_path;
  std::size_t m_at = 0;
};

// The checkpoint's body after the scene fingerprint, in file order: one list
// for writing (Writer) and reading (Reader).
template <class IO, class C>
void body(IO& io, C& c, std::uint32_t format = kFormat) {
  io.field(c.steps);
  io.field(c.world.position);
  io.field(c.world.velocity);
  io.field(c.world.angular_velocity);
  io.field(c.world.radius);
  io.field(c.world.inv_mass);
  io.field(c.world.inv_inertia);
  io.field(c.world.material);
  io.field(c.state.cache.key);
  io.field(c.state.cache.normal_impulse);
  io.field(c.state.cache.tangent_impulse);
  io.field(c.state.cache.rolling_impulse);
  if (format >= 2) io.field(c.state.cache.colour);
  io.field(c.state.walls);
  if (format >= 4) io.field(c.totals);
  else io.raw(&c.totals, kTotalsBefore4);
  io.field(c.probe);
  if (format >= 3) io.field(c.ids);
}

}  // namespace

std::uint64_t scene_fingerprint(const std::string& scene_path, const std::vector<std::string>& overrides) {
  std::ifstream in(scene_path, std::ios::binary);
  const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  return text_fingerprint(text, overrides);
}

std::uint64_t text_fingerprint(const std::string& text, const std::vector<std::string>& overrides) {
  std::uint64_t h = fnv1a(text.data(), text.size());
  for (const std::string& o : overrides) h = fnv1a(o.data(), o.size() + 1, h);  // with its terminator
  return h;
}

std::string checkpoint_precision(const std::string& path) {
  if (not_a_plain_file(path)) return "float";  // read_checkpoint says what it is
  std::ifstream in(path, std::ios::binary);
  char head[sizeof kMagic + 4 + sizeof kVersion + 4] = {};
  if (!in.read(head, sizeof head) || std::memcmp(head, kMagic, sizeof kMagic) != 0) return "float";
  std::uint32_t real_bytes = 0;
  std::memcpy(&real_bytes, head + sizeof kMagic + 4 + sizeof kVersion, 4);
  return real_bytes == 8 ? "double" : "float";
}

std::string checkpoint_path(const std::string& out_dir, std::uint64_t steps) {
  char name[40];
  std::snprintf(name, sizeof name, "step_%06llu.mck", static_cast<unsigned long long>(steps));
  return (fs::path(out_dir) / "checkpoints" / name).string();
}

std::string checkpoint_bytes(const Checkpoint& c) {
  Writer w;
  w.raw(kMagic, sizeof kMagic);
  const std::uint32_t format = c.totals.unswept > 0 ? 4 : c.ids.empty() ? 2 : 3;
  w.put(format);
  w.raw(kVersion, sizeof kVersion);
  w.put<std::uint32_t>(sizeof(real));
  w.put<std::uint32_t>(sizeof(narrowphase::WallShape));
  w.put(c.scene_hash);
  body(w, c, format);
  return w.finish();
}

void write_checkpoint(const std::string& path, const Checkpoint& c) {
  make_parent_folder(path);
  render::write_file_atomic(path, checkpoint_bytes(c));
}

void make_parent_folder(const std::string& path) {
  // A bare file name ("state.mck") has no parent to make.
  const fs::path parent = fs::path(path).parent_path();
  if (parent.empty()) return;
  std::error_code ec;
  fs::create_directories(parent, ec);
  if (ec) throw RuntimeFailure("cannot create " + parent.string() + ": " + ec.message());
}

Checkpoint read_checkpoint(const std::string& path, std::uint64_t scene_hash, std::optional<std::uint64_t> text_hash) {
  if (const char* what = not_a_plain_file(path))
    throw InputError(SourceLocation{path, 0, 0}, "--restart", std::string("is ") + what + ", not a checkpoint");
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(SourceLocation{path, 0, 0}, "--restart", "cannot open the checkpoint");
  Reader r(std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>()), path);
  const std::string& bytes = r.bytes();
  if (bytes.size() < sizeof kMagic + 8 || std::memcmp(bytes.data(), kMagic, sizeof kMagic) != 0)
    r.fail("is not a marbles checkpoint");
  std::uint64_t sum = 0;
  std::memcpy(&sum, bytes.data() + bytes.size() - 8, 8);
  if (sum != fnv1a(bytes.data(), bytes.size() - 8)) r.fail("is truncated or damaged (checksum)");
  char magic[sizeof kMagic];
  r.raw(magic, sizeof magic);
  const auto format = r.get<std::uint32_t>();
  if (format < 1 || format > kFormat) r.fail("has another format version");
  char version[sizeof kVersion];
  r.raw(version, sizeof version);
  if (std::memcmp(version, kVersion, sizeof kVersion) != 0)
    r.fail("was written by " + std::string(version, strnlen(version, sizeof version)) + ", this is " + kVersion);
  const auto real_bytes = r.get<std::uint32_t>();
  if (real_bytes != 4 && real_bytes != 8) r.fail("is damaged (its precision is neither float nor double)");
  if (real_bytes != sizeof(real))
    r.fail(std::string("is in ") + (real_bytes == 8 ? "double" : "float") + " precision, this run in " + kRealName +
           " (use --precision)");
  if (r.get<std::uint32_t>() != sizeof(narrowphase::WallShape)) r.fail("comes from an incompatible build");
  Checkpoint c;
  c.scene_hash = r.get<std::uint64_t>();
  if (c.scene_hash != scene_hash && c.scene_hash != text_hash)
    r.fail("belongs to another scene (or other --set overrides): a value of the scene file or of its overrides differs");
  body(r, c, format);
  if (r.at() + 8 != bytes.size()) r.fail("is damaged (bytes past its fields)");
  if (c.state.cache.colour.size() != c.state.cache.key.size()) c.state.cache.colour.clear();
  const std::size_t n = c.world.position.size();
  for (std::size_t size : {c.world.velocity.size(), c.world.angular_velocity.size(), c.world.radius.size(),
                           c.world.inv_mass.size(), c.world.inv_inertia.size(), c.world.material.size()})
    if (size != n) r.fail("is damaged (array lengths differ)");
  for (std::size_t size : {c.state.cache.normal_impulse.size(), c.state.cache.tangent_impulse.size(),
                           c.state.cache.rolling_impulse.size()})
    if (size != c.state.cache.key.size()) r.fail("is damaged (the cache's array lengths differ)");
  // Values a run could not have written: a sphere's size, mass or state not
  // finite, a radius not above zero, an inverse mass or inertia below zero
  // (zero: a fixed sphere), impulses or totals not finite.
  const auto finite = [](double x) { return x - x == 0; };
  if (const std::size_t i = c.world.first_non_finite(); i < n)
    r.fail("is damaged (sphere " + std::to_string(i) + "'s state is not finite)");
  for (std::size_t i = 0; i < n; ++i)
    if (!(c.world.radius[i] > 0) || !finite(c.world.radius[i]) ||
        !masses_as_made(c.world.radius[i], c.world.inv_mass[i], c.world.inv_inertia[i]))
      r.fail("is damaged (sphere " + std::to_string(i) + "'s radius, mass or inertia)");
  for (std::size_t k = 0; k < c.state.cache.key.size(); ++k)
    if (!finite(c.state.cache.normal_impulse[k]) || !is_finite(c.state.cache.tangent_impulse[k]) ||
        !is_finite(c.state.cache.rolling_impulse[k]))
      r.fail("is damaged (a cache entry's impulse is not finite)");
  // A state whose squares overflow (a speed or a distance past the
  // precision's range once squared): its kinetic energy would be inf.
  if (const std::size_t i = c.world.first_out_of_range(); i < n)
    r.fail("is damaged (sphere " + std::to_string(i) + "'s position, velocity or spin is past " + kRealName +
           "'s range once squared)");
  // Totals: finite, not negative, printable as percentages; rollbacks whole.
  for (double t : {c.totals.candidate_sum, c.totals.contact_sum, c.totals.deepest, c.totals.energy_start,
                   c.totals.overlap_end, c.totals.rollbacks, c.totals.unswept})
    if (!finite(t) || t < 0 || !(t < 1e300)) r.fail("is damaged (its running totals)");
  if (c.totals.rollbacks != std::floor(c.totals.rollbacks) || c.totals.unswept != std::floor(c.totals.unswept))
    r.fail("is damaged (its running totals)");
  for (double p : c.probe)
    if (!finite(p)) r.fail("is damaged (its reference's progress)");
  // Steps a run could have made: at most 2^53 (its time, steps x dt, exact in
  // double; no count wraps past it), far past the substep limit's 10^10.
  if (c.steps > (std::uint64_t{1} << 53)) r.fail("is damaged (its step count, " + std::to_string(c.steps) + ")");
  // Counts its steps could have made: a step kept unswept at most once, and
  // redone at most once a retry and once more for its first try (the
  // summary's counts are whole numbers: 2^64 and more read as 0).
  const double steps = static_cast<double>(c.steps);
  if (c.totals.unswept > steps || c.totals.rollbacks > steps * (Simulation::kWatchdogRetries + 1))
    r.fail("is damaged (its running totals: more rollbacks or steps kept unswept than its " + std::to_string(c.steps) +
           " steps make)");
  // Pairs of its spheres (a < b) or a sphere and a wall, in ascending key
  // order without repeats: the restore's runs by sphere and the kept
  // colours' split between the threads (or_kept_colours_by_a) rest on it.
  for (std::size_t k = 0; k < c.state.cache.key.size(); ++k) {
    const std::uint64_t key = c.state.cache.key[k];
    const auto a = static_cast<std::uint32_t>(key >> 32), b = static_cast<std::uint32_t>(key);
    if (a >= n || (!narrowphase::is_wall(b) && (b >= n || b <= a))) r.fail("is damaged (a cache entry names no pair)");
    if (k > 0 && key <= c.state.cache.key[k - 1]) r.fail("is damaged (the cache's entries are not in key order)");
  }
  if (!c.ids.empty()) {  // a permutation of the spheres
    std::vector<std::uint8_t> seen(n, 0);
    if (c.ids.size() != n) r.fail("is damaged (the numbering has another length)");
    for (std::uint32_t id : c.ids) {
      if (id >= n || seen[id]) r.fail("is damaged (the numbering is not a permutation)");
      seen[id] = 1;
    }
  }
  return c;
}

void check_checkpoint_fits(const Checkpoint& c, const std::string& path, const std::string& key, const World& scene,
                           const std::vector<std::uint32_t>& ids, std::size_t materials,
                           const std::vector<narrowphase::WallShape>& walls) {
  const std::size_t spheres = scene.size();
  if (c.world.size() != spheres)
    throw InputError(SourceLocation{path, 0, 0}, key,
                     "the checkpoint holds " + std::to_string(c.world.size()) + " spheres, the scene makes " +
                         std::to_string(spheres));
  // Each sphere's material and whether it is fixed, by its place in the
  // scene's numbering (the step's own numbering maps to it through ids).
  std::vector<std::uint32_t> material(spheres);
  std::vector<std::uint8_t> fixed(spheres);
  for (std::size_t j = 0; j < spheres; ++j) {
    const std::uint32_t id = ids.empty() ? static_cast<std::uint32_t>(j) : ids[j];
    material[id] = scene.material[j];
    fixed[id] = scene.inv_mass[j] == 0;
  }
  for (std::size_t i = 0; i < c.world.material.size(); ++i) {
    if (c.world.material[i] >= materials)
      throw InputError(SourceLocation{path, 0, 0}, key,
                       "the checkpoint is damaged (sphere " + std::to_string(i) + " names material " +
                           std::to_string(c.world.material[i]) + ", the scene has " + std::to_string(materials) + ")");
    const std::uint32_t id = c.ids.empty() ? static_cast<std::uint32_t>(i) : c.ids[i];
    if (c.world.material[i] != material[id] || (c.world.inv_mass[i] == 0) != (fixed[id] != 0))
      throw InputError(SourceLocation{path, 0, 0}, key,
                       "the checkpoint is damaged (sphere " + std::to_string(id) + " is not the scene's: " +
                           (c.world.material[i] != material[id] ? std::string("another material")
                                                                : fixed[id] ? "it moves where the scene's is fixed"
                                                                            : "fixed where the scene's moves") +
                           ")");
  }
  // The walls: the scene's, of which a run moves only the point (advance_walls).
  if (c.state.walls.size() != walls.size())
    throw InputError(SourceLocation{path, 0, 0}, key,
                     "the checkpoint holds " + std::to_string(c.state.walls.size()) + " wall shape(s), the scene makes " +
                         std::to_string(walls.size()));
  for (std::size_t k = 0; k < walls.size(); ++k) {
    const narrowphase::WallShape& w = c.state.walls[k];
    const narrowphase::WallShape& scene_wall = walls[k];
    const bool same = w.kind == scene_wall.kind && w.direction == scene_wall.direction &&
                      w.radius == scene_wall.radius && w.length == scene_wall.length &&
                      w.velocity == scene_wall.velocity && w.angular_velocity == scene_wall.angular_velocity &&
                      w.material == scene_wall.material;
    const bool moves = !(scene_wall.velocity == Vec3{});
    if (!same || !is_finite(w.point) || (!moves && !(w.point == scene_wall.point)))
      throw InputError(SourceLocation{path, 0, 0}, key,
                       "the checkpoint is damaged (wall shape " + std::to_string(k) +
                           " is not the scene's: only a moving wall's point may differ, and it must be finite)");
  }
}

void prune_checkpoints(const std::string& out_dir, int keep) {
  const fs::path dir = fs::path(out_dir) / "checkpoints";
  std::vector<fs::path> files;
  std::error_code ec;
  for (fs::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec))
    if (it->path().extension() == ".mck" && it->path().filename().string().rfind("step_", 0) == 0)
      files.push_back(it->path());
  auto step_of = [](const fs::path& p) { return std::strtoull(p.filename().string().c_str() + 5, nullptr, 10); };
  std::sort(files.begin(), files.end(), [&](const fs::path& a, const fs::path& b) { return step_of(a) < step_of(b); });
  for (std::size_t k = 0; k + static_cast<std::size_t>(keep) < files.size(); ++k) fs::remove(files[k], ec);
}

}  // namespace marbles
