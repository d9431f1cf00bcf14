// tests/render/renderer_test.cpp — pictures: where a sphere lands, what colour
// it gets, that culling changes nothing, the PNG and MP4 files, and the
// in-run and after-run outputs.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <random>
#include <fstream>
#include <sstream>

#include "core/error.hpp"
#include "render/frame_output.hpp"
#include "render/image.hpp"
#include "render/movie.hpp"
#include "render/renderer.hpp"
#include "render/vtk_output.hpp"

namespace fs = std::filesystem;
using namespace marbles;
using namespace marbles::render;

namespace {

constexpr int kW = 200, kH = 150;

fs::path fresh_dir(const std::string& name) {
  const fs::path dir = fs::path(MARBLES_BINARY_DIR) / "test-output" / "render" / name;
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

// Camera on -y looking at the origin: world +x is image right, +z image up.
Camera front_camera() {
  Camera c;
  c.position = Vec3(0, -10, 0);
  c.look_at = Vec3(0, 0, 0);
  c.up = Vec3(0, 0, 1);
  c.fov = 40;
  return c;
}

// Flat colours, no annotations: pixels are exactly the colour map.
RenderOptions flat_options() {
  RenderOptions o;
  o.width = kW, o.height = kH;
  o.camera = front_camera();
  o.lighting = false;
  o.overlay = false;
  return o;
}

// Colour by radius with turbo over [0, r]: a sphere of radius r is turbo's
// dark-red end.
RenderOptions red_options(double r) {
  RenderOptions o = flat_options();
  o.color_by = ColorBy::radius;
  o.color_map = ColorMapName::turbo;
  o.color_min = 0;
  o.color_max = r;
  return o;
}

Snapshot one_sphere(Vec3 at, real radius) {
  Snapshot s;
  s.position = {at};
  s.radius = {radius};
  s.velocity = {Vec3()};
  s.id = {0};
  s.material = {0};
  return s;
}

bool reddish(const std::uint8_t* p) { return p[0] > 60 && p[0] > 2 * p[1] + 10 && p[0] > 2 * p[2] + 10; }

struct Centroid {
  double x = 0, y = 0;
  std::size_t count = 0;
};

Centroid red_centroid(const Image& im) {
  Centroid c;
  for (int y = 0; y < im.height; ++y)
    for (int x = 0; x < im.width; ++x)
      if (reddish(im.pixel(x, y))) c.x += x + 0.5, c.y += y + 0.5, ++c.count;
  if (c.count) c.x /= double(c.count), c.y /= double(c.count);
  return c;
}

// Pixels per unit length at distance 1 for the front camera (f in pixels).
double focal_px() { return 0.5 * kH / std::tan(20.0 * M_PI / 180); }

std::string run_command(const std::string& command) {
  std::string out;
  if (std::FILE* p = popen(command.c_str(), "r")) {
    char buf[256];
    while (std::fgets(buf, sizeof buf, p)) out += buf;
    pclose(p);
  }
  return out;
}

bool on_path(const char* tool) { return run_command(std::string("command -v ") + tool + " 2>/dev/null").size() > 0; }

}  // namespace

TEST(Renderer, RedSphereInTheMiddleAndBackgroundInTheCorners) {
  Renderer r(red_options(0.5));
  const Image image = r.render(one_sphere(Vec3(0, 0, 0), 0.5f), Walls{});
  ASSERT_EQ(image.width, kW);
  ASSERT_EQ(image.height, kH);
  ASSERT_EQ(image.rgb.size(), std::size_t(kW) * kH * 3);
  const std::uint8_t* centre = image.pixel(kW / 2, kH / 2);
  EXPECT_TRUE(reddish(centre)) << int(centre[0]) << "," << int(centre[1]) << "," << int(centre[2]);
  // Exactly turbo's last colour, unlit.
  EXPECT_NEAR(centre[0], 122, 1);
  EXPECT_NEAR(centre[1], 4, 1);
  EXPECT_NEAR(centre[2], 3, 1);

  const Image empty = r.render(Snapshot{}, Walls{});
  for (auto [x, y] : {std::pair{0, 0}, {kW - 1, 0}, {0, kH - 1}, {kW - 1, kH - 1}}) {
    EXPECT_FALSE(reddish(image.pixel(x, y)));
    for (int c = 0; c < 3; ++c) EXPECT_EQ(image.pixel(x, y)[c], empty.pixel(x, y)[c]) << x << "," << y;
  }
  // The sphere's image has the projected size: radius f * r / sqrt(d^2 - r^2).
  const Centroid c = red_centroid(image);
  const double radius_px = focal_px() * 0.5 / std::sqrt(100 - 0.25);
  EXPECT_NEAR(double(c.count), M_PI * radius_px * radius_px, 0.06 * M_PI * radius_px * radius_px);
  EXPECT_NEAR(c.x, kW / 2.0, 0.5);
  EXPECT_NEAR(c.y, kH / 2.0, 0.5);
}

TEST(Renderer, MovingTheSphereMovesItsImageByTheProjection) {
  Renderer r(red_options(0.5));
  const Centroid c0 = red_centroid(r.render(one_sphere(Vec3(0, 0, 0), 0.5f), Walls{}));
  const Centroid cx = red_centroid(r.render(one_sphere(Vec3(1, 0, 0), 0.5f), Walls{}));
  const Centroid cz = red_centroid(r.render(one_sphere(Vec3(0, 0, 1), 0.5f), Walls{}));
  const Centroid cy = red_centroid(r.render(one_sphere(Vec3(0, 5, 0), 0.5f), Walls{}));
  const double shift = focal_px() * 1.0 / 10.0;  // 1 m across at 10 m
  EXPECT_NEAR(cx.x - c0.x, shift, 0.5);
  EXPECT_NEAR(cx.y - c0.y, 0, 0.5);
  EXPECT_NEAR(cz.y - c0.y, -shift, 0.5);  // up in the world is up in the image (rows run down)
  EXPECT_NEAR(cz.x - c0.x, 0, 0.5);
  // Farther away (15 m instead of 10 m): same place, smaller by 10/15 in area ratio squared.
  EXPECT_NEAR(cy.x, c0.x, 0.5);
  EXPECT_NEAR(double(cy.count) / double(c0.count), (10.0 / 15.0) * (10.0 / 15.0), 0.08);
}

TEST(Renderer, ImageSizeIsWhatWasAsked) {
  for (auto [w, h] : {std::pair{64, 48}, {333, 101}}) {
    RenderOptions o = red_options(0.5);
    o.width = w, o.height = h, o.overlay = true;
    Renderer r(o);
    const Image image = r.render(one_sphere(Vec3(0, 0, 0), 0.5f), Walls{});
    EXPECT_EQ(image.width, w);
    EXPECT_EQ(image.height, h);
  }
  RenderOptions tiny = flat_options();
  tiny.width = 8;
  EXPECT_THROW(Renderer{tiny}, RuntimeFailure);
}

TEST(Renderer, SpeedColoursSpanTheColourMap) {
  Snapshot s;
  s.position = {Vec3(-1.5f, 0, 0), Vec3(1.5f, 0, 0), Vec3(0, 0, 1.5f)};
  s.radius = {0.5f, 0.5f, 0.5f};
  s.velocity = {Vec3(1, 0, 0), Vec3(0, 3, 0), Vec3(0, 0, -2)};
  RenderOptions o = flat_options();
  o.color_by = ColorBy::speed;
  Renderer flat(o);
  const Image image = flat.render(s, Walls{});
  const int dx = int(std::lround(focal_px() * 1.5 / 10));
  const std::uint8_t* slow = image.pixel(kW / 2 - dx, kH / 2);
  const std::uint8_t* fast = image.pixel(kW / 2 + dx, kH / 2);
  const std::uint8_t* mid = image.pixel(kW / 2, kH / 2 - dx);
  const int viridis_lo[3] = {68, 1, 84}, viridis_hi[3] = {253, 231, 37};
  for (int c = 0; c < 3; ++c) {
    EXPECT_NEAR(slow[c], viridis_lo[c], 1) << c;
    EXPECT_NEAR(fast[c], viridis_hi[c], 1) << c;
  }
  const Rgb half = sample_color_map(ColorMapName::viridis, 0.5);  // speed 2 of [1, 3]
  EXPECT_NEAR(mid[1], half.g * 255, 1.5);

  // Lit and shadowed, the ends stay recognisable: purple-blue vs yellow.
  o.lighting = true;
  Renderer lit(o);
  const Image shaded = lit.render(s, Walls{});
  const std::uint8_t* a = shaded.pixel(kW / 2 - dx, kH / 2);
  const std::uint8_t* b = shaded.pixel(kW / 2 + dx, kH / 2);
  EXPECT_GT(a[2], a[1]);
  EXPECT_GT(b[0], b[2] + 60);
  EXPECT_GT(b[1], b[2] + 60);
}

TEST(Renderer, CullingHiddenSpheresChangesNoPixel) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> u(0, 1);
  Snapshot s;
  for (int i = 0; i < 4000; ++i) {  // a jittered 20 x 20 x 10 pile
    const int x = i % 20, y = (i / 20) % 20, z = i / 400;
    s.position.emplace_back(x * 0.1f + 0.01f * u(rng), y * 0.1f + 0.01f * u(rng), 0.05f + z * 0.1f + 0.01f * u(rng));
    s.radius.push_back(0.045f + 0.01f * u(rng));
    s.velocity.emplace_back(u(rng), u(rng), u(rng));
  }
  Walls walls;
  PlaneWall floor;
  walls.planes.push_back(floor);
  BoxWall box;
  box.lo = Vec3(-0.1f, -0.1f, 0), box.hi = Vec3(2, 2, 1.2f);
  walls.boxes.push_back(box);
  RenderOptions o;
  o.width = 320, o.height = 200;
  Renderer with(o);
  o.cull_hidden = false;
  Renderer without(o);
  const Image a = with.render(s, walls), b = without.render(s, walls);
  EXPECT_LT(with.last_frame_stats().spheres_drawn, s.size() * 3 / 4);
  EXPECT_EQ(without.last_frame_stats().spheres_drawn, s.size());
  ASSERT_EQ(a.rgb.size(), b.rgb.size());
  std::size_t differ = 0;
  for (std::size_t i = 0; i < a.rgb.size(); ++i) differ += a.rgb[i] != b.rgb[i];
  EXPECT_EQ(differ, 0u);
}

TEST(Renderer, EveryKindOfWallRenders) {
  Snapshot s;
  for (int i = 0; i < 50; ++i) {
    s.position.emplace_back(0.3f * std::cos(i * 0.7f), 0.3f * std::sin(i * 0.7f), 0.1f + 0.02f * i);
    s.radius.push_back(0.08f);
    s.material.push_back(std::uint32_t(i % 3));
  }
  Walls walls;
  PlaneWall floor;
  walls.planes.push_back(floor);
  CylinderWall drum;
  drum.base = Vec3(0, 0, 0), drum.axis = Vec3(0, 0, 1), drum.radius = 0.6f, drum.length = 1.4f;
  walls.cylinders.push_back(drum);
  CylinderWall post;
  post.base = Vec3(1.2f, 0.5f, 0), post.radius = 0.15f, post.length = 0.8f, post.inside = false;
  walls.cylinders.push_back(post);
  SphereWall ball;
  ball.centre = Vec3(-1.1f, 0.4f, 0.3f), ball.radius = 0.3f;
  walls.spheres.push_back(ball);
  BoxWall box;
  box.lo = Vec3(-1.6f, -1.0f, 0), box.hi = Vec3(1.6f, 1.0f, 1.5f);
  walls.boxes.push_back(box);
  RenderOptions o;
  o.width = 480, o.height = 270;
  o.color_by = ColorBy::material;
  Renderer r(o);
  const Image image = r.render(s, walls);
  EXPECT_EQ(r.last_frame_stats().spheres_drawn, s.size() + 1);  // the obstacle is drawn as a sphere too
#if defined(MARBLES_HAVE_PNG)
  const fs::path dir = fresh_dir("walls_picture");
  write_png(dir / "walls.png", image);
  const Image back = read_png(dir / "walls.png");
  EXPECT_EQ(back.width, 480);
  EXPECT_EQ(back.height, 270);
  EXPECT_EQ(back.rgb, image.rgb);
#endif
}

TEST(Renderer, WallsMoveWithTheirVelocity) {
  Walls w;
  BoxWall b;
  b.lo = Vec3(0, 0, 0), b.hi = Vec3(1, 1, 1), b.velocity = Vec3(2, 0, 0);
  w.boxes.push_back(b);
  const Walls later = walls_at(w, 0.5);
  EXPECT_EQ(later.boxes[0].lo, Vec3(1, 0, 0));
  EXPECT_EQ(later.boxes[0].hi, Vec3(2, 1, 1));
}

#if defined(MARBLES_HAVE_PNG)
TEST(Png, WritesAtomicallyAndReadsBack) {
  const fs::path dir = fresh_dir("png");
  Image im(37, 21);
  for (std::size_t i = 0; i < im.rgb.size(); ++i) im.rgb[i] = std::uint8_t(i * 7);
  write_png(dir / "x.png", im);
  const Image back = read_png(dir / "x.png");
  EXPECT_EQ(back.width, 37);
  EXPECT_EQ(back.height, 21);
  EXPECT_EQ(back.rgb, im.rgb);
  for (const auto& e : fs::directory_iterator(dir)) EXPECT_EQ(e.path().filename(), "x.png");
  EXPECT_THROW(read_png(dir / "missing.png"), RuntimeFailure);
}
#endif

TEST(Movie, Mp4HasTheFramesAndSize) {
  if (!on_path("ffmpeg") || !on_path("ffprobe")) GTEST_SKIP() << "ffmpeg/ffprobe not on PATH";
  const fs::path dir = fresh_dir("movie");
  for (auto [w, h] : {std::pair{96, 64}, {95, 63}}) {  // odd sizes are padded to even
    const fs::path path = dir / ("m" + std::to_string(w) + ".mp4");
    {
      MovieWriter movie(path, w, h, 24);
      Image frame(w, h);
      for (int f = 0; f < 12; ++f) {
        std::fill(frame.rgb.begin(), frame.rgb.end(), std::uint8_t(f * 20));
        movie.add(frame);
      }
      EXPECT_FALSE(fs::exists(path));  // not before finish()
      movie.finish();
    }
    ASSERT_TRUE(fs::exists(path));
    const std::string probe = run_command(
        "ffprobe -v error -select_streams v:0 -count_frames -show_entries "
        "stream=codec_name,width,height,pix_fmt,nb_read_frames -of default=noprint_wrappers=1 '" +
        path.string() + "'");
    EXPECT_NE(probe.find("codec_name=h264"), std::string::npos) << probe;
    EXPECT_NE(probe.find("pix_fmt=yuv420p"), std::string::npos) << probe;
    EXPECT_NE(probe.find("width=" + std::to_string(w + w % 2)), std::string::npos) << probe;
    EXPECT_NE(probe.find("height=" + std::to_string(h + h % 2)), std::string::npos) << probe;
    EXPECT_NE(probe.find("nb_read_frames=12"), std::string::npos) << probe;
  }
  for (const auto& e : fs::directory_iterator(dir))
    EXPECT_EQ(e.path().filename().string().find(".tmp"), std::string::npos) << e.path();
}

TEST(Movie, AbandonedMovieLeavesNothing) {
  if (!on_path("ffmpeg")) GTEST_SKIP() << "ffmpeg not on PATH";
  const fs::path dir = fresh_dir("movie_abandoned");
  {
    MovieWriter movie(dir / "m.mp4", 32, 32, 10);
    movie.add(Image(32, 32));
    EXPECT_THROW(movie.add(Image(16, 16)), RuntimeFailure);
  }
  EXPECT_TRUE(fs::is_empty(dir));
}

#if defined(MARBLES_HAVE_PNG)
TEST(FrameOutput, WritesNumberedImagesAndAMovie) {
  const fs::path dir = fresh_dir("frame_output");
  RenderOptions o;
  o.width = 160, o.height = 90;
  MovieOptions m;
  m.fps = 10;
  std::ostringstream log;
  Walls walls;
  walls.planes.push_back(PlaneWall{});
  {
    FrameOutput out(dir.string(), o, m, walls, log);
    for (int f = 0; f < 4; ++f) {
      Snapshot s = one_sphere(Vec3(0, 0, 1.0f - 0.2f * f), 0.2f);
      s.velocity = {Vec3(0, 0, -2.0f * f)};
      s.time = 0.1 * f;
      out.add(s);
    }
    out.finish();
    EXPECT_EQ(out.frames(), 4u);
    ASSERT_TRUE(out.camera().has_value());
  }
  for (int f = 0; f < 4; ++f) {
    char name[32];
    std::snprintf(name, sizeof name, "frame_%06d.png", f);
    const Image im = read_png(dir / "images" / name);
    EXPECT_EQ(im.width, 160);
    EXPECT_EQ(im.height, 90);
  }
  EXPECT_EQ(fs::exists(dir / "movie.mp4"), on_path("ffmpeg")) << log.str();
}
#endif

#if defined(MARBLES_HAVE_PNG)
TEST(RenderOutputDir, RerendersEveryFrameOfASeries) {
  const fs::path dir = fresh_dir("render_output_dir");
  {
    VtkSeriesWriter vtk(dir, {PointField::radius, PointField::velocity, PointField::id, PointField::material});
    for (int f = 0; f < 3; ++f) {
      Snapshot s;
      for (int i = 0; i < 30; ++i) {
        s.position.emplace_back(0.1f * (i % 5), 0.1f * (i / 5), 0.3f - 0.05f * f);
        s.radius.push_back(0.045f);
        s.velocity.emplace_back(0, 0, -real(f));
        s.id.push_back(std::uint32_t(i));
        s.material.push_back(0);
      }
      s.time = 0.05 * f;
      vtk.write(s);
    }
  }
  Walls walls;
  BoxWall box;
  box.lo = Vec3(-0.1f, -0.1f, 0), box.hi = Vec3(0.5f, 0.6f, 0.5f);
  walls.boxes.push_back(box);
  WallSeriesWriter wall_series(dir, Vec3(-0.1f, -0.1f, 0), Vec3(0.5f, 0.6f, 0.5f));
  for (int f = 0; f < 3; ++f) wall_series.write(walls, 0.05 * f, std::uint64_t(f));

  RenderOptions o;
  o.width = 128, o.height = 72;
  o.color_by = ColorBy::id;
  MovieOptions m;
  m.fps = 0;  // from the frame times: 20 fps
  std::ostringstream log;
  EXPECT_EQ(render_output_dir(dir.string(), o, m, false, log), 0);
  for (int f = 0; f < 3; ++f) {
    char name[32];
    std::snprintf(name, sizeof name, "frame_%06d.png", f);
    EXPECT_TRUE(fs::exists(dir / "images" / name)) << name;
  }
  EXPECT_NE(log.str().find("rendered 3 frames"), std::string::npos) << log.str();
  if (on_path("ffprobe")) {
    const std::string probe = run_command("ffprobe -v error -select_streams v:0 -count_frames -show_entries "
                                          "stream=nb_read_frames,r_frame_rate -of default=noprint_wrappers=1 '" +
                                          (dir / "movie.mp4").string() + "'");
    EXPECT_NE(probe.find("nb_read_frames=3"), std::string::npos) << probe;
    EXPECT_NE(probe.find("r_frame_rate=20/1"), std::string::npos) << probe;
  }
  for (const auto& e : fs::recursive_directory_iterator(dir))
    EXPECT_EQ(e.path().filename().string().find(".tmp"), std::string::npos) << e.path();

  // Rendered again with the series cut to its first two frames: the third
  // image, which no frame of the series names now, goes; a file of the
  // user's in images/ stays.
  {
    std::ifstream in(dir / "series.pvd");
    std::stringstream text;
    text << in.rdbuf();
    std::string pvd = text.str();
    const std::size_t last = pvd.find("frame_000002.vtp");
    ASSERT_NE(last, std::string::npos);
    pvd.erase(pvd.rfind('<', last), pvd.find('>', last) - pvd.rfind('<', last) + 1);
    std::ofstream(dir / "series.pvd") << pvd;
  }
  std::ofstream(dir / "images" / "notes.png") << "mine";
  std::ostringstream again;
  EXPECT_EQ(render_output_dir(dir.string(), o, m, false, again), 0);
  EXPECT_NE(again.str().find("rendered 2 frames"), std::string::npos) << again.str();
  EXPECT_TRUE(fs::exists(dir / "images" / "frame_000001.png"));
  EXPECT_FALSE(fs::exists(dir / "images" / "frame_000002.png")) << again.str();
  EXPECT_TRUE(fs::exists(dir / "images" / "notes.png"));

  EXPECT_THROW(render_output_dir((dir / "nothing-here").string(), o, m, false, log), InputError);
}
// Colouring by an array the frames do not carry draws one colour: said once,
// with the frame and the array, not left to be guessed from the image.
TEST(RenderOutputDir, ColouringByAMissingArrayIsAWarning) {
  if (!renderer_available()) GTEST_SKIP() << "skipped: built without OSMesa";
  const fs::path dir = fresh_dir("render_missing_colour");
  {
    VtkSeriesWriter vtk(dir, {PointField::radius});
    for (int f = 0; f < 2; ++f) {
      Snapshot s;
      s.position = {{0, 0, 0}, {0.2f, 0, 0}};
      s.radius = {0.05f, 0.05f};
      s.velocity = {{1, 0, 0}, {0, 1, 0}};  // not written: the series holds radius alone
      s.time = 0.1 * f;
      vtk.write(s);
    }
  }
  RenderOptions o;
  o.width = 32, o.height = 24;
  o.color_by = ColorBy::speed;
  MovieOptions m;
  m.enabled = false;
  std::ostringstream log;
  EXPECT_EQ(render_output_dir(dir.string(), o, m, false, log), 0);
  EXPECT_NE(log.str().find("warning: frame_000000.vtp carries no velocity array: colouring by speed draws every "
                           "sphere in one colour"),
            std::string::npos)
      << log.str();
  std::ostringstream by_radius;
  o.color_by = ColorBy::radius;
  EXPECT_EQ(render_output_dir(dir.string(), o, m, false, by_radius), 0);
  EXPECT_EQ(by_radius.str().find("warning"), std::string::npos) << by_radius.str();
}
#endif
