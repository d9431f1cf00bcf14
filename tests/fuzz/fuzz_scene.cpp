// tests/fuzz/fuzz_scene.cpp — libFuzzer over the scene loader and particle
// generation (built with clang: tests/fuzz/CMakeLists.txt).
//
// Every input must end in a scene, an InputError or a RuntimeFailure: a crash,
// a sanitizer report, an uncaught exception or an input slower than the
// -timeout fails the run. Generation is skipped for scenes that would make
// more than kMaxSpheres spheres (the loader's own caps and the memory guard
// are tested elsewhere; here they would only make the fuzzer slow).
#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>

#include "core/error.hpp"
#include "sim/particles.hpp"
#include "sim/scene.hpp"

namespace {

constexpr double kMaxSpheres = 500;

// An upper estimate of the spheres a scene makes, from its blocks.
double sphere_estimate(const marbles::scene::Scene& s) {
  double total = 0;
  for (const auto& b : s.particles) {
    switch (b.kind) {
      case marbles::scene::ParticleBlock::Kind::list: total += static_cast<double>(b.positions.size()); break;
      case marbles::scene::ParticleBlock::Kind::random: total += static_cast<double>(b.count); break;
      case marbles::scene::ParticleBlock::Kind::lattice: {
        double n = 1;
        for (int a = 0; a < 3; ++a) n *= (double(b.hi[a]) - double(b.lo[a])) / b.spacing + 2;
        total += n;
        break;
      }
      case marbles::scene::ParticleBlock::Kind::csv: total += 1; break;
    }
  }
  return total;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static const std::string path = "/tmp/marbles_fuzz_" + std::to_string(::getpid()) + ".yaml";
  // The input's file goes with the process (libFuzzer ends by exit()).
  static const bool removed_at_exit = std::atexit([] { std::remove(path.c_str()); }) == 0;
  (void)removed_at_exit;
  if (std::FILE* f = std::fopen(path.c_str(), "wb")) {
    std::fwrite(data, 1, size, f);
    std::fclose(f);
  }
  try {
    const marbles::scene::Scene scene = marbles::scene::load_scene(path);
    if (sphere_estimate(scene) <= kMaxSpheres) marbles::scene::generate_particles(scene);
  } catch (const marbles::InputError&) {
  } catch (const marbles::RuntimeFailure&) {
  }
  return 0;
}
