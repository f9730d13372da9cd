#include "active_tensegrity/core/outputs/csv.h"

#include <algorithm>

#include "active_tensegrity/core/model/model.h"
#include "active_tensegrity/core/outputs/observables.h"

namespace active_tensegrity::core
{
std::vector<std::string> memberColumns(const Model& model)
{
  std::vector<std::string> cols = { "t" };
  for (const Cable& c : model.cables)
    for (const char* what : { "_tension", "_length", "_rest_length" })
      cols.push_back(c.name + what);
  for (const Body& b : model.bodies)
    if (b.kind == BodyKind::kStrut)
      cols.push_back(b.name + "_force");
  return cols;
}

std::vector<double> memberRow(const Model& model, const State& state)
{
  std::vector<double> row = { state.t };
  for (const CableState& c : cableStates(model, state))
  {
    row.push_back(c.tension);
    row.push_back(c.length);
    row.push_back(c.rest_length);
  }
  const std::vector<double> axial = strutAxialForces(model, state);
  for (size_t b = 0; b < model.bodies.size(); ++b)
    if (model.bodies[b].kind == BodyKind::kStrut)
      row.push_back(axial[b]);
  return row;
}

std::vector<std::string> csvColumns(const Model& model)
{
  std::vector<std::string> cols = { "t",
                                    "actuation",
                                    "actuation_force",
                                    "height",
                                    "active_contacts",
                                    "min_gap",
                                    "max_normal_force",
                                    "max_friction_force",
                                    "slack_cables",
                                    "max_strut_bending_stress",
                                    "max_cable_stress",
                                    "min_cable_strut_gap" };
  if (model.ground.enabled)
    for (const char* name : { "ground_contacts", "min_ground_gap", "ground_normal_force", "max_ground_friction_force" })
      cols.push_back(name);
  if (hasLoadPath(model))
    cols.push_back("load_factor");
  for (const OutputLayer& layer : model.layers)
    cols.push_back("height_" + layer.name);
  if (model.actuators.size() > 1)
    for (const Actuator& a : model.actuators)
    {
      cols.push_back("actuation_" + a.name);
      cols.push_back("actuation_force_" + a.name);
    }
  return cols;
}

std::vector<double> csvRow(const Model& model, const State& state)
{
  const bool any = !model.actuators.empty();
  double max_normal = 0.0, max_friction = 0.0, ground_normal = 0.0, ground_friction = 0.0;
  int strut_contacts = 0, ground_contacts = 0;
  const std::vector<ContactPairState> contacts = activeContacts(model, state);
  for (const ContactPairState& c : contacts)
    if (c.body_b < 0)
    {
      ++ground_contacts;
      ground_normal += c.normal_force;
      ground_friction = std::max(ground_friction, c.friction_force);
    }
    else
    {
      ++strut_contacts;
      max_normal = std::max(max_normal, c.normal_force);
      max_friction = std::max(max_friction, c.friction_force);
    }
  std::vector<double> row = { state.t,
                              any ? state.u[0].value : 0.0,
                              any ? actuationForce(model, state, 0) : 0.0,
                              structureHeight(model, state.q),
                              static_cast<double>(strut_contacts),
                              minimumGap(model, state.q),
                              max_normal,
                              max_friction,
                              static_cast<double>(slackCables(model, state)),
                              maxStrutBendingStress(model, state.q, contacts),
                              maxCableStress(model, state),
                              minimumCableStrutGap(model, state.q).gap };
  if (model.ground.enabled)
    row.insert(row.end(), { static_cast<double>(ground_contacts), minimumGroundGap(model, state.q), ground_normal,
                            ground_friction });
  if (hasLoadPath(model))
    row.push_back(loadFactor(model, state));
  for (const OutputLayer& layer : model.layers)
    row.push_back(nodesHeight(model, layer.nodes, state.q));
  if (model.actuators.size() > 1)
    for (size_t i = 0; i < model.actuators.size(); ++i)
    {
      row.push_back(state.u[i].value);
      row.push_back(actuationForce(model, state, static_cast<int>(i)));
    }
  return row;
}

}  // namespace active_tensegrity::core
