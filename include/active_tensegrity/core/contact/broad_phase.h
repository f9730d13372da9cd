/// Broad phase of strut contact: which checked pairs can touch at all. Each strut is bounded by the
/// axis-aligned box of its axis segment grown by its radius (and a margin); a pair whose boxes do not
/// overlap cannot be in contact, so the narrow phase skips it. Exact for contact: the box contains
/// the strut (a capsule), so no contact is ever missed (test_broad_phase checks it against all pairs).
#pragma once

#include <cstdint>
#include <unordered_map>
#include <vector>

#include <Eigen/Core>

#include "active_tensegrity/core/model/model.h"

namespace active_tensegrity::core
{
/// Not thread-safe: its scratch (boxes, sort order) is shared by its const calls; use one per thread.
class BroadPhase
{
public:
  /// Throws std::invalid_argument when a pair of bodies is listed twice in model.listed_pairs.
  explicit BroadPhase(const Model& model);

  /// The checked strut pairs' slots (Model::strutPair, ascending) whose boxes, grown by `margin` (m),
  /// overlap at q. Few pairs per strut: every listed pair's boxes are compared; many pairs (e.g. `auto`
  /// on a large scene): sort and sweep along the axis of largest spread, O(n log n + overlaps).
  void candidates(const Eigen::VectorXd& q, double margin, std::vector<int>& out) const;

  /// The sweep alone (tests compare it with the direct comparison).
  void sweep(const Eigen::VectorXd& q, double margin, std::vector<int>& out) const;
  /// The direct comparison of every checked pair.
  void direct(const Eigen::VectorXd& q, double margin, std::vector<int>& out) const;

  bool usesSweep() const
  {
    return use_sweep_;
  }

private:
  struct Box
  {
    Eigen::Vector3d lo, hi;
  };
  void boxes(const Eigen::VectorXd& q, double margin) const;

  const Model& model_;
  std::vector<int> struts_;  // bodies that appear in a pair
  std::vector<int> slot_;    // body -> index in struts_ (or -1)
  std::unordered_map<std::uint64_t, int> pair_index_;
  bool use_sweep_ = false;
  mutable std::vector<Box> boxes_;  // scratch, per strut in struts_
  mutable std::vector<int> order_;
};

}  // namespace active_tensegrity::core
