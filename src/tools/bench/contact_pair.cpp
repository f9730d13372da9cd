//   tensegrity_bench contact-pair [--repeat N]
// times one strut pair's contact evaluation (evaluateContact, contactGeometry) in dynamics with
// friction, with and without the tangents, and in statics: ns per call, the median over N loops of
// 100000 calls on a two-strut model built in code.
#include <cmath>
#include <cstdio>
#include <iostream>
#include <vector>

#include "active_tensegrity/oracle/body_contact.h"
#include "active_tensegrity/core/contact/contact.h"
#include "active_tensegrity/core/base/rotation.h"
#include "bench.h"

namespace at = active_tensegrity::core;

namespace active_tensegrity::tools::bench
{
namespace
{
// Theta_dot tangent to the unit sphere at theta
at::Vec4 tangentRate(const at::Vec4& theta, const at::Vec4& rate)
{
  return rate - theta.dot(rate) * theta;
}
}  // namespace

int contactPair(int repeat)
{
  // two free rubber-coated struts (as test_contact's twoStruts), crossing at about 75 degrees with the
  // closest points inside both axes and 2 mm of overlap, sliding across each other faster than v1
  at::Model m;
  m.name = "pair";
  m.bodies.push_back(strut("A", 1.2, 0.04, 2.0e7, 0.45));
  m.bodies.push_back(strut("B", 1.0, 0.05, 2.0e7, 0.45));
  at::finalizeModel(m);
  m.contact.enabled = true;
  m.contact.friction = 0.1;
  m.contact.restitution = 0.5;
  m.contact.stick_velocity = 0.01;
  m.contact.slip_velocity = 0.1;
  m.listed_pairs.push_back(at::makeStrutPair(m, 0, 1));
  const at::Vec3 ax = at::Vec3(1.0, 0.2, -0.1).normalized(), bx = at::Vec3(0.1, 1.0, 0.3).normalized();
  const at::Vec3 n = ax.cross(bx).normalized();
  const double s1 = 0.2, s2 = -0.15, overlap = 2e-3;
  const at::Vec3 p1 = at::Vec3(0.1, -0.2, 0.3) + s1 * ax;
  const at::Vec3 p2 = p1 - (0.04 + 0.05 - overlap) * n;
  Eigen::VectorXd q(m.nq), qd(m.nq);
  q.segment<3>(0) = p1 - s1 * ax;
  q.segment<4>(3) = at::thetaFromZAxis(ax);
  q.segment<3>(7) = p2 - s2 * bx;
  q.segment<4>(10) = at::thetaFromZAxis(bx);
  qd.segment<3>(0) = at::Vec3(0.3, -0.1, 0.05);
  qd.segment<4>(3) = tangentRate(q.segment<4>(3), at::Vec4(0.1, -0.2, 0.3, 0.05));
  qd.segment<3>(7) = at::Vec3(-0.2, 0.25, 0.0);
  qd.segment<4>(10) = tangentRate(q.segment<4>(10), at::Vec4(-0.05, 0.1, 0.2, -0.1));
  const double v0 = 0.5;

  at::Model frictionless = m;
  frictionless.contact.friction = 0.0;
  const at::ContactPairState st = at::evaluateContact(m, 0, q, qd, v0, at::ContactMode::kDynamic, nullptr);
  if (!st.active || st.normal_force <= 0.0 || st.slip_speed <= m.contact.slip_velocity)
  {
    std::cerr << "tensegrity_bench: the pair is not in sliding contact\n";
    return 3;
  }
  std::printf("pair: A 1.2 m x r 0.04 m, B 1.0 m x r 0.05 m, E 2e7 Pa, nu 0.45; crossing %.1f deg, region %s\n",
              std::acos(std::abs(ax.dot(bx))) * 180.0 / M_PI,
              st.region == at::ClosestRegion::kInterior ? "interior" : "end/parallel");
  std::printf("state: penetration %.3g m, rate %.3g m/s, F_N %.4g N, slip %.3g m/s (v1 %.3g), F_T %.4g N (mu %.2g)\n",
              st.penetration, st.penetration_rate, st.normal_force, st.slip_speed, m.contact.slip_velocity,
              st.friction_force, m.contact.friction);

  constexpr int kCalls = 100000;
  at::ContactContribution c;
  struct Row
  {
    const char* what;
    double ns;
  };
  std::vector<Row> rows;
  const auto time = [&](const char* what, const auto& f)
  {
    f();  // warm up
    rows.push_back({ what, 1e9 * medianPerCall(f, kCalls, repeat) });
  };
  time("dynamic, friction (slip > v1), force + tangents",
       [&]
       {
         g_sink = g_sink + at::evaluateContact(m, 0, q, qd, v0, at::ContactMode::kDynamic, &c).normal_force +
                  c.stiffness(3, 12) + c.damping(5, 9);
       });
  time("dynamic, friction (slip > v1), state only (out = nullptr)", [&]
       { g_sink = g_sink + at::evaluateContact(m, 0, q, qd, v0, at::ContactMode::kDynamic, nullptr).friction_force; });
  time("dynamic, mu = 0, force + tangents",
       [&]
       {
         g_sink = g_sink + at::evaluateContact(frictionless, 0, q, qd, v0, at::ContactMode::kDynamic, &c).normal_force +
                  c.stiffness(3, 12) + c.damping(5, 9);
       });
  time("static (Hertz), force + tangents",
       [&]
       {
         g_sink = g_sink + at::evaluateContact(m, 0, q, qd, 0.0, at::ContactMode::kStatic, &c).normal_force +
                  c.stiffness(3, 12);
       });
  time("static (Hertz), state only (out = nullptr)", [&]
       { g_sink = g_sink + at::evaluateContact(m, 0, q, qd, 0.0, at::ContactMode::kStatic, nullptr).normal_force; });
  time("narrow phase only (contactGeometry)", [&] { g_sink = g_sink + at::contactGeometry(m, 0, q).gap; });
  std::printf("time per call, median over %d loops of %d calls:\n", repeat, kCalls);
  for (const Row& r : rows)
    std::printf("  %-58s %8.1f ns\n", r.what, r.ns);
  return 0;
}
}  // namespace active_tensegrity::tools::bench
