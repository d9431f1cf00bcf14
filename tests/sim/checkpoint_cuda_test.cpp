// tests/sim/checkpoint_cuda_test.cpp — checkpoint and restart on the GPU
// (label gpu): resumed on the device equals the whole device run, and a CPU
// checkpoint continued on the GPU equals the CPU run (the steps are
// bit-identical).
#include <gtest/gtest.h>

#include <string>

#include "core/device.hpp"
#include "tests/require_device.hpp"
#include "tests/sim/checkpoint_cases.hpp"
#include "tests/sim/scene_cases.hpp"

namespace marbles {
namespace {

using namespace test;

// On the GPU: resumed on the device equals the whole device run, and a CPU
// checkpoint continued on the GPU equals the CPU run.
TEST_F(Checkpoints, GpuRestartEqualsTheUninterruptedRun) {
  REQUIRE_DEVICE();
  const test::ScratchDir dir("ck_gpu");
  const std::string scene = dir.write("s.yaml", kScene);
  ASSERT_EQ(marbles("run " + scene + " --quiet --backend cuda --out " + dir.path() + "/gpu"), 0);
  ASSERT_EQ(marbles("run " + scene + " --quiet --backend cuda --duration 0.15 --out " + dir.path() + "/gpu_resumed"), 0);
  ASSERT_EQ(marbles("run " + scene + " --quiet --backend cuda --out " + dir.path() + "/gpu_resumed --restart " +
                    dir.path() + "/gpu_resumed/checkpoints/step_000150.mck"),
            0);
  expect_same_output(dir.path() + "/gpu", dir.path() + "/gpu_resumed");
  ASSERT_EQ(marbles("run " + scene + " --quiet --backend cpu --out " + dir.path() + "/cpu"), 0);
  ASSERT_EQ(marbles("run " + scene + " --quiet --backend cuda --out " + dir.path() + "/cpu_then_gpu --restart " +
                    dir.path() + "/cpu/checkpoints/step_000100.mck"),
            0);
  std::string cpu = physics_of(dir.path() + "/cpu/summary.json"), mixed = physics_of(dir.path() + "/cpu_then_gpu/summary.json");
  cpu.replace(cpu.find("\"cpu\""), 5, "\"cuda\"");  // the backend line says where the rest ran
  EXPECT_EQ(cpu, mixed);
}

// The watchdog on the device (its undo copies device memory, its figures are
// a kernel's): each injected fault (NaN, energy jump, escape) is rolled back
// and redone as on the CPU, bit for bit.
TEST_F(Checkpoints, GpuWatchdogRepairsAsTheCpuDoes) {
  REQUIRE_DEVICE();
  const test::ScratchDir dir("ck_gpu_watchdog");
  const std::string scene = dir.write("s.yaml", kScene);
  const std::pair<std::string, std::string> faults[] = {{"NAN", "non-finite state (sphere 0)"},
                                                        {"KICK", "kinetic energy jumped from"},
                                                        {"ESCAPE", "1 sphere(s) went through a wall"}};
  for (const auto& [fault, reason] : faults) {
    std::string err[2];
    int k = 0;
    for (const std::string backend : {"cpu", "cuda"}) {
      ASSERT_EQ(marbles("run " + scene + " --quiet --backend " + backend + " --out " + dir.path() + "/" + fault + backend,
                        &err[k], "MARBLES_FAULT_" + fault + "_STEP=100"),
                0)
          << err[k];
      ++k;
    }
    for (const std::string& e : err)  // the same rollback (the energies may differ in a last digit: summed in another order)
      EXPECT_NE(e.find("watchdog: step 100: " + reason), std::string::npos) << e;
    std::string cpu = physics_of(dir.path() + "/" + fault + "cpu/summary.json"),
                gpu = physics_of(dir.path() + "/" + fault + "cuda/summary.json");
    cpu.replace(cpu.find("\"cpu\""), 5, "\"cuda\"");
    EXPECT_EQ(cpu, gpu) << fault;
    EXPECT_EQ(summary_of(dir.path() + "/" + fault + "cuda/summary.json").at("rollbacks"), 1) << fault << ": " << gpu;
  }
}

// The contact frames (forces, normals, overlaps, ids) and the sphere frames
// with the per-sphere contact count are the same bytes on both backends.
TEST_F(Checkpoints, GpuContactFramesEqualTheCpus) {
  REQUIRE_DEVICE();
  const test::ScratchDir dir("ck_gpu_contacts");
  const std::string scene = dir.write("s.yaml", kScene);
  const std::string extra = " --set output.contacts.every=50 --set 'output.fields=[radius, velocity, contacts]'";
  for (const std::string backend : {"cpu", "cuda"})
    ASSERT_EQ(marbles("run " + scene + " --quiet --backend " + backend + extra + " --out " + dir.path() + "/" + backend), 0);
  int files = 0;
  for (const std::string folder : {"contacts", "frames"})
    for (const auto& entry : fs::directory_iterator(dir.path() + "/cpu/" + folder)) {
      ++files;
      EXPECT_TRUE(slurp(entry.path()) == slurp(dir.path() + "/cuda/" + folder + "/" + entry.path().filename().string()))
          << folder << "/" << entry.path().filename() << " differs";
    }
  EXPECT_EQ(files, 7 + 16);
}

}  // namespace
}  // namespace marbles
