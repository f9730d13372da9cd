#include "active_tensegrity/core/base/geometry.h"

#include <algorithm>
#include <cmath>

namespace active_tensegrity::core
{
namespace
{
double clamp01(double x)
{
  return std::min(1.0, std::max(0.0, x));
}
}  // namespace

SegmentClosest closestPointsSegments(const Vec3& a1, const Vec3& b1, const Vec3& a2, const Vec3& b2)
{
  const Vec3 d1 = b1 - a1;
  const Vec3 d2 = b2 - a2;
  const Vec3 r = a1 - a2;
  const double a = d1.squaredNorm();
  const double e = d2.squaredNorm();
  const double f = d2.dot(r);
  SegmentClosest out;
  double s = 0.0, t = 0.0;
  bool parallel = false;
  if (a <= 1e-300 && e <= 1e-300)
  {
    s = t = 0.0;
  }
  else if (a <= 1e-300)
  {
    t = clamp01(f / e);
  }
  else
  {
    const double c = d1.dot(r);
    if (e <= 1e-300)
    {
      s = clamp01(-c / a);
    }
    else
    {
      const double b = d1.dot(d2);
      const double denom = a * e - b * b;  // = |d1 x d2|^2 >= 0
      if (denom > 1e-12 * a * e)
        s = clamp01((b * f - c * e) / denom);
      else
      {
        // parallel: take the middle of the overlap seen from segment 1
        parallel = true;
        const double t0 = clamp01(-c / a);
        const double t1 = clamp01((b - c) / a);
        s = 0.5 * (t0 + t1);
      }
      t = (b * s + f) / e;
      if (t < 0.0)
      {
        t = 0.0;
        s = clamp01(-c / a);
      }
      else if (t > 1.0)
      {
        t = 1.0;
        s = clamp01((b - c) / a);
      }
    }
  }
  out.s1 = s;
  out.s2 = t;
  out.p1 = a1 + s * d1;
  out.p2 = a2 + t * d2;
  out.distance = (out.p1 - out.p2).norm();
  if (parallel)
    out.region = ClosestRegion::kParallel;
  else if (s <= 0.0 || s >= 1.0 || t <= 0.0 || t >= 1.0)
    out.region = ClosestRegion::kEnd;
  else
    out.region = ClosestRegion::kInterior;
  return out;
}

}  // namespace active_tensegrity::core
