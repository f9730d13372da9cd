// Time parameterization: rest to rest against the trapezoid's closed form; blended corners within their
// tolerance of the path; the time-optimal trajectory within every actuator's speed and acceleration limit,
// consistent (positions, velocities, accelerations agree by finite differences), from rest to rest, and
// no slower than rest to rest; a straight path gives the trapezoid again.
#include <gtest/gtest.h>

#include <cmath>

#include "active_tensegrity/planning/equilibria.h"
#include "active_tensegrity/planning/trajectory.h"

namespace ap = active_tensegrity::planning;
using Values = std::vector<double>;

namespace
{
/// Max-norm distance from x to the polyline through w.
double distanceToPath(const Values& x, const std::vector<Values>& w)
{
  double best = INFINITY;
  for (size_t k = 1; k < w.size(); ++k)
  {
    // the max-norm distance to a segment, by a fine search along it (the test's scale: 1e-6 of its length)
    double lo = 0.0, hi = 1.0;
    const auto at = [&](double f)
    {
      Values p(x.size());
      for (size_t i = 0; i < x.size(); ++i)
        p[i] = w[k - 1][i] + f * (w[k][i] - w[k - 1][i]);
      return ap::actuationDistance(p, x);
    };
    for (int it = 0; it < 100; ++it)  // the distance is convex along the segment: ternary search
    {
      const double a = lo + (hi - lo) / 3, b = hi - (hi - lo) / 3;
      (at(a) < at(b) ? hi : lo) = at(a) < at(b) ? b : a;
    }
    best = std::min(best, at(0.5 * (lo + hi)));
  }
  return best;
}

/// Every sample within the limits (up to the discretization, 1 %), and the three series consistent.
void checkLimits(const ap::Trajectory& t, const Values& vmax, const Values& amax)
{
  ASSERT_GT(t.times.size(), 2u);
  const size_t n = vmax.size();
  for (size_t k = 0; k < t.times.size(); ++k)
    for (size_t i = 0; i < n; ++i)
    {
      EXPECT_LE(std::abs(t.velocities[k][i]), vmax[i] * 1.01) << "sample " << k << " actuator " << i;
      EXPECT_LE(std::abs(t.accelerations[k][i]), amax[i] * 1.01) << "sample " << k << " actuator " << i;
    }
  EXPECT_EQ(t.velocities.front(), Values(n, 0.0));
  EXPECT_EQ(t.velocities.back(), Values(n, 0.0));
  EXPECT_NEAR(t.times.back(), t.duration, 1e-12);
  // each interval: the velocities integrate to the positions' change and the accelerations to the
  // velocities' (the trapezoid rule; an acceleration may jump inside an interval, by at most 2 amax)
  for (size_t k = 1; k < t.times.size(); ++k)
  {
    const double h = t.times[k] - t.times[k - 1];
    for (size_t i = 0; i < n; ++i)
    {
      const double dv = t.velocities[k][i] - t.velocities[k - 1][i];
      EXPECT_LE(std::abs(dv - 0.5 * h * (t.accelerations[k - 1][i] + t.accelerations[k][i])), 2.0 * amax[i] * h + 1e-9)
          << "interval " << k << " actuator " << i;
      const double dx = t.positions[k][i] - t.positions[k - 1][i];
      EXPECT_LE(std::abs(dx - 0.5 * h * (t.velocities[k - 1][i] + t.velocities[k][i])), amax[i] * h * h + 1e-9)
          << "interval " << k << " actuator " << i;
    }
  }
}
}  // namespace

TEST(Trajectory, RestToRestIsTheTrapezoidOfTheTightestActuator)
{
  // 1 m and 0.5 m at 0.2 m/s and 0.5 m/s^2: the first actuator binds, T = L / v + v / a = 5 + 0.4 s
  const ap::Trajectory t = ap::restToRest({ { 0.0, 0.0 }, { 1.0, 0.5 } }, { 0.2 }, { 0.5 }, 0.01);
  EXPECT_NEAR(t.duration, 5.4, 1e-9);
  checkLimits(t, { 0.2, 0.2 }, { 0.5, 0.5 });
  // the time-optimal parameterization of the same straight path is the same trapezoid, with 98 % of the
  // acceleration (grid: 1e-3 of it)
  const ap::Trajectory o = ap::timeOptimal({ { 0.0, 0.0 }, { 1.0, 0.5 } }, { 0.0, 0.0 }, { 0.2 }, { 0.5 }, 0.01);
  EXPECT_NEAR(o.duration, 5.0 + 0.2 / (0.98 * 0.5), 5.4e-3);
  checkLimits(o, { 0.2, 0.2 }, { 0.5, 0.5 });
}

TEST(Trajectory, BlendedCornersStayWithinTheirToleranceAndSaveTime)
{
  const std::vector<Values> w = { { 0.0, 0.0, 0.0 }, { 0.6, 0.1, 0.0 }, { 0.7, 0.9, 0.3 }, { 0.2, 1.0, 0.9 } };
  const Values vmax = { 0.3, 0.2, 0.25 }, amax = { 1.0, 0.5, 2.0 };
  for (const double tolerance : { 0.005, 0.05, 1.0 })
  {
    const std::vector<double> d = ap::blendLengths(w, tolerance);
    ASSERT_EQ(d.size(), w.size());
    EXPECT_EQ(d.front(), 0.0);
    EXPECT_EQ(d.back(), 0.0);
    for (size_t k = 1; k + 1 < w.size(); ++k)
    {
      EXPECT_GT(d[k], 0.0);
      // at most half of either segment
      Values a(3), b(3);
      double la = 0.0, lb = 0.0;
      for (size_t i = 0; i < 3; ++i)
      {
        la += std::pow(w[k][i] - w[k - 1][i], 2);
        lb += std::pow(w[k + 1][i] - w[k][i], 2);
      }
      EXPECT_LE(d[k], 0.5 * std::sqrt(std::min(la, lb)) + 1e-15);
    }
    std::vector<int> corner;
    const std::vector<Values> curve = ap::blendedCurve(w, d, 0.01, &corner);
    ASSERT_EQ(curve.size(), corner.size());
    EXPECT_EQ(curve.front(), w.front());
    EXPECT_EQ(curve.back(), w.back());
    double farthest = 0.0;
    for (size_t k = 0; k < curve.size(); ++k)
    {
      farthest = std::max(farthest, distanceToPath(curve[k], w));
      if (k > 0)
      {
        EXPECT_LE(ap::actuationDistance(curve[k - 1], curve[k]), corner[k] < 0 ? 10.0 : 0.01 + 1e-12);
      }
    }
    EXPECT_LE(farthest, tolerance + 1e-9);

    const ap::Trajectory blended = ap::timeOptimal(w, d, vmax, amax, 0.01);
    const ap::Trajectory stops = ap::restToRest(w, vmax, amax, 0.01);
    checkLimits(blended, vmax, amax);
    for (const Values& p : blended.positions)
      EXPECT_LE(distanceToPath(p, w), tolerance + 2e-3);  // the samples: on the curve up to the grid
    EXPECT_LT(blended.duration, stops.duration);
    std::printf("[ measured ] blend tolerance %.3f m: %.3f s, rest to rest %.3f s\n", tolerance, blended.duration,
                stops.duration);
  }
  // no blending (every d = 0): it stops at the corners, no faster than rest to rest beyond the grid
  const ap::Trajectory sharp = ap::timeOptimal(w, std::vector<double>(w.size(), 0.0), vmax, amax, 0.01);
  checkLimits(sharp, vmax, amax);
  EXPECT_GE(sharp.duration, ap::restToRest(w, vmax, amax, 0.01).duration * (1.0 - 2e-3));
}
