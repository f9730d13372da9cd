#include "active_tensegrity/core/solvers/modal.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <stdexcept>
#include <string>

#include <Eigen/Dense>

#include "active_tensegrity/core/solvers/natural.h"
#include "active_tensegrity/core/solvers/statics.h"
#include "active_tensegrity/core/base/text.h"

namespace active_tensegrity::core
{
ModalAnalysis naturalModes(const Model& model, const State& state, int count)
{
  const ReducedStructure r = reduceStructure(model, state);
  const int f = static_cast<int>(r.basis.cols());
  ModalAnalysis out;
  out.free_coordinates = f;
  if (f == 0 || count <= 0)
    return out;

  // M_r = N^T M N with the natural coordinates' constant mass matrix (no spin rates): positive definite, every strut
  // and point mass having a mass
  const NaturalModel nm = buildNaturalModel(model, false);
  Eigen::MatrixXd mr = r.basis.transpose() * (nm.mass * r.basis);
  mr = 0.5 * (mr + mr.transpose());
  Eigen::GeneralizedSelfAdjointEigenSolver<Eigen::MatrixXd> eig(r.stiffness, mr);
  if (eig.info() != Eigen::Success)
    throw std::invalid_argument("the mass matrix is not positive definite on the free coordinates");
  const Eigen::VectorXd& values = eig.eigenvalues();
  const double zero = kZeroEigenvalue * values.cwiseAbs().maxCoeff();

  const int n_nodes = static_cast<int>(model.nodes.size());
  for (int k = 0; k < std::min(count, f); ++k)
  {
    NaturalMode mode;
    mode.eigenvalue = std::abs(values(k)) <= zero ? 0.0 : values(k);
    mode.omega = std::copysign(std::sqrt(std::abs(mode.eigenvalue)), mode.eigenvalue);
    mode.frequency_hz = mode.omega / (2.0 * M_PI);
    // scaled to a largest point displacement of 1, that displacement's largest component positive
    mode.shape = r.basis * eig.eigenvectors().col(k);
    const Eigen::VectorXd u = r.node_map * mode.shape;
    int largest = 0;
    for (int i = 1; i < u.size() / 3; ++i)
      if (u.segment<3>(3 * i).norm() > u.segment<3>(3 * largest).norm())
        largest = i;
    const Vec3 top = u.segment<3>(3 * largest);
    int axis = 0;
    top.cwiseAbs().maxCoeff(&axis);
    const double norm = top.norm();
    if (norm > 0.0)
      mode.shape *= (top(axis) < 0.0 ? -1.0 : 1.0) / norm;
    // round-off of the unit displacement (a pinned node's 1e-16 m) written as 0
    const Eigen::VectorXd scaled =
        Eigen::VectorXd(r.node_map * mode.shape).unaryExpr([](double x) { return std::abs(x) < 1e-12 ? 0.0 : x; });
    for (int i = 0; i < n_nodes; ++i)
      mode.node_displacements.push_back(scaled.segment<3>(3 * i));
    out.modes.push_back(mode);
  }
  return out;
}

ModalRun runModal(const Model& model)
{
  const auto start = std::chrono::steady_clock::now();
  const auto finish = [&](ModalRun& run)
  { run.wall_time = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count(); };
  ModalRun run;
  State state = initialState(model);
  const std::vector<std::string> start_warnings = startWarnings(model, state);
  StaticSolver solver(model, model.solver);
  run.summary = solver.solve(state, state.u);
  run.summary.warnings.insert(run.summary.warnings.begin(), start_warnings.begin(), start_warnings.end());
  if (!run.summary.ok())
  {
    run.summary.message = "equilibrium at the start: " + run.summary.message;
    run.equilibrium = state;
    finish(run);
    return run;
  }
  const AnalysisSettings& an = model.analysis;
  if (an.max_actuation > 0.0 && !model.actuators.empty())
  {
    ActuationValues u_end = state.u;
    for (ActuationValue& v : u_end)
      v.value = an.max_actuation;
    const int first_iterations = run.summary.iterations;
    std::vector<std::string> warnings = run.summary.warnings;
    run.summary = solver.followPath(state, u_end, an.steps, [](const State&, const Summary&) {});
    run.summary.iterations += first_iterations;
    warnings.insert(warnings.end(), run.summary.warnings.begin(), run.summary.warnings.end());
    run.summary.warnings = warnings;
    if (!run.summary.ok())
    {
      run.summary.message =
          "equilibrium at actuation " + shortestNumber(an.max_actuation) + " m: " + run.summary.message;
      run.equilibrium = state;
      finish(run);
      return run;
    }
  }
  run.equilibrium = state;
  try
  {
    run.structure = checkStructure(model, state);
    run.modal = naturalModes(model, state, an.modes);
  }
  catch (const std::invalid_argument& e)
  {
    // a degenerate equilibrium (a motion that moves no node, a mass matrix that is not positive definite)
    run.summary.status = SolveStatus::kSingular;
    run.summary.message = std::string("modal analysis: ") + e.what();
    finish(run);
    return run;
  }
  std::vector<std::string>& warnings = run.summary.warnings;
  if (static_cast<int>(run.modal.modes.size()) < an.modes)
    warnings.push_back("analysis.modes asks for " + std::to_string(an.modes) + " modes; the structure has " +
                       std::to_string(run.modal.free_coordinates) + " free coordinates, so " +
                       std::to_string(run.modal.modes.size()) + " modes");
  for (size_t k = 0; k < run.modal.modes.size(); ++k)
    if (run.modal.modes[k].eigenvalue < 0.0)
      warnings.push_back("mode " + std::to_string(k + 1) +
                         " has a negative eigenvalue (omega^2 = " + shortestNumber(run.modal.modes[k].eigenvalue) +
                         " 1/s^2): the equilibrium is unstable along it");
  finish(run);
  return run;
}

}  // namespace active_tensegrity::core
