#include "active_tensegrity/core/contact/contact.h"

#include "active_tensegrity/core/model/kinematics.h"

#include <cmath>

namespace active_tensegrity::core
{
double contactElasticEnergy(const Model& model, const ContactPairState& st)
{
  if (!st.active)
    return 0.0;
  const bool ground = st.body_b < 0;
  const ContactLaw law = ground ? model.ground.law : model.contact.law;
  if (law == ContactLaw::kLinear)
    return 0.5 * st.stiffness * st.penetration * st.penetration;
  return 0.4 * (st.stiffness * std::pow(st.penetration, 2.5) + st.core_stiffness * std::pow(st.core_penetration, 2.5));
}

void appendGroundCandidates(const Model& model, const Eigen::VectorXd& q, double margin, std::vector<int>& out)
{
  const int first = model.pairSlots();
  for (size_t i = 0; i < model.ground_contacts.size(); ++i)
  {
    const GroundContact& g = model.ground_contacts[i];
    if (pointPosition(model, PointRef{ g.body, g.local }, q).z() - g.radius - model.ground.height <= margin)
      out.push_back(first + static_cast<int>(i));
  }
}

const std::string& contactBodyName(const Model& model, int body)
{
  static const std::string ground = "ground";
  return body < 0 ? ground : model.bodies[body].name;
}

bool axesPassedThrough(const AxisPose& a0, const AxisPose& b0, const AxisPose& a1, const AxisPose& b1, double half_a,
                       double half_b)
{
  const Vec3 m0 = a0.axis.cross(b0.axis), m1 = a1.axis.cross(b1.axis);
  if (m0.dot(m1) <= 0.0)
    return false;
  // signed distance of the axis lines (times |a1 x a2|) at both ends of the step
  const double side0 = (a0.centre - b0.centre).dot(m0), side1 = (a1.centre - b1.centre).dot(m1);
  if (side0 * side1 > 0.0 || (side0 == 0.0 && side1 == 0.0))
    return false;
  // where the lines met, moving linearly between the two states: inside both struts?
  const double tau = side0 / (side0 - side1);
  const Vec3 ca = (1.0 - tau) * a0.centre + tau * a1.centre, cb = (1.0 - tau) * b0.centre + tau * b1.centre;
  const Vec3 da = (1.0 - tau) * a0.axis + tau * a1.axis, db = (1.0 - tau) * b0.axis + tau * b1.axis;
  const double aa = da.squaredNorm(), bbn = db.squaredNorm(), ab = da.dot(db);
  const double det = aa * bbn - ab * ab;
  if (det <= 1e-12 * aa * bbn)
    return false;
  const Vec3 r = ca - cb;
  const double sa = (ab * db.dot(r) - bbn * da.dot(r)) / det;  // P_a = ca + sa da
  const double sb = (aa * db.dot(r) - ab * da.dot(r)) / det;   // P_b = cb + sb db
  const double reach_a = half_a / std::sqrt(aa);
  const double reach_b = half_b / std::sqrt(bbn);
  return std::abs(sa) <= reach_a && std::abs(sb) <= reach_b;
}

}  // namespace active_tensegrity::core
