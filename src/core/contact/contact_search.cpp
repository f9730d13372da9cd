#include "active_tensegrity/core/contact/contact_search.h"

#include <algorithm>
#include <cmath>

#include "active_tensegrity/core/contact/contact.h"
#include "active_tensegrity/core/base/rotation.h"

namespace active_tensegrity::core
{
void contactCandidates(const Model& model, const BroadPhase& broad, const Eigen::VectorXd& q, double margin,
                       std::vector<int>& out)
{
  if (model.contact.enabled)
    broad.candidates(q, margin, out);
  else
    out.clear();
  appendGroundCandidates(model, q, margin, out);
}

void nearContactSlots(const Model& model, const BroadPhase& broad, const Eigen::VectorXd& q, double reach,
                      std::vector<int>& candidates, std::vector<int>& out)
{
  contactCandidates(model, broad, q, reach, candidates);
  out.clear();
  for (int i : candidates)
    if (contactGeometry(model, i, q).gap <= 2.0 * reach)
      out.push_back(i);
}

double bodyMotion(const Body& b, const Eigen::VectorXd& q0, const Eigen::VectorXd& q1)
{
  double move = (q1.segment<3>(b.offset) - q0.segment<3>(b.offset)).norm();
  if (b.kind == BodyKind::kStrut)
    move += 0.5 * b.length * (bodyZAxis(q1.segment<4>(b.offset + 3)) - bodyZAxis(q0.segment<4>(b.offset + 3))).norm();
  return move;
}

double largestMotion(const Model& model, const Eigen::VectorXd& q0, const Eigen::VectorXd& q1)
{
  double reach = 0.0;
  for (const Body& b : model.bodies)
    reach = std::max(reach, bodyMotion(b, q0, q1));
  return reach;
}

}  // namespace active_tensegrity::core
