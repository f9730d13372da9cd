#include "active_tensegrity/core/contact/broad_phase.h"

#include <algorithm>
#include <limits>
#include <stdexcept>
#include <string>

#include "active_tensegrity/core/base/rotation.h"

namespace active_tensegrity::core
{
BroadPhase::BroadPhase(const Model& model) : model_(model)
{
  slot_.assign(model.bodies.size(), -1);
  if (model.all_strut_pairs && model.pair_struts.size() >= 2)
    for (int b : model.pair_struts)
    {
      slot_[b] = static_cast<int>(struts_.size());
      struts_.push_back(b);
    }
  for (size_t i = 0; i < model.listed_pairs.size(); ++i)
  {
    const StrutPair& p = model.listed_pairs[i];
    for (int b : { p.body_a, p.body_b })
      if (slot_[b] < 0)
      {
        slot_[b] = static_cast<int>(struts_.size());
        struts_.push_back(b);
      }
    if (!pair_index_.emplace(pairKey(p.body_a, p.body_b), static_cast<int>(i)).second)
      throw std::invalid_argument("BroadPhase: the pair of bodies " + std::to_string(p.body_a) + " and " +
                                  std::to_string(p.body_b) + " is listed twice in Model::listed_pairs");
  }
  // sorting n boxes costs about n log n comparisons; comparing every listed pair costs one each
  const double n = static_cast<double>(struts_.size());
  use_sweep_ = static_cast<double>(model.pairSlots()) > 4.0 * n;
  boxes_.resize(struts_.size());
  order_.resize(struts_.size());
}

void BroadPhase::boxes(const Eigen::VectorXd& q, double margin) const
{
  for (size_t k = 0; k < struts_.size(); ++k)
  {
    const Body& b = model_.bodies[struts_[k]];
    const Vec3 c = q.segment<3>(b.offset);
    const Vec3 half = 0.5 * b.length * bodyZAxis(q.segment<4>(b.offset + 3));
    const Vec3 grow = Vec3::Constant(b.radius() + margin) + half.cwiseAbs();
    boxes_[k].lo = c - grow;
    boxes_[k].hi = c + grow;
  }
}

void BroadPhase::direct(const Eigen::VectorXd& q, double margin, std::vector<int>& out) const
{
  out.clear();
  boxes(q, margin);
  for (int i = 0; i < model_.pairSlots(); ++i)
  {
    if (!model_.isCheckedPair(i))
      continue;
    const auto [body_a, body_b] = model_.pairBodies(i);
    const Box& a = boxes_[slot_[body_a]];
    const Box& b = boxes_[slot_[body_b]];
    if ((a.lo.array() <= b.hi.array()).all() && (b.lo.array() <= a.hi.array()).all())
      out.push_back(i);
  }
}

void BroadPhase::sweep(const Eigen::VectorXd& q, double margin, std::vector<int>& out) const
{
  out.clear();
  boxes(q, margin);
  const int n = static_cast<int>(struts_.size());
  if (n < 2)
    return;
  // sweep along the axis where the box centres spread most (fewest overlaps on it)
  Vec3 lo = Vec3::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
  for (const Box& b : boxes_)
  {
    const Vec3 c = 0.5 * (b.lo + b.hi);
    lo = lo.cwiseMin(c);
    hi = hi.cwiseMax(c);
  }
  int axis = 0;
  (hi - lo).maxCoeff(&axis);
  for (int k = 0; k < n; ++k)
    order_[k] = k;
  std::sort(order_.begin(), order_.end(),
            [this, axis](int x, int y) { return boxes_[x].lo(axis) < boxes_[y].lo(axis); });
  for (int i = 0; i < n; ++i)
  {
    const Box& a = boxes_[order_[i]];
    for (int j = i + 1; j < n; ++j)
    {
      const Box& b = boxes_[order_[j]];
      if (b.lo(axis) > a.hi(axis))
        break;
      if (!((a.lo.array() <= b.hi.array()).all() && (b.lo.array() <= a.hi.array()).all()))
        continue;
      const int body_a = struts_[order_[i]], body_b = struts_[order_[j]];
      if (model_.all_strut_pairs)
      {
        const int slot = model_.allPairsSlot(body_a, body_b);
        if (slot >= 0)
          out.push_back(slot);
        continue;
      }
      const auto it = pair_index_.find(pairKey(body_a, body_b));
      if (it != pair_index_.end())
        out.push_back(it->second);
    }
  }
  std::sort(out.begin(), out.end());
}

void BroadPhase::candidates(const Eigen::VectorXd& q, double margin, std::vector<int>& out) const
{
  if (use_sweep_)
    sweep(q, margin, out);
  else
    direct(q, margin, out);
}

}  // namespace active_tensegrity::core
