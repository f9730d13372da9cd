/// The rows tensegrity_run writes: the run's CSV columns and the members' (--members).
#pragma once

#include <string>
#include <vector>

#include "active_tensegrity/core/solvers/state.h"

namespace active_tensegrity::core
{
/// Column names of tensegrity_run --members: t, then NAME_tension, NAME_length, NAME_rest_length per cable
/// and spring (Model::cables order), then NAME_force per strut.
std::vector<std::string> memberColumns(const Model& model);
/// The row of memberColumns (state.t first).
std::vector<double> memberRow(const Model& model, const State& state);

/// Column names of the CSV: t, actuation, actuation_force, height, active_contacts, min_gap,
/// max_normal_force, max_friction_force (these three of strut pairs), slack_cables, max_strut_bending_stress,
/// max_cable_stress, min_cable_strut_gap (minimumCableStrutGap; empty when no pair is near), with the ground on
/// ground_contacts, min_ground_gap, ground_normal_force (their sum) and max_ground_friction_force, then
/// load_factor (static paths that scale their loads), height_<layer> per output layer, then actuation_<name> and
/// actuation_force_<name> per actuator when there are several.
std::vector<std::string> csvColumns(const Model& model);
std::vector<double> csvRow(const Model& model, const State& state);

}  // namespace active_tensegrity::core
