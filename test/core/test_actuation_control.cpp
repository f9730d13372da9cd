// ActuatorMotion and ActuationController: ramps against their closed forms, continuity of value and
// rate whenever a command takes over, rates and accelerations as the derivatives of the value,
// trajectories through their points within bounds, and whole-command rejection.
#include <gtest/gtest.h>

#include <cmath>

#include "active_tensegrity/core/solvers/actuation_control.h"

namespace at = active_tensegrity::core;

namespace
{
at::ActuationValue av(double value, double rate = 0.0)
{
  at::ActuationValue v;
  v.value = value;
  v.rate = rate;
  return v;
}

// samples the motion on [t0, t1]: value and rate continuous (no jump between close samples), rate
// and accel the derivatives of value (central differences), |rate| <= vmax, |accel| <= amax
void checkSmooth(const at::ActuatorMotion& m, double t0, double t1, double vmax, double amax)
{
  const double h = 1e-6;
  const int n = 4000;
  at::ActuationValue prev = m.evaluate(t0);
  for (int k = 1; k <= n; ++k)
  {
    const double t = t0 + (t1 - t0) * k / n;
    const at::ActuationValue v = m.evaluate(t);
    const double dt = (t1 - t0) / n;
    // continuity: the change over one sample is bounded by the limits
    EXPECT_LE(std::abs(v.value - prev.value), vmax * dt * (1 + 1e-9) + 1e-12) << "t = " << t;
    EXPECT_LE(std::abs(v.rate - prev.rate), amax * dt * (1 + 1e-9) + 1e-12) << "t = " << t;
    EXPECT_LE(std::abs(v.rate), vmax * (1 + 1e-12)) << "t = " << t;
    EXPECT_LE(std::abs(v.accel), amax * (1 + 1e-12)) << "t = " << t;
    const at::ActuationValue a = m.evaluate(t - h), b = m.evaluate(t + h);
    EXPECT_NEAR((b.value - a.value) / (2 * h), v.rate, 1e-6 * (1 + vmax)) << "t = " << t;
    // accel jumps at piece ends (trapezoid): compare only where both neighbours are on one piece
    if (std::abs(a.accel - b.accel) < 1e-9)
    {
      EXPECT_NEAR((b.rate - a.rate) / (2 * h), v.accel, 1e-5 * (1 + amax)) << "t = " << t;
    }
    prev = v;
  }
}

at::Model twoActuators()
{
  at::Model m;
  at::Actuator a;
  a.name = "pull1";
  a.min_value = 0.0;
  a.max_value = 1.0;
  m.actuators.push_back(a);
  a.name = "pull2";
  a.min_value = -0.5;
  a.max_value = 2.0;
  m.actuators.push_back(a);
  return m;
}
}  // namespace

TEST(ActuatorMotion, TrapezoidalRampMatchesItsClosedForm)
{
  // D = 0.8 m, V = 0.5 m/s, A = 2 m/s^2: accelerate 0.25 s, cruise, brake 0.25 s; T = D/V + V/A
  const double t0 = 3.0, D = 0.8, V = 0.5, A = 2.0;
  const at::ActuatorMotion m = at::ActuatorMotion::ramp(t0, av(0.1), 0.1 + D, V, A);
  EXPECT_NEAR(m.endTime(), t0 + D / V + V / A, 1e-12);
  EXPECT_NEAR(m.evaluate(t0 + 0.25).rate, V, 1e-12);
  EXPECT_NEAR(m.evaluate(t0 + 0.25).value, 0.1 + 0.5 * A * 0.25 * 0.25, 1e-12);
  EXPECT_DOUBLE_EQ(m.evaluate(t0 + 10.0).value, 0.1 + D);
  EXPECT_EQ(m.evaluate(t0 + 10.0).rate, 0.0);
  EXPECT_DOUBLE_EQ(m.evaluate(t0 - 1.0).value, 0.1);
  checkSmooth(m, t0 - 0.1, m.endTime() + 0.1, V, A);
}

TEST(ActuatorMotion, ShortRampIsTriangular)
{
  // D = 0.02 m < V^2 / A: the peak speed sqrt(A D) is below V and the time is 2 sqrt(D / A)
  const double D = 0.02, V = 0.5, A = 2.0;
  const at::ActuatorMotion m = at::ActuatorMotion::ramp(0.0, av(1.0), 1.0 - D, V, A);
  EXPECT_NEAR(m.endTime(), 2.0 * std::sqrt(D / A), 1e-12);
  EXPECT_NEAR(m.evaluate(std::sqrt(D / A)).rate, -std::sqrt(A * D), 1e-12);
  checkSmooth(m, 0.0, m.endTime() + 0.05, V, A);
  EXPECT_DOUBLE_EQ(m.evaluate(1.0).value, 1.0 - D);
}

TEST(ActuatorMotion, RampFromAMovingStartBrakesFirstAndStaysContinuous)
{
  const double V = 0.5, A = 2.0;
  // moving away from the target at 0.3 m/s
  const at::ActuatorMotion away = at::ActuatorMotion::ramp(1.0, av(0.5, 0.3), 0.2, V, A);
  EXPECT_DOUBLE_EQ(away.evaluate(1.0).value, 0.5);
  EXPECT_DOUBLE_EQ(away.evaluate(1.0).rate, 0.3);
  EXPECT_NEAR(away.evaluate(1.0 + 0.3 / A).rate, 0.0, 1e-12);  // stopped after |v| / A
  checkSmooth(away, 1.0, away.endTime() + 0.1, V, A);
  EXPECT_DOUBLE_EQ(away.evaluate(away.endTime()).value, 0.2);
  // toward the target faster than the new limit: slows to V (no overshoot)
  const at::ActuatorMotion fast = at::ActuatorMotion::ramp(0.0, av(0.0, 0.9), 1.0, V, A);
  checkSmooth(fast, 0.0, fast.endTime() + 0.1, 0.9, A);
  double lo = 0.0, hi = 0.0;
  fast.range(lo, hi);
  EXPECT_LE(hi, 1.0 + 1e-12);
  EXPECT_NEAR(fast.evaluate(0.4 / A + 0.01).rate, V, 1e-12);
  // too fast to stop before the target: overshoots, brakes, comes back
  const at::ActuatorMotion over = at::ActuatorMotion::ramp(0.0, av(0.0, 0.9), 0.1, V, A);
  over.range(lo, hi);
  EXPECT_NEAR(hi, 0.9 * 0.9 / (2 * A), 1e-12);
  checkSmooth(over, 0.0, over.endTime() + 0.1, 0.9, A);
  EXPECT_DOUBLE_EQ(over.evaluate(over.endTime()).value, 0.1);
}

TEST(ActuatorMotion, SplinePassesThroughItsPointsWithContinuousRate)
{
  const std::vector<double> times = { 1.5, 2.0, 3.0, 3.2 }, values = { 0.2, 0.6, 0.5, 0.5 };
  // no rates given: monotone rates, so the curve stays within the points' range and ends at rest
  const at::ActuatorMotion m = at::ActuatorMotion::spline(1.0, av(0.0, 0.1), times, values, {});
  for (size_t k = 0; k < times.size(); ++k)
    EXPECT_NEAR(m.evaluate(times[k]).value, values[k], 1e-12);
  EXPECT_DOUBLE_EQ(m.evaluate(1.0).rate, 0.1);  // takes over the current rate
  double lo = 0.0, hi = 0.0;
  m.range(lo, hi);
  EXPECT_GE(lo, -1e-12);
  EXPECT_LE(hi, 0.6 + 1e-12);
  EXPECT_EQ(m.evaluate(3.2).rate, 0.0);
  checkSmooth(m, 1.0, 3.5, 10.0, 100.0);
  // given rates are met at the points
  const at::ActuatorMotion g = at::ActuatorMotion::spline(0.0, av(0.0), { 1.0, 2.0 }, { 1.0, 0.0 }, { -0.5, 0.0 });
  EXPECT_NEAR(g.evaluate(1.0).rate, -0.5, 1e-12);
  g.range(lo, hi);
  EXPECT_GT(hi, 1.0);  // this one overshoots its point: range() must see the interior maximum
}

TEST(ActuationController, TargetsRampEveryNamedActuatorAndOnlyThem)
{
  const at::Model model = twoActuators();
  at::ActuationController c(model, { av(0.0), av(0.5) });
  EXPECT_EQ(c.setTargets(1.0, { "pull2" }, { 1.5 }, { 0.25 }, {}, 0.1, 1.0), "");
  EXPECT_DOUBLE_EQ(c.values(0.5)[1].value, 0.5);
  EXPECT_DOUBLE_EQ(c.values(100.0)[1].value, 1.5);
  EXPECT_DOUBLE_EQ(c.values(100.0)[0].value, 0.0);
  EXPECT_TRUE(c.moving(2.0));
  EXPECT_FALSE(c.moving(100.0));
  // 1 m at 0.25 m/s with A = 1 m/s^2: T = 4 + 0.25 s
  EXPECT_NEAR(c.values(1.0 + 4.25)[1].value, 1.5, 1e-12);
  EXPECT_LT(c.values(1.0 + 4.2)[1].value, 1.5);
  // a new command mid-ramp continues from the current value and rate
  const at::ActuationValue before = c.values(3.0)[1];
  EXPECT_EQ(c.setTargets(3.0, { "pull2", "pull1" }, { 0.0, 1.0 }, {}, {}, 0.5, 2.0), "");
  EXPECT_DOUBLE_EQ(c.values(3.0)[1].value, before.value);
  EXPECT_DOUBLE_EQ(c.values(3.0)[1].rate, before.rate);
  EXPECT_DOUBLE_EQ(c.values(100.0)[1].value, 0.0);
  EXPECT_DOUBLE_EQ(c.values(100.0)[0].value, 1.0);
  c.reset({ av(0.3), av(0.4) });
  EXPECT_DOUBLE_EQ(c.values(200.0)[0].value, 0.3);
  EXPECT_FALSE(c.moving(0.0));
}

TEST(ActuationController, BadCommandsAreRejectedWholeWithTheirReason)
{
  const at::Model model = twoActuators();
  at::ActuationController c(model, { av(0.0), av(0.5) });
  struct Case
  {
    std::vector<std::string> names;
    std::vector<double> targets, speeds, accels;
    const char* expect;  // a piece of the message
  };
  const double nan = std::nan("");
  const std::vector<Case> cases = {
    { { "pull1", "nope" }, { 0.5, 0.5 }, {}, {}, "unknown actuator 'nope'" },
    { {}, {}, {}, {}, "no actuator names" },
    { { "pull1", "pull1" }, { 0.5, 0.6 }, {}, {}, "named twice" },
    { { "pull1", "pull2" }, { 0.5 }, {}, {}, "1 targets for 2" },
    { { "pull2", "pull1" }, { 0.5, nan }, {}, {}, "target of 'pull1' is nan: not a finite number" },
    { { "pull2", "pull1" }, { 0.5, 1.2 }, {}, {}, "outside its range [0, 1]" },
    { { "pull2", "pull1" }, { 0.5, -0.1 }, {}, {}, "outside its range" },
    { { "pull2", "pull1" }, { 0.5, 0.5 }, { 0.1, -1.0 }, {}, "max_speeds of 'pull1' is -1" },
    { { "pull2", "pull1" }, { 0.5, 0.5 }, { 0.0 }, {}, "max_speeds of 'pull2' is 0" },
    { { "pull2", "pull1" }, { 0.5, 0.5 }, { 0.1, 0.1, 0.1 }, {}, "3 max_speeds for 2" },
    { { "pull2" }, { 0.5 }, {}, { INFINITY }, "max_accelerations of 'pull2' is inf" },
  };
  for (const Case& k : cases)
  {
    const std::string err = c.setTargets(1.0, k.names, k.targets, k.speeds, k.accels, 0.1, 1.0);
    EXPECT_NE(err.find(k.expect), std::string::npos) << "got: " << err;
    // nothing applied: both actuators still held
    EXPECT_DOUBLE_EQ(c.values(50.0)[0].value, 0.0);
    EXPECT_DOUBLE_EQ(c.values(50.0)[1].value, 0.5);
  }
  // a default speed that is not positive is refused too
  EXPECT_NE(c.setTargets(1.0, { "pull1" }, { 0.5 }, {}, {}, 0.0, 1.0).find("max_speeds"), std::string::npos);
}

TEST(ActuationController, AHugeNameIsCutInTheMessage)
{
  // a 1 MB actuator name: the node copies the message into its latched status and log
  const at::Model model = twoActuators();
  at::ActuationController c(model, { av(0.0), av(0.5) });
  const std::string huge(1000000, 'n');
  for (const std::vector<std::string>& names : { std::vector<std::string>{ huge }, { "pull1", huge, huge } })
  {
    const std::string err = c.setTargets(1.0, names, std::vector<double>(names.size(), 0.5), {}, {}, 0.1, 1.0);
    EXPECT_NE(err.find("unknown actuator 'nnn"), std::string::npos) << err.substr(0, 300);
    EXPECT_NE(err.find("(1000000 bytes)"), std::string::npos) << err.substr(0, 300);
    EXPECT_LT(err.size(), 1000u);
  }
  const std::string traj = c.setTrajectory(1.0, { huge }, { 1.0 }, { { 0.5 } }, {});
  EXPECT_LT(traj.size(), 1000u) << traj.substr(0, 300);
  EXPECT_FALSE(traj.empty());
}

TEST(ActuationController, TrajectoriesAreFollowedAndCheckedWhole)
{
  const at::Model model = twoActuators();
  at::ActuationController c(model, { av(0.0), av(0.5) });
  const std::vector<std::string> names = { "pull1", "pull2" };
  // first point at time 0 equal to the current values, then two more
  EXPECT_EQ(c.setTrajectory(2.0, names, { 0.0, 1.0, 3.0 }, { { 0.0, 0.5 }, { 0.4, 1.0 }, { 0.8, 0.0 } }, {}), "");
  EXPECT_NEAR(c.values(3.0)[0].value, 0.4, 1e-12);
  EXPECT_NEAR(c.values(3.0)[1].value, 1.0, 1e-12);
  EXPECT_NEAR(c.values(5.0)[0].value, 0.8, 1e-12);
  EXPECT_FALSE(c.moving(5.0));

  const double nan = std::nan("");
  struct Case
  {
    std::vector<std::string> names;
    std::vector<double> times;
    std::vector<std::vector<double>> pos, vel;
    const char* expect;
  };
  const std::vector<Case> cases = {
    { { "pull1", "x" }, { 1.0 }, { { 0.1, 0.1 } }, {}, "unknown actuator 'x'" },
    { names, {}, {}, {}, "no points" },
    { names, { 1.0, 1.0 }, { { 0.1, 0.1 }, { 0.2, 0.2 } }, {}, "strictly increasing" },
    { names, { 2.0, 1.0 }, { { 0.1, 0.1 }, { 0.2, 0.2 } }, {}, "strictly increasing" },
    { names, { -1.0 }, { { 0.1, 0.1 } }, {}, "time_from_start -1" },
    { names, { nan }, { { 0.1, 0.1 } }, {}, "time_from_start nan" },
    { names, { 1.0 }, { { 0.1 } }, {}, "1 positions for 2" },
    { names, { 1.0 }, { { 0.1, nan } }, {}, "position of 'pull2' is nan" },
    { names, { 1.0 }, { { 1.5, 0.1 } }, {}, "outside its range [0, 1]" },
    { names, { 0.0, 1.0 }, { { 0.3, 0.0 }, { 0.5, 0.5 } }, {}, "a jump is an impulse" },
    // given velocities that overshoot the bound between the points
    { names, { 1.0, 2.0 }, { { 0.95, 0.0 }, { 0.95, 0.0 } }, { { 1.0, 0.0 }, { 0.0, 0.0 } }, "outside its range" },
    { names, { 1.0 }, { { 0.5, 0.5 } }, { { 0.1, 0.0 } }, "must end at rest" },
  };
  for (const Case& k : cases)
  {
    const std::string err = c.setTrajectory(10.0, k.names, k.times, k.pos, k.vel);
    EXPECT_NE(err.find(k.expect), std::string::npos) << "got: " << err;
    EXPECT_NEAR(c.values(50.0)[0].value, 0.8, 1e-12);
    EXPECT_NEAR(c.values(50.0)[1].value, 0.0, 1e-12);
  }
}
