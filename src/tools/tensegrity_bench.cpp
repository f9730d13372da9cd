// tensegrity_bench: measurements that print numbers (never timed tests).
// Exit status: 0; 1 when a scene is refused or a run throws; 2 on bad arguments (usage, or an option value
// that is not what it must be, named with the value); 3 when a measured run does not converge.
//   tensegrity_bench steps SCENE [--set key=value]... [--repeat N] [--peaks]
// runs the scene's analysis N times and prints the wall time per solver step (median and minimum
// over the runs), Newton iterations per step, for dynamic runs the real-time factor, and where the
// time of the last run went (forces, contact, constraints, factorization, solve, the rest); with
// --peaks the run also evaluates a full output row after every step, as tensegrity_run does for
// its summary peaks, so that the cost of that tracking shows under "callbacks".
//   tensegrity_bench contact-pair [--repeat N]
// times one strut pair's contact evaluation (evaluateContact, contactGeometry) in dynamics with
// friction, with and without the tangents, and in statics: ns per call, the median over N loops of
// 100000 calls on a two-strut model built in code.
//   tensegrity_bench broad-phase [--repeat N]
// random scenes of 10 to 1000 struts (1 m long, radius 0.02 m, a constant number of struts per m^3)
// with every pair checked: candidates found and the time of BroadPhase::candidates() (the sweep),
// BroadPhase::direct() and of the narrow phase over the candidates (median over N timings).
//   tensegrity_bench plan SCENE --actuators a,b,... (--height H | --values v,...) [options]
// plans with several seeds from the scene's start equilibrium and prints status, planning time,
// equilibrium solves, waypoints and figures per seed and the median planning time; with
// --speed-limit, the time scale (and the largest speed) that keeps the dynamic peaks under the limits.
//   tensegrity_bench work-precision SCENE [--set key=value]... [--dts a,b,..] [--tols a,b,..]
//                                  [--schemes a,b,..] [--ref-dt R] [--csv FILE]
// runs the scene's dynamic analysis with several integrators over a ladder of steps (fixed-step schemes)
// or error tolerances (adaptive ones) and compares each run with a much finer reference
// (generalized-alpha at R, tolerance 1e-10): largest body-position and layer-height errors, largest
// actuation-force error (relative to the reference's largest force), error of the peak contact force,
// of its time and of the contact impulse (time integral of the summed normal forces); with the wall time
// of the run (callbacks excluded). One CSV row per run.
// --mujoco-dts a,b,.. then runs the scene translated into MuJoCo (mujoco_peer.h) over that ladder with each of
// --mujoco-integrators (default euler,implicit,rk4), rows named mujoco_<integrator>, measured the same way;
// --mujoco-contact-force F sets its contact stiffness scale (default: the reference's peak contact force).
// (Only when built with MuJoCo, ACTIVE_TENSEGRITY_HAVE_MUJOCO; without it these options exit with status 2.)
//   tensegrity_bench stress [--quick]
// runs the stability stress cases (tower and quadruplex: fast folding, large steps, bare steel, thin
// struts, slack cables, impulsive actuation; two nearly parallel struts pressed together) and prints one table row per
// case: how it ended, steps, cuts, steps refused for a strut passing through another, peaks, and whether every number is finite.
//   tensegrity_bench lattice [--struts a,b,..] [--max-struts N] [--duration S] [--repeat N] [--pairs all|auto|near]
//                            [--csv FILE] [--set key=value]... [--print-scene]
// lattices of quadruplex cells of about 10 to 500 struts (lattice.cpp), each run dynamically with contact: one row per
// size (sizes, Newton matrix non-zeros, us per step and its breakdown, peak contacts) and the fitted exponent of
// the time per step against the number of struts.
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <random>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include "active_tensegrity/core/analysis.h"
#include "active_tensegrity/core/broad_phase.h"
#include "active_tensegrity/core/contact.h"
#include "active_tensegrity/core/scene.h"
#include "active_tensegrity/core/statics.h"
#include "active_tensegrity/planning/folding_planner.h"
#include "cli.h"
#include "lattice.h"
#ifdef ACTIVE_TENSEGRITY_HAVE_MUJOCO
#include "mujoco_peer.h"
#endif

namespace at = active_tensegrity::core;
namespace tools = active_tensegrity::tools;
using tools::splitList;

// Heap allocations are counted by interposing glibc's malloc family in this executable (the core and
// Eigen allocate through them; operator new does too): `steps` reports them per step. Not with
// AddressSanitizer, which replaces malloc itself (this one would run before its initialization).
#ifndef __SANITIZE_ADDRESS__
#define ACTIVE_TENSEGRITY_COUNT_ALLOCATIONS
#endif
namespace
{
std::atomic<long> g_allocations{ 0 };
}
#ifdef ACTIVE_TENSEGRITY_COUNT_ALLOCATIONS
extern "C"
{
  void* __libc_malloc(size_t size);
  void* __libc_calloc(size_t n, size_t size);
  void* __libc_realloc(void* p, size_t size);
}
extern "C"
{
  void* malloc(size_t size)
  {
    g_allocations.fetch_add(1, std::memory_order_relaxed);
    return __libc_malloc(size);
  }
  void* calloc(size_t n, size_t size)
  {
    g_allocations.fetch_add(1, std::memory_order_relaxed);
    return __libc_calloc(n, size);
  }
  void* realloc(void* p, size_t size)
  {
    g_allocations.fetch_add(1, std::memory_order_relaxed);
    return __libc_realloc(p, size);
  }
}
#endif

namespace
{
const char* kUsage =
    "usage: tensegrity_bench steps SCENE.yaml [--set key=value]... [--repeat N] [--peaks]\n"
    "  Runs the scene's analysis N times (default 5) and prints wall time and Newton iterations per step\n"
    "  and where the time goes; --peaks also evaluates a full output row after every step (as\n"
    "  tensegrity_run's summary peaks do).\n"
    "       tensegrity_bench contact-pair [--repeat N]\n"
    "  Times one strut pair's contact evaluation (dynamic with friction, with and without tangents;\n"
    "  static): ns per call, median over N (default 5) loops of 100000 calls.\n"
    "       tensegrity_bench broad-phase [--repeat N]\n"
    "  Random scenes of 10 to 1000 struts with all pairs checked: candidates and the time of the broad\n"
    "  phase (sweep and direct) and of the narrow phase over the candidates, median over N (default 5).\n"
    "       tensegrity_bench plan SCENE.yaml --actuators a,b,.. (--height H | --values v,..) [--set key=value]...\n"
    "                        [--clearance M] [--contact-limit N] [--bending-limit PA] [--speed V] [--accel A]\n"
    "                        [--planner NAME] [--time-limit S] [--seeds K] [--speed-limit]\n"
    "  Plans from the scene's start equilibrium with seeds 1..K (default 5): status, planning time,\n"
    "  equilibrium solves, figures per seed, the median time; --contact-limit allows contact up to N newtons\n"
    "  (else --clearance, default 0.005 m); --speed-limit (seed 1) finds the time scale that keeps the\n"
    "  dynamic contact force and bending stress under the limits and prints the resulting largest speed.\n"
    "       tensegrity_bench work-precision SCENE.yaml [--set key=value]... [--dts a,b,..] [--tols a,b,..]\n"
    "                        [--schemes a,b,..] [--ref-dt R] [--csv FILE]\n"
    "  Integrators (newmark_paper, trapezoidal, generalized_alpha, newmark_paper_modified_newton over the\n"
    "  steps, default 1e-3,5e-4,2e-4,1e-4 s; adaptive_newmark_paper, adaptive_generalized_alpha over the\n"
    "  error tolerances, default 1e-3,1e-4,1e-5,1e-6 m) against a reference at R (default 2.5e-5 s):\n"
    "  errors and wall time per run (CSV to FILE or stdout).\n"
    "                        [--mujoco-dts a,b,..] [--mujoco-integrators euler,implicit,rk4]\n"
    "                        [--mujoco-contact-force F]\n"
    "  --mujoco-dts adds the scene in MuJoCo over that ladder (rows mujoco_<integrator>; contact\n"
    "  stiffness from F, default the reference's peak force; only when built with MuJoCo).\n"
    "       tensegrity_bench stress [--quick]\n"
    "  The stability stress cases (docs/benchmarks.md): one row per case; --quick runs the short ones.\n"
    "       tensegrity_bench lattice [--struts a,b,..] [--width W] [--max-struts N] [--duration S] [--repeat N]\n"
    "                        [--pairs all|auto|near] [--csv FILE] [--set key=value]... [--print-scene]\n"
    "  Quadruplex-cell lattices (default about 10, 20, 50, 100, 200, 500 struts) run dynamically into contact:\n"
    "  us per step (median over N runs, default 3), its breakdown, sizes, and the fitted exponent vs struts;\n"
    "  pairs: auto (default: every pair sharing no node), all (the same pairs listed), near (same or adjacent cells);\n"
    "  --width W: strips W cells across instead of nearly square lattices; --print-scene prints the scenes (YAML).\n";

using Clock = std::chrono::steady_clock;

double seconds(Clock::time_point t0, Clock::time_point t1)
{
  return std::chrono::duration<double>(t1 - t0).count();
}

// keeps a result alive so that the timed calls cannot be dropped
volatile double g_sink = 0.0;

// median over `repeat` samples of the time of one call of f (s); each sample runs f `calls` times
template <typename F>
double medianPerCall(const F& f, int calls, int repeat)
{
  std::vector<double> t;
  for (int r = 0; r < repeat; ++r)
  {
    const Clock::time_point t0 = Clock::now();
    for (int i = 0; i < calls; ++i)
      f();
    t.push_back(seconds(t0, Clock::now()) / calls);
  }
  std::sort(t.begin(), t.end());
  return t[t.size() / 2];
}

// calls per sample so that one sample takes about `target` seconds (at least 1)
template <typename F>
int callsFor(const F& f, double target)
{
  const Clock::time_point t0 = Clock::now();
  f();
  const double once = std::max(1e-9, seconds(t0, Clock::now()));
  return std::max(1, static_cast<int>(target / once));
}

at::Body strut(const std::string& name, double length, double radius, double youngs_modulus, double poisson_ratio)
{
  at::Body b;
  b.name = name;
  b.kind = at::BodyKind::kStrut;
  b.length = length;
  at::StrutLayer layer;
  layer.material = "bench";
  layer.outer_radius = radius;
  layer.density = 2000.0;
  layer.youngs_modulus = youngs_modulus;
  layer.poisson_ratio = poisson_ratio;
  b.layers.push_back(layer);
  b.mass = layer.density * M_PI * radius * radius * length;
  const double jt = b.mass * (3.0 * radius * radius + length * length) / 12.0;
  b.inertia = at::Vec3(jt, jt, 0.5 * b.mass * radius * radius);
  return b;
}

// Theta_dot tangent to the unit sphere at theta
at::Vec4 tangentRate(const at::Vec4& theta, const at::Vec4& rate)
{
  return rate - theta.dot(rate) * theta;
}

int contactPair(int repeat)
{
  // two free rubber-coated struts (as test_contact's twoStruts), crossing at about 75 degrees with the
  // closest points inside both axes and 2 mm of overlap, sliding across each other faster than v1
  at::Model m;
  m.name = "pair";
  m.bodies.push_back(strut("A", 1.2, 0.04, 2.0e7, 0.45));
  m.bodies.push_back(strut("B", 1.0, 0.05, 2.0e7, 0.45));
  at::finalizeModel(m);
  m.contact.enabled = true;
  m.contact.friction = 0.1;
  m.contact.restitution = 0.5;
  m.contact.stick_velocity = 0.01;
  m.contact.slip_velocity = 0.1;
  m.checked_pairs.push_back(at::makeStrutPair(m, 0, 1));
  const at::Vec3 ax = at::Vec3(1.0, 0.2, -0.1).normalized(), bx = at::Vec3(0.1, 1.0, 0.3).normalized();
  const at::Vec3 n = ax.cross(bx).normalized();
  const double s1 = 0.2, s2 = -0.15, overlap = 2e-3;
  const at::Vec3 p1 = at::Vec3(0.1, -0.2, 0.3) + s1 * ax;
  const at::Vec3 p2 = p1 - (0.04 + 0.05 - overlap) * n;
  Eigen::VectorXd q(m.nq), qd(m.nq);
  q.segment<3>(0) = p1 - s1 * ax;
  q.segment<4>(3) = at::thetaFromZAxis(ax);
  q.segment<3>(7) = p2 - s2 * bx;
  q.segment<4>(10) = at::thetaFromZAxis(bx);
  qd.segment<3>(0) = at::Vec3(0.3, -0.1, 0.05);
  qd.segment<4>(3) = tangentRate(q.segment<4>(3), at::Vec4(0.1, -0.2, 0.3, 0.05));
  qd.segment<3>(7) = at::Vec3(-0.2, 0.25, 0.0);
  qd.segment<4>(10) = tangentRate(q.segment<4>(10), at::Vec4(-0.05, 0.1, 0.2, -0.1));
  const double v0 = 0.5;

  at::Model frictionless = m;
  frictionless.contact.friction = 0.0;
  const at::ContactPairState st = at::evaluateContact(m, 0, q, qd, v0, at::ContactMode::kDynamic, nullptr);
  if (!st.active || st.normal_force <= 0.0 || st.slip_speed <= m.contact.slip_velocity)
  {
    std::cerr << "tensegrity_bench: the pair is not in sliding contact\n";
    return 3;
  }
  std::printf("pair: A 1.2 m x r 0.04 m, B 1.0 m x r 0.05 m, E 2e7 Pa, nu 0.45; crossing %.1f deg, region %s\n",
              std::acos(std::abs(ax.dot(bx))) * 180.0 / M_PI,
              st.region == at::ClosestRegion::kInterior ? "interior" : "end/parallel");
  std::printf("state: penetration %.3g m, rate %.3g m/s, F_N %.4g N, slip %.3g m/s (v1 %.3g), F_T %.4g N (mu %.2g)\n",
              st.penetration, st.penetration_rate, st.normal_force, st.slip_speed, m.contact.slip_velocity,
              st.friction_force, m.contact.friction);

  constexpr int kCalls = 100000;
  at::ContactContribution c;
  struct Row
  {
    const char* what;
    double ns;
  };
  std::vector<Row> rows;
  const auto time = [&](const char* what, const auto& f)
  {
    f();  // warm up
    rows.push_back({ what, 1e9 * medianPerCall(f, kCalls, repeat) });
  };
  time("dynamic, friction (slip > v1), force + tangents",
       [&]
       {
         g_sink = g_sink + at::evaluateContact(m, 0, q, qd, v0, at::ContactMode::kDynamic, &c).normal_force +
                  c.stiffness(3, 12) + c.damping(5, 9);
       });
  time("dynamic, friction (slip > v1), state only (out = nullptr)", [&]
       { g_sink = g_sink + at::evaluateContact(m, 0, q, qd, v0, at::ContactMode::kDynamic, nullptr).friction_force; });
  time("dynamic, mu = 0, force + tangents",
       [&]
       {
         g_sink = g_sink + at::evaluateContact(frictionless, 0, q, qd, v0, at::ContactMode::kDynamic, &c).normal_force +
                  c.stiffness(3, 12) + c.damping(5, 9);
       });
  time("static (Hertz), force + tangents",
       [&]
       {
         g_sink = g_sink + at::evaluateContact(m, 0, q, qd, 0.0, at::ContactMode::kStatic, &c).normal_force +
                  c.stiffness(3, 12);
       });
  time("static (Hertz), state only (out = nullptr)", [&]
       { g_sink = g_sink + at::evaluateContact(m, 0, q, qd, 0.0, at::ContactMode::kStatic, nullptr).normal_force; });
  time("narrow phase only (contactGeometry)", [&] { g_sink = g_sink + at::contactGeometry(m, 0, q).gap; });
  std::printf("time per call, median over %d loops of %d calls:\n", repeat, kCalls);
  for (const Row& r : rows)
    std::printf("  %-58s %8.1f ns\n", r.what, r.ns);
  return 0;
}

// n struts of length 1 m and radius 0.02 m, centres uniform in a cube of n / density m^3, random
// axes, every pair checked
at::Model randomStruts(int n, double density, std::mt19937& rng)
{
  at::Model m;
  m.name = "random";
  for (int i = 0; i < n; ++i)
    m.bodies.push_back(strut("S" + std::to_string(i), 1.0, 0.02, 210e9, 0.3));
  at::finalizeModel(m);
  const double side = std::cbrt(n / density);
  std::uniform_real_distribution<double> u(0.0, side);
  std::normal_distribution<double> g(0.0, 1.0);
  m.q0.setZero(m.nq);
  for (const at::Body& b : m.bodies)
  {
    m.q0.segment<3>(b.offset) = at::Vec3(u(rng), u(rng), u(rng));
    m.q0.segment<4>(b.offset + 3) = at::thetaFromZAxis(at::Vec3(g(rng), g(rng), g(rng)));
  }
  m.checked_pairs.reserve(static_cast<size_t>(n) * (n - 1) / 2);
  for (int i = 0; i < n; ++i)
    for (int j = i + 1; j < n; ++j)
      m.checked_pairs.push_back(at::makeStrutPair(m, i, j));
  return m;
}

int broadPhase(int repeat)
{
  constexpr double kDensity = 4.0;  // struts per m^3
  constexpr double kTarget = 0.02;  // s per timing sample
  std::printf("struts 1 m x r 0.02 m, centres uniform in a cube of n / %.0f m^3, all pairs checked, margin 0;\n",
              kDensity);
  std::printf("times: median over %d samples of about %.0f ms each\n", repeat, 1e3 * kTarget);
  std::printf("%6s %8s %6s %7s %8s %6s %9s %12s %12s %12s %12s\n", "n", "pairs", "cand", "contacts", "cand/n", "sweep",
              "setup ms", "candidates", "direct", "narrow/cand", "narrow/all");
  for (int n : { 10, 20, 50, 100, 200, 500, 1000 })
  {
    std::mt19937 rng(n);
    const at::Model m = randomStruts(n, kDensity, rng);
    const Clock::time_point t0 = Clock::now();
    const at::BroadPhase broad(m);
    const double setup = seconds(t0, Clock::now());
    std::vector<int> cand, dir;
    broad.candidates(m.q0, 0.0, cand);
    broad.direct(m.q0, 0.0, dir);
    if (cand != dir)
    {
      std::cerr << "tensegrity_bench: candidates() and direct() disagree at n = " << n << "\n";
      return 3;
    }
    int contacts = 0;
    for (size_t i = 0; i < m.checked_pairs.size(); ++i)
      contacts += at::contactGeometry(m, static_cast<int>(i), m.q0).gap < 0.0 ? 1 : 0;

    const auto f_cand = [&]
    {
      broad.candidates(m.q0, 0.0, cand);
      g_sink = g_sink + cand.size();
    };
    const auto f_direct = [&]
    {
      broad.direct(m.q0, 0.0, dir);
      g_sink = g_sink + dir.size();
    };
    const auto f_narrow = [&]
    {
      double s = 0.0;
      for (int i : cand)
        s += at::contactGeometry(m, i, m.q0).gap;
      g_sink = g_sink + s;
    };
    const auto f_all = [&]
    {
      double s = 0.0;
      for (size_t i = 0; i < m.checked_pairs.size(); ++i)
        s += at::contactGeometry(m, static_cast<int>(i), m.q0).gap;
      g_sink = g_sink + s;
    };
    const double t_cand = medianPerCall(f_cand, callsFor(f_cand, kTarget), repeat);
    const double t_direct = medianPerCall(f_direct, callsFor(f_direct, kTarget), repeat);
    const double t_narrow = medianPerCall(f_narrow, callsFor(f_narrow, kTarget), repeat);
    const double t_all = medianPerCall(f_all, callsFor(f_all, kTarget), repeat);
    std::printf("%6d %8zu %6zu %7d %8.2f %6s %9.2f %9.2f us %9.2f us %9.2f us %9.2f us\n", n, m.checked_pairs.size(),
                cand.size(), contacts, static_cast<double>(cand.size()) / n, broad.usesSweep() ? "yes" : "no",
                1e3 * setup, 1e6 * t_cand, 1e6 * t_direct, 1e6 * t_narrow, 1e6 * t_all);
  }
  return 0;
}

/// "--option value" arguments, walked in order: option() takes the next one, value() the value after it.
class Args
{
public:
  explicit Args(std::vector<std::string> args) : args_(std::move(args)) {}
  bool more() const
  {
    return next_ < args_.size();
  }
  std::string option()
  {
    return args_[next_++];
  }
  std::string value(const std::string& option)
  {
    if (next_ >= args_.size())
      throw std::invalid_argument(option + " needs a value");
    return args_[next_++];
  }

private:
  std::vector<std::string> args_;
  size_t next_ = 0;
};

int plan(const std::string& scene, const std::vector<std::string>& args)
{
  namespace ap = active_tensegrity::planning;
  std::vector<at::Override> overrides;
  ap::PlanRequest req;
  req.max_speeds = { 0.5 };
  req.max_accelerations = { 5.0 };
  req.time_limit = 60.0;
  req.limits.min_clearance = 0.005;
  int seeds = 5;
  bool speed_limit = false;
  Args in(args);
  while (in.more())
  {
    const std::string a = in.option();
    const auto next = [&]() { return in.value(a); };
    if (a == "--set")
      overrides.push_back(at::parseOverride(next()));
    else if (a == "--actuators")
      req.actuators = splitList(next());
    else if (a == "--height")
      req.target_height = std::stod(next());
    else if (a == "--values")
      for (const std::string& v : splitList(next()))
        req.target_values.push_back(std::stod(v));
    else if (a == "--clearance")
      req.limits.min_clearance = std::stod(next());
    else if (a == "--contact-limit")
    {
      req.limits.allow_contact = true;
      req.limits.max_contact_force = std::stod(next());
    }
    else if (a == "--bending-limit")
      req.max_bending_stress = std::stod(next());
    else if (a == "--speed")
      req.max_speeds = { std::stod(next()) };
    else if (a == "--accel")
      req.max_accelerations = { std::stod(next()) };
    else if (a == "--planner")
      req.planner = next();
    else if (a == "--time-limit")
      req.time_limit = std::stod(next());
    else if (a == "--seeds")
      seeds = std::max(1, std::stoi(next()));
    else if (a == "--speed-limit")
      speed_limit = true;
    else
      throw std::invalid_argument("unknown argument '" + a + "'");
  }
  const at::Model model = at::loadScene(scene, overrides);
  at::State start = at::initialState(model);
  at::Model statics = model;
  statics.analysis.type = at::AnalysisType::kStatic;
  at::StaticSolver solver(statics, statics.solver);
  const at::Summary eq = solver.solve(start, start.u);
  if (!eq.ok())
  {
    std::cerr << "tensegrity_bench: no start equilibrium: " << eq.message << "\n";
    return 3;
  }
  std::printf("scene: %s, actuators:", scene.c_str());
  for (const std::string& n : req.actuators)
    std::printf(" %s", n.c_str());
  std::printf(
      "; goal: %s; %s; planner %s, time limit %g s\n",
      req.target_values.empty() ? ("height <= " + std::to_string(req.target_height) + " m").c_str() : "target values",
      req.limits.allow_contact ? ("contact up to " + std::to_string(req.limits.max_contact_force) + " N").c_str() :
                                 ("clearance " + std::to_string(req.limits.min_clearance) + " m").c_str(),
      req.planner.c_str(), req.time_limit);
  std::printf("%5s %-16s %9s %7s %9s %12s %10s %12s\n", "seed", "status", "time s", "solves", "waypoints",
              "final h (m)", "min gap", "peak F_N (N)");
  std::vector<double> times;
  for (int seed = 1; seed <= seeds; ++seed)
  {
    req.seed = static_cast<unsigned>(seed);
    const ap::PlanResult p = ap::planFolding(model, start, req);
    if (p.status == ap::PlanStatus::kInvalidRequest)
    {
      std::cerr << "tensegrity_bench: " << p.message << "\n";
      return 2;
    }
    times.push_back(p.planning_time);
    std::printf("%5d %-16s %9.2f %7ld %9zu %12.4f %10.4f %12.1f\n", seed, ap::toString(p.status), p.planning_time,
                p.equilibrium_solves, p.waypoints.size(), p.final_height, p.min_gap, p.peak_contact_force);
  }
  std::sort(times.begin(), times.end());
  std::printf("median planning time: %.2f s over %d seeds\n", times[times.size() / 2], seeds);
  if (speed_limit)
  {
    req.seed = 1;
    req.verify_dynamics = req.find_speed_limit = true;
    const ap::PlanResult p = ap::planFolding(model, start, req);
    double vmax = 0.0;
    for (const auto& v : p.velocities)
      for (double x : v)
        vmax = std::max(vmax, std::abs(x));
    std::printf("speed limit (seed 1, dt %g s): %s; time scale %.3f after %d dynamic runs -> largest actuation speed "
                "%.4f m/s (planned at %.4f m/s); dynamic peaks: contact %.1f N, bending %.1f MPa; within limits: %s\n",
                model.solver.dt, ap::toString(p.status), p.time_scale, p.dynamic_runs, vmax, req.max_speeds[0],
                p.dynamic_peak_contact_force, 1e-6 * p.dynamic_peak_bending_stress,
                p.dynamics_within_limits ? "yes" : "no");
  }
  return 0;
}

struct Trace
{
  std::vector<double> t, force;
  std::vector<std::vector<double>> heights;  // per output: the layer heights (or the height)
  std::vector<Eigen::VectorXd> q;            // per output: the coordinates
  double peak = 0.0, peak_t = 0.0;           // largest normal contact force over every step, and when
  double impulse = 0.0;                      // time integral of the summed normal contact forces (N s)
  at::RunResult result;
};

Trace traceRun(const at::Model& model)
{
  Trace tr;
  std::vector<int> height_cols;
  const std::vector<std::string> cols = at::csvColumns(model);
  for (size_t i = 0; i < cols.size(); ++i)
    if (cols[i].rfind("height_", 0) == 0)
      height_cols.push_back(static_cast<int>(i));
  if (height_cols.empty())
    height_cols.push_back(3);  // height
  double last_t = 0.0, last_sum = 0.0;
  tr.result = at::runAnalysis(
      model,
      [&](const at::State& s)
      {
        const std::vector<double> row = at::csvRow(model, s);
        tr.t.push_back(row[0]);
        tr.force.push_back(row[2]);
        std::vector<double> h;
        for (int c : height_cols)
          h.push_back(row[c]);
        tr.heights.push_back(h);
        tr.q.push_back(s.q);
      },
      {},
      [&](const at::State& s)
      {
        double sum = 0.0;
        for (const at::ContactPairState& c : at::activeContacts(model, s))
        {
          sum += c.normal_force;
          if (c.normal_force > tr.peak)
          {
            tr.peak = c.normal_force;
            tr.peak_t = s.t;
          }
        }
        tr.impulse += 0.5 * (sum + last_sum) * (s.t - last_t);  // trapezoid over the steps taken
        last_t = s.t;
        last_sum = sum;
      });
  return tr;
}

/// One integrator of the work-precision benchmark; adaptive ones run over the tolerance ladder.
struct Scheme
{
  const char* name;
  at::Integrator integrator;
  double gamma, beta, rho;
  bool reuse, adaptive;
};

const std::vector<Scheme>& workPrecisionSchemes()
{
  static const std::vector<Scheme> schemes = {
    { "newmark_paper", at::Integrator::kNewmark, 0.6, 0.3025, 0.8, false, false },
    { "trapezoidal", at::Integrator::kNewmark, 0.5, 0.25, 0.8, false, false },
    { "generalized_alpha", at::Integrator::kGeneralizedAlpha, 0.5, 0.25, 0.8, false, false },
    { "newmark_paper_modified_newton", at::Integrator::kNewmark, 0.6, 0.3025, 0.8, true, false },
    { "adaptive_newmark_paper", at::Integrator::kNewmark, 0.6, 0.3025, 0.8, true, true },
    { "adaptive_generalized_alpha", at::Integrator::kGeneralizedAlpha, 0.5, 0.25, 0.8, true, true },
  };
  return schemes;
}

/// A run's errors against the reference, on the common output grid.
struct Errors
{
  double position = 0.0;   // largest body-position error (m)
  double height = 0.0;     // largest layer-height error (m)
  double force = 0.0;      // largest actuation-force error / the reference's largest force
  double peak = 0.0;       // relative error of the peak contact force
  double peak_time = 0.0;  // s
  double impulse = 0.0;    // relative error of the contact impulse
};

Errors compare(const at::Model& model, const Trace& tr, const Trace& ref)
{
  double ref_fmax = 1e-12;
  for (double f : ref.force)
    ref_fmax = std::max(ref_fmax, std::abs(f));
  Errors e;
  const size_t n = std::min(tr.t.size(), ref.t.size());
  for (size_t k = 0; k < n; ++k)
  {
    for (const at::Body& b : model.bodies)
      e.position = std::max(e.position, (tr.q[k].segment<3>(b.offset) - ref.q[k].segment<3>(b.offset)).norm());
    for (size_t j = 0; j < tr.heights[k].size(); ++j)
      e.height = std::max(e.height, std::abs(tr.heights[k][j] - ref.heights[k][j]));
    e.force = std::max(e.force, std::abs(tr.force[k] - ref.force[k]) / ref_fmax);
  }
  e.peak = ref.peak > 0.0 ? std::abs(tr.peak - ref.peak) / ref.peak : 0.0;
  e.peak_time = std::abs(tr.peak_t - ref.peak_t);
  e.impulse = ref.impulse > 0.0 ? std::abs(tr.impulse - ref.impulse) / ref.impulse : 0.0;
  return e;
}

int workPrecision(const std::string& scene, const std::vector<std::string>& args)
{
  std::vector<at::Override> overrides;
  std::vector<double> dts = { 1e-3, 5e-4, 2e-4, 1e-4 };
  std::vector<double> tols = { 1e-3, 1e-4, 1e-5, 1e-6 };
  std::vector<std::string> names;
  double ref_dt = 2.5e-5;
  std::string csv_path;
#ifdef ACTIVE_TENSEGRITY_HAVE_MUJOCO
  std::vector<double> mujoco_dts;  // the MuJoCo peer's ladder (none: not run)
  std::vector<std::string> mujoco_integrators = { "euler", "implicit", "rk4" };
  double mujoco_force = 0.0;  // contact force scale F* (0: the reference's peak)
#endif
  Args in(args);
  while (in.more())
  {
    const std::string a = in.option();
    const auto next = [&]() { return in.value(a); };
    const auto numbers = [&]() { return tools::parsePositiveList(a, next()); };
    if (a == "--set")
      overrides.push_back(at::parseOverride(next()));
    else if (a == "--dts")
      dts = numbers();
    else if (a == "--tols")
      tols = numbers();
    else if (a == "--schemes")
      names = splitList(next());
    else if (a == "--ref-dt")
      ref_dt = tools::parsePositive<double>(a, next());
    else if (a == "--csv")
      csv_path = next();
#ifdef ACTIVE_TENSEGRITY_HAVE_MUJOCO
    else if (a == "--mujoco-dts")
      mujoco_dts = numbers();
    else if (a == "--mujoco-integrators")
      mujoco_integrators = splitList(next());
    else if (a == "--mujoco-contact-force")
      mujoco_force = tools::parsePositive<double>(a, next());
#else
    else if (a == "--mujoco-dts" || a == "--mujoco-integrators" || a == "--mujoco-contact-force")
      throw tools::BadArgument(a + ": tensegrity_bench was built without MuJoCo (libmujoco-dev was not found, or "
                                   "-DACTIVE_TENSEGRITY_WITH_MUJOCO=OFF, when it was configured)");
#endif
    else
      throw std::invalid_argument("unknown argument '" + a + "'");
  }
  std::vector<Scheme> schemes;
  for (const Scheme& sc : workPrecisionSchemes())
    if (names.empty() || std::find(names.begin(), names.end(), sc.name) != names.end())
      schemes.push_back(sc);
  for (const std::string& n : names)
    if (std::none_of(schemes.begin(), schemes.end(), [&](const Scheme& sc) { return n == sc.name; }))
      throw std::invalid_argument("--schemes: unknown scheme '" + n + "'");
  at::Model base = at::loadScene(scene, overrides);
  if (base.analysis.type != at::AnalysisType::kDynamic)
    throw std::invalid_argument("work-precision needs a dynamic analysis (--set analysis.type=dynamic)");
  // a common output grid that every step divides (adaptive runs step onto it)
  double grid = base.analysis.output_interval > 0.0 ? base.analysis.output_interval : 0.01;
  for (double dt : dts)
    grid = std::max(grid, dt);
#ifdef ACTIVE_TENSEGRITY_HAVE_MUJOCO
  for (double dt : mujoco_dts)
    grid = std::max(grid, dt);
#endif
  base.analysis.output_interval = grid;

  const auto configure = [&](const Scheme& sc, double dt, double tol, double error_tol)
  {
    at::Model m = base;
    m.solver.integrator = sc.integrator;
    m.solver.newmark_gamma = sc.gamma;
    m.solver.newmark_beta = sc.beta;
    m.solver.rho_infinity = sc.rho;
    m.solver.reuse_jacobian = sc.reuse;
    m.solver.adaptive = sc.adaptive;
    m.solver.dt = dt;
    m.solver.newton_tolerance = tol;
    if (sc.adaptive)
    {
      m.solver.error_tolerance = error_tol;
      m.solver.newton_tolerance = std::min(tol, 0.1 * error_tol);
    }
    return m;
  };
  const Scheme reference = { "reference", at::Integrator::kGeneralizedAlpha, 0.5, 0.25, 0.8, false, false };
  std::fprintf(stderr, "work-precision: reference (generalized-alpha, dt %g s) ...\n", ref_dt);
  const Trace ref = traceRun(configure(reference, ref_dt, 1e-10, 0.0));
  if (!ref.result.summary.ok())
  {
    std::cerr << "tensegrity_bench: the reference run failed: " << ref.result.summary.message << "\n";
    return 3;
  }

  std::ofstream file;
  if (!csv_path.empty())
  {
    file.open(csv_path);
    if (!file)
      throw std::invalid_argument("cannot write '" + csv_path + "'");
  }
  std::ostream& out = csv_path.empty() ? std::cout : file;
  out << "scheme,dt,tolerance,status,steps,newton_iterations,wall_time,position_error,height_error,force_error,"
         "peak_force_error,peak_time_error,impulse_error,peak_force,reference_peak_force\n";
  const double tol = base.solver.newton_tolerance;
  for (const Scheme& sc : schemes)
    for (double x : sc.adaptive ? tols : dts)
    {
      // adaptive runs start from the scene's dt; dt in the table is then their mean step
      const Trace tr = traceRun(configure(sc, sc.adaptive ? base.solver.dt : x, tol, x));
      const Errors e = compare(base, tr, ref);
      const double wall = tr.result.wall_time - tr.result.callback_time;
      const double dt = sc.adaptive ? base.analysis.duration / std::max(1, tr.result.solver_steps) : x;
      out << sc.name << "," << dt << "," << (sc.adaptive ? x : 0.0) << "," << at::toString(tr.result.summary.status)
          << "," << tr.result.solver_steps << "," << tr.result.summary.iterations << "," << wall << "," << e.position
          << "," << e.height << "," << e.force << "," << e.peak << "," << e.peak_time << "," << e.impulse << ","
          << tr.peak << "," << ref.peak << "\n";
      out.flush();
      std::fprintf(stderr,
                   "  %-30s %s %-8g %-10s wall %7.2f s  position err %.3e m  force err %.3e  peak err %.3e  "
                   "impulse err %.3e\n",
                   sc.name, sc.adaptive ? "tol" : "dt ", x, at::toString(tr.result.summary.status), wall, e.position,
                   e.force, e.peak, e.impulse);
    }
#ifdef ACTIVE_TENSEGRITY_HAVE_MUJOCO
  // the MuJoCo peer over its own ladder, measured against the same reference (docs/benchmarks.md)
  for (const std::string& integrator : mujoco_integrators)
    for (double dt : mujoco_dts)
    {
      tools::MujocoOptions mo;
      mo.integrator = tools::parseMujocoIntegrator(integrator);
      mo.timestep = dt;
      mo.contact_force = mujoco_force > 0.0 ? mujoco_force : (ref.peak > 0.0 ? ref.peak : 1000.0);
      const tools::MujocoTrace mj = tools::runMujoco(base, mo);
      // as our trace (body centres into q; the peer measures no contact impulse: written as nan)
      Trace tr;
      tr.t = mj.t;
      tr.force = mj.force;
      tr.heights = mj.heights;
      tr.peak = mj.peak;
      tr.peak_t = mj.peak_t;
      for (const std::vector<at::Vec3>& centres : mj.positions)
      {
        Eigen::VectorXd q = Eigen::VectorXd::Zero(base.nq);
        for (size_t b = 0; b < base.bodies.size(); ++b)
          q.segment<3>(base.bodies[b].offset) = centres[b];
        tr.q.push_back(q);
      }
      const Errors e = compare(base, tr, ref);
      const std::string name = "mujoco_" + integrator;
      out << name << "," << dt << ",0," << mj.status << "," << mj.steps << "," << mj.solver_iterations << ","
          << mj.wall_time << "," << e.position << "," << e.height << "," << e.force << "," << e.peak << ","
          << e.peak_time << ",nan," << mj.peak << "," << ref.peak << "\n";
      out.flush();
      std::fprintf(stderr,
                   "  %-30s dt  %-8g %-10s wall %7.2f s  position err %.3e m  force err %.3e  peak err %.3e%s\n",
                   name.c_str(), dt, mj.status.c_str(), mj.wall_time, e.position, e.force, e.peak,
                   mj.ok() ? "" : ("  (" + mj.message + ")").c_str());
    }
#endif
  return 0;
}

struct StressCase
{
  const char* name;
  const char* scene;
  std::vector<std::string> overrides;
  bool quick;  // short enough for the test suite's version (test_stress)
};

int stress(bool quick_only)
{
  const std::string dir = tools::sceneDirectory(ACTIVE_TENSEGRITY_SCENE_DIR) + "/";
  std::fprintf(stderr, "stress: scenes from %s\n", dir.c_str());
  const std::vector<std::string> tower = { "analysis.type=dynamic" };
  const std::vector<std::string> quad = { "analysis.type=dynamic", "contact.enabled=true",
                                          "analysis.max_actuation=1.2" };
  const auto with = [](std::vector<std::string> base, std::initializer_list<std::string> more)
  {
    base.insert(base.end(), more);
    return base;
  };
  const std::vector<StressCase> cases = {
    { "tower V = 5 m/s", "tower.yaml", with(tower, { "actuation.speed=5", "analysis.duration=0.8" }), false },
    { "tower V = 10 m/s", "tower.yaml", with(tower, { "actuation.speed=10", "analysis.duration=0.5" }), false },
    { "tower V = 20 m/s", "tower.yaml", with(tower, { "actuation.speed=20", "analysis.duration=0.3" }), true },
    { "tower V = 50 m/s", "tower.yaml", with(tower, { "actuation.speed=50", "analysis.duration=0.2" }), true },
    { "tower V = 0.5 m/s, dt = 1e-3 s", "tower.yaml", with(tower, { "solver.dt=1e-3", "analysis.duration=4" }), false },
    { "tower V = 0.5 m/s, dt = 5e-3 s", "tower.yaml", with(tower, { "solver.dt=5e-3", "analysis.duration=4" }), true },
    { "tower V = 0.5 m/s, dt = 1e-2 s", "tower.yaml", with(tower, { "solver.dt=1e-2", "analysis.duration=4" }), true },
    { "tower bare steel struts, V = 5 m/s", "tower.yaml",
      with(tower, { "struts.material=steel", "actuation.speed=5", "analysis.duration=0.8" }), false },
    { "tower thin struts (r 5 mm), V = 5 m/s", "tower.yaml",
      with(tower, { "struts.radius=0.005", "struts.core.radius=0.0025", "actuation.speed=5", "analysis.duration=0.8" }),
      false },
    { "tower thin struts (r 5 mm), V = 20 m/s", "tower.yaml",
      with(tower, { "struts.radius=0.005", "struts.core.radius=0.0025", "actuation.speed=20", "analysis.duration=0.3" }),
      true },
    { "tower impulsive: 10 cm in 2 ms", "tower.yaml",
      with(tower, { "actuation.speed=50", "analysis.max_actuation=0.1", "analysis.duration=0.3" }), true },
    { "quadruplex V = 5 m/s", "quadruplex.yaml", with(quad, { "actuation.speed=5", "analysis.duration=0.6" }), true },
    { "quadruplex V = 10 m/s", "quadruplex.yaml", with(quad, { "actuation.speed=10", "analysis.duration=0.4" }), true },
    { "quadruplex V = 20 m/s", "quadruplex.yaml", with(quad, { "actuation.speed=20", "analysis.duration=0.3" }), true },
    { "quadruplex V = 50 m/s", "quadruplex.yaml", with(quad, { "actuation.speed=50", "analysis.duration=0.2" }), true },
    { "quadruplex dt = 1e-2 s, V = 0.5 m/s", "quadruplex.yaml",
      with(quad, { "solver.dt=1e-2", "actuation.speed=0.5", "analysis.duration=3" }), true },
    { "two struts 1 degree apart pressed side by side, 1 m/s", "parallel.yaml", { "actuation.speed=1" }, true },
    { "two struts 1 degree apart pressed side by side, 10 m/s", "parallel.yaml", { "actuation.speed=10" }, true },
    { "quadruplex all cables slack (no prestress), V = 1 m/s", "quadruplex.yaml",
      with(quad, { "cables.lower.prestress=0", "cables.upper.prestress=0", "cables.bracing.prestress=0",
                   "actuation.speed=1", "analysis.duration=1.5" }),
      true },
  };
  std::printf("| case | ended | simulated (s) | steps | step cuts | crossings refused | max F_N (N) | min gap (mm) | "
              "finite | wall (s) |\n|---|---|---|---|---|---|---|---|---|---|\n");
  int bad = 0;
  for (const StressCase& c : cases)
  {
    if (quick_only && !c.quick)
      continue;
    std::vector<at::Override> o;
    for (const std::string& kv : c.overrides)
      o.push_back(at::parseOverride(kv));
    const at::Model model = at::loadScene(dir + c.scene, o);
    double max_force = 0.0, min_gap = INFINITY;
    bool finite = true;
    const at::RunResult r = at::runAnalysis(
        model, [](const at::State&) {}, {},
        [&](const at::State& s)
        {
          finite = finite && s.q.allFinite() && s.qd.allFinite() && s.lambda.allFinite();
          for (const at::ContactPairState& p : at::activeContacts(model, s))
            max_force = std::max(max_force, p.normal_force);
          min_gap = std::min(min_gap, at::minimumGap(model, s.q));
        });
    const at::State& f = r.final_state;
    finite = finite && f.q.allFinite() && f.qd.allFinite();
    bad += finite ? 0 : 1;
    std::string ended = at::toString(r.summary.status);
    if (!r.summary.ok())
      ended += ": " + r.summary.message;
    std::printf("| %s | %s | %.4g | %d | %d | %d | %.0f | %.2f | %s | %.1f |\n", c.name, ended.c_str(), f.t,
                r.solver_steps, r.summary.step_cuts, r.summary.crossings_refused, max_force, 1e3 * min_gap,
                finite ? "yes" : "NO", r.wall_time);
    std::fflush(stdout);
  }
  return bad == 0 ? 0 : 3;
}

int steps(const std::string& scene, const std::vector<at::Override>& overrides, int repeat, bool peaks)
{
  const at::Model model = at::loadScene(scene, overrides);
  std::vector<double> per_step;
  at::RunResult last;
  long allocations = 0;
  for (int r = 0; r < repeat; ++r)
  {
    const auto per_step_row = [&model](const at::State& s) { g_sink = g_sink + at::csvRow(model, s).back(); };
    // allocations from the first step on (setup and initialization excluded)
    long at_first_step = -1;
    const auto count = [&at_first_step](const at::State&)
    {
      if (at_first_step < 0)
        at_first_step = g_allocations.load();
    };
    last = peaks ? at::runAnalysis(
                       model, [](const at::State&) {}, {}, per_step_row) :
                   at::runAnalysis(model, count);
    allocations = at_first_step < 0 ? 0 : g_allocations.load() - at_first_step;
    if (!last.summary.ok())
    {
      std::cerr << "tensegrity_bench: the analysis failed: " << last.summary.message << "\n";
      return 3;
    }
    per_step.push_back(last.wall_time / std::max(1, last.solver_steps));
  }
  std::sort(per_step.begin(), per_step.end());
  const double median = per_step[per_step.size() / 2];
  const bool dynamic = model.analysis.type == at::AnalysisType::kDynamic;
  std::printf("scene: %s\n", scene.c_str());
  std::printf("analysis: %s, %d bodies, %d coordinates, %d constraint rows, %zu cables\n",
              dynamic ? "dynamic" : "static", static_cast<int>(model.bodies.size()), model.nq, model.n_lambda,
              model.cables.size());
  if (dynamic)
    std::printf("dt: %g s, integrator: %s, duration: %g s\n", model.solver.dt,
                model.solver.integrator == at::Integrator::kNewmark ? "newmark" : "generalized_alpha",
                model.analysis.duration);
  std::printf("solver steps: %d, step cuts: %d\n", last.solver_steps, last.summary.step_cuts);
  std::printf("newton iterations per step: %.3f\n",
              static_cast<double>(last.summary.iterations) / std::max(1, last.solver_steps));
  std::printf("wall time per step: median %.3f us, min %.3f us over %d runs\n", 1e6 * median, 1e6 * per_step.front(),
              repeat);
#ifdef ACTIVE_TENSEGRITY_COUNT_ALLOCATIONS
  if (!peaks)
    std::printf("heap allocations per step (solver and loop, after the first output): %.2f\n",
                static_cast<double>(allocations) / std::max(1, last.solver_steps));
#else
  static_cast<void>(allocations);
  std::printf("heap allocations per step: not counted (built with AddressSanitizer)\n");
#endif
  std::printf("factorizations per step: %.3f, symbolic analyses: %ld\n",
              static_cast<double>(last.timings.factorizations) / std::max(1, last.solver_steps), last.timings.analyses);
  std::printf("where the time goes (last run, us per step, share of its wall time):\n");
  const int n = std::max(1, last.solver_steps);
  for (const auto& [part, seconds] : at::timeBreakdown(last))
    std::printf("  %-14s %10.2f us %6.1f %%\n", part.c_str(), 1e6 * seconds / n,
                last.wall_time > 0.0 ? 100.0 * seconds / last.wall_time : 0.0);
  if (dynamic)
    std::printf("real-time factor (simulated / wall, median): %.1f\n", model.solver.dt / median);
  return 0;
}
}  // namespace

int main(int argc, char** argv)
{
  const std::string command = argc >= 2 ? argv[1] : "";
  if (command == "lattice")
    return active_tensegrity::tools::latticeCommand(std::vector<std::string>(argv + 2, argv + argc));
  const bool needs_scene = command == "steps" || command == "plan" || command == "work-precision";
  if ((command != "steps" && command != "contact-pair" && command != "broad-phase" && command != "plan" &&
       command != "stress" && command != "work-precision") ||
      (needs_scene && argc < 3))
  {
    std::cerr << kUsage;
    return 2;
  }
  std::vector<at::Override> overrides;
  int repeat = 5;
  bool peaks = false;
  const std::string scene = needs_scene ? argv[2] : "";
  try
  {
    if (command == "plan")
      return plan(scene, std::vector<std::string>(argv + 3, argv + argc));
    if (command == "work-precision")
      return workPrecision(scene, std::vector<std::string>(argv + 3, argv + argc));
    if (command == "stress")
      return stress(argc >= 3 && std::string(argv[2]) == "--quick");
    for (int i = needs_scene ? 3 : 2; i < argc; ++i)
    {
      const std::string arg = argv[i];
      if (needs_scene && arg == "--set" && i + 1 < argc)
        overrides.push_back(at::parseOverride(argv[++i]));
      else if (needs_scene && arg == "--peaks")
        peaks = true;
      else if (arg == "--repeat" && i + 1 < argc)
        repeat = std::max(1, std::stoi(argv[++i]));
      else
      {
        std::cerr << "tensegrity_bench: unknown argument '" << arg << "'\n" << kUsage;
        return 2;
      }
    }
    if (command == "contact-pair")
      return contactPair(repeat);
    if (command == "broad-phase")
      return broadPhase(repeat);
    return steps(scene, overrides, repeat, peaks);
  }
  catch (const tools::BadArgument& e)
  {
    std::cerr << "tensegrity_bench: " << e.what() << "\n";
    return 2;
  }
  catch (const std::exception& e)
  {
    std::cerr << "tensegrity_bench: " << e.what() << "\n";
    return 1;
  }
}
