/// A kept list of near contact slots for the body coordinates' residuals (the oracle's System).
#pragma once

#include <utility>
#include <vector>

#include <Eigen/Core>

#include "active_tensegrity/oracle/slot_values.h"
#include "active_tensegrity/core/contact/broad_phase.h"
#include "active_tensegrity/core/contact/contact_search.h"
#include "active_tensegrity/core/model/model.h"

namespace active_tensegrity::core
{
/// nearContactSlots with a kept list (a Verlet list): the list is nearContactSlots at a reference q for kSkin
/// times the reach of the call that made it, R = kSkin reach_0. It serves every later call whose reach plus
/// the largest motion of a body since the reference (largestMotion) is at most R: a gap shrinks by at most
/// twice that motion, so every slot within 2 reach of touching is in it. The sweep and the narrow phase of the
/// far candidates thus run once in many calls; the result is the one nearContactSlots gives, in the same order.
/// Each kept slot remembers its gap at the reference and its bodies: while that gap less the two bodies' own
/// motions since the reference stays beyond 2 reach, the slot is not evaluated again (on a lattice most kept
/// slots, whose evaluation read the model's pair table and the known gaps at scattered places).
class NearSlotCache
{
public:
  static constexpr double kSkin = 16.0;
  static constexpr double kBoundMargin = 1e-9;  // m: a slot is skipped by its bound only beyond 2 reach + this
  void find(const Model& model, const BroadPhase& broad, const Eigen::VectorXd& q, double reach, std::vector<int>& out,
            const SlotValues* known_gap = nullptr);
  /// Lists built so far (one per call that found the kept list too far from q).
  long rebuilds() const
  {
    return rebuilds_;
  }
  /// Kept slots passed over by their bound so far (not evaluated).
  long bounded() const
  {
    return bounded_;
  }

private:
  Eigen::VectorXd reference_q_;
  double kept_reach_ = -1.0;  // R, the reach the kept list was made for
  std::vector<int> kept_, candidates_;
  std::vector<double> kept_gap_;                  // each kept slot's gap at the reference
  std::vector<std::pair<int, int>> kept_bodies_;  // its bodies (-1: the ground)
  std::vector<double> motion_;                    // each body's bodyMotion since the reference
  long rebuilds_ = 0;
  long bounded_ = 0;
};
}  // namespace active_tensegrity::core
