// Closest points of two segments (core/geometry): random pairs against an independent numerical
// minimum, then the special configurations one by one (crossing, parallel, collinear, degenerate, end).
#include <algorithm>
#include <cmath>
#include <random>
#include <string>

#include <gtest/gtest.h>

#include "active_tensegrity/core/base/geometry.h"

using namespace active_tensegrity::core;

namespace
{
struct Segments
{
  Vec3 a1, b1, a2, b2;
};

double gap(const Segments& g, double s, double t)
{
  return ((g.a1 + s * (g.b1 - g.a1)) - (g.a2 + t * (g.b2 - g.a2))).norm();
}

// minimum of a convex function on [0, 1] by golden-section search (plain doubles: it runs ~10^7 times)
template <typename F>
double goldenMin(const F& f)
{
  const double r = 0.5 * (std::sqrt(5.0) - 1.0);
  double lo = 0.0, hi = 1.0;
  double x1 = hi - r * (hi - lo), x2 = lo + r * (hi - lo);
  double f1 = f(x1), f2 = f(x2);
  for (int i = 0; i < 80; ++i)  // 0.618^80 ~ 2e-17
  {
    if (f1 < f2)
    {
      hi = x2;
      x2 = x1;
      f2 = f1;
      x1 = hi - r * (hi - lo);
      f1 = f(x1);
    }
    else
    {
      lo = x1;
      x1 = x2;
      f1 = f2;
      x2 = lo + r * (hi - lo);
      f2 = f(x2);
    }
  }
  return std::min({ f(lo), f(hi), f1, f2 });
}

// |p1(s) - p2(t)| is jointly convex in (s, t), so its minimum over t is convex in s and the nested
// search finds the global minimum without using any formula of the code under test
double bruteForceDistance(const Segments& g)
{
  const Vec3 d1 = g.b1 - g.a1, d2 = g.b2 - g.a2, r = g.a1 - g.a2;
  const auto dist = [&](double s, double t)
  {
    const double x = r.x() + s * d1.x() - t * d2.x(), y = r.y() + s * d1.y() - t * d2.y(),
                 z = r.z() + s * d1.z() - t * d2.z();
    return std::sqrt(x * x + y * y + z * z);
  };
  return goldenMin([&](double s) { return goldenMin([&](double t) { return dist(s, t); }); });
}

// the smallest distance over an n x n grid of parameters (an upper bound of the true minimum that
// does not rely on convexity)
double gridDistance(const Segments& g, int n)
{
  double best = INFINITY;
  for (int i = 0; i <= n; ++i)
    for (int j = 0; j <= n; ++j)
      best = std::min(best, gap(g, double(i) / n, double(j) / n));
  return best;
}

// what every answer must satisfy: parameters in [0, 1], points on their segments, distance = |p1 - p2|
void expectConsistent(const Segments& g, const SegmentClosest& c)
{
  EXPECT_GE(c.s1, 0.0);
  EXPECT_LE(c.s1, 1.0);
  EXPECT_GE(c.s2, 0.0);
  EXPECT_LE(c.s2, 1.0);
  EXPECT_LT((c.p1 - (g.a1 + c.s1 * (g.b1 - g.a1))).norm(), 1e-12);
  EXPECT_LT((c.p2 - (g.a2 + c.s2 * (g.b2 - g.a2))).norm(), 1e-12);
  EXPECT_NEAR(c.distance, (c.p1 - c.p2).norm(), 1e-14);
  EXPECT_TRUE(std::isfinite(c.distance));
}

SegmentClosest closest(const Segments& g)
{
  return closestPointsSegments(g.a1, g.b1, g.a2, g.b2);
}
}  // namespace

TEST(ClosestPointsSegments, RandomPairsMatchTheNumericalMinimum)
{
  std::mt19937 rng(20240611);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const auto point = [&] { return Vec3(u(rng), u(rng), u(rng)); };
  int interior = 0, end = 0;
  for (int k = 0; k < 400; ++k)
  {
    const Segments g{ point(), point(), point(), point() };
    SCOPED_TRACE("pair " + std::to_string(k));
    const SegmentClosest c = closest(g);
    expectConsistent(g, c);
    const double brute = bruteForceDistance(g);
    EXPECT_NEAR(c.distance, brute, 1e-9);
    // never worse than any sample
    EXPECT_LE(c.distance, gridDistance(g, 40) + 1e-12);
    // region as reported
    ASSERT_NE(c.region, ClosestRegion::kParallel);
    const bool inside = c.s1 > 0.0 && c.s1 < 1.0 && c.s2 > 0.0 && c.s2 < 1.0;
    EXPECT_EQ(c.region, inside ? ClosestRegion::kInterior : ClosestRegion::kEnd);
    (inside ? interior : end)++;
  }
  // both regimes were exercised
  EXPECT_GT(interior, 20);
  EXPECT_GT(end, 20);
}

TEST(ClosestPointsSegments, RandomNearlyTouchingPairsMatchTheNumericalMinimum)
{
  // segment 2 passes within 1e-3 of an interior point of segment 1: small distances, where a wrong
  // branch shows most
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-1.0, 1.0), w(0.05, 0.95);
  for (int k = 0; k < 200; ++k)
  {
    SCOPED_TRACE("pair " + std::to_string(k));
    const Vec3 a1(u(rng), u(rng), u(rng)), b1(u(rng), u(rng), u(rng));
    const Vec3 near = a1 + w(rng) * (b1 - a1) + 1e-3 * Vec3(u(rng), u(rng), u(rng));
    const Vec3 d(u(rng), u(rng), u(rng));
    const double t = w(rng);
    const Segments g{ a1, b1, near - t * d, near + (1.0 - t) * d };
    const SegmentClosest c = closest(g);
    expectConsistent(g, c);
    EXPECT_NEAR(c.distance, bruteForceDistance(g), 1e-9);
    EXPECT_LE(c.distance, 2e-3);
  }
}

TEST(ClosestPointsSegments, SymmetricInTheOrderOfSegmentsAndOfEnds)
{
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int k = 0; k < 100; ++k)
  {
    const Vec3 a1(u(rng), u(rng), u(rng)), b1(u(rng), u(rng), u(rng));
    const Vec3 a2(u(rng), u(rng), u(rng)), b2(u(rng), u(rng), u(rng));
    const SegmentClosest c = closestPointsSegments(a1, b1, a2, b2);
    const SegmentClosest swapped = closestPointsSegments(a2, b2, a1, b1);
    const SegmentClosest reversed = closestPointsSegments(b1, a1, a2, b2);
    EXPECT_NEAR(swapped.distance, c.distance, 1e-12);
    EXPECT_NEAR(reversed.distance, c.distance, 1e-12);
    // the closest pair is unique for non-parallel segments
    EXPECT_LT((swapped.p1 - c.p2).norm(), 1e-9);
    EXPECT_LT((reversed.p1 - c.p1).norm(), 1e-9);
    EXPECT_NEAR(reversed.s1, 1.0 - c.s1, 1e-9);
  }
}

TEST(ClosestPointsSegments, CrossingAtRightAnglesIsInterior)
{
  // x axis at z = 0 and y axis at z = 0.3, crossing over the point (0.25, 0.5)
  const Segments g{ Vec3(-0.75, 0.5, 0.0), Vec3(1.25, 0.5, 0.0), Vec3(0.25, -0.5, 0.3), Vec3(0.25, 1.5, 0.3) };
  const SegmentClosest c = closest(g);
  expectConsistent(g, c);
  EXPECT_EQ(c.region, ClosestRegion::kInterior);
  EXPECT_DOUBLE_EQ(c.distance, 0.3);
  EXPECT_DOUBLE_EQ(c.s1, 0.5);
  EXPECT_DOUBLE_EQ(c.s2, 0.5);
  EXPECT_LT((c.p1 - Vec3(0.25, 0.5, 0.0)).norm(), 1e-15);
  EXPECT_LT((c.p2 - Vec3(0.25, 0.5, 0.3)).norm(), 1e-15);
  // intersecting: distance exactly zero
  const Segments x{ Vec3(-1.0, 0.0, 0.0), Vec3(1.0, 0.0, 0.0), Vec3(0.0, -1.0, 0.0), Vec3(0.0, 1.0, 0.0) };
  EXPECT_EQ(closest(x).distance, 0.0);
  EXPECT_EQ(closest(x).region, ClosestRegion::kInterior);
}

TEST(ClosestPointsSegments, ParallelOverlappingSegmentsGiveTheOffset)
{
  const Vec3 offset(0.0, 0.3, 0.4);  // |offset| = 0.5, normal to the axes
  const Vec3 d = Vec3(1.0, 2.0, -1.5).cross(offset).normalized();
  for (const double sign : { 1.0, -1.0 })  // same and opposite directions
  {
    SCOPED_TRACE(sign);
    const Segments g{ Vec3(0.1, 0.2, 0.3), Vec3(0.1, 0.2, 0.3) + 2.0 * d, Vec3(0.1, 0.2, 0.3) + offset + 0.5 * d,
                      Vec3(0.1, 0.2, 0.3) + offset + (0.5 + sign * 1.0) * d };
    const SegmentClosest c = closest(g);
    expectConsistent(g, c);
    EXPECT_FALSE(std::isnan(c.s1) || std::isnan(c.s2) || c.p1.hasNaN() || c.p2.hasNaN());
    EXPECT_EQ(c.region, ClosestRegion::kParallel);
    EXPECT_NEAR(c.distance, 0.5, 1e-12);
    // the representative pair lies on the overlap
    EXPECT_NEAR((c.p2 - c.p1).dot(d), 0.0, 1e-12);
  }
  // identical segments
  const Segments same{ Vec3(0.0, 0.0, 0.0), Vec3(1.0, 1.0, 1.0), Vec3(0.0, 0.0, 0.0), Vec3(1.0, 1.0, 1.0) };
  const SegmentClosest c = closest(same);
  expectConsistent(same, c);
  EXPECT_EQ(c.region, ClosestRegion::kParallel);
  EXPECT_EQ(c.distance, 0.0);
}

TEST(ClosestPointsSegments, ParallelDisjointSegmentsMeasureBetweenTheNearEnds)
{
  // parallel, offset by 0.3, with a gap of 0.4 along the axis: distance 0.5 between b1 and a2
  const Segments g{ Vec3(0.0, 0.0, 0.0), Vec3(1.0, 0.0, 0.0), Vec3(1.4, 0.3, 0.0), Vec3(2.4, 0.3, 0.0) };
  const SegmentClosest c = closest(g);
  expectConsistent(g, c);
  EXPECT_NEAR(c.distance, 0.5, 1e-12);
  EXPECT_DOUBLE_EQ(c.s1, 1.0);
  EXPECT_DOUBLE_EQ(c.s2, 0.0);
}

TEST(ClosestPointsSegments, CollinearSegmentsEndToEnd)
{
  const Vec3 d = Vec3(0.3, -0.4, 1.2).normalized();
  const Vec3 o(0.5, 0.5, 0.5);
  // a gap of 0.25 between b1 and a2
  const Segments apart{ o, o + d, o + 1.25 * d, o + 2.25 * d };
  const SegmentClosest c = closest(apart);
  expectConsistent(apart, c);
  EXPECT_NEAR(c.distance, 0.25, 1e-12);
  EXPECT_DOUBLE_EQ(c.s1, 1.0);
  EXPECT_DOUBLE_EQ(c.s2, 0.0);
  // touching end to end, the second one reversed
  const Segments touching{ o, o + d, o + 2.0 * d, o + d };
  const SegmentClosest t = closest(touching);
  expectConsistent(touching, t);
  EXPECT_NEAR(t.distance, 0.0, 1e-12);
  EXPECT_NEAR(t.s1, 1.0, 1e-12);
  EXPECT_NEAR(t.s2, 1.0, 1e-12);
}

TEST(ClosestPointsSegments, DegenerateSegmentIsAPoint)
{
  const Vec3 p(0.2, 1.0, 0.5);
  const Vec3 a(0.0, 0.0, 0.0), b(1.0, 0.0, 0.0);
  // point over the interior of the segment, given as either segment
  const SegmentClosest first = closestPointsSegments(p, p, a, b);
  expectConsistent({ p, p, a, b }, first);
  EXPECT_NEAR(first.distance, std::hypot(1.0, 0.5), 1e-15);
  EXPECT_NEAR(first.s2, 0.2, 1e-15);
  EXPECT_EQ(first.region, ClosestRegion::kEnd);
  const SegmentClosest second = closestPointsSegments(a, b, p, p);
  expectConsistent({ a, b, p, p }, second);
  EXPECT_NEAR(second.distance, std::hypot(1.0, 0.5), 1e-15);
  EXPECT_NEAR(second.s1, 0.2, 1e-15);
  // point beyond an end: clamped
  const Vec3 q(-0.3, 0.4, 0.0);
  EXPECT_NEAR(closestPointsSegments(q, q, a, b).distance, 0.5, 1e-15);
  EXPECT_DOUBLE_EQ(closestPointsSegments(a, b, q, q).s1, 0.0);
  // both points
  const SegmentClosest both = closestPointsSegments(p, p, q, q);
  EXPECT_NEAR(both.distance, (p - q).norm(), 1e-15);
  EXPECT_FALSE(both.p1.hasNaN() || both.p2.hasNaN());
}

TEST(ClosestPointsSegments, EndRegionWhenTheInfiniteLinesMeetOutsideASegment)
{
  // the lines cross at x = 2, beyond b1 = (1, 0, 0): the closest pair is b1 and the middle of segment 2
  const Segments g{ Vec3(0.0, 0.0, 0.0), Vec3(1.0, 0.0, 0.0), Vec3(2.0, -1.0, 1.0), Vec3(2.0, 1.0, 1.0) };
  const SegmentClosest c = closest(g);
  expectConsistent(g, c);
  EXPECT_EQ(c.region, ClosestRegion::kEnd);
  EXPECT_NEAR(c.distance, std::sqrt(2.0), 1e-15);
  EXPECT_DOUBLE_EQ(c.s1, 1.0);
  EXPECT_NEAR(c.s2, 0.5, 1e-15);
  // both beyond their ends: end to end
  const Segments corners{ Vec3(0.0, 0.0, 0.0), Vec3(1.0, 0.0, 0.0), Vec3(2.0, 1.0, 0.5), Vec3(2.0, 3.0, 0.5) };
  const SegmentClosest e = closest(corners);
  expectConsistent(corners, e);
  EXPECT_EQ(e.region, ClosestRegion::kEnd);
  EXPECT_NEAR(e.distance, std::sqrt(1.0 + 1.0 + 0.25), 1e-15);
  EXPECT_DOUBLE_EQ(e.s1, 1.0);
  EXPECT_DOUBLE_EQ(e.s2, 0.0);
}

TEST(ClosestPointsSegments, NearlyParallelOutsideTheToleranceIsExact)
{
  // angles between 1e-2 and 1e-5 rad are not 'parallel': the interior formula must stay accurate
  for (const double angle : { 1e-2, 1e-3, 1e-4, 1e-5 })
  {
    SCOPED_TRACE(angle);
    const Segments g{ Vec3(0.0, 0.0, 0.0), Vec3(1.0, 0.0, 0.0), Vec3(0.3, 0.0, 1e-3),
                      Vec3(0.3 + std::cos(angle), std::sin(angle), 1e-3) };
    const SegmentClosest c = closest(g);
    expectConsistent(g, c);
    EXPECT_NE(c.region, ClosestRegion::kParallel);
    EXPECT_NEAR(c.distance, bruteForceDistance(g), 1e-12);
  }
}
