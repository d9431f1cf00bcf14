// sim/reference.hpp — measuring a run against its scene's known answer.
//
// A scene's `reference:` block (scene::ReferenceSpec) states the physics it
// expects: a rebound height, an acceleration, a conserved quantity. The probe
// watches the run's own states (sampled after steps), measures the same
// quantity and reports the relative error; nothing it reports is copied from
// the reference. docs/accuracy.md lists the kinds and their formulas.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "render/d3.hpp"
#include "sim/scene.hpp"
#include "sim/world.hpp"

namespace marbles {

struct ReferenceResult {
  std::string kind;               // scene::reference_name
  std::vector<double> expected;   // the analytic values (empty for finest)
  std::vector<double> measured;   // the same quantities from the run
  double error = 0;               // relative error; NaN for finest (the study computes it)
  std::string note;               // what was measured, or why it could not be
};

class ReferenceProbe {
 public:
  // Checks that the reference fits the scene (the ball exists, a plane for
  // oblique_rebound, no gravity where a conservation needs none); throws
  // InputError at the `reference:` block otherwise.
  ReferenceProbe(const scene::Scene& scene, const World& initial);

  // Sample every this many steps (1 for the single-ball kinds).
  std::uint64_t every(std::uint64_t total_steps) const;
  void sample(double time, const World& world);
  ReferenceResult finish(double time, const World& world);
  // What the probe has gathered so far (a checkpoint's copy), and back: a
  // probe made from the same scene's initial world then goes on as if it had
  // watched the whole run.
  std::vector<double> progress() const;
  void resume(const std::vector<double>& progress);

 private:
  using Kind = scene::ReferenceSpec::Kind;
  double height(const World& w) const;  // of the ball's lowest point above the floor, along -g
  double up_speed(const World& w) const;

  scene::ReferenceSpec m_spec;
  render::D3 m_down;          // unit vector along g
  double m_g = 0;        // |g|
  render::D3 m_plane_normal;  // oblique_rebound
  double m_h0 = 0;       // drop height of the ball's apex, m
  double m_t_up = 0;     // time to that apex, s
  render::D3 m_x0, m_v0;      // the ball's start
  double m_e0 = 0, m_p_scale = 0;
  render::D3 m_p0;
  // rebound tracking
  double m_last_up = 0;
  std::vector<double> m_recent;  // heights since the last bounce
  bool m_rising = false;
  std::vector<double> m_apexes;
  double m_last_off_floor = 0;
  double m_max_error = 0;
};

}  // namespace marbles
