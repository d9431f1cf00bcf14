// tests/render/basics_test.cpp — the parts of render/ that need no optional
// library: colour maps, font, overlay text, walls file, atomic files, default
// camera, occlusion culling, .pvd parsing.
#include <gtest/gtest.h>

#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <functional>
#include <iterator>
#include <random>
#include <set>

#include "core/error.hpp"
#include "render/atomic_file.hpp"
#include "render/bitmap_font.hpp"
#include "render/camera.hpp"
#include "render/color_map.hpp"
#include "render/frame_output.hpp"
#include "render/occlusion.hpp"
#include "render/overlay.hpp"
#include "render/vtk_output.hpp"

namespace fs = std::filesystem;
using namespace marbles;
using namespace marbles::render;

namespace {

fs::path fresh_dir(const std::string& name) {
  const fs::path dir = fs::path(MARBLES_BINARY_DIR) / "test-output" / "render" / name;
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

std::size_t count_temp_files(const fs::path& dir) {
  std::size_t n = 0;
  for (const auto& e : fs::recursive_directory_iterator(dir))
    if (e.path().filename().string().find(".tmp") != std::string::npos) ++n;
  return n;
}

}  // namespace

TEST(ColorMap, EndsAreThePublishedColours) {
  const Rgb lo = sample_color_map(ColorMapName::viridis, 0), hi = sample_color_map(ColorMapName::viridis, 1);
  EXPECT_NEAR(lo.r, 0.267004, 1e-6);
  EXPECT_NEAR(lo.b, 0.329415, 1e-6);
  EXPECT_NEAR(hi.r, 0.993248, 1e-6);
  EXPECT_NEAR(hi.g, 0.906157, 1e-6);
  // Clamped outside [0, 1]; NaN goes to the low end.
  EXPECT_EQ(sample_color_map(ColorMapName::viridis, -3).r, lo.r);
  EXPECT_EQ(sample_color_map(ColorMapName::viridis, 7).g, hi.g);
  EXPECT_EQ(sample_color_map(ColorMapName::viridis, std::nan("")).r, lo.r);
  const Rgb t0 = sample_color_map(ColorMapName::turbo, 0), t1 = sample_color_map(ColorMapName::turbo, 1);
  EXPECT_NEAR(t0.r, 0.18995, 1e-6);
  EXPECT_NEAR(t1.r, 0.47960, 1e-6);
  // Viridis brightens monotonically (its luminance rises along the map).
  double last = -1;
  for (int i = 0; i <= 100; ++i) {
    const Rgb c = sample_color_map(ColorMapName::viridis, i / 100.0);
    const double y = 0.2126 * c.r + 0.7152 * c.g + 0.0722 * c.b;
    EXPECT_GT(y, last - 1e-6);
    last = y;
  }
}

TEST(ColorMap, NamesParse) {
  EXPECT_EQ(parse_color_by("speed"), ColorBy::speed);
  EXPECT_EQ(parse_color_by("material"), ColorBy::material);
  EXPECT_FALSE(parse_color_by("colour").has_value());
  EXPECT_EQ(parse_color_map("turbo"), ColorMapName::turbo);
  for (ColorBy c : {ColorBy::speed, ColorBy::id, ColorBy::radius, ColorBy::material})
    EXPECT_EQ(parse_color_by(color_by_name(c)), c);
  std::set<std::tuple<float, float, float>> distinct;
  for (std::uint32_t i = 0; i < 8; ++i) distinct.insert({category_color(i).r, category_color(i).g, category_color(i).b});
  EXPECT_EQ(distinct.size(), 8u);
}

TEST(BitmapFont, GlyphsAndWidths) {
  // '1' has its stem in the middle column; space is empty; unknown -> '?'.
  for (int y = 0; y < 6; ++y) EXPECT_TRUE(glyph_pixel('1', 2, y)) << y;
  for (int y = 0; y < kGlyphHeight; ++y)
    for (int x = 0; x < kGlyphWidth; ++x) {
      EXPECT_FALSE(glyph_pixel(' ', x, y));
      EXPECT_EQ(glyph_pixel('\x7f', x, y), glyph_pixel('?', x, y));
    }
  EXPECT_FALSE(glyph_pixel('A', -1, 0));
  EXPECT_EQ(text_width("", 3), 0);
  EXPECT_EQ(text_width("ab", 1), 11);
  EXPECT_EQ(text_width("ab", 2), 22);
  // Every printable character other than space sets some pixel.
  for (char c = 33; c < 127; ++c) {
    int on = 0;
    for (int y = 0; y < kGlyphHeight; ++y)
      for (int x = 0; x < kGlyphWidth; ++x) on += glyph_pixel(c, x, y);
    EXPECT_GT(on, 0) << c;
  }
}

TEST(BitmapFont, DrawsIntoTheImageAndClips) {
  Image image(40, 12);
  const std::uint8_t white[3] = {255, 255, 255};
  draw_text(image, 1, 1, "1", 1, white);
  EXPECT_EQ(image.pixel(3, 1)[0], 255);  // stem of '1' at column 2 of the glyph
  EXPECT_EQ(image.pixel(0, 0)[0], 0);
  draw_text(image, 35, 8, "WWW", 2, white);  // mostly outside: must not crash
}

TEST(Overlay, ValueFormatting) {
  EXPECT_EQ(format_value(0), "0");
  EXPECT_EQ(format_value(1.5), "1.5");
  EXPECT_EQ(format_value(29.0213), "29.02");
  EXPECT_EQ(format_value(2e-5), "2.000e-05");
  EXPECT_EQ(format_value(-3e6), "-3.000e+06");
  EXPECT_EQ(overlay_scale(720), 2);
  EXPECT_EQ(overlay_scale(100), 1);
}

// The walls series: every kind of wall comes back from its .vtp exactly, the
// surfaces are there (a plane is one square, a box six faces), and a moving
// wall's later frame has moved.
TEST(WallsVtp, RoundTripsEveryKindOfWall) {
  Walls w;
  PlaneWall p;
  p.point = Vec3(0.1f, -2, 3);
  p.normal = Vec3(0, 0, 1);
  p.velocity = Vec3(1, 0, 0);
  p.material = 2;
  p.index = 3;  // the scene's order, not the kinds': plane last
  w.planes.push_back(p);
  BoxWall b;
  b.lo = Vec3(-1, -1, 0);
  b.hi = Vec3(1, 1, 2.5f);
  b.index = 0;
  w.boxes.push_back(b);
  CylinderWall c;
  c.base = Vec3(0, 0, 0.25f);
  c.axis = Vec3(0, 1, 0);
  c.radius = 0.75f;
  c.length = 2;
  c.inside = false;
  c.angular_velocity = 3.5f;
  c.material = 1;
  c.index = 1;
  w.cylinders.push_back(c);
  SphereWall s;
  s.centre = Vec3(0.5f, 0.5f, 1);
  s.radius = 0.2f;
  s.index = 2;
  w.spheres.push_back(s);

  const fs::path dir = fresh_dir("walls_vtp");
  WallSeriesWriter writer(dir, Vec3(-1, -1, 0), Vec3(1, 1, 2));
  const fs::path first = writer.write(w, 0, 0);
  EXPECT_EQ(count_temp_files(dir / "walls"), 0u);
  const Walls r = read_walls_vtp(first);
  const VtpArrays surfaces = read_vtp_arrays(first);
  const auto& wall_of_cell = surfaces.arrays.at("CellData/wall").values;
  // Each wall's cells carry its place in the scene.
  EXPECT_EQ(std::count(wall_of_cell.begin(), wall_of_cell.end(), 3.0), 1);  // the plane: one square
  EXPECT_EQ(std::count(wall_of_cell.begin(), wall_of_cell.end(), 0.0), 6);  // the box: six faces
  EXPECT_GT(std::count(wall_of_cell.begin(), wall_of_cell.end(), 1.0), 8);  // the cylinder: a band of quads
  EXPECT_GT(std::count(wall_of_cell.begin(), wall_of_cell.end(), 2.0), 8);  // the sphere
  ASSERT_EQ(r.planes.size(), 1u);
  ASSERT_EQ(r.boxes.size(), 1u);
  ASSERT_EQ(r.cylinders.size(), 1u);
  ASSERT_EQ(r.spheres.size(), 1u);
  EXPECT_EQ(r.planes[0].point, p.point);
  EXPECT_EQ(r.planes[0].normal, p.normal);
  EXPECT_EQ(r.planes[0].velocity, p.velocity);
  EXPECT_EQ(r.planes[0].material, 2u);
  EXPECT_EQ(r.boxes[0].lo, b.lo);
  EXPECT_EQ(r.boxes[0].hi, b.hi);
  EXPECT_EQ(r.cylinders[0].base, c.base);
  EXPECT_EQ(r.cylinders[0].axis, c.axis);
  EXPECT_EQ(r.cylinders[0].radius, c.radius);
  EXPECT_EQ(r.cylinders[0].length, c.length);
  EXPECT_FALSE(r.cylinders[0].inside);
  EXPECT_EQ(r.cylinders[0].angular_velocity, c.angular_velocity);
  EXPECT_EQ(r.spheres[0].centre, s.centre);
  EXPECT_EQ(r.spheres[0].radius, s.radius);
}

TEST(AtomicFile, WritesAndLeavesNoTemporaries) {
  const fs::path dir = fresh_dir("atomic");
  write_file_atomic(dir / "a.txt", "hello");
  write_file_atomic(dir / "a.txt", "world");  // replaces
  std::ifstream in(dir / "a.txt");
  std::string text;
  in >> text;
  EXPECT_EQ(text, "world");
  EXPECT_EQ(count_temp_files(dir), 0u);
  EXPECT_NE(temp_path_beside(dir / "a.txt"), temp_path_beside(dir / "a.txt"));
  EXPECT_EQ(temp_path_beside(dir / "a.txt").parent_path(), dir);
  EXPECT_THROW(write_file_atomic(dir / "no-such-folder" / "b.txt", "x"), RuntimeFailure);
}

// A folder on the way that is gone (a series folder moved while a run writes
// into it) is named: the outermost one missing.
TEST(AtomicFile, AFolderGoneIsNamed) {
  const fs::path dir = fresh_dir("atomic_gone");
  fs::create_directories(dir / "out" / "frames");
  write_file_atomic(dir / "out" / "frames" / "a.vtp", "x");
  fs::rename(dir / "out", dir / "moved");
  for (const fs::path& path : {dir / "out" / "frames" / "b.vtp", dir / "out" / "b.vtp"})
    try {
      write_file_atomic(path, "x");
      ADD_FAILURE() << "no error for " << path;
    } catch (const RuntimeFailure& e) {
      const std::string said = e.what();
      EXPECT_NE(said.find("No such file or directory (the folder " + (dir / "out").string() +
                          " is gone: moved or removed while this wrote into it)"),
                std::string::npos)
          << said;
    }
  EXPECT_TRUE(fs::exists(dir / "moved" / "frames" / "a.vtp"));
  // A run's folder as it is often given, relative: the folder is named, not "".
  const fs::path was = fs::current_path();
  fs::current_path(dir);
  fs::create_directories("rel/frames");
  fs::rename("rel", "rel-moved");
  try {
    write_file_atomic("rel/frames/c.vtp", "x");
    ADD_FAILURE() << "no error for a relative path";
  } catch (const RuntimeFailure& e) {
    EXPECT_NE(std::string(e.what()).find("(the folder " + (dir / "rel").string() + " is gone"), std::string::npos)
        << e.what();
  }
  fs::current_path(was);
  // Another reason is said as it is, with no folder named.
  fs::create_directories(dir / "locked");
  fs::permissions(dir / "locked", fs::perms::owner_read | fs::perms::owner_exec);
  try {
    write_file_atomic(dir / "locked" / "c.txt", "x");
    if (::geteuid() != 0) ADD_FAILURE() << "no error in a folder without write permission";
  } catch (const RuntimeFailure& e) {
    EXPECT_EQ(std::string(e.what()).find("is gone"), std::string::npos) << e.what();
  }
  fs::permissions(dir / "locked", fs::perms::owner_all);
}

// A pipe or a folder under the name is not replaced by the file (run as root,
// a checkpoint written to /dev/full had replaced the device node); a link is
// replaced itself and its target left alone.
TEST(AtomicFile, ReplacesNoDevicePipeOrFolder) {
  const fs::path dir = fresh_dir("atomic_special");
  ASSERT_EQ(mkfifo((dir / "pipe").c_str(), 0600), 0);
  fs::create_directory(dir / "folder");
  for (const char* name : {"pipe", "folder"}) {
    try {
      write_file_atomic(dir / name, "x");
      ADD_FAILURE() << name << " was replaced";
    } catch (const RuntimeFailure& e) {
      EXPECT_NE(std::string(e.what()).find("nothing was replaced"), std::string::npos) << e.what();
    }
  }
  EXPECT_EQ(fs::status(dir / "pipe").type(), fs::file_type::fifo);
  EXPECT_TRUE(fs::is_directory(dir / "folder"));
  EXPECT_EQ(count_temp_files(dir), 0u);
  write_file_atomic(dir / "target.txt", "kept");
  fs::create_symlink(dir / "target.txt", dir / "link.txt");
  write_file_atomic(dir / "link.txt", "new");
  EXPECT_FALSE(fs::is_symlink(dir / "link.txt"));
  std::ifstream in(dir / "target.txt");
  std::string text;
  in >> text;
  EXPECT_EQ(text, "kept");
}

// Files written together: where any one cannot be (its temporary's name too
// long, its final name a folder, left incomplete), none is, and the files
// there before keep their contents; otherwise every one is written.
TEST(AtomicFile, FilesWrittenTogetherOrNotAtAll) {
  const fs::path dir = fresh_dir("atomic_together");
  const auto text_of = [](const fs::path& p) {
    std::ifstream in(p);
    return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
  };
  write_files_atomic({{dir / "a", "old a"}, {dir / "b", "old b"}});
  ASSERT_EQ(text_of(dir / "a"), "old a");
  ASSERT_EQ(text_of(dir / "b"), "old b");
  // A name whose temporary (".NAME.tmp-PID-K") passes 255 bytes where the name itself fits.
  const fs::path long_name = dir / std::string(250, 'y');
  fs::create_directory(dir / "folder");
  for (const fs::path& second : {long_name, dir / "folder"}) {
    EXPECT_THROW(write_files_atomic({{dir / "a", "new a"}, {second, "new"}}), RuntimeFailure) << second;
    EXPECT_EQ(text_of(dir / "a"), "old a") << second;
    EXPECT_FALSE(fs::exists(long_name));
    EXPECT_EQ(count_temp_files(dir), 0u);
  }
  // The second left incomplete (the full-disk hook truncates files named with "b"): the first is not renamed either.
  setenv("MARBLES_FAULT_TRUNCATE", "b", 1);
  EXPECT_THROW(write_files_atomic({{dir / "a", "new a"}, {dir / "b", "new b"}}), RuntimeFailure);
  unsetenv("MARBLES_FAULT_TRUNCATE");
  EXPECT_EQ(text_of(dir / "a"), "old a");
  EXPECT_EQ(text_of(dir / "b"), "old b");
  EXPECT_EQ(count_temp_files(dir), 0u);
  write_files_atomic({{dir / "a", "new a"}, {dir / "b", "new b"}});
  EXPECT_EQ(text_of(dir / "a"), "new a");
  EXPECT_EQ(text_of(dir / "b"), "new b");
}

TEST(Camera, DefaultViewFramesTheBounds) {
  Bounds b;
  b.add(-1, -2, 0);
  b.add(3, 2, 1.5);
  const int w = 1280, h = 720;
  const Camera cam = default_camera(b, w, h, 40);
  // Project the eight corners with the camera: all inside the frame.
  const double fx = cam.look_at.x - cam.position.x, fy = cam.look_at.y - cam.position.y,
               fz = cam.look_at.z - cam.position.z;
  const double fl = std::sqrt(fx * fx + fy * fy + fz * fz);
  const double f[3] = {fx / fl, fy / fl, fz / fl};
  double r[3] = {f[1] * 1 - f[2] * 0, f[2] * 0 - f[0] * 1, 0};  // forward x up(0,0,1)
  const double rl = std::hypot(r[0], r[1]);
  r[0] /= rl, r[1] /= rl;
  const double u[3] = {r[1] * f[2] - r[2] * f[1], r[2] * f[0] - r[0] * f[2], r[0] * f[1] - r[1] * f[0]};
  const double t = std::tan(20.0 * M_PI / 180);
  for (int i = 0; i < 8; ++i) {
    const double p[3] = {i & 1 ? b.hi[0] : b.lo[0], i & 2 ? b.hi[1] : b.lo[1], i & 4 ? b.hi[2] : b.lo[2]};
    const double d[3] = {p[0] - cam.position.x, p[1] - cam.position.y, p[2] - cam.position.z};
    const double z = d[0] * f[0] + d[1] * f[1] + d[2] * f[2];
    ASSERT_GT(z, 0);
    const double x = (d[0] * r[0] + d[1] * r[1] + d[2] * r[2]) / (z * t * w / h);
    const double y = (d[0] * u[0] + d[1] * u[1] + d[2] * u[2]) / (z * t);
    EXPECT_LE(std::abs(x), 1.0) << i;
    EXPECT_LE(std::abs(y), 1.0) << i;
  }
  // Looking down on it (elevation above the horizon).
  EXPECT_GT(cam.position.z, cam.look_at.z);
}

TEST(Camera, SceneBoundsIncludeSpheresBoxesAndTheFloorBelow) {
  Snapshot s;
  s.position = {Vec3(0, 0, 5), Vec3(1, 0, 6)};
  s.radius = {0.5f, 0.5f};
  Walls w;
  PlaneWall floor;
  floor.point = Vec3(0, 0, 0);
  w.planes.push_back(floor);
  const Bounds b = scene_bounds(s, w);
  EXPECT_NEAR(b.lo[0], -0.5, 1e-6);
  EXPECT_NEAR(b.hi[0], 1.5, 1e-6);
  EXPECT_NEAR(b.hi[2], 6.5, 1e-6);
  EXPECT_NEAR(b.lo[2], 0.0, 1e-6);  // the floor under the spheres
  EXPECT_FALSE(scene_bounds(Snapshot{}, Walls{}).empty());
}

TEST(Occlusion, KeepsFrontAndDropsWhatIsBehindOrOffScreen) {
  std::vector<ProjectedSphere> s(4);
  s[0] = {50, 50, 10, 1, 20, 21};   // big, near
  s[1] = {50, 50, 20, 1, 5, 6};     // small, right behind it: hidden
  s[2] = {90, 50, 20, 1, 5, 6};     // beside it: visible
  s[3] = {500, 50, 5, 1, 5, 6};     // off screen
  const auto kept = visible_spheres(s, 100, 100, 2, 0.1f);
  EXPECT_EQ(kept, (std::vector<std::uint32_t>{0, 2}));
  // A sphere reaching the near plane is always kept.
  std::vector<ProjectedSphere> t = {s[0], {50, 50, 0.5f, 1, 0, 1e30f}};
  EXPECT_EQ(visible_spheres(t, 100, 100, 2, 0.1f).size(), 2u);
}

TEST(Occlusion, NeverDropsASphereThatOwnsAPixel) {
  // Random discs: brute-force which disc wins each pixel centre (nearest
  // front, using the inner disk where the surface is at most `depth` and the
  // outer disk otherwise) and check every winner is kept.
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> pos(0, 64), dep(5, 50), rad(2, 9);
  std::vector<ProjectedSphere> s(300);
  for (auto& q : s) {
    q.x = pos(rng), q.y = pos(rng), q.depth = dep(rng), q.radius = 0.5f;
    q.inner = rad(rng), q.outer = q.inner * 1.05f + 1;
  }
  const auto kept = visible_spheres(s, 64, 64, 2, 0.1f);
  const std::set<std::uint32_t> keep(kept.begin(), kept.end());
  for (int y = 0; y < 64; ++y)
    for (int x = 0; x < 64; ++x) {
      // The drawn depth of a disc at a pixel lies in [depth - radius, depth]
      // inside `inner`; the winner with the nearest possible front must be kept.
      int best = -1;
      float best_front = 1e30f;
      for (std::size_t i = 0; i < s.size(); ++i) {
        const float dx = x + 0.5f - s[i].x, dy = y + 0.5f - s[i].y;
        if (dx * dx + dy * dy > s[i].inner * s[i].inner) continue;
        if (s[i].depth - s[i].radius < best_front) best_front = s[i].depth - s[i].radius, best = int(i);
      }
      if (best >= 0) {
        EXPECT_TRUE(keep.count(std::uint32_t(best))) << x << "," << y;
      }
    }
  EXPECT_LT(kept.size(), s.size());  // and it does drop something
}

TEST(PointFields, ParseAndReject) {
  EXPECT_EQ(parse_point_fields({"radius", "velocity", "radius", "speed"}),
            (std::vector<PointField>{PointField::radius, PointField::velocity, PointField::speed}));
  EXPECT_THROW(parse_point_fields({"radius", "colour"}), InputError);
  for (PointField f : {PointField::radius, PointField::velocity, PointField::angular_velocity, PointField::id,
                       PointField::material, PointField::speed})
    EXPECT_EQ(parse_point_field(point_field_name(f)), f);
}

// DIR/series.pvd holding `datasets` (its DataSet lines), read back.
std::vector<SeriesEntry> pvd_of(const fs::path& dir, const std::string& datasets) {
  write_file_atomic(dir / "series.pvd", "<?xml version=\"1.0\"?>\n<VTKFile type=\"Collection\">\n<Collection>\n" +
                                            datasets + "</Collection>\n</VTKFile>\n");
  return read_pvd(dir / "series.pvd");
}

TEST(Pvd, ParsesEntriesRelativeToItsFolder) {
  const fs::path dir = fresh_dir("pvd");
  const auto entries = pvd_of(dir,
                              "  <DataSet timestep=\"0\" part=\"0\" file=\"frames/frame_000000.vtp\"/>\n"
                              "  <DataSet file='frames/frame_000001.vtp' timestep='0.25'/>\n");
  ASSERT_EQ(entries.size(), 2u);
  EXPECT_EQ(entries[0].time, 0);
  EXPECT_EQ(entries[1].time, 0.25);
  EXPECT_EQ(entries[1].path, dir / "frames" / "frame_000001.vtp");
  EXPECT_THROW(read_pvd(dir / "missing.pvd"), InputError);
}

// Attributes and tags of any length are read by a scan, not a regular
// expression (libstdc++'s recursed once a character and overflowed the
// stack on an attribute of 30 kB: SIGSEGV in render and in a resume): a
// DataSet behind a 400 kB attribute, and one behind 100 000 tags left open,
// read as written.
TEST(Pvd, LongAttributesAndOpenTagsAreReadWithoutRecursion) {
  const fs::path dir = fresh_dir("pvd_long");
  const std::string long_value(400'000, 'a');
  std::string open_tags;
  for (int k = 0; k < 100'000; ++k) open_tags += "<DataSet ";
  const auto entries = pvd_of(dir, "  <DataSet x=\"" + long_value + "\" timestep=\"0.5\" file=\"f0.vtp\"/>\n  " +
                                       open_tags + "timestep=\"2\" file=\"f1.vtp\"/>\n");
  ASSERT_EQ(entries.size(), 2u);
  EXPECT_EQ(entries[0].time, 0.5);
  EXPECT_EQ(entries[0].path, dir / "f0.vtp");
  EXPECT_EQ(entries[1].time, 2);
  EXPECT_EQ(entries[1].path, dir / "f1.vtp");
  // The same in a frame's tags: an attribute of 400 kB on its root.
  VtkSeriesWriter writer(dir, parse_point_fields({"radius"}));
  Snapshot one;
  one.position = {Vec3(1, 2, 3)};
  one.radius = {real(0.25)};
  const fs::path frame = writer.write(one);
  std::string text = [&] {
    std::ifstream in(frame, std::ios::binary);
    return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
  }();
  text.insert(text.find("<PolyData") + 9, " x=\"" + long_value + "\"");
  write_file_atomic(frame, text);
  const Snapshot back = read_vtp(frame);
  ASSERT_EQ(back.size(), 1u);
  EXPECT_EQ(back.position[0], Vec3(1, 2, 3));
  EXPECT_EQ(back.radius[0], real(0.25));
}

// A series' time that is not a finite number (nan, inf, words, nothing, a
// number with more after it) is refused naming the .pvd; a DataSet with no
// timestep takes its place in the series, as before.
TEST(Pvd, TimesThatAreNotFiniteNumbersAreRefused) {
  const fs::path dir = fresh_dir("pvd_times");
  for (const std::string bad : {"nan", "inf", "-inf", "abc", "", "1.5x", "1e999"}) {
    try {
      pvd_of(dir, "  <DataSet timestep=\"" + bad + "\" file=\"f.vtp\"/>\n");
      ADD_FAILURE() << "timestep \"" << bad << "\" read";
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find("series.pvd: a DataSet's timestep \"" + bad + "\" is not a finite number"),
                std::string::npos)
          << e.what();
    }
  }
  const auto entries = pvd_of(dir, "  <DataSet file=\"f.vtp\"/>\n  <DataSet timestep=\" 3\" file=\"g.vtp\"/>\n");
  ASSERT_EQ(entries.size(), 2u);
  EXPECT_EQ(entries[0].time, 0);
  EXPECT_EQ(entries[1].time, 3);
}

// A series lists its frames in time order, as a run writes them (the movie
// and its frame rate follow the list): a timestep not after the one before
// (earlier, or the same) is refused naming both; a DataSet with no timestep
// between two is passed over in the comparison.
TEST(Pvd, TimesOutOfOrderAreRefused) {
  const fs::path dir = fresh_dir("pvd_order");
  for (const auto& [times, at] : std::vector<std::pair<std::vector<std::string>, std::string>>{
           {{"0", "0.5", "0.25"}, "frame 2's timestep 0.25 is not after the one before it, 0.5"},
           {{"0", "0", "1"}, "frame 1's timestep 0 is not after the one before it, 0"},
           {{"1e300", "2"}, "frame 1's timestep 2 is not after the one before it, 1e+300"}}) {
    std::string datasets;
    for (std::size_t k = 0; k < times.size(); ++k)
      datasets += "  <DataSet timestep=\"" + times[k] + "\" file=\"f" + std::to_string(k) + ".vtp\"/>\n";
    try {
      pvd_of(dir, datasets);
      ADD_FAILURE() << datasets << " read";
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find("series.pvd: " + at), std::string::npos) << e.what();
    }
  }
  const auto entries = pvd_of(dir, "  <DataSet timestep=\"1\" file=\"f.vtp\"/>\n  <DataSet file=\"g.vtp\"/>\n"
                                   "  <DataSet timestep=\"2\" file=\"h.vtp\"/>\n");
  ASSERT_EQ(entries.size(), 3u);
  EXPECT_EQ(entries[2].time, 2);
}

// A frame holding what no run writes (a position, speed or time not finite,
// a radius not above zero, an id or material that is not a whole number in
// range) is refused naming the frame, the array and the point, not drawn
// with the sphere left out or its colour at the scale's end.
TEST(Frames, ValuesNoRunWritesAreRefused) {
  const fs::path dir = fresh_dir("frames_values");
  VtkSeriesWriter writer(dir, parse_point_fields({"radius", "velocity", "id", "material"}));
  const auto snapshot = [] {
    Snapshot s;
    for (int i = 0; i < 4; ++i) {
      s.position.push_back(Vec3(real(i), 0, 1));
      s.velocity.push_back(Vec3(0, real(i), 0));
      s.radius.push_back(real(0.1));
      s.id.push_back(std::uint32_t(i));
      s.material.push_back(0);
    }
    return s;
  };
  const real nan = std::numeric_limits<real>::quiet_NaN(), inf = std::numeric_limits<real>::infinity();
  EXPECT_NO_THROW(read_vtp(writer.write(snapshot()))) << "premise: a frame as a run writes it";
  const std::vector<std::pair<std::string, std::function<void(Snapshot&)>>> damages{
      {"Points/Points: point 2", [&](Snapshot& s) { s.position[2].y = nan; }},
      {"Points/Points: point 1", [&](Snapshot& s) { s.position[1].x = -inf; }},
      {"PointData/velocity: point 3", [&](Snapshot& s) { s.velocity[3].z = inf; }},
      {"PointData/radius: point 0", [&](Snapshot& s) { s.radius[0] = 0; }},
      {"PointData/radius: point 1", [&](Snapshot& s) { s.radius[1] = -s.radius[1]; }},
      {"PointData/radius: point 2", [&](Snapshot& s) { s.radius[2] = nan; }},
      {"FieldData/TimeValue", [&](Snapshot& s) { s.time = std::numeric_limits<double>::infinity(); }},
  };
  for (const auto& [what, damage] : damages) {
    Snapshot bad = snapshot();
    damage(bad);
    const fs::path frame = writer.write(bad);
    try {
      read_vtp(frame);
      ADD_FAILURE() << what << " read";
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find(frame.filename().string() + ": " + what), std::string::npos) << e.what();
    }
  }
  // An array of another shape than the frame's points is refused by its
  // name, where it was read as absent (a velocity of one component dropped).
  const fs::path frame = writer.write(snapshot());
  std::string text;
  {
    std::ifstream in(frame, std::ios::binary);
    text.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
  }
  const std::string three = "Name=\"velocity\" NumberOfComponents=\"3\"";
  ASSERT_NE(text.find(three), std::string::npos);
  text.replace(text.find(three), three.size(), "Name=\"velocity\" NumberOfComponents=\"1\"");
  std::ofstream(frame, std::ios::binary | std::ios::trunc) << text;
  try {
    read_vtp(frame);
    ADD_FAILURE() << "a velocity of one component read";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("PointData/velocity: 12 values of 1 component(s), not the frame's 4 points of 3"),
              std::string::npos)
        << e.what();
  }
}

// A series cut anywhere before its closing tags (a copy that stopped, a
// full disk) is refused, not read as the frames before the cut.
TEST(Pvd, ASeriesCutShortIsRefused) {
  const fs::path dir = fresh_dir("pvd_cut");
  pvd_of(dir, "  <DataSet timestep=\"0\" file=\"frames/frame_000000.vtp\"/>\n"
              "  <DataSet timestep=\"1\" file=\"frames/frame_000001.vtp\"/>\n");
  const std::string whole = [&] {
    std::ifstream in(dir / "series.pvd", std::ios::binary);
    return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
  }();
  const std::size_t closed = whole.rfind("</VTKFile>") + std::strlen("</VTKFile>");
  for (std::size_t cut = 0; cut < closed; ++cut) {
    write_file_atomic(dir / "series.pvd", whole.substr(0, cut));
    try {
      read_pvd(dir / "series.pvd");
      ADD_FAILURE() << "read when cut at byte " << cut;
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find("series.pvd: is cut short or damaged"), std::string::npos)
          << cut << ": " << e.what();
    }
  }
  write_file_atomic(dir / "series.pvd", whole.substr(0, closed));
  EXPECT_EQ(read_pvd(dir / "series.pvd").size(), 2u);
}

// A run's series of many files rewrites its .pvd once a sixteenth of it is new
// (or a second has passed), not at every file, so that the writes grow with
// the files and not with their square; meanwhile it lists the first files in
// order, every one there, and lags by at most a sixteenth of them; once the
// series is gone (the end of a run, a stop or a failure) it lists them all.
TEST(Pvd, ASeriesRelistsItsFilesInStepsAndWhollyAtItsEnd) {
  const fs::path dir = fresh_dir("pvd_relisting");
  const std::size_t n = 1000;
  std::size_t writes = 0;
  const auto start = std::chrono::steady_clock::now();
  {
    Series series(dir, "frames", "frame", "series.pvd");
    series.list_in_steps();
    ino_t inode = 0;
    for (std::size_t k = 1; k <= n; ++k) {
      series.add(0.001 * static_cast<double>(k), "frame " + std::to_string(k) + "\n");
      struct stat st {};
      ASSERT_EQ(::stat((dir / "series.pvd").c_str(), &st), 0);
      const bool written = st.st_ino != inode;  // each write renames a new file over it
      writes += written ? 1 : 0;
      inode = st.st_ino;
      if (written || k <= 20 || k % 97 == 0) {
        const auto entries = read_pvd(dir / "series.pvd");
        ASSERT_LE(entries.size(), k);
        ASSERT_GE(16 * entries.size() + 16, 15 * k) << k;  // lags by a sixteenth at most
        if (k <= 16) {
          ASSERT_EQ(entries.size(), k);  // the first ones at once
        }
        for (std::size_t e = 0; e < entries.size(); ++e) {
          ASSERT_EQ(entries[e].path, dir / "frames" / ("frame_" + std::string(6 - std::to_string(e).size(), '0') +
                                                       std::to_string(e) + ".vtp"));
          ASSERT_TRUE(fs::exists(entries[e].path));
        }
      }
    }
  }
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  // Growth by 16/15 a write past the first 16: 16 + ln(1000 / 16) / ln(16 / 15), 80; one more a second.
  EXPECT_LE(static_cast<double>(writes), 82.0 + seconds) << seconds << " s";
  EXPECT_EQ(read_pvd(dir / "series.pvd").size(), n);
  // Without list_in_steps (a Python simulation's frames, written as its
  // caller goes) every file is listed as it is written.
  const fs::path each = fresh_dir("pvd_each");
  Series series(each, "frames", "frame", "series.pvd");
  for (std::size_t k = 1; k <= 40; ++k) {
    series.add(0.001 * static_cast<double>(k), "frame\n");
    ASSERT_EQ(read_pvd(each / "series.pvd").size(), k);
  }
}

// A device or a pipe where a run's file should be (a .pvd edited or linked
// to one): refused by what it is, naming the path, before any byte is read
// (a device would be read without end, a pipe would wait for a writer).
TEST(Pvd, DevicesAndPipesAreRefusedByWhatTheyAre) {
  const fs::path dir = fresh_dir("pvd_devices");
  const fs::path pipe = dir / "frame_000001.vtp";
  ASSERT_EQ(mkfifo(pipe.c_str(), 0600), 0);
  const auto entries = pvd_of(dir,
                              "  <DataSet timestep=\"0\" file=\"/dev/zero\"/>\n"
                              "  <DataSet timestep=\"1\" file=\"frame_000001.vtp\"/>\n");
  ASSERT_EQ(entries.size(), 2u);
  const auto refusal = [](const fs::path& path, const auto& read) {
    try {
      read(path);
      ADD_FAILURE() << path << " was read";
    } catch (const InputError& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  const auto frame = [](const fs::path& p) { read_vtp(p); };
  const auto walls = [](const fs::path& p) { read_walls_vtp(p); };
  const auto pvd = [](const fs::path& p) { read_pvd(p); };
  EXPECT_NE(refusal(entries[0].path, frame).find("/dev/zero: is a device"), std::string::npos);
  EXPECT_NE(refusal(entries[0].path, walls).find("is a device"), std::string::npos);
  EXPECT_NE(refusal(entries[1].path, frame).find("frame_000001.vtp: is a pipe"), std::string::npos);
  EXPECT_NE(refusal(pipe, pvd).find("is a pipe"), std::string::npos);
  EXPECT_NE(refusal(dir, pvd).find("is a folder"), std::string::npos);
  fs::create_symlink("/dev/zero", dir / "walls.pvd");  // a link is followed
  EXPECT_NE(refusal(dir / "walls.pvd", pvd).find("is a device"), std::string::npos);
}

TEST(Camera, ParsesTheCommandLineForm) {
  const Camera c = parse_camera("1,2.5,-3:0,0,0.5");
  EXPECT_EQ(c.position, Vec3(1, 2.5f, -3));
  EXPECT_EQ(c.look_at, Vec3(0, 0, 0.5f));
  EXPECT_EQ(c.up, Vec3(0, 0, 1));
  for (const char* bad : {"1,2,3", "1,2:0,0,0", "1,2,3:0,0,0,4", "a,b,c:0,0,0", "1,1,1:1,1,1", ""})
    EXPECT_THROW(parse_camera(bad), InputError) << bad;
  // Beyond the precision (1e39 is inf in float), or squared beyond it: an
  // empty image before, now refused with the argument's name.
  for (const char* huge : {"1e39,0,0:0,0,0", "0,0,0:0,3e19,0", "2e19,0,0:-2e19,0,0"}) {
    if (sizeof(real) == 8) continue;  // all of them fit in double
    try {
      parse_camera(huge, "--camera");
      ADD_FAILURE() << huge << " was taken";
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find("--camera: too large for float precision"), std::string::npos) << e.what();
    }
  }
  // Straight down the vertical: the renderer takes another up there.
  EXPECT_NO_THROW(parse_camera("0,0,10:0,0,0", "--camera"));
}

TEST(MaterialNames, RoundTripAndLegendLabels) {
  const fs::path dir = fresh_dir("material-names");
  EXPECT_TRUE(read_material_names(dir).empty());  // no file: no names
  const std::vector<std::string> names{"steel", "glass", "wood"};
  write_material_names(dir, names);
  EXPECT_EQ(read_material_names(dir), names);
  EXPECT_EQ(count_temp_files(dir), 0u);

  // The names are drawn in place of the ids: the two legends differ, and a
  // legend with names missing is the legend with ids.
  auto legend_image = [](std::vector<std::string> labels) {
    Image image(400, 200);
    ColorLegend legend;
    legend.by = ColorBy::material;
    legend.categories = {0, 1, 2};
    legend.category_names = std::move(labels);
    draw_color_legend(image, legend);
    return image.rgb;
  };
  EXPECT_NE(legend_image(names), legend_image({}));
  EXPECT_EQ(legend_image({"", "", ""}), legend_image({}));
}
