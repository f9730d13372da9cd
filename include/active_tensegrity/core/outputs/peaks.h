/// The peaks of a run's CSV columns over every step (a run summary's `peaks`).
#pragma once

#include <string>
#include <vector>

#include "active_tensegrity/core/outputs/observables.h"

namespace active_tensegrity::core
{
/// A CSV column's largest magnitude over every step of a run (time step or load step, not only the output
/// steps), with its sign, and the time (or path parameter) at which it was reached.
struct Peak
{
  std::string name;
  double value = 0.0;
  double t = 0.0;
};

/// Tracks the peaks of actuation_force, max_normal_force, max_friction_force, max_strut_bending_stress and
/// max_cable_stress (what a run's summary lists under `peaks`): give it every step's state (runAnalysis's
/// on_step) and the initial one.
class PeakTracker
{
public:
  explicit PeakTracker(const Model& model);
  /// `contacts`: the state's active contacts when the caller has them (runAnalysis's StepCallback), else null
  /// and they are found here.
  void add(const State& state, const std::vector<ContactPairState>* contacts = nullptr);
  const std::vector<Peak>& peaks() const
  {
    return peaks_;
  }

private:
  const Model& model_;
  std::vector<Peak> peaks_;
  ContactScan contacts_;
  CableStressScan cable_stress_;
};

}  // namespace active_tensegrity::core
