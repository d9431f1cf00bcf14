// tests/sim/checkpoint_test.cpp — checkpoint and restart through the real
// program: a run resumed from any checkpoint writes the same frames (byte for
// byte), series.pvd and summary.json (all but its timings) as the run that
// was never stopped; a checkpoint of another scene, precision or a damaged
// one is refused with exit 2. checkpoint_cuda_test.cpp does it on the GPU.
#include <gtest/gtest.h>

#include <fcntl.h>
#include <sys/file.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <map>
#include <sstream>
#include <set>
#include <string>
#include <vector>

#include "core/hash.hpp"
#include "tests/sim/checkpoint_cases.hpp"
#include "tests/sim/scene_cases.hpp"

namespace marbles {
namespace {

using namespace test;

std::string replace_all(std::string text, const std::string& from, const std::string& to) {
  for (std::size_t at = text.find(from); at != std::string::npos; at = text.find(from, at + to.size()))
    text.replace(at, from.size(), to);
  return text;
}

// Several cut points, both precisions: the resumed run equals the whole run.
TEST_F(Checkpoints, RestartEqualsTheUninterruptedRun) {
  const test::ScratchDir dir("ck_equal");
  const std::string scene = dir.write("s.yaml", kScene);
  for (const std::string precision : {"float", "double"}) {
    const std::string whole = dir.path() + "/whole_" + precision;
    const std::string common = " --quiet --backend cpu --precision " + precision;
    ASSERT_EQ(marbles("run " + scene + common + " --out " + whole), 0);
    for (const int cut : {50, 150, 250}) {
      // Stopped after `cut` steps, then resumed in the same folder from its last checkpoint.
      const std::string resumed = dir.path() + "/resumed_" + precision + std::to_string(cut);
      ASSERT_EQ(marbles("run " + scene + common + " --out " + resumed + " --duration " + std::to_string(cut * 1e-3)), 0);
      char name[32];
      std::snprintf(name, sizeof name, "/checkpoints/step_%06d.mck", cut);
      std::string err;
      ASSERT_EQ(marbles("run " + scene + " --quiet --backend cpu --out " + resumed + " --restart " + resumed + name, &err),
                0)
          << err;  // the precision comes from the checkpoint
      expect_same_output(whole, resumed);
    }
  }
}

// A resumed run that renders makes the images and the movie the
// uninterrupted run makes: one image every render.every steps, numbered as
// the run numbers them, the same bytes (the same camera, the colour range of
// the images so far), though it draws them from the frames, here twice as
// many as the images; the ones before the cut included. Where the images'
// steps are not all frames' it draws the steps both share, and says so.
TEST_F(Checkpoints, ResumedRunRendersItsImagesAndMovie) {
  const test::ScratchDir dir("ck_render");
  const std::string scene = dir.write("s.yaml", kScene);
  const std::string common = " --quiet --backend cpu --set output.vtk.every=10 --set output.render.every=20"
                             " --set output.render.width=64 --set output.render.height=48";
  ASSERT_EQ(marbles("run " + scene + common + " --out " + dir.path() + "/whole"), 0);
  const std::string resumed = dir.path() + "/resumed";
  ASSERT_EQ(marbles("run " + scene + common + " --out " + resumed + " --duration 0.1"), 0);
  fs::remove_all(resumed + "/images");
  fs::remove(resumed + "/movie.mp4");
  std::string err;
  ASSERT_EQ(marbles("run " + scene + common + " --out " + resumed + " --restart " + resumed +
                        "/checkpoints/step_000100.mck", &err),
            0)
      << err;
  auto names = [](const fs::path& folder) {
    std::vector<std::string> out;
    if (fs::exists(folder))
      for (const auto& entry : fs::directory_iterator(folder)) out.push_back(entry.path().filename().string());
    std::sort(out.begin(), out.end());
    return out;
  };
  const std::vector<std::string> images = names(dir.path() + "/whole/images");
  EXPECT_EQ(names(resumed + "/images"), images) << err;
  if (!images.empty()) {  // a build that renders
    EXPECT_EQ(images.size(), 16u);  // steps 0, 20, ..., 300
    for (const std::string& image : images)
      EXPECT_TRUE(slurp(resumed + "/images/" + image) == slurp(dir.path() + "/whole/images/" + image)) << image;
  }
  EXPECT_EQ(fs::exists(resumed + "/movie.mp4"), fs::exists(dir.path() + "/whole/movie.mp4")) << err;

  // Ctrl-C during the closing render ends the render at once (it ran on, and
  // a second one ended the run with no summary): exit 1 saying so, the run's
  // summary whole, the images left to `marbles render`.
  if (!images.empty()) {
    const std::string stopped = dir.path() + "/stopped";
    ASSERT_EQ(marbles("run " + scene + common + " --out " + stopped + " --duration 0.1"), 0);
    EXPECT_EQ(marbles("run " + scene + common + " --out " + stopped + " --restart " + stopped +
                          "/checkpoints/step_000100.mck",
                      &err, "MARBLES_FAULT_SIGNAL=INT@render"),
              1)
        << err;
    EXPECT_NE(err.find("stopped by SIGINT during the closing render: the run is whole (" + stopped +
                       "/summary.json) but its images are not; `marbles render " + stopped + "`"),
              std::string::npos)
        << err;
    EXPECT_NE(err.find("stopped at image 0 of 16"), std::string::npos) << err;
    EXPECT_EQ(physics_of(stopped + "/summary.json"), physics_of(dir.path() + "/whole/summary.json"));

    // A closing render that fails midway (a full disk: the fault hook cuts
    // image 10 short) is a warning, and the earlier run's images and movie
    // that the resume set aside stay there, whole, where the note says
    // (they were discarded with the run's end, past those it redrew).
    const std::string failed = dir.path() + "/failed";
    ASSERT_EQ(marbles("run " + scene + common + " --out " + failed), 0);
    EXPECT_EQ(marbles("run " + scene + common + " --out " + failed + " --restart " + failed +
                          "/checkpoints/step_000100.mck",
                      &err, "MARBLES_FAULT_TRUNCATE=frame_000010.png"),
              0)
        << err;
    EXPECT_NE(err.find("warning: no images: cannot write " + failed + "/images/frame_000010.png"), std::string::npos)
        << err;
    const std::size_t at = err.find("kept whole in " + failed + "/.earlier-run-");
    ASSERT_NE(at, std::string::npos) << err;
    const fs::path aside = err.substr(at + 14, err.find('\n', at) - at - 14);
    for (int k = 6; k < 16; ++k) {  // the images past the checkpoint's step 100 (one every 20 steps)
      char name[40];
      std::snprintf(name, sizeof name, "frame_%06d.png", k);
      EXPECT_TRUE(slurp(aside / "images" / name) == slurp(dir.path() + "/whole/images/" + name)) << name;
    }
    EXPECT_EQ(fs::exists(aside / "movie.mp4"), fs::exists(dir.path() + "/whole/movie.mp4"));
  }

  // Frames every 15 steps, images every 20: the resumed run's images at the
  // steps both share (0, 60, ...), with a warning.
  const std::string odd = " --quiet --backend cpu --set output.vtk.every=15 --set output.render.every=20"
                          " --set output.render.width=32 --set output.render.height=24";
  const std::string stepped = dir.path() + "/stepped";
  ASSERT_EQ(marbles("run " + scene + odd + " --out " + stepped + " --duration 0.1"), 0);
  ASSERT_EQ(marbles("run " + scene + odd + " --out " + stepped + " --restart " + stepped +
                        "/checkpoints/step_000100.mck", &err),
            0)
      << err;
  if (!images.empty()) {
    EXPECT_NE(err.find("its images come every 60 steps"), std::string::npos) << err;
    EXPECT_EQ(names(stepped + "/images").size(), 6u) << err;  // steps 0, 60, ..., 300
  }

  // A killed render leaves its movie, the movie's log and an image under
  // temporary names: the next `marbles render` removes them (a writer that
  // lives keeps its own).
  const std::string dead = std::to_string(999999999), alive = std::to_string(::getpid());
  const std::vector<std::string> stale = {resumed + "/.movie.mp4.tmp-" + dead + "-0",
                                          resumed + "/.movie.mp4.tmp-" + dead + "-0.log",
                                          resumed + "/images/.frame_000003.png.tmp-" + dead + "-3"};
  const std::string kept = resumed + "/images/.frame_000004.png.tmp-" + alive + "-4";
  for (const std::string& path : stale) std::ofstream(path) << "x";
  std::ofstream(kept) << "x";
  marbles("render " + resumed + " --no-movie --width 32 --height 24", &err);
  for (const std::string& path : stale) EXPECT_FALSE(fs::exists(path)) << path << "\n" << err;
  EXPECT_TRUE(fs::exists(kept));
}

// A run whose frames carry no radius (output.fields without it) resumes and
// ends whole, its images left out with a warning (they are drawn from the
// frames), and `marbles render` of its folder names the frame and the field.
TEST_F(Checkpoints, ResumedRunWithoutRadiiEndsWhole) {
  const test::ScratchDir dir("ck_no_radius");
  const std::string scene = dir.write("s.yaml", kScene);
  const std::string common = " --quiet --backend cpu --set 'output.fields=[speed, contacts]'"
                             " --set output.render.every=20 --set output.render.width=32 --set output.render.height=24";
  const std::string first = dir.path() + "/first", resumed = dir.path() + "/resumed";
  ASSERT_EQ(marbles("run " + scene + common + " --out " + first + " --duration 0.1"), 0);
  std::string err;
  ASSERT_EQ(marbles("run " + scene + common + " --out " + resumed + " --restart " + first +
                        "/checkpoints/step_000100.mck", &err),
            0)
      << err;
  EXPECT_TRUE(fs::exists(resumed + "/summary.json")) << err;
  EXPECT_TRUE(fs::exists(resumed + "/thermo.csv")) << err;
  EXPECT_NE(err.find("output.fields lacks radius: no images"), std::string::npos) << err;
  const int render = marbles("render " + first, &err);
  if (err.find("OSMesa") == std::string::npos) {  // a build that renders
    EXPECT_EQ(render, 2) << err;
    EXPECT_NE(err.find("frames/frame_000000.vtp: has no radius array"), std::string::npos) << err;
  }
}

// A frame of another run (another count of spheres) mixed into a series is
// refused by `marbles render`, naming it and the series' first frame, where
// it was drawn among the others without a word.
TEST_F(Checkpoints, RenderRefusesAFrameOfAnotherRun) {
  const test::ScratchDir dir("ck_mixed_frames");
  const std::string scene = dir.write("s.yaml", kScene);
  const std::string a = dir.path() + "/a", b = dir.path() + "/b";
  ASSERT_EQ(marbles("run " + scene + " --quiet --backend cpu --no-render --duration 0.06 --out " + a), 0);
  ASSERT_EQ(marbles("run " + scene + " --quiet --backend cpu --no-render --duration 0.06 --out " + b +
                    " --set particles[0].random.count=200"),
            0);
  std::string err;
  const int whole = marbles("render " + a + " --no-movie --width 32 --height 24", &err);
  if (err.find("OSMesa") != std::string::npos) GTEST_SKIP() << "a build that does not render";
  ASSERT_EQ(whole, 0) << err;
  fs::copy_file(b + "/frames/frame_000002.vtp", a + "/frames/frame_000002.vtp", fs::copy_options::overwrite_existing);
  EXPECT_EQ(marbles("render " + a + " --no-movie --width 32 --height 24", &err), 2);
  EXPECT_NE(err.find(a + "/frames/frame_000002.vtp: holds 200 spheres where the series' first frame, " + a +
                     "/frames/frame_000000.vtp, holds 300"),
            std::string::npos)
      << err;
}

// A folder holding an earlier run is refused (exit 2, nothing touched);
// --overwrite replaces that run's files, so no stale frame survives, and
// leaves the user's own files.
TEST_F(Checkpoints, EarlierRunIsRefusedOrOverwritten) {
  const test::ScratchDir dir("ck_overwrite");
  const std::string scene = dir.write("s.yaml", kScene);
  const std::string out = dir.path() + "/o";
  ASSERT_EQ(marbles("run " + scene + " --quiet --backend cpu --out " + out), 0);
  std::ofstream(out + "/notes.txt") << "mine";
  auto listing = [&] {
    std::vector<std::string> names;
    for (const auto& entry : fs::recursive_directory_iterator(out))
      names.push_back(fs::relative(entry.path(), out).string());
    std::sort(names.begin(), names.end());
    return names;
  };
  const std::vector<std::string> before = listing();
  const std::string summary = slurp(out + "/summary.json");
  std::string err;
  EXPECT_EQ(marbles("run " + scene + " --quiet --backend cpu --duration 0.1 --out " + out, &err), 2);
  EXPECT_NE(err.find("--out: " + out + " holds the output of an earlier run ("), std::string::npos) << err;
  EXPECT_NE(err.find("--overwrite replaces it"), std::string::npos) << err;
  EXPECT_EQ(listing(), before);
  EXPECT_EQ(slurp(out + "/summary.json"), summary);

  ASSERT_EQ(marbles("run " + scene + " --quiet --backend cpu --duration 0.1 --overwrite --out " + out, &err), 0) << err;
  const std::string fresh = dir.path() + "/fresh";
  ASSERT_EQ(marbles("run " + scene + " --quiet --backend cpu --duration 0.1 --out " + fresh), 0);
  std::vector<std::string> expected;
  for (const auto& entry : fs::recursive_directory_iterator(fresh))
    expected.push_back(fs::relative(entry.path(), fresh).string());
  expected.push_back("notes.txt");
  std::sort(expected.begin(), expected.end());
  EXPECT_EQ(listing(), expected);
  expect_same_output(fresh, out);
}

// --overwrite sets the earlier run aside (DIR/.earlier-run-PID) until the
// new one stands: a run that fails keeps it whole there and says so; a
// process that dies leaves it, and the next run into the folder names it; a
// run that ends, or is stopped with its checkpoint, removes it.
TEST_F(Checkpoints, OverwriteKeepsTheEarlierRunUntilTheNewOneStands) {
  const test::ScratchDir dir("ck_overwrite_aside");
  const std::string scene = dir.write("s.yaml", kScene);
  const std::string out = dir.path() + "/o";
  ASSERT_EQ(marbles("run " + scene + " --quiet --backend cpu --out " + out), 0);
  auto files_in = [](const fs::path& folder) {  // each file below `folder` with its bytes
    std::map<std::string, std::string> files;
    for (const auto& entry : fs::recursive_directory_iterator(folder))
      if (entry.is_regular_file()) files[fs::relative(entry.path(), folder).string()] = slurp(entry.path().string());
    return files;
  };
  auto asides = [&] {
    std::vector<fs::path> found;
    for (const auto& entry : fs::directory_iterator(out))
      if (entry.path().filename().string().starts_with(".earlier-run-")) found.push_back(entry.path());
    return found;
  };
  const std::map<std::string, std::string> earlier = files_in(out);
  const std::string again = "run " + scene + " --quiet --backend cpu --duration 0.2 --overwrite --out " + out;

  std::string err;
  EXPECT_EQ(marbles(again, &err, "MARBLES_FAULT_NAN_STEP=120:all"), 1);
  ASSERT_EQ(asides().size(), 1u) << err;
  const fs::path kept = asides().front();
  EXPECT_NE(err.find("the files of the earlier run that this run was to replace are kept whole in " + kept.string()),
            std::string::npos)
      << err;
  EXPECT_EQ(files_in(kept), earlier);
  EXPECT_TRUE(fs::exists(out + "/checkpoints/step_000119.mck")) << "the failed run's last good state";

  EXPECT_EQ(marbles(again, &err, "MARBLES_FAULT_SIGNAL=SEGV@40"), 1);
  EXPECT_NE(err.find("note: " + kept.string() + " holds an earlier run's files, set aside by a run that did not end"),
            std::string::npos)
      << err;
  EXPECT_EQ(asides().size(), 2u) << "the dead process's folder stays";
  EXPECT_EQ(files_in(kept), earlier);
  // A run without --overwrite is refused, naming the folders set aside too.
  EXPECT_EQ(marbles("run " + scene + " --quiet --backend cpu --duration 0.2 --out " + out, &err), 2);
  for (const fs::path& folder : asides())
    EXPECT_NE(err.find("; " + folder.string() + " holds files set aside by a run that did not end"), std::string::npos)
        << err;

  EXPECT_EQ(marbles(again, &err, "MARBLES_FAULT_SIGNAL=INT@60"), 1);
  EXPECT_NE(err.find("stopped by SIGINT after step 60"), std::string::npos) << err;
  EXPECT_EQ(asides().size(), 2u) << "the stopped run resumes in the folder: what it replaced is gone";
  EXPECT_EQ(marbles("run " + scene + " --quiet --backend cpu --duration 0.2 --out " + out + " --restart " + out +
                        "/checkpoints/step_000060.mck",
                    &err),
            0)
      << err;
  for (const fs::path& folder : asides()) fs::remove_all(folder);
  EXPECT_EQ(marbles(again, &err), 0) << err;
  EXPECT_TRUE(asides().empty()) << "a run that ends removes what it replaced";
  // A folder of the run's own process number (numbers come round again, a
  // container's first process is 1 each time) is another's: kept, and the
  // run sets its own aside beside it (its shell's number, through exec).
  EXPECT_EQ(marbles(again, &err,
                    "mkdir -p '" + out + "/.earlier-run-'$$ && echo mine > '" + out + "/.earlier-run-'$$/notes.txt && exec"),
            0)
      << err;
  ASSERT_EQ(asides().size(), 1u) << err;
  EXPECT_EQ(slurp((asides().front() / "notes.txt").string()), "mine\n");
}

// An output folder the user may not write in is named as such, with the
// system's reason (it said "cannot open DIR/.marbles-run.lock: No such file
// or directory", the second try's reason). Run as another user where the
// test runs as root, which may write anywhere.
TEST_F(Checkpoints, AFolderThatMayNotBeWrittenIsNamed) {
  const test::ScratchDir dir("ck_read_only");
  const std::string scene = dir.write("s.yaml", kScene);
  const std::string out = dir.path() + "/ro";
  fs::create_directories(out);
  fs::permissions(out, fs::perms::owner_read | fs::perms::owner_exec | fs::perms::group_read | fs::perms::group_exec |
                           fs::perms::others_read | fs::perms::others_exec);
  std::string as_another;
  if (::geteuid() == 0) {
    if (std::system("setpriv --version > /dev/null 2>&1") != 0) GTEST_SKIP() << "root, and no setpriv to drop it";
    as_another = "setpriv --reuid=65534 --regid=65534 --clear-groups";
    fs::permissions(dir.path(), fs::perms::others_read | fs::perms::others_exec, fs::perm_options::add);
    fs::permissions(scene, fs::perms::others_read, fs::perm_options::add);
  }
  std::string err;
  EXPECT_EQ(marbles("run " + scene + " --quiet --backend cpu --no-render --duration 0.05 --out " + out, &err, as_another),
            1);
  EXPECT_NE(err.find("cannot write in the output folder " + out + ": Permission denied"), std::string::npos) << err;
  EXPECT_TRUE(fs::is_empty(out));
}

// One run at a time in a folder: while another process holds the folder's
// lock, a run into it is refused (exit 2, naming that process) and touches
// nothing, --overwrite or not; a lock file left by a process that ended
// holds nothing; a run removes its lock file as it ends, and a refused run
// leaves no folder it made.
TEST_F(Checkpoints, OneRunAtATimeInAFolder) {
  const test::ScratchDir dir("ck_lock");
  const std::string scene = dir.write("s.yaml", kScene);
  const std::string out = dir.path() + "/o";
  const std::string run = "run " + scene + " --quiet --backend cpu --no-render --duration 0.05 --out " + out;
  ASSERT_EQ(marbles(run), 0);
  EXPECT_FALSE(fs::exists(out + "/.marbles-run.lock"));
  const std::string summary = slurp(out + "/summary.json");
  {
    const int fd = ::open((out + "/.marbles-run.lock").c_str(), O_RDWR | O_CREAT, 0644);
    ASSERT_GE(fd, 0);
    ASSERT_EQ(::flock(fd, LOCK_EX | LOCK_NB), 0);
    ASSERT_EQ(::write(fd, "4242", 4), 4);
    for (const std::string extra : {"", " --overwrite"}) {
      std::string err;
      EXPECT_EQ(marbles(run + extra, &err), 2) << extra;
      EXPECT_NE(err.find("--out: " + out + " is being written by another marbles command (process 4242); wait for it "
                         "to end, or choose another folder"),
                std::string::npos)
          << err;
      EXPECT_EQ(slurp(out + "/summary.json"), summary);
    }
    std::string err;  // nor is the folder rendered meanwhile (the run's newer images would be taken for stale)
    EXPECT_EQ(marbles("render " + out + " --no-movie", &err), 2);
    EXPECT_NE(err.find("outdir: " + out + " is being written by another marbles command (process 4242)"),
              std::string::npos)
        << err;
    ::close(fd);  // as a process that ended: its file stays, unlocked
  }
  std::string err;
  EXPECT_EQ(marbles(run + " --overwrite", &err), 0) << err;
  EXPECT_FALSE(fs::exists(out + "/.marbles-run.lock"));
  // Refused after the lock (the scene file is no checkpoint): no folder it made is left.
  EXPECT_EQ(marbles("run " + scene + " --quiet --backend cpu --out " + dir.path() + "/new/a/b --restart " + scene, &err),
            2);
  EXPECT_NE(err.find("s.yaml"), std::string::npos) << err;
  EXPECT_FALSE(fs::exists(dir.path() + "/new")) << "a refused run leaves no folder it made";
}

// The lock file is made in the folder, never through a link: a link there
// (to a file, or to none) is refused, exit 2, and what it names is left as
// it was (the process's number replaced a file's contents, and a link to
// nothing made a file outside the folder); a folder there is refused so too.
TEST_F(Checkpoints, TheLockIsNeverTakenThroughALink) {
  const test::ScratchDir dir("ck_lock_link");
  const std::string scene = dir.write("s.yaml", kScene);
  const std::string victim = dir.write("victim.txt", "precious\n");
  const std::string out = dir.path() + "/o", lock = out + "/.marbles-run.lock";
  fs::create_directories(out);
  for (const std::string& target : {victim, dir.path() + "/none"}) {
    fs::create_symlink(target, lock);
    for (const std::string& command : {"run " + scene + " --quiet --backend cpu --no-render --duration 0.05 --out " + out,
                                       "render " + out + " --no-movie"}) {
      std::string err;
      EXPECT_EQ(marbles(command, &err), 2) << command;
      EXPECT_NE(err.find(lock + " is a link where a run keeps its lock file"), std::string::npos) << err;
    }
    EXPECT_TRUE(fs::is_symlink(lock));
    EXPECT_EQ(slurp(victim), "precious\n");
    EXPECT_FALSE(fs::exists(dir.path() + "/none"));
    fs::remove(lock);
  }
  fs::create_directory(lock);
  std::string err;
  EXPECT_EQ(marbles("run " + scene + " --quiet --backend cpu --no-render --duration 0.05 --out " + out, &err), 2);
  EXPECT_NE(err.find(lock + " is a folder where a run keeps its lock file"), std::string::npos) << err;
}

// A resume in its run's folder replaces the steps after its checkpoint: a
// shorter run leaves no frame, wall frame or checkpoint of the longer one
// (a checkpoint past the new end outranked the new ones under `keep`), and
// its folder holds what a run of that length alone writes. A checkpoint kept
// outside a run's checkpoints/ brings no output, so it resumes into a folder
// holding a run only with --overwrite.
// A resume in its folder that cannot set a later file aside (here a frames
// folder made immutable, where the filesystem and the user allow it) leaves
// the folder as it was: the files moved are put back, and the listings it
// had cut to its step come back whole from their copies.
TEST_F(Checkpoints, AResumeThatCannotSetFilesAsideLeavesTheFolderAsItWas) {
  const test::ScratchDir dir("ck_resume_stuck");
  const std::string scene = dir.write("s.yaml", kScene);
  const std::string out = dir.path() + "/o";
  const std::string common = " --quiet --backend cpu --no-render --set output.vtk.every=10";
  ASSERT_EQ(marbles("run " + scene + common + " --out " + out), 0);
  const std::string series = slurp(out + "/series.pvd"), walls = slurp(out + "/walls.pvd"),
                    thermo = slurp(out + "/thermo.csv");
  if (std::system(("chattr +i '" + out + "/frames' 2>/dev/null").c_str()) != 0) GTEST_SKIP() << "no chattr +i here";
  std::string err;
  const int code = marbles("run " + scene + common + " --out " + out + " --restart " + out +
                               "/checkpoints/step_000150.mck",
                           &err);
  std::system(("chattr -i '" + out + "/frames'").c_str());
  EXPECT_EQ(code, 1) << err;
  EXPECT_NE(err.find("cannot set the earlier run's files aside"), std::string::npos) << err;
  EXPECT_NE(err.find("(they are left as they were)"), std::string::npos) << err;
  EXPECT_EQ(slurp(out + "/series.pvd"), series);
  EXPECT_EQ(slurp(out + "/walls.pvd"), walls);
  EXPECT_EQ(slurp(out + "/thermo.csv"), thermo);
  for (const auto& entry : fs::directory_iterator(out))
    EXPECT_EQ(entry.path().filename().string().rfind(".earlier-run-", 0), std::string::npos) << entry.path();
}

TEST_F(Checkpoints, AResumeInItsFolderReplacesTheStepsAfterIt) {
  const test::ScratchDir dir("ck_resume_shorter");
  const std::string scene = dir.write("s.yaml", kScene);
  const std::string out = dir.path() + "/o", alone = dir.path() + "/alone";
  const std::string common = " --quiet --backend cpu --no-render";
  ASSERT_EQ(marbles("run " + scene + common + " --out " + out), 0);
  ASSERT_EQ(marbles("run " + scene + common + " --duration 0.2 --out " + alone), 0);
  std::string err;
  ASSERT_EQ(marbles("run " + scene + common + " --duration 0.2 --out " + out + " --restart " + out +
                        "/checkpoints/step_000150.mck",
                    &err),
            0)
      << err;
  auto listing = [](const std::string& folder) {
    std::vector<std::string> names;
    for (const auto& entry : fs::recursive_directory_iterator(folder))
      if (entry.is_regular_file()) names.push_back(fs::relative(entry.path(), folder).string());
    std::sort(names.begin(), names.end());
    return names;
  };
  EXPECT_EQ(listing(out), listing(alone));
  expect_same_output(alone, out);
  // A resume in place that fails keeps what it replaced whole: the later
  // files, and the series and thermo rows as they were.
  const std::string thermo = slurp(out + "/thermo.csv"), series = slurp(out + "/series.pvd");
  EXPECT_EQ(marbles("run " + scene + common + " --out " + out + " --restart " + out + "/checkpoints/step_000100.mck",
                    &err, "MARBLES_FAULT_NAN_STEP=150:all"),
            1);
  std::vector<fs::path> kept;
  for (const auto& entry : fs::directory_iterator(out))
    if (entry.path().filename().string().starts_with(".earlier-run-")) kept.push_back(entry.path());
  ASSERT_EQ(kept.size(), 1u) << err;
  EXPECT_NE(err.find("are kept whole in " + kept[0].string()), std::string::npos) << err;
  EXPECT_EQ(slurp((kept[0] / "thermo.csv").string()), thermo);
  EXPECT_EQ(slurp((kept[0] / "series.pvd").string()), series);
  EXPECT_TRUE(fs::exists(kept[0] / "frames" / "frame_000010.vtp"));
  EXPECT_TRUE(fs::exists(kept[0] / "checkpoints" / "step_000200.mck"));
  EXPECT_TRUE(fs::exists(kept[0] / "summary.json"));
  fs::remove_all(out);
  fs::copy(alone, out, fs::copy_options::recursive);

  fs::copy_file(out + "/checkpoints/step_000100.mck", dir.path() + "/loose.mck");
  EXPECT_EQ(marbles("run " + scene + common + " --out " + out + " --restart " + dir.path() + "/loose.mck", &err), 2);
  EXPECT_NE(err.find("--out: " + out + " holds the output of an earlier run"), std::string::npos) << err;
  EXPECT_EQ(listing(out), listing(alone)) << "a refusal touches nothing";
  EXPECT_EQ(marbles("run " + scene + common + " --overwrite --out " + out + " --restart " + dir.path() + "/loose.mck",
                    &err),
            0)
      << err;
  EXPECT_FALSE(fs::exists(out + "/frames/frame_000000.vtp")) << "a loose checkpoint brings no frames";
  EXPECT_TRUE(fs::exists(out + "/frames/frame_000015.vtp"));
}

// --summary-only: summary.json, and the checkpoints a stopped run resumes
// from; no frame of any series (contact frames were written), no thermo rows,
// no material names.
TEST_F(Checkpoints, SummaryOnlyWritesTheSummaryAndCheckpointsAlone) {
  const test::ScratchDir dir("ck_summary_only");
  const std::string scene = dir.write("s.yaml", kScene);
  const std::string out = dir.path() + "/o";
  std::string err;
  ASSERT_EQ(marbles("run " + scene + " --quiet --backend cpu --summary-only --set output.contacts.every=10 --out " + out,
                    &err),
            0)
      << err;
  std::vector<std::string> names;
  for (const auto& entry : fs::recursive_directory_iterator(out))
    if (entry.is_regular_file()) names.push_back(fs::relative(entry.path(), out).string());
  std::sort(names.begin(), names.end());
  std::vector<std::string> expected{"summary.json"};
  for (const int step : {50, 100, 150, 200, 250, 300}) {  // output.checkpoint.every 50 of 300 steps
    char name[40];
    std::snprintf(name, sizeof name, "checkpoints/step_%06d.mck", step);
    expected.push_back(name);
  }
  std::sort(expected.begin(), expected.end());
  EXPECT_EQ(names, expected);
}

// thermo.csv: one row per frame; its energies are the summary's at the
// start and the end; under gravity alone with velocity Verlet the mechanical
// energy it reports is conserved; a resumed run keeps the rows before its
// checkpoint and writes the same ones after (all but the timing column).
std::vector<std::vector<std::string>> csv_rows(const std::string& path) {
  std::vector<std::vector<std::string>> rows;
  std::istringstream in(slurp(path));
  std::string line;
  while (std::getline(in, line)) {
    std::vector<std::string> cells;
    std::istringstream cells_in(line);
    for (std::string cell; std::getline(cells_in, cell, ',');) cells.push_back(cell);
    rows.push_back(cells);
  }
  return rows;
}

TEST_F(Checkpoints, ThermoRowsFollowTheRun) {
  const test::ScratchDir dir("ck_thermo");
  const std::string scene = dir.write("s.yaml", kScene);
  const std::string out = dir.path() + "/o";
  ASSERT_EQ(marbles("run " + scene + " --quiet --backend cpu --out " + out), 0);
  const auto rows = csv_rows(out + "/thermo.csv");
  ASSERT_EQ(rows.size(), 1u + 16u);  // the header and a row per 20 steps, 0 to 300
  EXPECT_EQ(rows[0], (std::vector<std::string>{"step", "t", "ke_translational", "ke_rotational", "potential_energy",
                                               "contacts", "max_overlap", "max_speed", "ms_per_step"}));
  const auto summary = summary_of(out + "/summary.json");
  auto kinetic = [&](std::size_t r) { return std::stod(rows[r][2]) + std::stod(rows[r][3]); };
  EXPECT_NEAR(kinetic(1), summary.at("kinetic_energy_start").get<double>(), 1e-6 * kinetic(1));
  EXPECT_NEAR(kinetic(16), summary.at("kinetic_energy_end").get<double>(), 1e-6 * kinetic(16));
  // The last row is the end's: the summary's parts and largest speed are its.
  EXPECT_EQ(std::stod(rows[16][2]), summary.at("kinetic_energy_end_translational").get<double>());
  EXPECT_EQ(std::stod(rows[16][3]), summary.at("kinetic_energy_end_rotational").get<double>());
  EXPECT_EQ(std::stod(rows[16][7]), summary.at("max_speed_end").get<double>());
  for (std::size_t r = 1; r < rows.size(); ++r) {
    ASSERT_EQ(rows[r].size(), 9u);
    EXPECT_EQ(std::stoul(rows[r][0]), 20 * (r - 1));
    EXPECT_LE(std::stod(rows[r][6]), summary.at("max_overlap").get<double>() + 1e-12);
  }
  EXPECT_EQ(rows[3][1], "0.04");  // the shortest text of the frame time

  // Resumed at step 150: the rows up to it are kept, the later ones equal.
  const std::string resumed = dir.path() + "/resumed";
  ASSERT_EQ(marbles("run " + scene + " --quiet --backend cpu --duration 0.15 --out " + resumed), 0);
  ASSERT_EQ(marbles("run " + scene + " --quiet --backend cpu --out " + resumed + " --restart " + resumed +
                    "/checkpoints/step_000150.mck"),
            0);
  auto physics = [](std::vector<std::vector<std::string>> table) {
    for (auto& row : table) row.pop_back();  // ms_per_step times this process
    return table;
  };
  EXPECT_EQ(physics(csv_rows(resumed + "/thermo.csv")), physics(rows));

  // Gravity alone, velocity Verlet: kinetic + potential energy is constant.
  ASSERT_EQ(marbles("run " MARBLES_SOURCE_DIR "/scenes/validation/free_fall.yaml --quiet --backend cpu --precision double "
                    "--set solver.integrator=velocity_verlet --set output.vtk.every=100 --out " + dir.path() + "/fall"),
            0);
  const auto fall = csv_rows(dir.path() + "/fall/thermo.csv");
  ASSERT_EQ(fall.size(), 1u + 11u);
  const double e0 = std::stod(fall[1][2]) + std::stod(fall[1][4]);
  for (std::size_t r = 2; r < fall.size(); ++r) {
    EXPECT_GT(std::stod(fall[r][8]), 0.0);
    EXPECT_NEAR(std::stod(fall[r][2]) + std::stod(fall[r][4]), e0, 1e-9 * std::fabs(e0)) << "row " << r;
  }
}

// A run of many frames rewrites its listings (series.pvd, walls.pvd,
// thermo.csv) in steps, not at every frame; each checkpoint has them whole,
// so a run that dies one step past a checkpoint (no listing written since)
// resumes from it into the same listings as the run that never stopped.
TEST_F(Checkpoints, ListingsOfManyFramesAreWholeAtEachCheckpoint) {
  const test::ScratchDir dir("ck_listings");
  const std::string scene = dir.write("s.yaml", kScene);
  const std::string sets = " --quiet --backend cpu --set output.vtk.every=1 --set output.checkpoint.every=100";
  ASSERT_EQ(marbles("run " + scene + sets + " --out " + dir.path() + "/whole"), 0);
  const std::string out = dir.path() + "/died";
  std::string err;
  ASSERT_EQ(marbles("run " + scene + sets + " --out " + out, &err, "MARBLES_FAULT_SIGNAL=SEGV@201"), 1) << err;
  // Where the run died its listings may lag, but name only frames that are there.
  if (fs::exists(out + "/frames")) {
    const std::string series = slurp(out + "/series.pvd");
    for (std::size_t at = series.find("file=\""); at != std::string::npos; at = series.find("file=\"", at + 1)) {
      const std::size_t from = at + 6, to = series.find('"', from);
      EXPECT_TRUE(fs::exists(out + "/" + series.substr(from, to - from))) << series.substr(from, to - from);
    }
  }
  ASSERT_EQ(marbles("run " + scene + sets + " --out " + out + " --restart " + out + "/checkpoints/step_000200.mck", &err),
            0)
      << err;
  expect_same_output(dir.path() + "/whole", out);
  auto physics = [](std::vector<std::vector<std::string>> table) {
    for (auto& row : table) row.pop_back();  // ms_per_step times this process
    return table;
  };
  const auto rows = csv_rows(dir.path() + "/whole/thermo.csv");
  ASSERT_EQ(rows.size(), 302u);  // the header and a row a step, 0 to 300
  EXPECT_EQ(physics(csv_rows(out + "/thermo.csv")), physics(rows));
  if (fs::exists(out + "/frames")) {
    EXPECT_EQ(slurp(out + "/walls.pvd"), slurp(dir.path() + "/whole/walls.pvd"));
    const std::string series = slurp(out + "/series.pvd"), walls = slurp(out + "/walls.pvd");
    EXPECT_EQ(std::count(series.begin(), series.end(), '\n'), std::count(walls.begin(), walls.end(), '\n'));
  }
}

// A --summary-only resume in its run's folder with a shorter duration: the
// folder reads as a run of that length, the earlier run's frames, contact
// frames, images and thermo rows up to its end kept (the same run's) and
// those past it gone, listed by no .pvd; it left them all, and listed.
TEST_F(Checkpoints, ASummaryOnlyResumeLeavesNothingPastItsEnd) {
  const test::ScratchDir dir("ck_summary_only_resume");
  const std::string scene = dir.write("s.yaml", kScene);
  const std::string common = " --quiet --backend cpu --set output.contacts.every=10";
  const std::string out = dir.path() + "/o", shorter = dir.path() + "/shorter";
  std::string err;
  ASSERT_EQ(marbles("run " + scene + common + " --out " + out), 0);
  ASSERT_EQ(marbles("run " + scene + common + " --duration 0.2 --out " + shorter), 0);
  ASSERT_EQ(marbles("run " + scene + common + " --summary-only --duration 0.2 --out " + out + " --restart " + out +
                        "/checkpoints/step_000100.mck",
                    &err),
            0)
      << err;
  EXPECT_EQ(physics_of(out + "/summary.json"), physics_of(shorter + "/summary.json"));
  auto physics = [](std::vector<std::vector<std::string>> table) {
    for (auto& row : table) row.pop_back();  // ms_per_step times each process
    return table;
  };
  EXPECT_EQ(physics(csv_rows(out + "/thermo.csv")), physics(csv_rows(shorter + "/thermo.csv")));
  for (const char* folder : {"frames", "walls", "contacts", "images", "checkpoints"}) {
    std::vector<std::string> here, there;
    for (const auto& [path, names] : {std::pair{out, &here}, std::pair{shorter, &there}})
      if (fs::exists(path + "/" + folder))
        for (const auto& entry : fs::directory_iterator(path + "/" + folder)) names->push_back(entry.path().filename());
    std::sort(here.begin(), here.end());
    std::sort(there.begin(), there.end());
    EXPECT_EQ(here, there) << folder;
  }
  for (const char* pvd : {"series.pvd", "walls.pvd", "contacts.pvd"})
    EXPECT_EQ(slurp(out + "/" + pvd), slurp(shorter + "/" + pvd)) << pvd;
  EXPECT_FALSE(fs::exists(out + "/movie.mp4"));  // the earlier run's, of its whole length
}

// summary.json says what made it: version, the commit of this source tree,
// the command line, the threads asked for, units and material names; the
// pipeline line prints the threads.
TEST_F(Checkpoints, SummaryCarriesItsProvenance) {
  const test::ScratchDir dir("ck_provenance");
  const std::string scene = dir.write("s.yaml", kScene);
  for (const int threads : {1, 3}) {
    const std::string out = dir.path() + "/t" + std::to_string(threads);
    const std::string listing = dir.path() + "/stdout.txt";
    ASSERT_EQ(std::system(("'" + kMarbles + "' run " + scene + " --backend cpu --summary-only --threads " +
                           std::to_string(threads) + " --out " + out + " >" + listing + " 2>/dev/null")
                              .c_str()),
              0);
    EXPECT_NE(slurp(listing).find("on the CPU, " + std::to_string(threads) + (threads == 1 ? " thread)" : " threads)")),
              std::string::npos)
        << slurp(listing);
    const auto summary = summary_of(out + "/summary.json");
    EXPECT_EQ(summary.at("threads"), threads) << summary;
    EXPECT_EQ(summary.at("command_line").get<std::string>().rfind(kMarbles + " run " + scene, 0), 0u) << summary;
    EXPECT_EQ(summary.at("materials"), nlohmann::ordered_json::array({"glass"})) << summary;
    EXPECT_EQ(summary.at("units").at("length"), "m") << summary;
    EXPECT_EQ(summary.at("units").at("angular_velocity"), "rad/s") << summary;
    EXPECT_FALSE(summary.at("marbles_version").get<std::string>().empty()) << summary;
    // The commit: a commit of this source tree, as git knows it (when it is a
    // git checkout; the build may predate the newest commit).
    std::string commit = summary.at("commit");
    if (commit.size() > 6 && commit.substr(commit.size() - 6) == "-dirty") commit.resize(commit.size() - 6);
    if (std::system("git -C " MARBLES_SOURCE_DIR " rev-parse HEAD >/dev/null 2>&1") == 0) {
      EXPECT_EQ(commit.size(), 12u) << summary;
      EXPECT_EQ(std::system(("git -C " MARBLES_SOURCE_DIR " cat-file -e '" + commit + "^{commit}' 2>/dev/null").c_str()), 0)
          << commit;
    }
    const std::string date = summary.at("date");  // ISO 8601 in UTC: 2026-11-23T07:00:00Z
    ASSERT_EQ(date.size(), 20u) << date;
    EXPECT_EQ(date.substr(4, 1), "-");
    EXPECT_EQ(date.substr(19, 1), "Z");
  }
}

// `bench ... --json` prints JSON only: one document (step, effects) or one
// object per line (broadphase), no table; each parses, and each case has a
// positive median.
TEST_F(Checkpoints, BenchJsonIsJsonOnly) {
  const test::ScratchDir dir("ck_bench_json");
  const std::string out = dir.path() + "/out.json";
  const std::pair<std::string, bool> cases[] = {
      {"bench effects --n 300 --repeats 2 --json", false},
      {"bench step --backend cpu --scene gas --n 300 --repeats 2 --json", false},
      {"bench broadphase --backend cpu --n 500 1000 --repeats 2 --json", true}};
  for (const auto& [args, lines] : cases) {
    ASSERT_EQ(std::system(("'" + kMarbles + "' " + args + " >" + out + " 2>/dev/null").c_str()), 0) << args;
    const std::string text = slurp(out);
    ASSERT_FALSE(text.empty()) << args;
    EXPECT_EQ(text.front(), '{') << args << "\n" << text;
    EXPECT_EQ(text.substr(text.size() - 2), "}\n") << args << "\n" << text;
    std::vector<std::string> documents{text};
    if (lines) {  // one object per line
      documents.clear();
      std::istringstream in(text);
      for (std::string line; std::getline(in, line);) documents.push_back(line);
      EXPECT_EQ(documents.size(), 2u) << text;
    }
    for (const std::string& d : documents) {
      nlohmann::json j;
      ASSERT_NO_THROW(j = nlohmann::json::parse(d)) << args << "\n" << d;
      const auto results = j.contains("results") ? j.at("results") : nlohmann::json::array({j});
      ASSERT_FALSE(results.empty()) << d;
      for (const auto& r : results) {  // every case timed: a positive median
        const auto& median = r.contains("step_ms_median") ? r.at("step_ms_median") : r.at("total").at("median_ms");
        EXPECT_TRUE(median.is_number() && median.get<double>() > 0) << d;
      }
    }
  }
  // The effects' cost a contact where the gas met contacts, none where it met none
  // (a gas of two spheres said 9.5 us a contact of 0 contacts).
  for (const auto& [args, met] : {std::pair<std::string, bool>{"bench effects --n 2 --volume-fraction 0.01 --repeats 2 --json", false},
                                  {"bench effects --n 2000 --volume-fraction 0.4 --repeats 2 --json", true}}) {
    ASSERT_EQ(std::system(("'" + kMarbles + "' " + args + " >" + out + " 2>/dev/null").c_str()), 0) << args;
    for (const auto& r : nlohmann::json::parse(slurp(out)).at("results")) {
      const double contacts = r.at("contacts").get<double>();
      EXPECT_EQ(contacts >= 1, met) << args << ": " << r.dump();
      if (met) {
        EXPECT_NEAR(r.at("us_per_contact").get<double>(), 1e3 * r.at("step_ms_median").get<double>() / contacts,
                    1e-9 * r.at("us_per_contact").get<double>())
            << r.dump();
      } else {
        EXPECT_TRUE(r.at("us_per_contact").is_null()) << r.dump();
      }
    }
  }
}

// `bench step --sphere-order` reaches the benchmark: the first step of the
// same settling lattice finds the same candidate pairs and contacts in every
// order (a sphere lost or doubled would change them; that every field moves
// with its sphere: tests/bench/sphere_order_test.cpp), and an unknown order
// is refused naming the option.
TEST_F(Checkpoints, BenchSphereOrderPermutesOnly) {
  const test::ScratchDir dir("ck_bench_order");
  const std::string out = dir.path() + "/out.json";
  std::vector<nlohmann::json> rows;
  for (const char* order : {"made", "shuffled", "morton", "cells"}) {
    const std::string args =
        std::string("bench step --backend cpu --scene settle --n 3000 --warmup 0 --repeats 1 --json --sphere-order ") +
        order;
    ASSERT_EQ(std::system(("'" + kMarbles + "' " + args + " >" + out + " 2>/dev/null").c_str()), 0) << args;
    const nlohmann::json j = nlohmann::json::parse(slurp(out));
    EXPECT_EQ(j.at("sphere_order"), order);
    rows.push_back(j.at("results").at(0));
  }
  EXPECT_GT(rows[0].at("candidate_pairs").get<double>(), 100.0) << rows[0];
  for (const nlohmann::json& r : rows) {
    EXPECT_EQ(r.at("candidate_pairs"), rows[0].at("candidate_pairs")) << r;
    EXPECT_EQ(r.at("contacts"), rows[0].at("contacts")) << r;
  }
  std::string err;
  EXPECT_NE(marbles("bench step --backend cpu --scene gas --n 300 --sphere-order spiral", &err), 0);
  EXPECT_NE(err.find("--sphere-order"), std::string::npos) << err;
}

// A checkpoint copied beside another run's frames, resumed into a new
// folder, would have brought that run's frames: refused (exit 2), naming the
// frame, where it holds another count of spheres, or other positions at the
// checkpoint's step; nothing written in the new folder. Its own run's frames
// come along as before (RestartIntoAnotherFolderWritesEverySeries).
TEST_F(Checkpoints, FramesOfAnotherRunBesideACheckpointAreRefused) {
  const test::ScratchDir dir("ck_beside_other");
  const std::string scene = dir.write("s.yaml", kScene);
  const std::string fewer = dir.write("fewer.yaml", replace_all(kScene, "count: 300", "count: 200"));
  const std::string moved = dir.write("moved.yaml", replace_all(kScene, "seed: 3", "seed: 5"));
  const std::string common = " --quiet --backend cpu --duration 0.1";
  ASSERT_EQ(marbles("run " + scene + common + " --out " + dir.path() + "/first"), 0);
  for (const auto& [other, what] : {std::pair{fewer, std::string("frame_000005.vtp holds 200 spheres, the checkpoint 300")},
                                    std::pair{moved, std::string("frame_000005.vtp, at the checkpoint's step 100, holds "
                                                                 "sphere 0 elsewhere than the checkpoint does")}}) {
    const std::string there = dir.path() + "/other", into = dir.path() + "/into";
    fs::remove_all(there);
    ASSERT_EQ(marbles("run " + other + common + " --out " + there), 0);
    fs::copy_file(dir.path() + "/first/checkpoints/step_000100.mck", there + "/checkpoints/step_000100.mck",
                  fs::copy_options::overwrite_existing);
    std::string err;
    EXPECT_EQ(marbles("run " + scene + common + " --out " + into + " --restart " + there + "/checkpoints/step_000100.mck",
                      &err),
              2)
        << err;
    EXPECT_NE(err.find("--restart: the frames beside this checkpoint are another run's: " + there + "/frames/" + what),
              std::string::npos)
        << err;
    EXPECT_FALSE(fs::exists(into + "/frames")) << err;
    EXPECT_FALSE(fs::exists(into + "/summary.json")) << err;
  }
  // The checkpoint beside its own run's frames, at a step off their cadence (50 of every 20): frame 0 counted, taken.
  std::string err;
  EXPECT_EQ(marbles("run " + scene + common + " --out " + dir.path() + "/own --restart " + dir.path() +
                        "/first/checkpoints/step_000050.mck",
                    &err),
            0)
      << err;
  expect_same_output(dir.path() + "/first", dir.path() + "/own");
}

// A restart into another folder copies its run's files up to the
// checkpoint's step: one of them overwritten or cut short (frames, walls,
// contacts; an early one, not the frame at the step that is compared) is
// refused (exit 2) naming it, before anything is written in the new folder.
TEST_F(Checkpoints, DamagedFilesOfItsRunAreRefusedOnAResume) {
  const test::ScratchDir dir("ck_damaged_frames");
  const std::string scene = dir.write("s.yaml", kScene);
  const std::string common = " --quiet --backend cpu --set output.contacts.every=50";
  ASSERT_EQ(marbles("run " + scene + common + " --out " + dir.path() + "/first --duration 0.1"), 0);
  for (const std::string file : {"frames/frame_000000.vtp", "walls/walls_000002.vtp", "contacts/contacts_000001.vtp"}) {
    for (const bool cut : {false, true}) {
      const std::string there = dir.path() + "/damaged", into = dir.path() + "/into";
      fs::remove_all(there);
      fs::remove_all(into);
      fs::copy(dir.path() + "/first", there, fs::copy_options::recursive);
      const std::string whole = slurp(there + "/" + file);
      ASSERT_GT(whole.size(), 1000u) << file;
      std::ofstream(there + "/" + file, std::ios::binary | std::ios::trunc)
          << (cut ? whole.substr(0, whole.size() / 2) : std::string("junk\n"));
      std::string err;
      EXPECT_EQ(marbles("run " + scene + common + " --out " + into + " --restart " + there +
                            "/checkpoints/step_000100.mck",
                        &err),
                2)
          << file << (cut ? " cut" : " overwritten") << ": " << err;
      EXPECT_NE(err.find(there + "/" + file + ": is cut short or damaged"), std::string::npos) << err;
      EXPECT_FALSE(fs::exists(into + "/frames")) << err;
      EXPECT_FALSE(fs::exists(into + "/summary.json")) << err;
    }
  }
}

// A restart into another folder (the checkpoint taken elsewhere) writes
// every series there too: frames, walls and contacts.
TEST_F(Checkpoints, RestartIntoAnotherFolderWritesEverySeries) {
  const test::ScratchDir dir("ck_elsewhere");
  const std::string scene = dir.write("s.yaml", kScene);
  const std::string common = " --quiet --backend cpu --set output.contacts.every=50";
  ASSERT_EQ(marbles("run " + scene + common + " --out " + dir.path() + "/first --duration 0.1"), 0);
  std::string err;
  ASSERT_EQ(marbles("run " + scene + common + " --out " + dir.path() + "/second --restart " + dir.path() +
                        "/first/checkpoints/step_000100.mck",
                    &err),
            0)
      << err;
  for (const std::string file : {"frames/frame_000015.vtp", "walls/walls_000015.vtp", "contacts/contacts_000006.vtp",
                                 "series.pvd", "walls.pvd", "contacts.pvd", "summary.json"})
    EXPECT_TRUE(fs::exists(dir.path() + "/second/" + file)) << file;
  // The frames before the cut come along, so every file a .pvd names is in
  // the folder, the same bytes as the first run's; and the thermo rows start
  // at step 0.
  for (const std::string pvd : {"series.pvd", "walls.pvd", "contacts.pvd"}) {
    const std::string text = slurp(dir.path() + "/second/" + pvd);
    std::size_t named = 0;
    for (std::size_t at = text.find("file=\""); at != std::string::npos; at = text.find("file=\"", at + 1)) {
      const std::string file = text.substr(at + 6, text.find('"', at + 6) - at - 6);
      ++named;
      ASSERT_TRUE(fs::exists(dir.path() + "/second/" + file)) << pvd << " names " << file;
      if (fs::exists(dir.path() + "/first/" + file)) {
        EXPECT_EQ(slurp(dir.path() + "/second/" + file), slurp(dir.path() + "/first/" + file)) << file;
      }
    }
    EXPECT_GT(named, 5u) << pvd;
  }
  EXPECT_TRUE(fs::exists(dir.path() + "/second/frames/frame_000000.vtp"));
  const std::string thermo = slurp(dir.path() + "/second/thermo.csv");
  EXPECT_EQ(thermo.substr(0, thermo.find('\n', thermo.find('\n') + 1) + 1),
            slurp(dir.path() + "/first/thermo.csv").substr(0, thermo.find('\n', thermo.find('\n') + 1) + 1));
  // A checkpoint moved away from its run's folder, resumed into a new one:
  // the earlier frames are nowhere to be had, so the .pvd files list only the
  // frames from the cut on, each one in the folder, numbered as in the first run.
  fs::copy_file(dir.path() + "/first/checkpoints/step_000100.mck", dir.path() + "/lone.mck");
  ASSERT_EQ(marbles("run " + scene + common + " --out " + dir.path() + "/third --restart " + dir.path() + "/lone.mck",
                    &err),
            0)
      << err;
  const std::string third = slurp(dir.path() + "/third/series.pvd");
  EXPECT_EQ(third.find("frame_000000.vtp"), std::string::npos);
  std::size_t listed = 0;
  for (std::size_t at = third.find("file=\""); at != std::string::npos; at = third.find("file=\"", at + 1)) {
    const std::string file = third.substr(at + 6, third.find('"', at + 6) - at - 6);
    ++listed;
    EXPECT_TRUE(fs::exists(dir.path() + "/third/" + file)) << file;
    EXPECT_EQ(slurp(dir.path() + "/third/" + file), slurp(dir.path() + "/second/" + file)) << file;
  }
  EXPECT_GT(listed, 5u);
  // Into a folder that holds another run: refused unless --overwrite, which replaces it.
  const std::string again = "run " + scene + common + " --out " + dir.path() + "/second --restart " + dir.path() +
                            "/first/checkpoints/step_000100.mck";
  EXPECT_EQ(marbles(again, &err), 2);
  EXPECT_NE(err.find("holds the output of an earlier run"), std::string::npos) << err;
  EXPECT_EQ(marbles(again + " --overwrite", &err), 0) << err;
  // Resumed at its last step: nothing is left to write, and the folder is whole still.
  ASSERT_EQ(marbles("run " + scene + common + " --duration 0.1 --out " + dir.path() + "/fourth --restart " + dir.path() +
                        "/first/checkpoints/step_000100.mck",
                    &err),
            0)
      << err;
  for (const std::string file : {"series.pvd", "walls.pvd", "contacts.pvd", "thermo.csv", "frames/frame_000005.vtp"})
    EXPECT_TRUE(fs::exists(dir.path() + "/fourth/" + file)) << file;
  EXPECT_EQ(slurp(dir.path() + "/fourth/thermo.csv"), slurp(dir.path() + "/first/thermo.csv"));
}

// The newest `keep` checkpoints stay.
TEST_F(Checkpoints, KeepsTheNewest) {
  const test::ScratchDir dir("ck_keep");
  const std::string scene = dir.write("s.yaml", kScene);
  ASSERT_EQ(marbles("run " + scene + " --quiet --backend cpu --set output.checkpoint.keep=2 --out " + dir.path() + "/o"), 0);
  std::vector<std::string> names;
  for (const auto& entry : fs::directory_iterator(dir.path() + "/o/checkpoints"))
    names.push_back(entry.path().filename().string());
  std::sort(names.begin(), names.end());
  EXPECT_EQ(names, (std::vector<std::string>{"step_000250.mck", "step_000300.mck"}));
}

// Another scene, another precision or a damaged file: exit 2 and why.
TEST_F(Checkpoints, ForeignOrDamagedCheckpointsAreRefused) {
  const test::ScratchDir dir("ck_foreign");
  const std::string scene = dir.write("s.yaml", kScene);
  ASSERT_EQ(marbles("run " + scene + " --quiet --backend cpu --out " + dir.path() + "/o"), 0);
  const std::string ck = dir.path() + "/o/checkpoints/step_000100.mck";
  std::string err;
  EXPECT_EQ(marbles("run " + scene + " --quiet --set materials.glass.friction=0.5 --restart " + ck, &err), 2);
  EXPECT_NE(err.find("belongs to another scene"), std::string::npos) << err;
  EXPECT_EQ(marbles("run " + scene + " --quiet --precision double --restart " + ck, &err), 2);
  EXPECT_NE(err.find("is in float precision, this run in double"), std::string::npos) << err;
  // A duration that ends before the checkpoint's step.
  EXPECT_EQ(marbles("run " + scene + " --quiet --duration 0.05 --restart " + ck, &err), 2);
  EXPECT_NE(err.find("the checkpoint is at step 100, past this run's end at step 50"), std::string::npos) << err;
  const std::string bytes = slurp(ck);
  const std::string cut = dir.write("cut.mck", bytes.substr(0, bytes.size() / 2));
  EXPECT_EQ(marbles("run " + scene + " --quiet --restart " + cut, &err), 2);
  EXPECT_NE(err.find("truncated or damaged"), std::string::npos) << err;
  const std::string other = dir.write("other.mck", "not a checkpoint at all, just text");
  EXPECT_EQ(marbles("run " + scene + " --quiet --restart " + other, &err), 2);
  EXPECT_NE(err.find("is not a marbles checkpoint"), std::string::npos) << err;
}

// What a checkpoint must match is the scene as read, not its texts: the same
// values written otherwise (5e-4 and 0.0005, 12.0 and 12, True and true,
// quoted or not, a map for dotted keys, the file's own value), in another
// order or set twice, resume it, and the run ends as the uninterrupted one;
// another value, an override left out, or a name written otherwise (a name is
// its text: 1 is not 1.0) is refused.
TEST_F(Checkpoints, OverridesThatReadAlikeResume) {
  const test::ScratchDir dir("ck_alike");
  const std::string scene = dir.write("s.yaml", kScene);
  const std::string common = " --quiet --backend cpu";
  const std::string given = " --set time.dt=5e-4 --set solver.iterations=12.0 --set solver.speculative=true"
                            " --set materials.glass.friction=0.3 --set 'solver.integrator=\"velocity_verlet\"'"
                            " --set name=1";
  const std::string whole = dir.path() + "/whole", cut = dir.path() + "/cut";
  ASSERT_EQ(marbles("run " + scene + common + given + " --out " + whole), 0);
  ASSERT_EQ(marbles("run " + scene + common + given + " --out " + cut + " --duration 0.05"), 0);
  const std::string ck = " --restart " + cut + "/checkpoints/step_000100.mck";
  const std::string alike = " --set name=1 --set materials.glass.friction=0.30 --set solver.iterations=5"
                            " --set 'solver={iterations: 12, integrator: velocity_verlet, speculative: True}'"
                            " --set 'time.dt=\"0.0005\"' --set time.substeps=2";
  std::string err;
  for (const std::string& other : {replace_all(given, "dt=5e-4", "dt=4e-4"), replace_all(given, "name=1", "name=1.0"),
                                   replace_all(given, " --set materials.glass.friction=0.3", "")}) {
    EXPECT_EQ(marbles("run " + scene + common + other + " --out " + dir.path() + "/other" + ck, &err), 2) << other;
    EXPECT_NE(err.find("belongs to another scene"), std::string::npos) << other << ": " << err;
  }
  // The file written otherwise: a comment, a wall's and a block's keys in another order (only the materials'
  // order counts: it is their numbering).
  std::string text = replace_all(kScene, "  - plane: {point: [0, 0, 0.05], normal: [0, 0, 1]}\n    velocity: [0, 0, 0.02]",
                                 "  - velocity: [0, 0, 0.02]  # rising\n    plane: {point: [0, 0, 0.05], normal: [0, 0, 1]}");
  text = replace_all(text, "  - random: {count: 300, min: [0.02, 0.02, 0.08], max: [0.18, 0.18, 0.55], radius: "
                           "{uniform: [0.006, 0.01]}, seed: 3}\n    velocity: {random: {speed: 0.3, seed: 4}}",
                     "  - velocity: {random: {seed: 4, speed: 0.30}}\n    random: {count: 300, min: [0.02, 0.02, 0.08], "
                     "max: [0.18, 0.18, 0.55], radius: {uniform: [0.006, 0.01]}, seed: 3}");
  ASSERT_NE(text, kScene);
  const std::string respelled = dir.write("respelled.yaml", text);
  EXPECT_EQ(marbles("run " + respelled + common + given + " --out " + dir.path() + "/respelled" + ck, &err), 0) << err;
  ASSERT_EQ(marbles("run " + scene + common + alike + " --out " + cut + ck, &err), 0) << err;
  expect_same_output(whole, cut);
}

// A checkpoint of an earlier build holds the fingerprint of the texts (the
// scene file's bytes, then each --set text with its NUL): it resumes with
// the same texts still, and only with them.
TEST_F(Checkpoints, CheckpointsOfTheTextsStillResume) {
  const test::ScratchDir dir("ck_texts");
  const std::string scene = dir.write("s.yaml", kScene);
  ASSERT_EQ(marbles("run " + scene + " --quiet --backend cpu --set time.dt=5e-4 --duration 0.05 --out " + dir.path() +
                    "/o"),
            0);
  const std::string ck = dir.path() + "/o/checkpoints/step_000100.mck";
  std::string bytes = slurp(ck);
  std::uint64_t texts = fnv1a(kScene, std::strlen(kScene));
  texts = fnv1a("time.dt=5e-4", 13, texts);
  std::memcpy(bytes.data() + 8 + 4 + 16 + 4 + 4, &texts, 8);  // after magic, format, version, real and wall sizes
  const std::uint64_t sum = fnv1a(bytes.data(), bytes.size() - 8);
  std::memcpy(bytes.data() + bytes.size() - 8, &sum, 8);
  std::ofstream(ck, std::ios::binary) << bytes;
  std::string err;
  EXPECT_EQ(marbles("run " + scene + " --quiet --backend cpu --set time.dt=0.0005 --out " + dir.path() +
                        "/o --restart " + ck,
                    &err),
            2);
  EXPECT_NE(err.find("belongs to another scene"), std::string::npos) << err;
  EXPECT_EQ(marbles("run " + scene + " --quiet --backend cpu --set time.dt=5e-4 --out " + dir.path() +
                        "/o --restart " + ck,
                    &err),
            0)
      << err;
}

// The watchdog: an injected non-finite velocity (test hook) is rolled back
// and the step redone; the run finishes and counts the rollback.
TEST_F(Checkpoints, WatchdogRepairsAnInjectedFault) {
  const test::ScratchDir dir("ck_watchdog");
  const std::string scene = dir.write("s.yaml", kScene);
  std::string err;
  ASSERT_EQ(marbles("run " + scene + " --quiet --backend cpu --out " + dir.path() + "/o", &err, "MARBLES_FAULT_NAN_STEP=100"),
            0)
      << err;
  EXPECT_NE(err.find("watchdog: step 100: non-finite state (sphere 0); rolled back"), std::string::npos) << err;
  const auto summary = summary_of(dir.path() + "/o/summary.json");
  EXPECT_TRUE(summary.at("rollbacks").is_number_integer()) << summary;  // a count
  EXPECT_EQ(summary.at("rollbacks"), 1);
}

// The other invariants: a kick of 100 radii per step (a finite blow-up) is
// an energy jump, a sphere put beyond a wall went through it; both are
// rolled back and the run finishes.
TEST_F(Checkpoints, WatchdogCatchesAnEnergyJumpAndAnEscape) {
  const test::ScratchDir dir("ck_watchdog_kinds");
  const std::string scene = dir.write("s.yaml", kScene);
  std::string err;
  ASSERT_EQ(marbles("run " + scene + " --quiet --backend cpu --out " + dir.path() + "/kick", &err,
                    "MARBLES_FAULT_KICK_STEP=80"),
            0)
      << err;
  EXPECT_NE(err.find("watchdog: step 80: kinetic energy jumped from "), std::string::npos) << err;
  EXPECT_EQ(summary_of(dir.path() + "/kick/summary.json").at("rollbacks"), 1) << err;
  ASSERT_EQ(marbles("run " + scene + " --quiet --backend cpu --out " + dir.path() + "/escape", &err,
                    "MARBLES_FAULT_ESCAPE_STEP=90"),
            0)
      << err;
  EXPECT_NE(err.find("watchdog: step 90: 1 sphere(s) went through a wall"), std::string::npos) << err;
  EXPECT_EQ(summary_of(dir.path() + "/escape/summary.json").at("rollbacks"), 1) << err;
}

// No false alarms where walls inject energy: a spinning drum and a ball
// ploughing through a bed at 2 m/s (plus the rising floor of kScene, which
// every other test here runs).
TEST_F(Checkpoints, WatchdogStaysQuietWhereWallsDoWork) {
  const test::ScratchDir dir("ck_watchdog_quiet");
  const std::string bed = R"(format: 1
name: quiet
time: {duration: 0.5, dt: 1.0e-3, substeps: 2}
effects: [gravity, collisions, walls, restitution, friction]
materials:
  steel: {density: 7800, restitution: 0.9, friction: 0.5}
particles:
  - lattice: {min: [-0.1, -0.08, -0.15], max: [0.1, 0.08, 0.0], spacing: 0.021, radius: 0.01}
    velocity: {random: {speed: 0.5, seed: 1}}
walls:
)";
  const std::string drum = dir.write("drum.yaml", bed + R"(  - cylinder: {base: [0, -0.1, 0], axis: [0, 1, 0], radius: 0.2, length: 0.2, inside: true, angular_velocity: 8.0}
  - plane: {point: [0, -0.1, 0], normal: [0, 1, 0]}
  - plane: {point: [0, 0.1, 0], normal: [0, -1, 0]}
)");
  const std::string plough = dir.write("plough.yaml", bed + R"(  - plane: {point: [0, 0, -0.16], normal: [0, 0, 1]}
  - sphere: {centre: [-0.4, 0, -0.1], radius: 0.08}
    velocity: [2, 0, 0]
)");
  for (const std::string& scene : {drum, plough}) {
    std::string err;
    const std::string out = dir.path() + "/" + fs::path(scene).stem().string();
    ASSERT_EQ(marbles("run " + scene + " --quiet --backend cpu --out " + out, &err), 0) << err;
    EXPECT_EQ(err.find("watchdog"), std::string::npos) << scene << ": " << err;
    EXPECT_EQ(summary_of(out + "/summary.json").at("rollbacks"), 0) << scene;
  }
}

// A stop request (SIGINT, SIGTERM; raised by a test hook after step 130):
// the run ends that step, writes a checkpoint, exits 1 with the command that
// resumes it, and the resumed run equals the run that was never stopped.
TEST_F(Checkpoints, StopRequestCheckpointsAndResumes) {
  const test::ScratchDir dir("ck_stop");
  const std::string scene = dir.write("s.yaml", kScene);
  ASSERT_EQ(marbles("run " + scene + " --quiet --backend cpu --out " + dir.path() + "/whole"), 0);
  for (const std::string sig : {"INT", "TERM"}) {
    const std::string out = dir.path() + "/stopped_" + sig;
    std::string err;
    EXPECT_EQ(marbles("run " + scene + " --quiet --backend cpu --out " + out, &err, "MARBLES_FAULT_SIGNAL=" + sig + "@130"),
              1);
    const std::string path = out + "/checkpoints/step_000130.mck";
    EXPECT_NE(err.find("stopped by SIG" + sig + " after step 130 of 300; the state is in " + path), std::string::npos)
        << err;
    EXPECT_FALSE(fs::exists(out + "/summary.json")) << "a stopped run wrote a summary";
    ASSERT_EQ(marbles("run " + scene + " --quiet --backend cpu --out " + out + " --restart " + path, &err), 0) << err;
    expect_same_output(dir.path() + "/whole", out);
  }
}

// A stop's checkpoint is one of the newest `keep`, as every checkpoint is (it
// left keep + 1), and a folder named with a line break is said in one line,
// the break as \x0a, where the run stops and where it is no folder.
TEST_F(Checkpoints, AStopKeepsTheNewestAndNamesItsFolderInOneLine) {
  const test::ScratchDir dir("ck_stop_keep");
  const std::string scene = dir.write("s.yaml", kScene);
  const std::string out = dir.path() + "/stop\nped";
  std::string err;
  EXPECT_EQ(marbles("run " + scene + " --quiet --backend cpu --set output.checkpoint.keep=2 --out '" + out + "'", &err,
                    "MARBLES_FAULT_SIGNAL=INT@130"),
            1);
  EXPECT_NE(err.find("the state is in " + dir.path() + "/stop\\x0aped/checkpoints/step_000130.mck (resume with"),
            std::string::npos)
      << err;
  std::set<std::string> kept;
  for (const auto& entry : fs::directory_iterator(out + "/checkpoints")) kept.insert(entry.path().filename().string());
  EXPECT_EQ(kept, (std::set<std::string>{"step_000100.mck", "step_000130.mck"}));
  const std::string file = dir.write("f\nile", "a file");
  EXPECT_EQ(marbles("run " + scene + " --quiet --backend cpu --out '" + file + "'", &err), 2);
  EXPECT_NE(err.find("'" + dir.path() + "/f\\x0aile' exists and is not a folder\n"), std::string::npos) << err;
  // A run's closing line, and a run refused a folder holding an earlier run's output.
  const std::string done = dir.path() + "/do\nne", said = dir.path() + "/said.txt";
  const std::string run = "'" + kMarbles + "' run " + scene + " --quiet --backend cpu --duration 0.02 --out '" + done + "'";
  ASSERT_EQ(std::system((run + " > '" + said + "' 2>&1").c_str()), 0);
  EXPECT_NE(slurp(said).find("output: " + dir.path() + "/do\\x0ane  ("), std::string::npos) << slurp(said);
  EXPECT_NE(std::system((run + " > '" + said + "' 2>&1").c_str()), 0);
  EXPECT_NE(slurp(said).find("--out: " + dir.path() + "/do\\x0ane holds the output of an earlier run"),
            std::string::npos)
      << slurp(said);
}

// The command a stopped run says resumes it does, as typed: with the run's
// overrides (one with a blank, quoted for the shell) and duration, it ends as
// the run that was never stopped. Without them it was refused as another
// scene, or stopped at the scene's own duration.
TEST_F(Checkpoints, TheResumeCommandSaidResumes) {
  const test::ScratchDir dir("ck_resume_said");
  const std::string scene = dir.write("s.yaml", kScene);
  const std::string given = " --set time.dt=5e-4 --set 'name=run two' --duration 0.1 --summary-only --backend cpu"
                            " --broadphase seed --threads 1 --limit substeps=1e11";
  ASSERT_EQ(marbles("run " + scene + " --quiet" + given + " --out " + dir.path() + "/whole"), 0);
  const std::string out = dir.path() + "/stopped";
  std::string err;
  ASSERT_EQ(marbles("run " + scene + " --quiet" + given + " --out " + out, &err, "MARBLES_FAULT_SIGNAL=INT@60"), 1);
  const std::size_t from = err.find("(resume with marbles "), to = err.rfind(')');
  ASSERT_NE(from, std::string::npos) << err;
  ASSERT_NE(to, std::string::npos) << err;
  const std::string command = err.substr(from + 21, to - from - 21);
  for (const std::string& part : {std::string("--set time.dt=5e-4"), std::string("--set 'name=run two'"),
                                  std::string("--duration 0.1"), std::string("--summary-only"),
                                  std::string("--backend cpu"), std::string("--broadphase seed"),
                                  std::string("--threads 1"), std::string("--limit substeps=1e11"),
                                  "--restart " + out + "/checkpoints/step_000060.mck"})
    EXPECT_NE(command.find(part), std::string::npos) << part << " in " << command;
  ASSERT_EQ(marbles(command + " --quiet", &err), 0) << command << ": " << err;
  expect_same_output(dir.path() + "/whole", out);
  // A stop asked while the start's output is written (a first image may take long) ends the first step, with
  // its checkpoint: the process was ended at once, exit 130, with nothing to resume.
  const std::string early = dir.path() + "/early";
  ASSERT_EQ(marbles("run " + scene + " --quiet" + given + " --out " + early, &err, "MARBLES_FAULT_SIGNAL=INT@0"), 1)
      << err;
  EXPECT_NE(err.find("stopped by SIGINT after step 1 of 200"), std::string::npos) << err;
  ASSERT_EQ(marbles("run " + scene + " --quiet" + given + " --out " + early + " --restart " + early +
                    "/checkpoints/step_000001.mck", &err),
            0)
      << err;
  expect_same_output(dir.path() + "/whole", early);
}

// A real SIGINT from outside, once the steps run: exit 1, and the checkpoint
// it names resumes.
TEST_F(Checkpoints, InterruptFromOutsideLeavesAResumableCheckpoint) {
  const test::ScratchDir dir("ck_interrupt");
  const std::string scene = dir.write("s.yaml", kScene);
  const std::string out = dir.path() + "/o", err_file = dir.path() + "/err.txt";
  const std::string script = "'" + kMarbles + "' run " + scene + " --quiet --backend cpu --duration 30 --out " + out +
                             " >/dev/null 2>" + err_file + " & pid=$!; for i in $(seq 600); do [ -e " + out +
                             "/checkpoints/step_000050.mck ] && break; sleep 0.05; done; kill -INT $pid; wait $pid";
  const int status = std::system(("bash -c '" + replace_all(script, "'", "'\\''") + "'").c_str());
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 1) << slurp(err_file);
  const std::string err = slurp(err_file);
  const std::size_t at = err.find("the state is in ");
  ASSERT_NE(at, std::string::npos) << err;
  const std::string path = err.substr(at + 16, err.find(' ', at + 16) - (at + 16));
  ASSERT_TRUE(fs::exists(path)) << err;
  const unsigned long steps = std::stoul(path.substr(path.size() - 10, 6));
  std::string err2;
  EXPECT_EQ(marbles("run " + scene + " --quiet --backend cpu --out " + out + " --restart " + path + " --duration " +
                        std::to_string((steps + 20) * 1e-3),
                    &err2),
            0)
      << err2;
}

// One request delivered twice at once (as `timeout` sends SIGTERM to the
// process and then to its group): still a stop with its checkpoint and
// message, not the second request that ends the process at once (exit 143,
// no message, as it was).
TEST_F(Checkpoints, ARequestDeliveredTwiceIsOneRequest) {
  const test::ScratchDir dir("ck_twice");
  const std::string scene = dir.write("s.yaml", kScene);
  const auto stop = [&](const std::string& name, const std::string& signals) {
    const std::string out = dir.path() + "/" + name, err_file = dir.path() + "/" + name + ".txt";
    const std::string script = "'" + kMarbles + "' run " + scene + " --quiet --backend cpu --duration 1000 --out " +
                               out + " >/dev/null 2>" + err_file + " & pid=$!; for i in $(seq 600); do [ -e " + out +
                               "/checkpoints/step_000050.mck ] && break; sleep 0.05; done; " + signals +
                               "; wait $pid; echo $? >>" + err_file;
    std::system(("bash -c '" + replace_all(script, "'", "'\\''") + "'").c_str());
    return slurp(err_file);
  };
  const std::string twice = stop("twice", "kill -TERM $pid; kill -TERM $pid");
  EXPECT_NE(twice.find("marbles: stopped by SIGTERM after step "), std::string::npos) << twice;
  EXPECT_EQ(twice.substr(twice.rfind('\n', twice.size() - 2) + 1), "1\n") << twice;
}

// Internal errors (a test hook raises the signal): one line naming it, exit 1.
TEST_F(Checkpoints, FatalSignalsBecomeAMessageAndExitOne) {
  const test::ScratchDir dir("ck_fatal");
  const std::string scene = dir.write("s.yaml", kScene);
  for (const std::string sig : {"SEGV", "ABRT"}) {
    std::string err;
    EXPECT_EQ(marbles("run " + scene + " --quiet --backend cpu --out " + dir.path() + "/" + sig, &err,
                      "MARBLES_FAULT_SIGNAL=" + sig + "@40"),
              1);
    EXPECT_NE(err.find("marbles: internal error: fatal signal SIG" + sig), std::string::npos) << err;
  }
}

// A fault that every retry meets: exit 1 naming the step and the invariant,
// and a checkpoint of the last good state, from which the run (without the
// fault) goes on exactly as one that never met it.
TEST_F(Checkpoints, WatchdogGivesUpWithTheLastGoodState) {
  const test::ScratchDir dir("ck_watchdog_fail");
  const std::string scene = dir.write("s.yaml", kScene);
  std::string err;
  EXPECT_EQ(marbles("run " + scene + " --quiet --backend cpu --out " + dir.path() + "/o", &err,
                    "MARBLES_FAULT_NAN_STEP=120:all"),
            1);
  EXPECT_NE(err.find("watchdog: step 120: non-finite state (sphere 0) after 3 retries"), std::string::npos) << err;
  const std::string last_good = dir.path() + "/o/checkpoints/step_000119.mck";
  ASSERT_TRUE(fs::exists(last_good)) << err;
  ASSERT_EQ(marbles("run " + scene + " --quiet --backend cpu --out " + dir.path() + "/o --restart " + last_good), 0);
  ASSERT_EQ(marbles("run " + scene + " --quiet --backend cpu --out " + dir.path() + "/whole"), 0);
  expect_same_output(dir.path() + "/whole", dir.path() + "/o");
}

}  // namespace
}  // namespace marbles
