// bench/order_study.cpp — how fast the velocity solve converges on a deep
// pile in the solver's order against a local order (marbles_order_study).
//
// The solver sweeps every contact of a substep colour by colour, forwards
// then backwards, `iterations` times: each sweep is a pass over memory (the
// records and the bodies; docs/architecture.md "Where the pile's step goes
// now"). A local order cuts space into cubes (tiles) and, in each pass,
// sweeps each tile's own contacts (both spheres in the tile, or a sphere and
// a wall) several times before the contacts between tiles once: a GPU block
// could keep a tile's bodies on the chip for its local sweeps, so a pass
// would cost about one sweep's memory traffic. This program measures what
// each order leaves undone, on the CPU, with the solver's per-contact
// functions (prepare_one, warm_start_one, solve_one; friction, and rolling
// resistance with --rolling):
//
//   a pile of close-packed layers (ABC stacking, a rhombus of side x side
//   spheres a layer, radius 1 cm, on a floor, friction 0.5) held still: each
//   substep gives every sphere gravity's kick g h, warm-starts the contacts
//   from the last substep's impulses and solves; the pile does not move
//   between substeps, so the impulses can only converge towards the static
//   ones. After the substeps: the spheres' speeds left (the 99th percentile
//   and the root mean square, in units of g h: 0 is converged, 1 is no
//   support at all; the rhombus's overhanging edges keep the largest near
//   1) and the floor's impulse over the pile's weight (1 when the floor
//   carries it all).
//
//   With --pile cubic, columns of touching spheres on a cubic lattice in a
//   box that touches them (side walls and floor): every speed is then 0 and
//   the floor carries the whole weight once converged. With --pile settled
//   --n N, the benchmark's settled pile of N spheres in its box (from
//   `marbles bench step`'s cache, --cache DIR), which rests under the
//   solver: every speed can fall to 0, the walls carrying part of the
//   weight by friction.
//
//   Besides the solver's order and the local orders: sweeps by height
//   (every contact lowest first, then highest first) or by horizontal
//   bands colour by colour, the solver's order over-relaxed, and
//   conjugate gradients over the solver's sweeps (Order).
//
//   marbles_order_study [--side 30] [--layers 30] [--substeps 30]
//                       [--pile close-packed|cubic|settled] [--n N] [--cache DIR]
//                       [--rolling] [--json]
#include "bench/order_study.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <iostream>
#include <utility>

#include "bench/step_bench.hpp"
#include "broadphase/broadphase.hpp"
#include "narrowphase/contacts.hpp"
#include "narrowphase/solver.hpp"
#include "narrowphase/solver_math.hpp"
#include "sim/step_model.hpp"

namespace marbles::order_study {
namespace {

using narrowphase::Contact;


// The world of w's positions: spheres of radius r and density 2500 kg/m^3
// at rest.
World with_glass_spheres(World w, real r) {
  const std::size_t n = w.position.size();
  const real mass = real(4.0 / 3.0 * M_PI) * r * r * r * 2500;
  w.velocity.assign(n, Vec3{});
  w.angular_velocity.assign(n, Vec3{});
  w.radius.assign(n, r);
  w.inv_mass.assign(n, 1 / mass);
  w.inv_inertia.assign(n, 1 / (real(0.4) * mass * r * r));
  w.material.assign(n, 0);
  return w;
}

// Close-packed layers stacked ABC (each sphere in a pocket of three below),
// a rhombus of side x side spheres a layer, the lowest touching z = 0.
World close_packed_pile(int side, int layers, real r) {
  World w;
  const real sq3 = std::sqrt(real(3)), dz = 2 * r * std::sqrt(real(2) / 3);
  for (int z = 0; z < layers; ++z) {
    const int k = z % 3;
    const real ox = k * r, oy = k * sq3 * r / 3;
    for (int j = 0; j < side; ++j)
      for (int i = 0; i < side; ++i) w.position.push_back(Vec3(i * 2 * r + j * r + ox, j * sq3 * r + oy, r + z * dz));
  }
  return with_glass_spheres(std::move(w), r);
}

// Columns: side x side x layers touching spheres on a cubic lattice, in a
// box whose four side walls and floor touch the outer spheres. Its static
// impulses are known: each column carries the weight above, the floor all
// of it, and every speed is 0.
World cubic_pile(int side, int layers, real r) {
  World w;
  for (int z = 0; z < layers; ++z)
    for (int j = 0; j < side; ++j)
      for (int i = 0; i < side; ++i) w.position.push_back(Vec3(r + 2 * r * i, r + 2 * r * j, r + 2 * r * z));
  return with_glass_spheres(std::move(w), r);
}

// The floor z = 0, and for the cubic pile the box's sides at 0 and side 2r.
std::vector<narrowphase::WallShape> walls_for(bool cubic, int side, real r) {
  std::vector<narrowphase::WallShape> walls(1);
  if (!cubic) return walls;
  const real far = 2 * r * side;
  const Vec3 normals[4] = {{1, 0, 0}, {-1, 0, 0}, {0, 1, 0}, {0, -1, 0}};
  const Vec3 points[4] = {{0, 0, 0}, {far, 0, 0}, {0, 0, 0}, {0, far, 0}};
  for (int k = 0; k < 4; ++k) {
    narrowphase::WallShape w;
    w.point = points[k];
    w.direction = normals[k];
    walls.push_back(w);
  }
  return walls;
}

// Each tile's contacts (colour-major, as the colouring sorted them: the
// solver's own cubes, split_by_cube) and those between tiles.
void split_by_tile(const std::vector<Contact>& contacts, const BodiesView& bodies, real edge,
                   std::vector<std::vector<std::uint32_t>>& tiles, std::vector<std::uint32_t>& between) {
  std::vector<narrowphase::BodyPair> pairs(contacts.size());
  for (std::size_t k = 0; k < contacts.size(); ++k) pairs[k] = {contacts[k].a, contacts[k].b};
  narrowphase::CubeSplit split;
  narrowphase::split_by_cube(pairs.data(), static_cast<std::uint32_t>(pairs.size()), bodies.position, edge, split);
  for (std::size_t t = 0; t + 1 < split.starts.size(); ++t) {
    tiles.emplace_back();
    for (std::uint32_t i = split.starts[t]; i < split.starts[t + 1]; ++i) tiles.back().push_back(split.own[i].second);
  }
  between = std::move(split.between);
}

constexpr real kRadius = real(0.01), kSubstep = real(1e-3), kGravity = real(9.81);

// The pile's contacts (its spheres given gravity's kick, within the skin of
// 0.001 of a radius) in the colouring's colour-major order.
void find_contacts(Pile& p, real r) {
  const real h = kSubstep, g = kGravity;
  World& w = p.world;
  BodiesView view = w.view();
  const std::size_t n = view.count;
  const std::vector<narrowphase::PairCoefficients> coefficients{{0, real(0.5), p.rolling ? real(0.05) : 0, 0}};
  const narrowphase::PairTable table{coefficients.data(), 1};
  std::vector<broadphase::Pair> pairs;
  broadphase::make_home_cell_cpu()->find_pairs({view.position, view.radius, n}, real(0.001) * r, pairs);
  for (Vec3& v : w.velocity) v = Vec3(0, 0, -g * h);  // the contacts of spheres given gravity's kick
  std::vector<real> reach;
  narrowphase::contact_reaches(view, h, reach);
  narrowphase::sphere_contacts(view, pairs.data(), pairs.size(), table, h, reach.data(), p.contacts);
  narrowphase::wall_contacts(view, p.walls, table, h, reach.data(), p.contacts);
  narrowphase::ContactColouring colouring;
  colouring.colour_and_sort(p.contacts, n, p.ranges, nullptr, nullptr, 0);
  for (Vec3& v : w.velocity) v = Vec3{};
}

}  // namespace

Pile make_pile(PileKind kind, int side, int layers, bool rolling) {
  const bool cubic = kind == PileKind::cubic;
  const real r = kRadius;
  Pile p;
  p.world = cubic ? cubic_pile(side, layers, r) : close_packed_pile(side, layers, r);
  p.walls = walls_for(cubic, side, r);
  p.rolling = rolling;
  find_contacts(p, r);
  return p;
}

Pile settled_pile(std::size_t n, const std::string& cache_dir, bool rolling) {
  bench::StepBenchOptions options;
  options.scene = "pile";
  options.rolling = rolling;
  options.cache_dir = cache_dir;
  auto [scene, world] = bench::bench_start(options, n, std::cerr);
  Pile p;
  p.world = std::move(world);
  p.rolling = rolling;
  p.walls = compile_step_model(scene, broadphase::kDefaultCpuAlgorithm).wall_shapes;  // the box, as the step has it
  find_contacts(p, p.world.radius.empty() ? kRadius : p.world.radius[0]);
  return p;
}

std::vector<Order> default_orders() {
  return {{"solver 10", 10, 0, 0},         {"solver 20", 20, 0, 0},        {"solver 3", 3, 0, 0},
          {"local 3x4 tile 4", 3, 4, 4},   {"local 3x4 tile 8", 3, 4, 8},  {"local 4x3 tile 6", 4, 3, 6},
          {"local 3x4 tile 12", 3, 4, 12}, {"local 2x10 tile 8", 2, 10, 8}, {"local 1x10 tile 8", 1, 10, 8},
          {"local 10x1 tile 8", 10, 1, 8}, {"height 10", 10, 0, 0, 0},   {"height 3", 3, 0, 0, 0},
          {"height 5", 5, 0, 0, 0},        {"bands 1 x 10", 10, 0, 0, 1}, {"bands 3 x 10", 10, 0, 0, 3},
          {"bands 1 x 5", 5, 0, 0, 1},     {"bands 1 x 3", 3, 0, 0, 1},
          {"solver 10 omega 1.3", 10, 0, 0, -1, 1.3}, {"solver 10 omega 1.6", 10, 0, 0, -1, 1.6},
          {"solver 6 omega 1.3", 6, 0, 0, -1, 1.3},   {"solver 6 omega 1.6", 6, 0, 0, -1, 1.6},
          {"solver 6 omega 1.8", 6, 0, 0, -1, 1.8},   {"nncg 10", 10, 0, 0, -1, 0, 1},
          {"nncg 6", 6, 0, 0, -1, 0, 1},              {"nncg 5", 5, 0, 0, -1, 0, 1},
          {"nncg in sweeps 10", 10, 0, 0, -1, 0, 2},  {"nncg in sweeps 6", 6, 0, 0, -1, 0, 2},
          {"nncg in sweeps 5", 5, 0, 0, -1, 0, 2},   {"nncg 5 cap 0.4", 5, 0, 0, -1, 0, 1, 0.4},
          {"nncg 5 cap 0.7", 5, 0, 0, -1, 0, 1, 0.7}, {"nncg by bodies 10", 10, 0, 0, -1, 0, 3},
          {"nncg by bodies 5", 5, 0, 0, -1, 0, 3},    {"nncg by bodies 5 cap 0.4", 5, 0, 0, -1, 0, 3, 0.4},
          {"nncg by bodies 6 tail 2", 6, 0, 0, -1, 0, 3, 1, 2}, {"nncg by bodies 7 tail 3", 7, 0, 0, -1, 0, 3, 1, 3},
          {"nncg by bodies 10 tail 3", 10, 0, 0, -1, 0, 3, 1, 3}};
}

namespace {

template <bool Rolling>
Result run_with(const Order& o, Pile& pile, int substeps) {
  const real r = kRadius, h = kSubstep, g = kGravity;
  const std::vector<Contact>& found = pile.contacts;
  BodiesView view = pile.world.view();
  const std::size_t n = view.count, m = found.size();
  Result res;
  std::vector<std::vector<std::uint32_t>> tiles;
  std::vector<std::uint32_t> between;
  if (o.local > 0) split_by_tile(found, view, o.tile * 2 * r, tiles, between);
  // The order by height: each contact's key, then a stable sort by band
  // (bands of height_band diameters; 0: by the key itself) and, within a
  // band, by colour (the colour-major index order the colouring left).
  std::vector<std::uint32_t> by_height;
  if (o.local == 0 && o.height_band >= 0) {
    std::vector<double> key(m);
    for (std::size_t k = 0; k < m; ++k) {
      const Contact& c = found[k];
      key[k] = narrowphase::is_wall(c.b) ? double(view.position[c.a].z)
                                         : 0.5 * (double(view.position[c.a].z) + double(view.position[c.b].z));
      if (o.height_band > 0) key[k] = std::floor(key[k] / (o.height_band * 2 * double(r)));
    }
    by_height.resize(m);
    for (std::uint32_t k = 0; k < m; ++k) by_height[k] = k;
    std::stable_sort(by_height.begin(), by_height.end(), [&](std::uint32_t x, std::uint32_t y) { return key[x] < key[y]; });
  }
  res.tiles = tiles.size();
  res.between = m ? double(between.size()) / m : 0;
  std::vector<Contact> cs = found;
  for (Contact& c : cs) c.normal_impulse = 0, c.tangent_impulse = Vec3{}, c.rolling_impulse = Vec3{};
  std::vector<narrowphase::SolverBody> bodies(n);
  narrowphase::SolverBody* b = bodies.data();
  const real inv_h = 1 / h;
  auto solve = [&](std::uint32_t k) { narrowphase::solve_one<true, Rolling>(cs[k], b, inv_h); };
  // The conjugate gradients' step of one contact: its impulses, and its
  // bodies through them.
  auto take_step = [&](Contact& c, real add_n, const Vec3& add_t) {
    c.normal_impulse += add_n;
    c.tangent_impulse += add_t;
    narrowphase::BodyState A = narrowphase::load_body(b, c.a, c), B = narrowphase::load_body(b, c.b, c);
    narrowphase::apply_impulse(c, A, B, c.normal * add_n + add_t);
    narrowphase::store_body(b, c.a, A);
    narrowphase::store_body(b, c.b, B);
  };
  // The conjugate gradients' beta after sweep p: the ratio of its squared
  // change to the last sweep's, 0 (a restart) past 1 or without a last.
  auto next_beta = [cap = o.beta_cap](double norm, double last_norm, int p) {
    const double beta = p > 0 && last_norm > 0 ? norm / last_norm : 0;
    return beta > 1 ? 0 : std::min(beta, cap);
  };
  auto sweep = [&](const std::vector<std::uint32_t>& list, bool backwards) {
    if (backwards) std::for_each(list.rbegin(), list.rend(), solve);
    else std::for_each(list.begin(), list.end(), solve);
  };
  // Pass p in the solver's order: index order, backwards on odd passes.
  auto solver_pass = [&](int p) {
    for (std::uint32_t k = 0; k < m; ++k) solve(p % 2 == 0 ? k : std::uint32_t(m - 1 - k));
  };
  // The conjugate gradients' arrays, made once (outside the timed substeps'
  // allocations): each sweep's change (delta: the impulses or velocities
  // before it, then its change) and the directions, 0 at each substep's
  // start. Form 3 also steps the rolling impulses and moves the bodies by
  // their own direction.
  const bool by_bodies = o.nncg == 3;
  const std::size_t mc = o.nncg > 0 ? m : 0, mr = by_bodies ? m : 0, nb = by_bodies ? n : 0;
  std::vector<real> delta_n(mc), dir_n(mc);
  std::vector<Vec3> delta_t(mc), dir_t(mc), delta_r(mr), dir_r(mr);
  std::vector<Vec3> before_v(nb), before_w(nb), dir_v(nb), dir_w(nb);
  const auto t0 = std::chrono::steady_clock::now();
  for (int s = 0; s < substeps; ++s) {
    for (std::size_t i = 0; i < n; ++i) {  // at rest, then gravity's kick
      view.velocity[i] = Vec3(0, 0, -g * h);
      view.angular_velocity[i] = Vec3{};
      bodies[i] = narrowphase::gather_solver_body(view, i);
    }
    for (Contact& c : cs) narrowphase::prepare_one(c, b);
    for (const Contact& c : cs) narrowphase::warm_start_one<true, Rolling>(c, b);
    // Over-relaxed: the normal and tangential masses times omega make each
    // step of solve_normal and solve_friction omega times the solver's
    // (with omega 1 the same bits); the rolling mass as the solver's.
    if (o.omega > 0)
      for (Contact& c : cs) c.normal_mass *= real(o.omega), c.tangent_mass *= real(o.omega);
    std::fill(dir_n.begin(), dir_n.end(), real(0));
    for (std::vector<Vec3>* d : {&dir_t, &dir_r, &dir_v, &dir_w}) std::fill(d->begin(), d->end(), Vec3{});
    if (o.nncg == 2) {  // the momentum taken contact by contact within the sweep, right after its solve
      double last_norm = 0, beta = 0;  // beta of the two sweeps before this one
      for (int p = 0; p < o.passes; ++p) {
        double norm = 0;
        const bool step = beta > 0 && p + 1 < o.passes;
        for (std::uint32_t i = 0; i < m; ++i) {
          const std::uint32_t k = p % 2 == 0 ? i : std::uint32_t(m - 1 - i);
          Contact& c = cs[k];
          const real before_n = c.normal_impulse;
          const Vec3 before_t = c.tangent_impulse;
          solve(k);
          const real dn = c.normal_impulse - before_n;
          const Vec3 dt = c.tangent_impulse - before_t;
          norm += double(dn) * double(dn) + double(dot(dt, dt));
          const real add_n = real(beta) * dir_n[k];
          const Vec3 add_t = dir_t[k] * real(beta);
          if (step) take_step(c, add_n, add_t);
          dir_n[k] = add_n + dn;
          dir_t[k] = add_t + dt;
        }
        beta = next_beta(norm, last_norm, p);
        last_norm = norm;
      }
      continue;
    }
    if (o.nncg == 1 || o.nncg == 3) {  // the solver's order, each sweep's change kept as a direction
      double last_norm = 0;
      for (int p = 0; p < o.passes; ++p) {
        for (std::uint32_t k = 0; k < m; ++k) delta_n[k] = cs[k].normal_impulse, delta_t[k] = cs[k].tangent_impulse;
        for (std::size_t k = 0; k < mr; ++k) delta_r[k] = cs[k].rolling_impulse;
        for (std::size_t i = 0; i < nb; ++i) before_v[i] = b[i].v, before_w[i] = b[i].w;
        solver_pass(p);
        double norm = 0;
        for (std::uint32_t k = 0; k < m; ++k) {
          delta_n[k] = cs[k].normal_impulse - delta_n[k];
          delta_t[k] = cs[k].tangent_impulse - delta_t[k];
          norm += double(delta_n[k]) * double(delta_n[k]) + double(dot(delta_t[k], delta_t[k]));
        }
        for (std::size_t k = 0; k < mr; ++k) {
          delta_r[k] = cs[k].rolling_impulse - delta_r[k];
          norm += double(dot(delta_r[k], delta_r[k]));
        }
        const double beta = next_beta(norm, last_norm, p);
        last_norm = norm;
        const bool step = beta > 0 && p + o.tail < o.passes;
        const real be = real(beta);
        for (std::uint32_t k = 0; k < m; ++k) {
          Contact& c = cs[k];
          if (step && by_bodies) c.normal_impulse += be * dir_n[k], c.tangent_impulse += dir_t[k] * be;
          else if (step) take_step(c, be * dir_n[k], dir_t[k] * be);
          dir_n[k] = be * dir_n[k] + delta_n[k];
          dir_t[k] = dir_t[k] * be + delta_t[k];
        }
        for (std::size_t k = 0; k < mr; ++k) {
          if (step) cs[k].rolling_impulse += dir_r[k] * be;
          dir_r[k] = dir_r[k] * be + delta_r[k];
        }
        for (std::size_t i = 0; i < nb; ++i) {
          const Vec3 dv = b[i].v - before_v[i], dw = b[i].w - before_w[i];  // the sweep's change
          if (step) b[i].v += dir_v[i] * be, b[i].w += dir_w[i] * be;
          dir_v[i] = dir_v[i] * be + dv;
          dir_w[i] = dir_w[i] * be + dw;
        }
      }
      continue;
    }
    for (int p = 0; p < o.passes; ++p) {
      if (o.local == 0 && !by_height.empty()) {
        sweep(by_height, p % 2 == 1);
        continue;
      }
      if (o.local == 0) {
        solver_pass(p);
        continue;
      }
      for (const auto& t : tiles)
        for (int l = 0; l < o.local; ++l) sweep(t, (l + p) % 2 == 1);
      sweep(between, p % 2 == 1);
    }
  }
  res.ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count() / substeps;
  std::vector<double> speed(n);
  double sum = 0;
  for (std::size_t i = 0; i < n; ++i) {
    speed[i] = length(bodies[i].v) / (g * h);
    sum += speed[i] * speed[i];
  }
  res.rms = std::sqrt(sum / double(n));
  std::nth_element(speed.begin(), speed.begin() + n * 99 / 100, speed.end());
  res.p99 = speed[n * 99 / 100];
  double floor = 0;
  for (const Contact& c : cs)
    if (narrowphase::is_wall(c.b) && c.normal.z > real(0.5)) floor += c.normal_impulse;
  res.floor_ratio = floor / (double(n) / view.inv_mass[0] * g * h);
  res.velocity.resize(n);
  for (std::size_t i = 0; i < n; ++i) res.velocity[i] = bodies[i].v;
  return res;
}

}  // namespace

Result run(const Order& o, Pile& pile, int substeps) {
  return pile.rolling ? run_with<true>(o, pile, substeps) : run_with<false>(o, pile, substeps);
}

}  // namespace marbles::order_study

