//   tensegrity_bench work-precision SCENE [--set key=value]... [--dts a,b,..] [--tols a,b,..]
//                                  [--schemes a,b,..] [--ref-dt R] [--csv FILE]
// runs the scene's dynamic analysis with several integrators over a ladder of steps (fixed-step schemes)
// or error tolerances (adaptive ones) and compares each run with a much finer reference
// (generalized-alpha at R, tolerance 1e-10): largest body-position and layer-height errors, largest
// actuation-force error (relative to the reference's largest force), error of the peak contact force,
// of its time and of the contact impulse (time integral of the summed normal forces); with the wall time
// of the run (callbacks excluded). One CSV row per run. The schemes natural_generalized_alpha and
// adaptive_natural_generalized_alpha (the same in natural coordinates, core/solvers/natural.h) run only when named.
// --mujoco-dts a,b,.. then runs the scene translated into MuJoCo (mujoco_peer.h) over that ladder with each of
// --mujoco-integrators (default euler,implicit,rk4), rows named mujoco_<integrator>, measured the same way;
// --mujoco-contact-force F sets its contact stiffness scale (default: the reference's peak contact force).
// --paths FILE writes, per run and output step, the bodies' mass centre (scheme, dt, t, x, y, z; the
// reference's rows first).
// (Only when built with MuJoCo, ACTIVE_TENSEGRITY_HAVE_MUJOCO; without it these options exit with status 2.)
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <string>
#include <vector>

#include "active_tensegrity/core/model/actuation_schedule.h"
#include "active_tensegrity/core/outputs/observables.h"
#include "active_tensegrity/core/outputs/csv.h"
#include "active_tensegrity/core/outputs/run.h"
#include "active_tensegrity/core/contact/contact.h"
#include "active_tensegrity/core/solvers/natural.h"
#include "active_tensegrity/core/scene/scene.h"
#include "active_tensegrity/core/solvers/structure_check.h"
#include "active_tensegrity/core/base/text.h"
#include "../cli.h"
#ifdef ACTIVE_TENSEGRITY_HAVE_MUJOCO
#include "../mujoco_peer.h"
#endif
#include "bench.h"

namespace at = active_tensegrity::core;

namespace active_tensegrity::tools::bench
{
namespace
{
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

/// traceRun's trace of the same analysis in natural coordinates (core/solvers/natural.h): the body coordinates of its
/// nodes at every output, the first actuator's force, the heights; the contacts' peak and impulse over every step.
Trace traceNatural(const at::Model& model)
{
  Trace tr;
  const at::NaturalModel nm = at::buildNaturalModel(model);
  at::NaturalSolver solver(nm, model.solver);
  const at::ActuationLaw law =
      at::ActuationLaw::writing([&model](double t, at::ActuationValues& u) { at::scheduledActuation(model, t, u); });
  at::NaturalState s = at::naturalInitialState(nm);
  double last_t = 0.0, last_sum = 0.0, callbacks = 0.0;
  std::vector<double> forces;
  const auto t0 = std::chrono::steady_clock::now();
  const auto output = [&](const at::NaturalState& st)
  {
    const at::ActuationValues u = at::scheduledActuation(model, st.t);
    const Eigen::VectorXd q = at::naturalToBodyCoordinates(nm, st.x, u);
    tr.t.push_back(st.t);
    if (model.actuators.empty())
      tr.force.push_back(0.0);
    else
    {
      solver.actuationForces(st, u, forces);
      tr.force.push_back(forces[0]);
    }
    std::vector<double> h;
    for (const at::OutputLayer& layer : model.layers)
      h.push_back(at::nodesHeight(model, layer.nodes, q));
    if (h.empty())
      h.push_back(at::structureHeight(model, q));
    tr.heights.push_back(h);
    tr.q.push_back(q);
  };
  const std::function<void(const at::NaturalState&)> each = [&](const at::NaturalState& st)
  {
    const auto c0 = std::chrono::steady_clock::now();
    double sum = 0.0;
    for (const at::ContactPairState& c : solver.contactsAt(st))
    {
      sum += c.normal_force;
      if (c.normal_force > tr.peak)
      {
        tr.peak = c.normal_force;
        tr.peak_t = st.t;
      }
    }
    tr.impulse += 0.5 * (sum + last_sum) * (st.t - last_t);
    last_t = st.t;
    last_sum = sum;
    callbacks += std::chrono::duration<double>(std::chrono::steady_clock::now() - c0).count();
  };
  at::Summary r = solver.initialize(s, law);
  if (r.ok())
    output(s);
  const double interval = model.analysis.output_interval;
  const int outputs = static_cast<int>(std::llround(model.analysis.duration / interval));
  for (int k = 1; k <= outputs && r.ok(); ++k)
  {
    const at::Summary step = solver.advanceTo(s, std::min(model.analysis.duration, k * interval), law, each);
    r.iterations += step.iterations;
    r.step_cuts += step.step_cuts;
    if (!step.ok())
    {
      r.status = step.status;
      r.message = step.message;
      break;
    }
    const auto c0 = std::chrono::steady_clock::now();
    output(s);
    callbacks += std::chrono::duration<double>(std::chrono::steady_clock::now() - c0).count();
  }
  tr.result.summary = r;
  tr.result.wall_time = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  tr.result.callback_time = callbacks;
  tr.result.solver_steps = static_cast<int>(solver.stats().steps);
  return tr;
}

/// One integrator of the work-precision benchmark; adaptive ones run over the tolerance ladder; `natural` ones in
/// natural coordinates (core/solvers/natural.h, modified Newton).
struct Scheme
{
  const char* name;
  at::Integrator integrator;
  double gamma, beta, rho;
  bool reuse, adaptive;
  bool natural = false;
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
    { "natural_generalized_alpha", at::Integrator::kGeneralizedAlpha, 0.5, 0.25, 0.8, true, false, true },
    { "adaptive_natural_generalized_alpha", at::Integrator::kGeneralizedAlpha, 0.5, 0.25, 0.8, true, true, true },
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

/// With --paths: per output step of a run, the mass centre of the bodies (m) and the layer heights.
void writePath(std::ostream* paths, const at::Model& model, const std::string& name, double dt, const Trace& tr)
{
  if (!paths)
    return;
  double mass = 0.0;
  for (const at::Body& b : model.bodies)
    mass += b.mass;
  for (size_t k = 0; k < tr.t.size(); ++k)
  {
    at::Vec3 c = at::Vec3::Zero();
    for (const at::Body& b : model.bodies)
      c += b.mass / mass * tr.q[k].segment<3>(b.offset);
    *paths << name << "," << dt << "," << tr.t[k] << "," << c.x() << "," << c.y() << "," << c.z() << "\n";
  }
  paths->flush();
}

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

/// A run's position error above this fraction of the structure's size (core::structureSize): the run left the
/// structure behind, whatever its solver said (a MuJoCo run that blew up to finite numbers, 1.5 m off a 1.6 m
/// prism with contact forces of 4e7 N, "converged").
constexpr double kDivergedError = 0.5;

/// The status column of a run: `status`, or "diverged" when a converged run's position error is above
/// kDivergedError of the structure's size `size`; `why` says so.
std::string rowStatus(const std::string& status, const Errors& e, double size, std::string& why)
{
  if (status == "converged" && !(e.position <= kDivergedError * size))
  {
    why = "position error " + at::roundedNumber(e.position, 3) + " m, more than " + at::shortestNumber(kDivergedError) +
          " of the structure's size " + at::roundedNumber(size, 3) + " m";
    return "diverged";
  }
  return status;
}

#ifdef ACTIVE_TENSEGRITY_HAVE_MUJOCO
/// The MuJoCo peer's rows: the scene translated into MuJoCo (mujoco_peer.h) with each integrator over the
/// ladder `dts`, measured against the same reference as our runs (docs/benchmarks.md); `force` is the
/// contact force scale F* (0: the reference's peak force).
void mujocoRows(const at::Model& base, const Trace& ref, const std::vector<std::string>& integrators,
                const std::vector<double>& dts, double force, std::ostream& out, std::ostream* paths)
{
  for (const std::string& integrator : integrators)
    for (double dt : dts)
    {
      tools::MujocoOptions mo;
      mo.integrator = tools::parseMujocoIntegrator(integrator);
      mo.timestep = dt;
      mo.contact_force = force > 0.0 ? force : (ref.peak > 0.0 ? ref.peak : 1000.0);
      const tools::MujocoTrace mj = tools::runMujoco(base, mo);
      // as our trace (body centres into q)
      Trace tr;
      tr.t = mj.t;
      tr.force = mj.force;
      tr.heights = mj.heights;
      tr.peak = mj.peak;
      tr.peak_t = mj.peak_t;
      tr.impulse = mj.impulse;
      for (const std::vector<at::Vec3>& centres : mj.positions)
      {
        Eigen::VectorXd q = Eigen::VectorXd::Zero(base.nq);
        for (size_t b = 0; b < base.bodies.size(); ++b)
          q.segment<3>(base.bodies[b].offset) = centres[b];
        tr.q.push_back(q);
      }
      const Errors e = compare(base, tr, ref);
      const std::string name = "mujoco_" + integrator;
      std::string why = mj.message;
      const std::string status = rowStatus(mj.status, e, mj.size, why);
      writePath(paths, base, name, dt, tr);
      out << name << "," << dt << ",0," << status << "," << mj.steps << "," << mj.solver_iterations << ","
          << mj.wall_time << "," << e.position << "," << e.height << "," << e.force << "," << e.peak << ","
          << e.peak_time << "," << e.impulse << "," << mj.peak << "," << ref.peak << "\n";
      out.flush();
      std::fprintf(stderr,
                   "  %-30s dt  %-8g %-10s wall %7.2f s  position err %.3e m  force err %.3e  peak err %.3e  "
                   "impulse err %.3e%s\n",
                   name.c_str(), dt, status.c_str(), mj.wall_time, e.position, e.force, e.peak, e.impulse,
                   why.empty() ? "" : ("  (" + why + ")").c_str());
    }
}
#endif
}  // namespace

int workPrecision(const std::string& scene, const std::vector<std::string>& args)
{
  std::vector<at::Override> overrides;
  std::vector<double> dts = { 1e-3, 5e-4, 2e-4, 1e-4 };
  std::vector<double> tols = { 1e-3, 1e-4, 1e-5, 1e-6 };
  std::vector<std::string> names;
  double ref_dt = 2.5e-5;
  std::string csv_path;
  std::vector<double> mujoco_dts;  // the MuJoCo peer's ladder (none: not run)
  std::vector<std::string> mujoco_integrators = { "euler", "implicit", "rk4" };
  double mujoco_force = 0.0;  // contact force scale F* (0: the reference's peak)
  std::string paths_path;
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
    else if (a == "--paths")
      paths_path = next();
#ifndef ACTIVE_TENSEGRITY_HAVE_MUJOCO
    else if (a == "--mujoco-dts" || a == "--mujoco-integrators" || a == "--mujoco-contact-force")
      throw tools::BadArgument(a + ": tensegrity_bench was built without MuJoCo (libmujoco-dev was not found, or "
                                   "-DACTIVE_TENSEGRITY_WITH_MUJOCO=OFF, when it was configured)");
#endif
    else if (a == "--mujoco-dts")
      mujoco_dts = numbers();
    else if (a == "--mujoco-integrators")
      mujoco_integrators = splitList(next());
    else if (a == "--mujoco-contact-force")
      mujoco_force = tools::parsePositive<double>(a, next());
    else
      throw BadArgument("unknown argument '" + a + "'");
  }
  std::vector<Scheme> schemes;
  for (const Scheme& sc : workPrecisionSchemes())
    if ((names.empty() && !sc.natural) || std::find(names.begin(), names.end(), sc.name) != names.end())
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
  for (double dt : mujoco_dts)
    grid = std::max(grid, dt);
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
  std::ofstream paths_file;
  if (!paths_path.empty())
  {
    paths_file.open(paths_path);
    if (!paths_file)
      throw std::invalid_argument("cannot write '" + paths_path + "'");
    paths_file << "scheme,dt,t,x,y,z\n";
  }
  std::ostream* paths = paths_path.empty() ? nullptr : &paths_file;
  writePath(paths, base, "reference", ref_dt, ref);
  out << "scheme,dt,tolerance,status,steps,newton_iterations,wall_time,position_error,height_error,force_error,"
         "peak_force_error,peak_time_error,impulse_error,peak_force,reference_peak_force\n";
  const double tol = base.solver.newton_tolerance;
  const double size = at::structureSize(base, base.q0);
  for (const Scheme& sc : schemes)
    for (double x : sc.adaptive ? tols : dts)
    {
      // adaptive runs start from the scene's dt; dt in the table is then their mean step
      const at::Model m = configure(sc, sc.adaptive ? base.solver.dt : x, tol, x);
      const Trace tr = sc.natural ? traceNatural(m) : traceRun(m);
      const Errors e = compare(base, tr, ref);
      const double wall = tr.result.wall_time - tr.result.callback_time;
      const double dt = sc.adaptive ? base.analysis.duration / std::max(1, tr.result.solver_steps) : x;
      std::string why = tr.result.summary.message;
      const std::string status = rowStatus(at::toString(tr.result.summary.status), e, size, why);
      writePath(paths, base, sc.name, dt, tr);
      out << sc.name << "," << dt << "," << (sc.adaptive ? x : 0.0) << "," << status << "," << tr.result.solver_steps
          << "," << tr.result.summary.iterations << "," << wall << "," << e.position << "," << e.height << ","
          << e.force << "," << e.peak << "," << e.peak_time << "," << e.impulse << "," << tr.peak << "," << ref.peak
          << "\n";
      out.flush();
      std::fprintf(stderr,
                   "  %-30s %s %-8g %-10s wall %7.2f s  position err %.3e m  force err %.3e  peak err %.3e  "
                   "impulse err %.3e%s\n",
                   sc.name, sc.adaptive ? "tol" : "dt ", x, status.c_str(), wall, e.position, e.force, e.peak,
                   e.impulse, why.empty() ? "" : ("  (" + why + ")").c_str());
    }
#ifdef ACTIVE_TENSEGRITY_HAVE_MUJOCO
  mujocoRows(base, ref, mujoco_integrators, mujoco_dts, mujoco_force, out, paths);
#else
  static_cast<void>(mujoco_force);  // the options are refused above
#endif
  return 0;
}
}  // namespace active_tensegrity::tools::bench
