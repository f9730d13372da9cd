// Ramp actuation laws (core/schedule): the three phases, continuity across the blend boundaries, rate
// and acceleration against finite differences, and the distance covered.
#include <cmath>
#include <random>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "active_tensegrity/core/base/schedule.h"

using namespace active_tensegrity::core;

namespace
{
RampSchedule ramp(double speed, double start, double final_value, double blend)
{
  RampSchedule r;
  r.speed = speed;
  r.start_time = start;
  r.final_value = final_value;
  r.blend_time = blend;
  return r;
}

// schedules whose blends fit in the ramp (blend_time <= final_value / speed)
const std::vector<RampSchedule> kBlended = { ramp(0.2, 0.5, 1.0, 1.5), ramp(0.01, 0.0, 0.02, 0.3),
                                             ramp(3.0, 2.0, 6.0, 2.0) };

// the phase boundaries: start, end of the smooth start, end of the cruise, end
std::vector<double> boundaries(const RampSchedule& r)
{
  return { r.start_time, r.start_time + r.blend_time, r.start_time + r.final_value / r.speed, r.endTime() };
}

// composite two-point Gauss-Legendre rule of the rate over [a, b] (no end points: the sharp ramp's rate
// jumps there)
double integratedRate(const RampSchedule& r, double a, double b, int n = 2000)
{
  const double h = (b - a) / n, x = 0.5 * h / std::sqrt(3.0);
  double sum = 0.0;
  for (int i = 0; i < n; ++i)
  {
    const double mid = a + (i + 0.5) * h;
    sum += r.evaluate(mid - x).rate + r.evaluate(mid + x).rate;
  }
  return 0.5 * h * sum;
}

std::string describe(const RampSchedule& r)
{
  return "speed " + std::to_string(r.speed) + ", start " + std::to_string(r.start_time) + ", final " +
         std::to_string(r.final_value) + ", blend " + std::to_string(r.blend_time);
}
}  // namespace

TEST(RampSchedule, SharpRampPhases)
{
  const RampSchedule r = ramp(0.25, 1.0, 0.5, 0.0);
  EXPECT_DOUBLE_EQ(r.endTime(), 3.0);
  // before the start: nothing
  for (const double t : { -1.0, 0.0, 0.999, 1.0 })
  {
    const ActuationValue v = r.evaluate(t);
    EXPECT_EQ(v.value, 0.0) << t;
    EXPECT_EQ(v.rate, 0.0) << t;
    EXPECT_EQ(v.accel, 0.0) << t;
  }
  // in the middle: constant speed
  for (const double t : { 1.001, 1.5, 2.0, 2.999 })
  {
    const ActuationValue v = r.evaluate(t);
    EXPECT_NEAR(v.value, 0.25 * (t - 1.0), 1e-15) << t;
    EXPECT_EQ(v.rate, 0.25) << t;
    EXPECT_EQ(v.accel, 0.0) << t;
  }
  // after the end: the final value, at rest
  for (const double t : { 3.0, 3.001, 100.0 })
  {
    const ActuationValue v = r.evaluate(t);
    EXPECT_EQ(v.value, 0.5) << t;
    EXPECT_EQ(v.rate, 0.0) << t;
    EXPECT_EQ(v.accel, 0.0) << t;
  }
}

TEST(RampSchedule, EndTimeIsStartPlusTravelTimePlusOneBlend)
{
  for (const RampSchedule& r : kBlended)
    EXPECT_NEAR(r.endTime(), r.start_time + r.final_value / r.speed + r.blend_time, 1e-12) << describe(r);
  EXPECT_DOUBLE_EQ(ramp(0.2, 0.5, 1.0, 0.0).endTime(), 5.5);
}

TEST(RampSchedule, BlendedRampPhases)
{
  for (const RampSchedule& r : kBlended)
  {
    SCOPED_TRACE(describe(r));
    const std::vector<double> b = boundaries(r);
    EXPECT_EQ(r.evaluate(b[0] - 0.1).value, 0.0);
    EXPECT_EQ(r.evaluate(b[0]).rate, 0.0);
    // cruise at the set speed, on the line that reaches the final value at start + final / speed + blend / 2
    for (int i = 1; i < 10; ++i)
    {
      const double t = b[1] + (b[2] - b[1]) * i / 10.0;
      const ActuationValue v = r.evaluate(t);
      EXPECT_NEAR(v.rate, r.speed, 1e-12 * r.speed);
      EXPECT_NEAR(v.accel, 0.0, 1e-12);
      EXPECT_NEAR(v.value, r.speed * (t - r.start_time - 0.5 * r.blend_time), 1e-12);
    }
    // within the blends: speed between 0 and the cruise speed, accelerating then decelerating
    for (int i = 1; i < 10; ++i)
    {
      const ActuationValue in = r.evaluate(b[0] + (b[1] - b[0]) * i / 10.0);
      const ActuationValue out = r.evaluate(b[2] + (b[3] - b[2]) * i / 10.0);
      EXPECT_GT(in.rate, 0.0);
      EXPECT_LT(in.rate, r.speed);
      EXPECT_GT(in.accel, 0.0);
      EXPECT_GT(out.rate, 0.0);
      EXPECT_LT(out.rate, r.speed);
      EXPECT_LT(out.accel, 0.0);
    }
    const ActuationValue end = r.evaluate(b[3] + 1.0);
    EXPECT_EQ(end.value, r.final_value);
    EXPECT_EQ(end.rate, 0.0);
    EXPECT_EQ(end.accel, 0.0);
  }
}

TEST(RampSchedule, ValueRateAndAccelerationAreContinuousAcrossTheBlends)
{
  const double eps = 1e-9;
  for (const RampSchedule& r : kBlended)
    for (const double tb : boundaries(r))
    {
      SCOPED_TRACE(describe(r) + ", boundary " + std::to_string(tb));
      const ActuationValue before = r.evaluate(tb - eps), after = r.evaluate(tb + eps);
      // a jump of the acceleration would be of order speed / blend (here >= 0.03), of the rate of order speed
      const double w = M_PI / r.blend_time;
      EXPECT_NEAR(before.value, after.value, 4.0 * r.speed * eps);
      EXPECT_NEAR(before.rate, after.rate, 4.0 * r.speed * w * eps);
      EXPECT_NEAR(before.accel, after.accel, 4.0 * r.speed * w * w * eps);
    }
}

TEST(RampSchedule, SharpRampRateJumpsAtTheEnds)
{
  // the control for the continuity test: without a blend the rate does jump, and the test sees it
  const RampSchedule r = ramp(0.2, 0.5, 1.0, 0.0);
  const double eps = 1e-9;
  EXPECT_NEAR(r.evaluate(0.5 + eps).rate - r.evaluate(0.5 - eps).rate, 0.2, 1e-15);
  EXPECT_NEAR(r.evaluate(5.5 - eps).rate - r.evaluate(5.5 + eps).rate, 0.2, 1e-15);
}

TEST(RampSchedule, RateAndAccelerationAreDerivativesAtRandomTimes)
{
  std::mt19937 rng(1234);
  const double h = 1e-5;
  std::vector<RampSchedule> schedules = kBlended;
  schedules.push_back(ramp(0.2, 0.5, 1.0, 0.0));  // sharp: rate = speed, accel = 0 inside
  for (const RampSchedule& r : schedules)
  {
    SCOPED_TRACE(describe(r));
    std::uniform_real_distribution<double> time(r.start_time, r.endTime());
    int checked = 0;
    while (checked < 200)
    {
      const double t = time(rng);
      // central differences need the law to be smooth on [t - h, t + h]: stay clear of the phase boundaries
      bool near_boundary = false;
      for (const double b : boundaries(r))
        near_boundary |= std::abs(t - b) < 2.0 * h;
      if (near_boundary)
        continue;
      ++checked;
      const ActuationValue v = r.evaluate(t), lo = r.evaluate(t - h), hi = r.evaluate(t + h);
      const double w = r.blend_time > 0.0 ? M_PI / r.blend_time : 0.0;
      // truncation h^2 / 6 times the next derivative, plus rounding
      EXPECT_NEAR((hi.value - lo.value) / (2.0 * h), v.rate, r.speed * (w * w * h * h + 1e-9)) << "t = " << t;
      EXPECT_NEAR((hi.rate - lo.rate) / (2.0 * h), v.accel, r.speed * (w * w * w * h * h + 1e-8)) << "t = " << t;
    }
  }
}

TEST(RampSchedule, TotalTravelIsTheFinalValue)
{
  std::vector<RampSchedule> schedules = kBlended;
  schedules.push_back(ramp(0.2, 0.5, 1.0, 0.0));
  for (const RampSchedule& r : schedules)
  {
    SCOPED_TRACE(describe(r));
    EXPECT_EQ(r.evaluate(r.endTime()).value, r.final_value);
    // the value is the integral of the rate, phase by phase
    const std::vector<double> b = boundaries(r);
    double travelled = 0.0;
    for (size_t i = 0; i + 1 < b.size(); ++i)
    {
      if (b[i + 1] > b[i])
        travelled += integratedRate(r, b[i], b[i + 1]);
      EXPECT_NEAR(r.evaluate(b[i + 1]).value, travelled, 1e-9 * r.final_value) << "up to " << b[i + 1];
    }
    EXPECT_NEAR(travelled, r.final_value, 1e-9 * r.final_value);
  }
}

TEST(RampSchedule, BlendLongerThanTheRampStillReachesTheFinalValueSmoothly)
{
  // final / speed = 0.8 s < blend_time = 2 s: there is no cruise, the speed never reaches 0.5
  const RampSchedule r = ramp(0.5, 1.0, 0.4, 2.0);
  const double end = r.endTime();
  EXPECT_GT(end, 1.0 + 0.4 / 0.5);
  EXPECT_EQ(r.evaluate(end).value, 0.4);
  EXPECT_LT(r.evaluate(end - 1e-3).value, 0.4);
  EXPECT_NEAR(integratedRate(r, 1.0, end), 0.4, 1e-9);
  double previous = 0.0;
  for (int i = 0; i <= 1000; ++i)
  {
    const ActuationValue v = r.evaluate(1.0 + (end - 1.0) * i / 1000.0);
    EXPECT_GE(v.value, previous);  // monotone
    EXPECT_GE(v.rate, 0.0);
    EXPECT_LE(v.rate, 0.5 + 1e-15);
    previous = v.value;
  }
  const double eps = 1e-9;
  for (const double t : { 1.0, 0.5 * (1.0 + end), end })
  {
    EXPECT_NEAR(r.evaluate(t - eps).rate, r.evaluate(t + eps).rate, 1e-6) << t;
    EXPECT_NEAR(r.evaluate(t - eps).accel, r.evaluate(t + eps).accel, 1e-6) << t;
  }
}

TEST(RampSchedule, NoSpeedOrNoTravelMeansNoMotion)
{
  for (const RampSchedule& r : { ramp(0.0, 1.0, 0.5, 0.2), ramp(0.3, 1.0, 0.0, 0.2) })
  {
    EXPECT_DOUBLE_EQ(r.endTime(), 1.0);
    for (const double t : { 0.0, 1.5, 10.0 })
    {
      const ActuationValue v = r.evaluate(t);
      EXPECT_EQ(v.value, 0.0);
      EXPECT_EQ(v.rate, 0.0);
      EXPECT_EQ(v.accel, 0.0);
    }
  }
}

TEST(RampSchedule, BreakpointsAreTheKinksOfTheLaw)
{
  // sharp: start and end; blended: also where the blends meet the cruise; a blend as long as half the
  // ramp: the cruise vanishes and its two ends merge
  EXPECT_EQ(ramp(0.5, 1.0, 1.0, 0.0).breakpoints(), (std::vector<double>{ 1.0, 3.0 }));
  const std::vector<double> blended = ramp(0.5, 1.0, 1.0, 0.4).breakpoints();
  ASSERT_EQ(blended.size(), 4u);
  EXPECT_DOUBLE_EQ(blended[1], 1.4);
  EXPECT_DOUBLE_EQ(blended[2], 3.0);
  EXPECT_DOUBLE_EQ(blended[3], 3.4);
  EXPECT_EQ(ramp(1.0, 0.0, 1.0, 1.0).breakpoints().size(), 3u);
  EXPECT_TRUE(ramp(0.0, 1.0, 1.0, 0.0).breakpoints().empty());
  // the law is smooth between them: the rate is continuous away from the breakpoints, the
  // acceleration jumps at the sharp ones
  const RampSchedule sharp = ramp(0.5, 1.0, 1.0, 0.0);
  EXPECT_NE(sharp.evaluate(1.0 - 1e-9).rate, sharp.evaluate(1.0 + 1e-9).rate);
}
