#include "active_tensegrity/core/elements/cable.h"

#include <algorithm>
#include <array>
#include <cstdlib>
#include <vector>

namespace active_tensegrity::core
{
namespace
{
/// Whether the element stores energy at this stretch l - l0: taut, or a spring that also pushes.
bool storesEnergy(const Cable& cable, double stretch)
{
  return stretch > 0.0 || !cable.tension_only;
}

/// k (l - l0) where the element stores energy, else 0 (N): the elastic part of the tension.
double elasticTension(const Cable& cable, const CableState& s)
{
  const double stretch = s.length - s.rest_length;
  return storesEnergy(cable, stretch) ? s.stiffness * stretch : 0.0;
}
/// A cable's state from its points' motion, supplied by the caller: motion(j, p, v).
template <class Motion>
CableState cableState(const Cable& cable, const ActuationValues& u, bool damping, Motion&& motion)
{
  std::array<Vec3, Cable::kMaxPoints> p, v;
  const int m = static_cast<int>(cable.points.size());
  for (int j = 0; j < m; ++j)
    motion(j, p[j], v[j]);
  double length = 0.0, rate = 0.0;
  for (int k = 0; k + 1 < m; ++k)
  {
    const Vec3 d = p[k + 1] - p[k];
    const double seg = d.norm();
    const Vec3 n = seg > 0.0 ? Vec3(d / seg) : Vec3::Zero();
    length += seg;
    rate += n.dot(v[k + 1] - v[k]);
  }
  return cableLaw(cable, length, rate, u, damping);
}
}  // namespace

CableState cableLaw(const Cable& cable, double length, double rate, const ActuationValues& u, bool damping)
{
  CableState s;
  s.length = length;
  s.rate = rate;
  double pull_in = 0.0, pull_rate = 0.0;
  if (cable.actuator >= 0 && cable.actuator < static_cast<int>(u.size()))
  {
    pull_in = u[cable.actuator].value;
    pull_rate = u[cable.actuator].rate;
  }
  s.rest_length = cable.rest_length - pull_in;
  // a material cable keeps EA when pulled in, so k = EA / l0 grows; a spring keeps k
  s.stiffness = cable.area > 0.0 ? cable.stiffness * cable.rest_length / s.rest_length : cable.stiffness;
  const double c = damping ? cable.damping : 0.0;
  const double stretch = s.length - s.rest_length;
  const double tension = s.stiffness * stretch + c * (s.rate + pull_rate);  // damping on the material stretch rate
  if (s.length <= 0.0 || (cable.tension_only && (stretch <= 0.0 || tension <= 0.0)))
  {
    s.slack = true;
    return s;
  }
  s.tension = tension;
  s.damping_tension = c * (s.rate + pull_rate);
  return s;
}

CableState evaluateCable(const Model& model, const Cable& cable, const Eigen::VectorXd& q, const Eigen::VectorXd& qd,
                         const ActuationValues& u, bool damping)
{
  return cableState(cable, u, damping,
                    [&](int j, Vec3& p, Vec3& v) { pointMotion(model, cable.points[j], q, qd, p, v); });
}

CableState evaluateCable(const Cable& cable, const PointSlot* points, const BodyFrames& frames,
                         const Eigen::VectorXd& q, const Eigen::VectorXd& qd, const ActuationValues& u, bool damping)
{
  return cableState(cable, u, damping, [&](int j, Vec3& p, Vec3& v) { frames.motion(points[j], q, qd, p, v); });
}

double cablePotentialEnergy(const Cable& cable, const CableState& s)
{
  const double stretch = s.length - s.rest_length;
  return storesEnergy(cable, stretch) ? 0.5 * s.stiffness * stretch * stretch : 0.0;
}

double cableConservativePower(const Cable& cable, const CableState& s)
{
  return -elasticTension(cable, s) * s.rate;
}

double cableNonConservativePower(const Cable& cable, const CableState& s)
{
  return s.slack ? elasticTension(cable, s) * s.rate : -s.damping_tension * s.rate;
}

}  // namespace active_tensegrity::core
