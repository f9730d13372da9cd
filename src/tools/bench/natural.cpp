//   tensegrity_bench natural SCENE [--set key=value]... [--dts a,b,..] [--tols a,b,..] [--ref-dt R] [--repeat N]
//                            [--csv FILE] [--no-spin] [--fixed-only]
// The scene's dynamic analysis in body coordinates (the package's solver) and in natural coordinates
// (core/solvers/natural.h), in one run: each over the fixed steps `dts` and, adaptive, over the error tolerances `tols`,
// with the scene's integrator and Newton settings. Each run is compared with a fine reference of
// the body coordinates (generalized-alpha at R, tolerance 1e-10) on the output grid: the largest error of a strut
// centre or point mass; the natural coordinates' own fine reference (trapezoidal at R) gives the two models'
// difference. Wall time is the least of N repeats of the bare stepping loop (no outputs formed in it). A static scene's
// path of equilibria is followed in both and compared at every load step.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <string>
#include <vector>

#include "active_tensegrity/core/solvers/adaptive.h"
#include "active_tensegrity/oracle/body_adaptive.h"
#include "active_tensegrity/core/model/actuation_schedule.h"
#include "active_tensegrity/core/outputs/observables.h"
#include "active_tensegrity/core/solvers/natural.h"
#include "active_tensegrity/core/scene/scene.h"
#include "active_tensegrity/core/solvers/state.h"
#include "active_tensegrity/oracle/body_statics.h"
#include "active_tensegrity/core/solvers/statics.h"
#include "active_tensegrity/oracle/body_dynamics.h"
#include "../cli.h"
#include "bench.h"

namespace at = active_tensegrity::core;

namespace active_tensegrity::tools::bench
{
namespace
{
/// The centres of the bodies at each output time.
using Path = std::vector<std::vector<at::Vec3>>;

std::vector<at::Vec3> centres(const at::Model& model, const Eigen::VectorXd& q)
{
  std::vector<at::Vec3> c;
  for (const at::Body& b : model.bodies)
    c.push_back(q.segment<3>(b.offset));
  return c;
}

struct Run
{
  Path path;
  double wall = 0.0;
  long steps = 0, iterations = 0, factorizations = 0;
  std::string status = "converged";
  double impulse = 0.0;         // time integral of the summed normal contact forces over every step (N s)
  double peak = 0.0;            // the largest normal contact force over every step (N)
  double first_contact = -1.0;  // when a pair first touched (s; -1: never)
  double callbacks = 0.0;       // wall time of the measurements after each step (s; not in `wall`)
};

/// After every step: the contact impulse, the peak force and the first touch.
struct ContactAccount
{
  Run& run;
  double last_t = 0.0, last_sum = 0.0;
  void add(double t, const std::vector<at::ContactPairState>& contacts)
  {
    double sum = 0.0;
    for (const at::ContactPairState& c : contacts)
    {
      sum += c.normal_force;
      run.peak = std::max(run.peak, c.normal_force);
    }
    if (!contacts.empty() && run.first_contact < 0.0)
      run.first_contact = t;
    run.impulse += 0.5 * (sum + last_sum) * (t - last_t);
    last_t = t;
    last_sum = sum;
  }
};

/// The output times: every output interval to the end, and the actuation breakpoints the adaptive runs stop at.
struct Stops
{
  std::vector<double> times;
  std::vector<bool> output;
};

Stops stopsOf(const at::Model& model)
{
  Stops s;
  const double interval = model.analysis.output_interval, end = model.analysis.duration;
  std::vector<std::pair<double, bool>> all;
  for (long k = 1;; ++k)
  {
    const double t = std::min(end, k * interval);
    all.emplace_back(t, true);
    if (t >= end - 1e-12)
      break;
  }
  for (double t : at::actuationBreakpoints(model))
    if (t > 0.0 && t < end && std::abs(t - interval * std::round(t / interval)) > model.solver.dt_min)
      all.emplace_back(t, false);
  std::sort(all.begin(), all.end());
  for (const auto& [t, out] : all)
  {
    s.times.push_back(t);
    s.output.push_back(out);
  }
  return s;
}

Run runBody(const at::Model& model)
{
  Run run;
  const Stops stops = stopsOf(model);
  at::BodyDynamicsSolver solver(model, model.solver);
  const at::ActuationLaw law =
      at::ActuationLaw::writing([&model](double t, at::ActuationValues& u) { at::scheduledActuation(model, t, u); });
  at::BodyState s = at::bodyInitialState(model);
  std::vector<Eigen::VectorXd> qs;
  qs.reserve(stops.times.size());
  const Clock::time_point t0 = Clock::now();
  at::Summary first = solver.initialize(s, law);
  if (!first.ok())
  {
    run.status = at::toString(first.status);
    return run;
  }
  at::BodyAdaptiveStepper stepper(solver, model.solver);
  ContactAccount account{ run };
  const std::function<void(const at::State&)> each = [&](const at::State& st)
  {
    const Clock::time_point c0 = Clock::now();
    account.add(st.t, at::activeContacts(model, st));
    run.callbacks += seconds(c0, Clock::now());
  };
  for (size_t k = 0; k < stops.times.size(); ++k)
  {
    const double t_end = stops.times[k];
    at::Summary r;
    if (model.solver.adaptive)
      r = stepper.advanceTo(s, t_end, law, each);
    else
      while (s.t < t_end - 1e-12)
      {
        const double h = t_end - s.t <= 1.05 * model.solver.dt ? t_end - s.t : model.solver.dt;
        const double t1 = s.t + h;
        const at::Summary one = solver.step(s, h, law);
        r.iterations += one.iterations;
        if (!one.ok())
        {
          r.status = one.status;
          break;
        }
        s.t = t1;
        ++run.steps;
        each(s);
      }
    run.iterations += r.iterations;
    if (!r.ok())
    {
      run.status = at::toString(r.status);
      break;
    }
    if (stops.output[k])
      qs.push_back(s.q);
  }
  run.wall = seconds(t0, Clock::now()) - run.callbacks;
  if (model.solver.adaptive)
    run.steps = stepper.stats().accepted;
  run.factorizations = -1;  // (the body solver counts its factorizations by kind: not compared here)
  for (const Eigen::VectorXd& q : qs)
    run.path.push_back(centres(model, q));
  return run;
}

Run runNatural(const at::Model& model, bool spin)
{
  Run run;
  const Stops stops = stopsOf(model);
  const at::NaturalModel nm = at::buildNaturalModel(model, spin);
  at::NaturalSolver solver(nm, model.solver);
  const at::ActuationLaw law =
      at::ActuationLaw::writing([&model](double t, at::ActuationValues& u) { at::scheduledActuation(model, t, u); });
  at::NaturalState s = at::naturalInitialState(nm);
  std::vector<std::pair<Eigen::VectorXd, double>> xs;
  xs.reserve(stops.times.size());
  const Clock::time_point t0 = Clock::now();
  at::Summary first = solver.initialize(s, law);
  if (!first.ok())
  {
    run.status = at::toString(first.status);
    return run;
  }
  ContactAccount account{ run };
  const std::function<void(const at::NaturalState&)> each = [&](const at::NaturalState& st)
  {
    const Clock::time_point c0 = Clock::now();
    account.add(st.t, solver.contactsAt(st));
    run.callbacks += seconds(c0, Clock::now());
  };
  for (size_t k = 0; k < stops.times.size(); ++k)
  {
    const at::Summary r = solver.advanceTo(s, stops.times[k], law, each);
    if (!r.ok())
    {
      run.status = at::toString(r.status) + std::string(" (") + r.message + ")";
      break;
    }
    if (stops.output[k])
      xs.emplace_back(s.x, s.t);
  }
  run.wall = seconds(t0, Clock::now()) - run.callbacks;
  run.steps = solver.stats().steps;
  run.iterations = solver.stats().iterations;
  run.factorizations = solver.stats().factorizations;
  for (const auto& [x, t] : xs)
    run.path.push_back(centres(model, at::naturalToBodyCoordinates(nm, x, at::scheduledActuation(model, t))));
  return run;
}

/// The mass centre at the last output (m).
at::Vec3 endCentre(const at::Model& model, const Path& path)
{
  at::Vec3 c = at::Vec3::Zero();
  double mass = 0.0;
  if (path.empty())
    return c;
  for (size_t i = 0; i < model.bodies.size(); ++i)
  {
    c += model.bodies[i].mass * path.back()[i];
    mass += model.bodies[i].mass;
  }
  return c / mass;
}

double pathError(const Path& a, const Path& b)
{
  double e = 0.0;
  const size_t n = std::min(a.size(), b.size());
  for (size_t k = 0; k < n; ++k)
    for (size_t i = 0; i < a[k].size(); ++i)
      e = std::max(e, (a[k][i] - b[k][i]).norm());
  if (a.size() != b.size())
    return std::numeric_limits<double>::infinity();
  return e;
}

/// The least wall time over `repeat` runs (the path of the first).
template <typename F>
Run timed(const F& f, int repeat)
{
  Run best = f();
  for (int k = 1; k < repeat; ++k)
    best.wall = std::min(best.wall, f().wall);
  return best;
}

/// log-log interpolation of a run list's wall time at error e (NaN when e is outside the list's errors)
double wallAtError(std::vector<std::pair<double, double>> pts, double e)
{
  std::sort(pts.begin(), pts.end());
  for (size_t k = 1; k < pts.size(); ++k)
  {
    const auto [e0, w0] = pts[k - 1];
    const auto [e1, w1] = pts[k];
    if (e >= e0 && e <= e1 && e0 > 0.0 && e1 > e0)
    {
      const double f = std::log(e / e0) / std::log(e1 / e0);
      return std::exp(std::log(w0) + f * (std::log(w1) - std::log(w0)));
    }
  }
  return std::numeric_limits<double>::quiet_NaN();
}
// The scene's static path (initial equilibrium, then analysis.steps load steps to analysis.max_actuation) in both
// formulations: the least wall time of `repeat` runs each, and the largest strut-centre difference over the path.
int naturalStatics(const std::string& scene, const at::Model& model, int repeat)
{
  if (model.analysis.arc_length || model.analysis.load_factor_start != model.analysis.load_factor_end)
    throw std::invalid_argument("natural statics: arc-length paths and load paths are not compared");
  const int steps = model.analysis.steps;
  const auto body = [&](Path* path)
  {
    at::BodyStaticSolver solver(model, model.solver);
    at::BodyState s = at::bodyInitialState(model);
    at::Summary r = solver.solve(s, s.u);
    if (r.ok())
    {
      at::ActuationValues u_end = s.u;
      for (at::ActuationValue& v : u_end)
        v.value = model.analysis.max_actuation;
      r = solver.followPath(s, u_end, steps,
                            [&](const at::State& st, const at::Summary&)
                            {
                              if (path)
                                path->push_back(centres(model, st.q));
                            });
    }
    return std::make_pair(r, solver.timings().newton_iterations);
  };
  long natural_iterations = 0, natural_factorizations = 0;
  const auto natural = [&](Path* path)
  {
    at::StaticSolver solver(model, model.solver);
    at::State s = at::initialState(model);
    at::Summary r = solver.solve(s, s.u);
    if (r.ok())
    {
      at::ActuationValues u_end = s.u;
      for (at::ActuationValue& v : u_end)
        v.value = model.analysis.max_actuation;
      r = solver.followPath(s, u_end, steps,
                            [&](const at::State& st, const at::Summary&)
                            {
                              if (path)
                                path->push_back(centres(model, st.q));
                            });
    }
    natural_iterations = solver.timings().newton_iterations;
    natural_factorizations = solver.timings().factorizations;
    return std::make_pair(r, natural_iterations);
  };
  Path body_path, natural_path;
  const auto [body_result, body_iterations] = body(&body_path);
  const auto [natural_result, natural_its] = natural(&natural_path);
  std::printf("# %s: %s, %s\n", scene.c_str(), cpuModel().c_str(), cpuVectorFlags().c_str());
  std::printf("# static path, %d load steps to actuation %g: body %s (%zu equilibria), natural %s (%zu equilibria)\n",
              steps, model.analysis.max_actuation, at::toString(body_result.status), body_path.size(),
              at::toString(natural_result.status), natural_path.size());
  if (!body_result.ok() || !natural_result.ok())
  {
    std::printf("# body: %s\n# natural: %s\n", body_result.message.c_str(), natural_result.message.c_str());
    return 3;
  }
  double most = 0.0;
  size_t most_at = 0;
  for (size_t k = 0; k < std::min(body_path.size(), natural_path.size()); ++k)
    for (size_t i = 0; i < body_path[k].size(); ++i)
    {
      const double d = (body_path[k][i] - natural_path[k][i]).norm();
      if (d > most)
      {
        most = d;
        most_at = k + 1;
      }
    }
  double body_wall = 1e300, natural_wall = 1e300;
  for (int r = 0; r < repeat; ++r)
  {
    Clock::time_point t0 = Clock::now();
    body(nullptr);
    body_wall = std::min(body_wall, seconds(t0, Clock::now()));
    t0 = Clock::now();
    natural(nullptr);
    natural_wall = std::min(natural_wall, seconds(t0, Clock::now()));
  }
  std::printf("%-8s %8s %8s %10s %12s\n", "model", "it/step", "fac/step", "wall s", "us/step");
  std::printf("%-8s %8.2f %8s %10.4f %12.1f\n", "body", double(body_iterations) / steps, "-", body_wall,
              1e6 * body_wall / steps);
  std::printf("%-8s %8.2f %8.3f %10.4f %12.1f\n", "natural", double(natural_its) / steps,
              double(natural_factorizations) / steps, natural_wall, 1e6 * natural_wall / steps);
  double end = 0.0;
  if (!body_path.empty() && body_path.size() == natural_path.size())
    for (size_t i = 0; i < body_path.back().size(); ++i)
      end = std::max(end, (body_path.back()[i] - natural_path.back()[i]).norm());
  std::printf("# largest strut-centre difference over the path: %.3e m, at load step %zu; at the end %.3e m\n", most,
              most_at, end);
  return 0;
}
}  // namespace

int natural(const std::string& scene, const std::vector<std::string>& args)
{
  std::vector<at::Override> overrides;
  std::vector<double> dts = { 4e-4, 2e-4, 1e-4 };
  std::vector<double> tols = { 1e-4, 1e-5, 1e-6 };
  double ref_dt = 2.5e-5;
  int repeat = 3;
  bool spin = true;
  std::string csv_path;
  Args in(args);
  while (in.more())
  {
    const std::string a = in.option();
    const auto next = [&]() { return in.value(a); };
    if (a == "--set")
      overrides.push_back(at::parseOverride(next()));
    else if (a == "--dts")
      dts = tools::parsePositiveList(a, next());
    else if (a == "--tols")
      tols = tools::parsePositiveList(a, next());
    else if (a == "--ref-dt")
      ref_dt = tools::parsePositive<double>(a, next());
    else if (a == "--repeat")
      repeat = tools::parsePositive<int>(a, next());
    else if (a == "--csv")
      csv_path = next();
    else if (a == "--no-spin")
      spin = false;
    else if (a == "--fixed-only")
      tols.clear();
    else
      throw BadArgument("unknown argument '" + a + "'");
  }
  at::Model base = at::loadScene(scene, overrides);
  if (base.analysis.type == at::AnalysisType::kStatic)
    return naturalStatics(scene, base, repeat);
  if (base.analysis.type != at::AnalysisType::kDynamic)
    throw BadArgument("natural compares dynamic and static analyses (analysis.type), not a modal one");
  if (!(base.analysis.output_interval > 0.0))
    base.analysis.output_interval = 0.01;
  at::buildNaturalModel(base);  // (refuses what the natural coordinates do not cover, before any run)

  const auto configured =
      [&](bool adaptive, double x, at::Integrator integrator, double gamma, double beta, double newton)
  {
    at::Model m = base;
    m.solver.integrator = integrator;
    m.solver.newmark_gamma = gamma;
    m.solver.newmark_beta = beta;
    m.solver.adaptive = adaptive;
    m.solver.newton_tolerance = newton;
    if (adaptive)
    {
      m.solver.error_tolerance = x;
      m.solver.newton_tolerance = std::min(newton, 0.1 * x);
    }
    else
      m.solver.dt = x;
    return m;
  };
  std::fprintf(stderr, "natural: references at dt %g s ...\n", ref_dt);
  const double gamma = base.solver.newmark_gamma, beta = base.solver.newmark_beta;
  const at::Integrator integrator = base.solver.integrator;
  const Run ref = runBody(configured(false, ref_dt, integrator, gamma, beta, 1e-10));
  const Run nat_ref = runNatural(configured(false, ref_dt, integrator, gamma, beta, 1e-10), spin);
  if (ref.status != "converged" || nat_ref.status != "converged")
  {
    std::cerr << "tensegrity_bench: a reference run failed: body " << ref.status << ", natural " << nat_ref.status
              << "\n";
    return 3;
  }
  const double model_difference = pathError(ref.path, nat_ref.path);
  const auto relative = [](double a, double b) { return b > 0.0 ? std::abs(a - b) / b : std::abs(a); };
  std::printf("# %s: %s, %s\n", scene.c_str(), cpuModel().c_str(), cpuVectorFlags().c_str());
  std::printf(
      "# references at dt %g s (the scene's integrator, Newton tolerance 1e-10): contact impulse %.6g and %.6g N "
      "s (difference %.2e), first touch at %.4f and %.4f s, largest "
      "position difference %.3e m\n",
      ref_dt, ref.impulse, nat_ref.impulse, relative(nat_ref.impulse, ref.impulse), ref.first_contact,
      nat_ref.first_contact, model_difference);
  const at::Vec3 ref_end = endCentre(base, ref.path), nat_end = endCentre(base, nat_ref.path);
  std::printf("# mass centre at the end: body (%.4f, %.4f, %.4f) m, natural%s (%.4f, %.4f, %.4f) m\n", ref_end.x(),
              ref_end.y(), ref_end.z(), spin ? "" : " without spin", nat_end.x(), nat_end.y(), nat_end.z());

  std::ofstream file;
  if (!csv_path.empty())
  {
    file.open(csv_path);
    if (!file)
      throw std::invalid_argument("cannot write '" + csv_path + "'");
    file << "formulation,adaptive,dt_or_tolerance,status,steps,newton_iterations,factorizations,wall_time,us_per_step,"
            "position_error,position_error_own_reference,impulse_error,impulse_error_own_reference,first_contact,"
            "peak_force\n";
  }
  std::printf("%-8s %-8s %-8s %-9s %6s %5s %6s %8s %7s %9s %9s %9s %9s %7s %8s\n", "model", "mode", "dt|tol", "status",
              "steps", "it/st", "fac/st", "wall s", "us/st", "pos m", "pos own", "impulse", "imp own", "touch s",
              "peak N");
  // (error, wall) per formulation, fixed and adaptive, for positions and impulse
  std::vector<std::pair<double, double>> pts[2][2][2];
  for (const bool adaptive : { false, true })
    for (double x : adaptive ? tols : dts)
      for (const bool natural : { false, true })
      {
        const at::Model m = configured(adaptive, x, base.solver.integrator, base.solver.newmark_gamma,
                                       base.solver.newmark_beta, base.solver.newton_tolerance);
        const Run r = natural ? timed([&]() { return runNatural(m, spin); }, repeat) :
                                timed([&]() { return runBody(m); }, repeat);
        const Run& own_ref = natural ? nat_ref : ref;
        const double err = pathError(r.path, ref.path), own = pathError(r.path, own_ref.path);
        const double imp = relative(r.impulse, ref.impulse), imp_own = relative(r.impulse, own_ref.impulse);
        const double us = 1e6 * r.wall / std::max(1L, r.steps);
        if (r.status == "converged")
        {
          pts[natural][adaptive][0].emplace_back(err, r.wall);
          pts[natural][adaptive][1].emplace_back(imp, r.wall);
        }
        std::printf("%-8s %-8s %-8g %-9s %6ld %5.2f %6.3f %8.4f %7.2f %9.2e %9.2e %9.2e %9.2e %7.4f %8.1f\n",
                    natural ? "natural" : "body", adaptive ? "adaptive" : "fixed", x, r.status.substr(0, 9).c_str(),
                    r.steps, double(r.iterations) / std::max(1L, r.steps),
                    r.factorizations < 0 ? std::nan("") : double(r.factorizations) / std::max(1L, r.steps), r.wall, us,
                    err, own, imp, imp_own, r.first_contact, r.peak);
        std::fflush(stdout);
        if (file)
          file << (natural ? "natural" : "body") << "," << adaptive << "," << x << "," << r.status << "," << r.steps
               << "," << r.iterations << "," << r.factorizations << "," << r.wall << "," << us << "," << err << ","
               << own << "," << imp << "," << imp_own << "," << r.first_contact << "," << r.peak << "\n";
      }
  // at equal error: the natural run time interpolated at each body run's error
  std::printf("# at equal error against the body reference: the natural time interpolated log-log at each body run's "
              "error (nan: outside the natural runs' errors)\n");
  for (int measure = 0; measure < 2; ++measure)
    for (int adaptive = 0; adaptive < 2; ++adaptive)
      for (const auto& [e, w] : pts[0][adaptive][measure])
      {
        const double wn = wallAtError(pts[1][adaptive][measure], e);
        std::printf("%-8s %-8s error %.3e: body %.4f s, natural %.4f s, body / natural %.2f\n",
                    measure ? "impulse" : "position", adaptive ? "adaptive" : "fixed", e, w, wn, w / wn);
      }
  return 0;
}
}  // namespace active_tensegrity::tools::bench
