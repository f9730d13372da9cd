// A folding request checked against its scene.
#include "folding_steps.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <functional>
#include <map>
#include <mutex>
#include <random>
#include <set>
#include <sstream>

#include <ompl/base/PlannerTerminationCondition.h>
#include <ompl/base/ProblemDefinition.h>
#include <ompl/base/SpaceInformation.h>
#include <ompl/base/StateSampler.h>
#include <ompl/base/goals/GoalSampleableRegion.h>
#include <ompl/base/goals/GoalState.h>
#include <ompl/base/objectives/MaximizeMinClearanceObjective.h>
#include <ompl/base/objectives/PathLengthOptimizationObjective.h>
#include <ompl/base/spaces/RealVectorStateProjections.h>
#include <ompl/base/spaces/RealVectorStateSpace.h>
#include <ompl/datastructures/NearestNeighborsLinear.h>
#include <ompl/geometric/PathGeometric.h>
#include <ompl/util/Console.h>

#include "active_tensegrity/planning/folding_planner.h"
#include "active_tensegrity/core/solvers/actuation_control.h"
#include "active_tensegrity/core/outputs/observables.h"
#include "active_tensegrity/core/contact/contact.h"
#include "active_tensegrity/core/solvers/dynamics.h"
#include "active_tensegrity/core/solvers/modal.h"
#include "active_tensegrity/core/solvers/statics.h"
#include "active_tensegrity/core/base/text.h"
#include "active_tensegrity/planning/trajectory.h"
#include "active_tensegrity/planning/validity.h"

namespace active_tensegrity::planning::detail
{
namespace og = ompl::geometric;

std::string checkRequest(const core::Model& model, const PlanRequest& r, std::vector<int>& idx)
{
  std::ostringstream msg;
  if (r.actuators.empty())
    return "no actuators named";
  std::set<std::string> seen;
  for (const std::string& n : r.actuators)
  {
    const int i = model.findActuator(n);
    if (i < 0)
    {
      msg << "unknown actuator " << core::quoted(n) << " (the scene has:";
      for (const core::Actuator& a : model.actuators)
        msg << " " << a.name;
      msg << ")";
      return msg.str();
    }
    if (!seen.insert(n).second)
      return "actuator " + core::quoted(n) + " named twice";
    idx.push_back(i);
  }
  const size_t n = idx.size();
  if (r.target_values.empty())
  {
    if (!std::isfinite(r.target_height))
      return "give a finite target_height or target_values";
  }
  else
  {
    if (r.target_values.size() != n)
    {
      msg << r.target_values.size() << " target_values for " << n << " actuators";
      return msg.str();
    }
    for (size_t k = 0; k < n; ++k)
    {
      const core::Actuator& a = model.actuators[idx[k]];
      if (!std::isfinite(r.target_values[k]))
      {
        msg << "target value of '" << a.name << "' is " << r.target_values[k] << ": not a finite number";
        return msg.str();
      }
      if (r.target_values[k] < a.min_value || r.target_values[k] > a.max_value)
      {
        msg << "target value of '" << a.name << "' is " << r.target_values[k] << ", outside its range [" << a.min_value
            << ", " << a.max_value << "]";
        return msg.str();
      }
    }
  }
  const auto positive = [&](const std::vector<double>& v, const char* what) -> std::string
  {
    if (v.size() != 1 && v.size() != n)
    {
      std::ostringstream m;
      m << v.size() << " " << what << " for " << n << " actuators (give one for all, or one each)";
      return m.str();
    }
    for (double x : v)
      if (!std::isfinite(x) || x <= 0.0)
      {
        std::ostringstream m;
        m << what << " must be finite and > 0, got " << x;
        return m.str();
      }
    return "";
  };
  std::string err = positive(r.max_speeds, "max_speeds");
  if (err.empty())
    err = positive(r.max_accelerations, "max_accelerations");
  if (!err.empty())
    return err;
  const auto nonneg = [&](double x, const char* what, bool allow_inf) -> std::string
  {
    if (std::isnan(x) || x < 0.0 || (!allow_inf && !std::isfinite(x)))
    {
      std::ostringstream m;
      m << what << " must be " << (allow_inf ? ">= 0" : "finite and >= 0") << ", got " << x;
      return m.str();
    }
    return "";
  };
  for (const auto& [x, what, inf] :
       { std::make_tuple(r.limits.min_clearance, "min_clearance", false),
         std::make_tuple(r.limits.max_contact_force, "max_contact_force", true),
         std::make_tuple(r.limits.max_cable_stress, "max_cable_stress", true),
         std::make_tuple(r.max_bending_stress, "max_bending_stress", true),
         std::make_tuple(r.settle_time, "settle_time", false), std::make_tuple(r.range, "range", false),
         std::make_tuple(r.blend_tolerance, "blend_tolerance", false) })
    if (!(err = nonneg(x, what, inf)).empty())
      return err;
  for (const auto& [x, what] :
       { std::make_pair(r.time_limit, "time_limit"), std::make_pair(r.continuation_step, "continuation_step"),
         std::make_pair(r.sample_dt, "sample_dt"), std::make_pair(r.rest_speed, "rest_speed"),
         std::make_pair(r.max_settle_time, "max_settle_time"),
         std::make_pair(r.speed_limit_tolerance, "speed_limit_tolerance") })
    if (!std::isfinite(x) || x <= 0.0)
    {
      msg << what << " must be finite and > 0, got " << x;
      return msg.str();
    }
  if (r.planner == "FMT" || r.planner == "BFMT")
  {
    // not offered: OMPL 1.5's FMT, stopped by the deadline, crashed the process when it was released (a
    // segmentation fault in FMT::freeMemory, the quadruplex's top to 0.888 m with a 0.1 s limit), and BFMT crashed
    // once in a run of random requests
    msg << "planner " << core::quoted(r.planner)
        << " is not offered: OMPL 1.5's FMT and BFMT can crash the process when a deadline stops them (BITstar and "
           "PRMstar are asymptotically optimal too)";
    return msg.str();
  }
  if (!planners().count(r.planner))
  {
    msg << "unknown planner " << core::quoted(r.planner) << " (known:";
    for (const std::string& p : plannerNames())
      msg << " " << p;
    msg << ")";
    return msg.str();
  }
  return "";
}
}  // namespace active_tensegrity::planning::detail
