// The tower's dynamic fold at the paper's step in body coordinates, walked to given instants: for the tests of the
// body solver's Newton matrices.
#pragma once

#include <functional>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "active_tensegrity/core/model/actuation_schedule.h"
#include "active_tensegrity/oracle/body_dynamics.h"
#include "active_tensegrity/core/scene/scene.h"

namespace active_tensegrity::test
{
/// What walkTowerFold() shows at each instant: the model, its solver (residualAndJacobian) and state, the
/// actuation law.
using TowerVisit =
    std::function<void(const core::Model&, core::BodyDynamicsSolver&, const core::BodyState&, const core::ActuationLaw&)>;

/// Steps config/scenes/tower.yaml's dynamic fold (V = its scene's speed) at its dt to each of `times`
/// (ascending, s) and calls `visit` there; a step that fails fails the test.
inline void walkTowerFold(const std::vector<double>& times, const TowerVisit& visit)
{
  using namespace active_tensegrity::core;
  const Model m = loadScene(std::string(ACTIVE_TENSEGRITY_SOURCE_DIR) + "/config/scenes/tower.yaml",
                            { parseOverride("analysis.type=dynamic") });
  BodyDynamicsSolver solver(m, m.solver);
  BodyState s = bodyInitialState(m);
  const ActuationLaw law = [&m](double t) { return scheduledActuation(m, t); };
  ASSERT_TRUE(solver.initialize(s, law).ok());
  const double h = m.solver.dt;
  for (double t : times)
  {
    while (s.t < t - 0.5 * h)
      ASSERT_TRUE(solver.step(s, h, law).ok()) << s.t;
    visit(m, solver, s, law);
  }
}
}  // namespace active_tensegrity::test
