#include "active_tensegrity/oracle/near_slot_cache.h"

#include <algorithm>
#include <cmath>

#include "active_tensegrity/core/contact/contact.h"

namespace active_tensegrity::core
{
namespace
{
double gapAt(const Model& model, int slot, const Eigen::VectorXd& q, const SlotValues* known_gap)
{
  if (known_gap && !std::isnan((*known_gap)[slot]))
    return (*known_gap)[slot];
  return contactGeometry(model, slot, q).gap;
}
}  // namespace

void NearSlotCache::find(const Model& model, const BroadPhase& broad, const Eigen::VectorXd& q, double reach,
                         std::vector<int>& out, const SlotValues* known_gap)
{
  double moved = -1.0;  // the largest motion of a body since the reference (negative: no kept list)
  if (kept_reach_ >= 0.0 && reference_q_.size() == q.size())
  {
    moved = 0.0;
    for (size_t b = 0; b < model.bodies.size(); ++b)
    {
      motion_[b] = bodyMotion(model.bodies[b], reference_q_, q);
      moved = std::max(moved, motion_[b]);
    }
  }
  if (moved < 0.0 || reach + moved > kept_reach_)
  {
    kept_reach_ = kSkin * reach;
    // (contact_search.h's nearContactSlots, with the gaps already known and kept)
    contactCandidates(model, broad, q, kept_reach_, candidates_);
    kept_.clear();
    kept_gap_.clear();
    for (int i : candidates_)
    {
      const double gap = gapAt(model, i, q, known_gap);
      if (gap > 2.0 * kept_reach_)
        continue;
      kept_.push_back(i);
      kept_gap_.push_back(gap);
    }
    kept_bodies_.clear();
    for (int i : kept_)
    {
      if (model.isGroundSlot(i))
        kept_bodies_.emplace_back(model.groundContactOf(i).body, -1);
      else
        kept_bodies_.push_back(model.pairBodies(i));
    }
    reference_q_ = q;
    motion_.assign(model.bodies.size(), 0.0);
    ++rebuilds_;
  }
  // A gap is a distance between two bodies' surfaces less their radii: it closes by at most the sum of the two
  // bodies' largest point motions since the reference. A slot whose reference gap less that sum stays beyond
  // 2 reach (with a margin far above round-off) is apart by more than it, and skips the narrow phase.
  out.clear();
  const double limit = 2.0 * reach;
  for (size_t k = 0; k < kept_.size(); ++k)
  {
    const auto [a, b] = kept_bodies_[k];
    const double closing = motion_[a] + (b >= 0 ? motion_[b] : 0.0);
    if (kept_gap_[k] - closing > limit + kBoundMargin)
    {
      ++bounded_;
      continue;
    }
    if (gapAt(model, kept_[k], q, known_gap) <= limit)
      out.push_back(kept_[k]);
  }
}
}  // namespace active_tensegrity::core
