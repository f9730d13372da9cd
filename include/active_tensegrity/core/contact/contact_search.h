/// Which contact slots can touch: the broad phase's candidates and the ground's, narrowed to those near touching, and
/// how far the bodies moved between two configurations.
#pragma once

#include <utility>
#include <vector>

#include <Eigen/Core>

#include "active_tensegrity/core/contact/broad_phase.h"
#include "active_tensegrity/core/model/model.h"

namespace active_tensegrity::core
{
/// The largest distance any point of body b moved between q0 and q1 (m): for a strut, its centre's move plus
/// half its length times its axis' turn.
double bodyMotion(const Body& b, const Eigen::VectorXd& q0, const Eigen::VectorXd& q1);

/// The largest distance any point of any body moved between q0 and q1 (m): bodyMotion's largest.
double largestMotion(const Model& model, const Eigen::VectorXd& q0, const Eigen::VectorXd& q1);

/// Contact slots that can touch at q with boxes grown by margin (m): the broad phase's strut pairs (when strut
/// contact is on), then the ground contacts within margin of the ground.
void contactCandidates(const Model& model, const BroadPhase& broad, const Eigen::VectorXd& q, double margin,
                       std::vector<int>& out);

/// The contact slots within 2 reach (m) of touching at q: contactCandidates with boxes grown by reach, kept when
/// their gap is at most 2 reach. While no body point moves by more than reach from q, every slot that touches
/// is among them (two bodies close their distance by at most twice that). `candidates`: scratch.
void nearContactSlots(const Model& model, const BroadPhase& broad, const Eigen::VectorXd& q, double reach,
                      std::vector<int>& candidates, std::vector<int>& out);

}  // namespace active_tensegrity::core
